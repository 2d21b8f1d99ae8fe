"""The studio's web server: the page, its JSON API and the command line.

Routes (JSON in and out; every error is ``{"error": message}`` with a 4xx code, or 503 when the save
folder is gone and 507 when its disk is full; a 500 is a bug):

=======================  ==============================================================
``GET /``                the page
``GET /api/domains``     the domains, their maps and the "Try it" bounds
``GET /api/geometry``    ``?domain=&map=``: the map to draw
``POST /api/validate``   a drawing (see :mod:`~torchrl_subgoal.studio.document`): ok or why not
``GET /api/files``       the subgoal files in the save folder
``GET /api/files/NAME``  one file as a drawing (``/files/NAME``: the file itself)
``PUT /api/files/NAME``  save a drawing as ``NAME`` (``.yaml`` added when no suffix);
                         ``?overwrite=1`` to replace an existing file (else 409)
``POST /api/try``        start a "Try it" learning of one pattern: ``{..drawing, pattern, method,
                         episodes, learners, max_steps}``; 202 with the job
``GET /api/try/ID``      the job's state, progress and, when done, its result
``DELETE /api/try/ID``   cancel it
=======================  ==============================================================

Every request is checked first (:func:`create_app`): it must carry a ``Host`` header naming one this
studio serves (loopback names and the addresses it listens on), a browser's
``Origin`` must be the studio's own, anything that changes state (POST, PUT; a
DELETE that has a body) must be JSON (``Content-Type: application/json``), and with a token (the
command line makes one per launch) every request but the page's static files must
carry it. So neither another web site the user visits nor a DNS-rebinding page can
drive the studio.
"""

from __future__ import annotations

import argparse
import contextlib
import hmac
import io
import ipaddress
import logging
import secrets
import socket
import sys
import tempfile
import threading
import webbrowser
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any
from urllib.parse import quote, urlsplit

from flask import Flask, Response, jsonify, render_template, request, send_file
from werkzeug.exceptions import HTTPException
from werkzeug.serving import BaseWSGIServer, get_sockaddr, make_server, select_address_family

from torchrl_subgoal.registry import load_patterns
from torchrl_subgoal.studio.document import (
    MAX_REQUEST_BYTES,
    SUFFIXES,
    RequestError,
    file_path,
    folder_error,
    infer_domain,
    parse_json,
    read_drawing,
    read_file,
    save_drawing,
    to_document,
)
from torchrl_subgoal.studio.domains import Domain, default_domains
from torchrl_subgoal.studio.jobs import JobError, Jobs
from torchrl_subgoal.studio.training import METHODS, TrySettings, try_pattern
from torchrl_subgoal.subgoals import (
    MAX_FILE_BYTES,
    SubgoalFileError,
    file_description,
    parse_text,
)

__all__ = ["create_app", "listen", "main", "serve", "served_hosts", "studio_url"]

log = logging.getLogger(__name__)
DEFAULT_PORT = 8765
#: The header (or ``?token=`` in a URL) that carries the studio's per-launch token.
TOKEN_HEADER = "X-Studio-Token"
#: Methods that change state: only JSON requests (a DELETE may carry no body), which a browser sends to
#: another site only after asking it (a CORS preflight, which the studio never grants).
_UNSAFE = frozenset({"POST", "PUT", "PATCH", "DELETE"})
#: Sent with every response: no framing (clickjacking), no MIME sniffing, no referrer (it would carry
#: the token), no reading by another site's ``<img>``/``<script>``.
_HEADERS = {
    "Content-Security-Policy": "frame-ancestors 'none'",
    "X-Frame-Options": "DENY",
    "X-Content-Type-Options": "nosniff",
    "Referrer-Policy": "no-referrer",
    "Cross-Origin-Resource-Policy": "same-origin",
}


class Studio:
    """The state behind one app: save folder, domains, jobs.

    Examples:
        >>> import tempfile
        >>> from torchrl_subgoal.studio.jobs import Jobs
        >>> studio = Studio(Path(tempfile.mkdtemp()), default_domains(), Jobs(max_running=1))
        >>> "four_rooms" in studio.domains
        True
    """

    def __init__(self, folder: Path, domains: Mapping[str, Domain], jobs: Jobs) -> None:
        self.folder = folder
        self.domains = domains
        self.jobs = jobs


def _error(message: str, status: int) -> tuple[Response, int]:
    return jsonify(error=message), status


def _body() -> Any:
    return parse_json(request.get_data(cache=False))


def _host_name(host: str) -> str | None:
    """The name in a ``Host`` header (``"[::1]:8765"`` -> ``"::1"``), lower case; ``None`` if malformed."""
    try:
        parts = urlsplit(f"//{host}")
        parts.port  # noqa: B018  (raises ValueError for a bad port)
    except ValueError:
        return None
    name = parts.hostname
    return name.rstrip(".") if name else None


def _is_loopback(name: str) -> bool:
    if name == "localhost":
        return True
    try:
        return ipaddress.ip_address(name).is_loopback
    except ValueError:
        return False


def served_hosts(host: str) -> list[str]:
    """The host names a studio listening on ``host`` answers to, besides the loopback ones.

    ``host`` itself, or for an unspecified address (``0.0.0.0``, ``::``) this machine's
    name, its fully qualified name and their addresses (others can be added with
    ``--allow-host``).

    Args:
        host: the address the server listens on.

    Examples:
        >>> served_hosts("127.0.0.1")
        ['127.0.0.1']
        >>> socket.gethostname().lower() in served_hosts("0.0.0.0")
        True
    """
    try:
        unspecified = ipaddress.ip_address(host.strip("[]")).is_unspecified
    except ValueError:
        unspecified = False
    if not unspecified:
        return [host.strip("[]").lower()]
    names = {socket.gethostname(), socket.getfqdn()}
    for name in list(names):
        with contextlib.suppress(OSError):
            names.update(str(info[4][0]) for info in socket.getaddrinfo(name, None))
    return sorted(n.lower() for n in names if n)


def _check_request(hosts: frozenset[str], token: str | None) -> None:
    """Refuse a request a foreign page could have made (see the module doc); raises :class:`RequestError`."""
    if "HTTP_HOST" not in request.environ:  # else werkzeug makes one up from the server's own address
        raise RequestError(
            "request: no Host header; the studio answers only requests that name it: open the address it printed",
            status=403,
        )
    name = _host_name(request.host)
    if name is None or not (name in hosts or _is_loopback(name)):
        served = ", ".join(["localhost", "127.0.0.1", "::1", *sorted(hosts - {"localhost", "127.0.0.1", "::1"})])
        raise RequestError(
            f"request: the host {request.host!r} is not served by this studio (it answers to "
            f"{served}); open the address it printed, or start it with --allow-host NAME",
            status=403,
        )
    origin = request.headers.get("Origin")
    if origin is not None and origin.lower() != f"{request.scheme}://{request.host}".lower():
        raise RequestError(f"request: from another site ({origin}); the studio answers only its own page", status=403)
    private = request.path.startswith(("/api/", "/files/"))
    if private and request.headers.get("Sec-Fetch-Site") in ("cross-site", "same-site"):
        raise RequestError("request: from another site; the studio answers only its own page", status=403)
    if token is not None and (private or request.path == "/"):
        given = request.headers.get(TOKEN_HEADER) or request.args.get("token") or ""
        if not hmac.compare_digest(given.encode(), token.encode()):
            raise RequestError(
                "request: the studio's token is missing or wrong; open the address it printed (with its ?token=...)",
                status=403,
            )
    bodiless = request.method == "DELETE" and not request.mimetype  # a DELETE carries nothing to read
    routed = request.url_rule is not None  # else the 404 or 405 says more
    if routed and request.method in _UNSAFE and not bodiless and request.mimetype != "application/json":
        raise RequestError(
            f"request: {request.method} needs a JSON body (Content-Type: application/json), got "
            f"{request.mimetype or 'no content type'!r}",
            status=415,
        )


def create_app(
    folder: str | Path,
    *,
    pinball_maps: Mapping[str, str | Path] | None = None,
    max_jobs: int = 2,
    hosts: Iterable[str] = (),
    token: str | None = None,
) -> Flask:
    """The studio as a Flask app saving into ``folder`` (created if missing).

    Every request must name a host the studio serves (the loopback names and
    ``hosts``); a browser's request must come from the studio's own page (its
    ``Origin``); POST and PUT must send JSON; with ``token``, every request
    but the static files must carry it (header ``X-Studio-Token`` or ``?token=``).
    Anything else is refused with a 4xx and changes nothing.

    Args:
        folder: where subgoal files are listed, opened and saved.
        pinball_maps: extra PinBall maps, name -> configuration file.
        max_jobs: "Try it" learnings that may run at once.
        hosts: host names served besides the loopback ones (see :func:`served_hosts`).
        token: a secret every request must carry (``None``: none needed).

    Examples:
        >>> import tempfile
        >>> app = create_app(tempfile.mkdtemp())
        >>> app.test_client().get("/api/domains").json[0]["name"]
        'four_rooms'
        >>> app.test_client().get("/api/domains", headers={"Host": "evil.example"}).status_code
        403
    """
    app = Flask(__name__)
    served = frozenset(n.strip("[]").lower().rstrip(".") for n in hosts)
    app.config["MAX_CONTENT_LENGTH"] = MAX_REQUEST_BYTES
    app.url_map.merge_slashes = False  # "//etc/passwd" is a bad file name, not a redirect
    root = Path(folder)
    root.mkdir(parents=True, exist_ok=True)
    studio = Studio(root, default_domains(pinball_maps), Jobs(max_running=max_jobs))
    app.extensions["studio"] = studio

    @app.before_request
    def check_request() -> None:
        _check_request(served, token)

    @app.after_request
    def secure_headers(response: Response) -> Response:
        for header, value in _HEADERS.items():
            response.headers.setdefault(header, value)
        return response

    @app.errorhandler(RequestError)
    def bad_request(exc: RequestError) -> Any:
        if not request.path.startswith(("/api/", "/files/")):  # the page: a line of text, not JSON
            return Response(str(exc) + "\n", status=exc.status, mimetype="text/plain")
        return _error(str(exc), exc.status)

    @app.errorhandler(JobError)
    def job_refused(exc: JobError) -> tuple[Response, int]:
        return _error(str(exc), exc.status)

    @app.errorhandler(HTTPException)
    def http_error(exc: HTTPException) -> Any:
        if not request.path.startswith("/api/"):
            return exc
        if exc.code == 413:
            return _error(f"request: over the limit of {MAX_REQUEST_BYTES} bytes", 413)
        return _error(f"{request.method} {request.path}: {exc.description}", exc.code or 500)

    @app.errorhandler(Exception)
    def internal_error(exc: Exception) -> tuple[Response, int]:
        log.exception("studio: %s %s failed", request.method, request.path)
        return _error(f"internal error: {type(exc).__name__}: {exc} (please report it)", 500)

    @app.get("/")
    def index() -> str:
        return render_template("index.html", folder=str(root.resolve()))

    @app.get("/api/domains")
    def domains() -> Response:
        return jsonify([d.describe() for d in studio.domains.values()])

    @app.get("/api/geometry")
    def geometry() -> Response:
        domain = _domain(studio, request.args.get("domain"))
        map_name = request.args.get("map") or next(iter(domain.maps), "")
        if domain.maps and map_name not in domain.maps:
            raise RequestError(f"map: expected one of {list(domain.maps)}, got {map_name!r}")
        assert domain.geometry is not None  # the studio serves only domains with a map
        return jsonify(domain.geometry(domain.maps.get(map_name, "")))

    @app.post("/api/validate")
    def validate() -> Response:
        data = _body()
        source = _source(data)
        drawing = read_drawing(data, studio.domains, source=source)
        return jsonify(ok=True, patterns=list(drawing.patterns))

    @app.get("/api/files")
    def files() -> Response:
        resolved = root.resolve()
        try:
            entries = sorted(resolved.iterdir())
        except OSError as exc:
            raise folder_error(exc, resolved, "list the files") from None
        listed = []
        for p in entries:
            if p.suffix.lower() not in SUFFIXES or p.name.startswith("."):
                continue
            try:  # links out of the folder are not listed; an entry removed meanwhile neither
                if p.resolve(strict=True).parent == resolved and p.is_file():
                    listed.append({"name": p.name, "bytes": p.stat().st_size})
            except (OSError, RuntimeError):
                continue
        return jsonify(folder=str(resolved), files=listed)

    @app.get("/api/files/<path:name>")
    def open_file(name: str) -> Response:
        path, data = read_file(root, name)
        with tempfile.TemporaryDirectory(prefix="studio-open-") as private:
            copy = Path(private) / path.name
            copy.write_bytes(data)
            try:
                patterns = load_patterns(copy)
                description = file_description(copy)
                declared = parse_text(data, path.name).get("domain")  # a mapping: the file loaded
            except SubgoalFileError as exc:
                raise RequestError(str(exc).replace(str(copy), path.name), status=422) from None
        domain = infer_domain(patterns, studio.domains, path.name, declared if isinstance(declared, str) else None)
        return jsonify(
            file=path.name,
            path=str(path),
            domain=domain.name,
            recipe=_recipe(domain, path),
            description=description,
            patterns=to_document(patterns, domain, path.name),
        )

    @app.get("/files/<path:name>")
    def download(name: str) -> Response:
        path, data = read_file(root, name)
        if len(data) > MAX_FILE_BYTES:
            raise RequestError(
                f"{path.name}: larger than {MAX_FILE_BYTES} bytes, the limit for a subgoal file", status=422
            )
        return send_file(io.BytesIO(data), mimetype="text/plain", as_attachment=True, download_name=path.name)

    @app.put("/api/files/<path:name>")
    def save(name: str) -> Response:
        path = file_path(root, name)
        overwrite = request.args.get("overwrite", "").lower() in ("1", "true", "yes")
        data = _body()
        drawing = read_drawing(data, studio.domains, source=path.name)
        save_drawing(drawing, path, overwrite=overwrite)
        return jsonify(
            file=path.name,
            path=str(path),
            domain=drawing.domain.name,
            patterns=list(drawing.patterns),
            recipe=_recipe(drawing.domain, path, drawing.map),
        )

    @app.post("/api/try")
    def start_try() -> tuple[Response, int]:
        data = _body()
        if not isinstance(data, Mapping):
            raise RequestError("request: expected a JSON object")
        fields = {"pattern", "method", "episodes", "learners", "max_steps"}
        drawing = read_drawing({k: v for k, v in data.items() if k not in fields}, studio.domains, source=_source(data))
        name = data.get("pattern", next(iter(drawing.patterns)) if len(drawing.patterns) == 1 else None)
        if not isinstance(name, str) or name not in drawing.patterns:
            raise RequestError(f"pattern: expected one of {list(drawing.patterns)}, got {name!r}")
        method = data.get("method", "HRS-D")
        if not isinstance(method, str) or method not in METHODS:
            raise RequestError(f"method: expected one of {list(METHODS)}, got {method!r}")
        domain = drawing.domain
        if not domain.limits:
            raise RequestError(f"Try it: {domain.try_note or 'not offered for ' + domain.title}")
        given = {k: data.get(k, limit.default) for k, limit in domain.limits.items()}
        try:
            values = {k: domain.limits[k].check(v, k) for k, v in given.items()}
        except ValueError as exc:
            raise RequestError(str(exc)) from None
        settings = TrySettings(values["episodes"], values["learners"], max_steps=values["max_steps"])
        series = drawing.patterns[name]
        map_ = domain.maps.get(drawing.map)

        def work(progress: Any) -> dict[str, Any]:
            result = try_pattern(domain.name, series, settings, method=method, map=map_, progress=progress)
            return {**result.to_json(), "pattern": name}

        key = f"{domain.name}/{name}/{method}"
        job = studio.jobs.start(key, 2 * settings.learners * settings.episodes, work)
        return jsonify(job.status()), 202

    @app.get("/api/try/<job_id>")
    def poll(job_id: str) -> Response:
        return jsonify(_job(studio, job_id).status())

    @app.delete("/api/try/<job_id>")
    def cancel(job_id: str) -> Response:
        studio.jobs.cancel(job_id)
        return jsonify(_job(studio, job_id).status())

    return app


def _source(data: Any) -> str:
    """The file name messages about a drawing name (the page's file name, else ``drawing.yaml``)."""
    name = data.get("file") if isinstance(data, Mapping) else None
    if not name:
        return "drawing.yaml"
    return Path(file_path(Path("."), str(name))).name


def _recipe(domain: Domain, path: Path, map_name: str = "") -> str:
    """The command that trains with the file (on the map it was drawn on)."""
    command = f"{domain.recipe} --subgoals {path}"
    return f"{command} --map {domain.maps[map_name]}" if map_name else command


def _domain(studio: Studio, name: str | None) -> Domain:
    if name is None or name not in studio.domains:
        raise RequestError(f"domain: expected one of {sorted(studio.domains)}, got {name!r}")
    return studio.domains[name]


def _job(studio: Studio, job_id: str) -> Any:
    job = studio.jobs.get(job_id)
    if job is None:
        raise RequestError(f"job {job_id!r}: unknown (finished jobs are forgotten after a while)", status=404)
    return job


def serve(app: Flask, host: str = "127.0.0.1", port: int = 0) -> BaseWSGIServer:
    """A threaded server for ``app`` (``port=0``: a free port; see ``.port``); call ``serve_forever``.

    Raises:
        OSError: when ``host:port`` cannot be bound (in use, unknown host).

    Examples:
        >>> server = serve(Flask("demo"))  # a free port on 127.0.0.1
        >>> server.port > 0
        True
        >>> server.server_close()
    """
    family = select_address_family(host, port)
    with socket.socket(family, socket.SOCK_STREAM) as sock:  # bound here: werkzeug would exit the process
        sock.bind(get_sockaddr(host, port, family))
        sock.listen(128)
        return make_server(host, port, app, threaded=True, fd=sock.fileno())


def listen(app: Flask, host: str, port: int | None) -> BaseWSGIServer:
    """:func:`serve` on ``port``; ``None``: on :data:`DEFAULT_PORT`, or a free port when it is taken.

    Raises:
        OSError: naming the host and port when the server cannot listen.

    Examples:
        >>> server = listen(Flask("demo"), "127.0.0.1", 0)
        >>> server.port > 0
        True
        >>> server.server_close()
    """
    for candidate in [port] if port is not None else [DEFAULT_PORT, 0]:
        try:
            return serve(app, host, candidate)
        except OSError as exc:
            error = f"--host {host} --port {candidate}: cannot listen: {exc}"
    raise OSError(error)


def _pinball_maps(values: Sequence[str]) -> dict[str, str]:
    maps = {}
    for value in values:
        name, _, path = value.rpartition("=")
        maps[name or Path(path).stem] = path
    return maps


def studio_url(host: str, port: int, token: str | None = None) -> str:
    """The address of the page (with its token), as the command line prints it.

    Args:
        host: the address the server listens on (an unspecified one prints as this machine's name).
        port: its port.
        token: the studio's token, if it has one.

    Examples:
        >>> studio_url("127.0.0.1", 8765, "abc")
        'http://127.0.0.1:8765/?token=abc'
        >>> studio_url("::1", 8765)
        'http://[::1]:8765/'
    """
    with contextlib.suppress(ValueError):
        if ipaddress.ip_address(host.strip("[]")).is_unspecified:
            host = socket.gethostname()
    host = host.strip("[]")
    shown = f"[{host}]" if ":" in host else host
    return f"http://{shown}:{port}/" + (f"?token={quote(token)}" if token else "")


def main(argv: Sequence[str] | None = None) -> int:
    """``torchrl-subgoal studio`` / ``python -m torchrl_subgoal.studio``: serve the studio until Ctrl-C.

    Examples:
        >>> main(["--max-jobs", "0"])  # a one-line error on stderr
        2
    """
    parser = argparse.ArgumentParser(
        prog="torchrl-subgoal studio",
        description="Subgoal studio: draw subgoal series on the map, save subgoal files, try them.",
    )
    parser.add_argument(
        "--folder",
        type=Path,
        default=Path("subgoals"),
        help="where subgoal files are opened and saved (default: ./subgoals)",
    )
    parser.add_argument("--host", default="127.0.0.1", help="address to listen on (default: 127.0.0.1)")
    parser.add_argument(
        "--port", type=int, default=None, help=f"port (default: {DEFAULT_PORT}, or a free one if taken; 0: a free one)"
    )
    parser.add_argument(
        "--pinball-map",
        action="append",
        default=[],
        metavar="[NAME=]FILE",
        help="an extra PinBall configuration file to draw on (repeatable)",
    )
    parser.add_argument("--max-jobs", type=int, default=2, help="'Try it' learnings at once (default: 2)")
    parser.add_argument(
        "--allow-host",
        action="append",
        default=[],
        metavar="NAME",
        help="another host name the page may be opened under, e.g. behind a proxy (repeatable)",
    )
    parser.add_argument("--open", action="store_true", help="open the page in a web browser")
    args = parser.parse_args(argv)
    if args.max_jobs < 1:
        print("error: --max-jobs: must be >= 1", file=sys.stderr)
        return 2
    import torch

    logging.getLogger("werkzeug").setLevel(logging.WARNING)  # no line per request
    torch.set_num_threads(1)  # batched small ops run fastest on one thread
    token = secrets.token_urlsafe(24)
    try:
        app = create_app(
            args.folder,
            pinball_maps=_pinball_maps(args.pinball_map),
            max_jobs=args.max_jobs,
            hosts=[*served_hosts(args.host), *args.allow_host],
            token=token,
        )
    except (OSError, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    try:
        server = listen(app, args.host, args.port)
    except OSError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    try:
        loopback = ipaddress.ip_address(socket.gethostbyname(args.host)).is_loopback
    except (OSError, ValueError):
        loopback = False
    if not loopback:
        print(
            f"warning: listening on {args.host}: anyone who reaches it with the address below (its token) can "
            f"write subgoal files in {args.folder} and start learnings",
            file=sys.stderr,
        )
    url = studio_url(args.host, server.port, token)
    print(f"Subgoal studio at {url} (files in {args.folder.resolve()}); Ctrl-C stops it", flush=True)
    if args.open:
        threading.Timer(0.5, webbrowser.open, args=(url,)).start()
    try:
        server.serve_forever()
    except KeyboardInterrupt:
        pass
    finally:
        server.server_close()
        app.extensions["studio"].jobs.shutdown()
    return 0

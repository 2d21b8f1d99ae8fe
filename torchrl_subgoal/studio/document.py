"""The studio's drawings: JSON requests to and from subgoal files, validated by the subgoal loader.

A *drawing* is what the page sends: the domain, the map, and a list of
patterns, each with its name, its subgoals (a predicate as in a subgoal file,
plus an optional ``name``) and ``order`` (``null`` for the chain, else
``[before, after]`` pairs of subgoal names)::

    {"domain": "four_rooms", "map": "", "patterns": [
        {"name": "hallways", "subgoals": [{"cell": [3, 6]}, {"cell": [7, 9]}], "order": null}]}

:func:`read_drawing` turns it into the subgoal file it would save and checks
that file with :func:`torchrl_subgoal.load_patterns`, the very code
``torchrl_subgoal.load_pattern`` and the recipes run, so whatever the studio saves
the recipes read. Every problem is a :class:`RequestError` whose message names
the file, the pattern and the field.
"""

from __future__ import annotations

import errno
import itertools
import json
import math
import os
import re
import secrets
import stat
import tempfile
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from torchrl_subgoal.registry import load_patterns
from torchrl_subgoal.studio.domains import Domain, FormError
from torchrl_subgoal.subgoals import (
    FORMAT,
    MAX_FILE_BYTES,
    Predicate,
    SubgoalFileError,
    SubgoalSeries,
    save_patterns,
)

__all__ = [
    "Drawing",
    "RequestError",
    "file_path",
    "folder_error",
    "parse_json",
    "read_drawing",
    "read_file",
    "save_drawing",
    "to_document",
]

MAX_REQUEST_BYTES = 256 * 1024
#: Arrays and objects nested deeper than this are refused (a drawing needs about 7 levels).
MAX_DEPTH = 32
SUFFIXES = (".yaml", ".yml", ".json")
_NAME = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.-]{0,79}")


class RequestError(ValueError):
    """A bad request: the page shows the message; ``status`` is the HTTP code.

    Examples:
        >>> error = RequestError("alice.yaml: not a subgoal file", status=422)
        >>> str(error), error.status
        ('alice.yaml: not a subgoal file', 422)
    """

    def __init__(self, message: str, status: int = 400) -> None:
        super().__init__(message)
        self.status = status


def parse_json(body: bytes) -> Any:
    """Decode a request body; duplicate keys, NaN and bad UTF-8 are errors, not silently merged.

    So are values nested deeper than :data:`MAX_DEPTH`, numbers that are not finite
    (``1e400``) or too long to convert, and strings that cannot be written as UTF-8
    (a lone surrogate such as ``"\\ud800"``): every malformed body is a
    :class:`RequestError` (400), never an exception of the decoder.

    Args:
        body: the request's bytes.

    Examples:
        >>> parse_json(b'{"a": 1}')
        {'a': 1}
        >>> parse_json(b'{"a": 1, "a": 2}')
        Traceback (most recent call last):
        ...
        torchrl_subgoal.studio.document.RequestError: request: the key 'a' appears twice in one object
        >>> parse_json(b"[" * 100 + b"]" * 100)
        Traceback (most recent call last):
        ...
        torchrl_subgoal.studio.document.RequestError: request: nested deeper than 32 levels
    """
    if len(body) > MAX_REQUEST_BYTES:
        raise RequestError(f"request: {len(body)} bytes, over the limit of {MAX_REQUEST_BYTES}", status=413)

    def unique(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
        out: dict[str, Any] = {}
        for key, value in pairs:
            if key in out:
                raise RequestError(f"request: the key {key!r} appears twice in one object")
            out[key] = value
        return out

    def constant(name: str) -> Any:
        raise RequestError(f"request: {name} is not a JSON number")

    try:
        text = body.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise RequestError(f"request: the body is not UTF-8 text ({exc.reason} at byte {exc.start})") from None
    _check_nesting(text)
    try:
        data = json.loads(text, object_pairs_hook=unique, parse_constant=constant)
    except RequestError:
        raise
    except json.JSONDecodeError as exc:
        raise RequestError(f"request: not valid JSON: {exc.msg} (line {exc.lineno}, column {exc.colno})") from None
    except (ValueError, RecursionError) as exc:  # e.g. an integer of more digits than Python converts
        raise RequestError(f"request: not valid JSON: {' '.join(str(exc).split())}") from None
    _check_values(data)
    return data


def _check_nesting(text: str) -> None:
    """Refuse text whose brackets nest deeper than :data:`MAX_DEPTH`, before the decoder recurses into it."""
    depth = 0
    in_string = escaped = False
    for char in text:
        if in_string:
            if escaped:
                escaped = False
            elif char == "\\":
                escaped = True
            elif char == '"':
                in_string = False
        elif char == '"':
            in_string = True
        elif char in "[{":
            depth += 1
            if depth > MAX_DEPTH:
                raise RequestError(f"request: nested deeper than {MAX_DEPTH} levels")
        elif char in "]}":
            depth -= 1


def _check_values(data: Any) -> None:
    """Refuse numbers that are not finite and strings that are not valid Unicode text (lone surrogates)."""
    stack = [data]
    while stack:
        value = stack.pop()
        if isinstance(value, dict):
            stack.extend(value.keys())
            stack.extend(value.values())
        elif isinstance(value, list):
            stack.extend(value)
        elif isinstance(value, float) and not math.isfinite(value):
            raise RequestError(f"request: a number is too large to be finite ({value})")
        elif isinstance(value, str):
            try:
                value.encode("utf-8")
            except UnicodeEncodeError as exc:
                raise RequestError(
                    f"request: a string holds {value[exc.start]!r}, which is not a character (a lone surrogate)"
                ) from None


def file_name(name: str) -> str:
    """A safe file name in the save folder: ``.yaml`` is added when no suffix is given.

    Examples:
        >>> file_name("alice"), file_name("bob.json")
        ('alice.yaml', 'bob.json')
        >>> file_name("../etc/passwd")
        Traceback (most recent call last):
        ...
        torchrl_subgoal.studio.document.RequestError: file name '../etc/passwd': use letters, digits, ...
    """
    if not isinstance(name, str) or not _NAME.fullmatch(name) or ".." in name:
        raise RequestError(
            f"file name {name!r}: use letters, digits, '_', '-' and '.' (at most 80, not starting with '.' or '-')"
        )
    return name if name.lower().endswith(SUFFIXES) else f"{name}.yaml"


def file_path(folder: Path, name: str) -> Path:
    """``folder / file_name(name)``: a name directly in ``folder`` (resolved), whatever is there.

    The last component is not resolved: a link of that name is the link itself, which
    saving replaces (see :func:`save_drawing`) and reading follows only into ``folder``.

    Examples:
        >>> import tempfile
        >>> folder = Path(tempfile.mkdtemp())
        >>> file_path(folder, "alice") == folder.resolve() / "alice.yaml"
        True
    """
    root = folder.resolve()
    path = root / file_name(name)
    if path.parent != root:
        raise RequestError(f"file name {name!r}: must name a file directly in the save folder")
    return path


@dataclass
class Drawing:
    """A checked drawing: its domain, map and patterns, ready to save or train.

    Examples:
        >>> from torchrl_subgoal.studio.domains import default_domains
        >>> from torchrl_subgoal.subgoals import Cell
        >>> series = SubgoalSeries([Cell(4, 9)], name="alice")
        >>> drawing = Drawing(default_domains()["four_rooms"], "", {"alice": series}, "a hallway")
        >>> drawing.domain.name, list(drawing.patterns)
        ('four_rooms', ['alice'])
    """

    domain: Domain
    map: str
    patterns: dict[str, SubgoalSeries]
    description: str | None = None


def _expect(condition: bool, message: str) -> None:
    if not condition:
        raise RequestError(message)


def _pattern_body(index: int, raw: Any, domain: Domain) -> tuple[str, dict[str, Any]]:
    """One request pattern as the file's ``patterns: {name: body}`` entry."""
    where = f"request: patterns[{index}]"
    _expect(isinstance(raw, Mapping), f"{where}: expected an object with name, subgoals and order")
    unknown = set(raw) - {"name", "subgoals", "order", "description"}
    _expect(not unknown, f"{where}: unknown field(s) {sorted(unknown)}; allowed: name, subgoals, order, description")
    described = {"description": raw["description"]} if raw.get("description") is not None else {}
    name = raw.get("name")
    _expect(isinstance(name, str) and name.strip() != "", f"{where}.name: expected a non-empty string")
    subgoals = raw.get("subgoals")
    _expect(isinstance(subgoals, list), f"{where}.subgoals: expected a list of subgoals")
    predicates, names = [], []
    for j, sg in enumerate(subgoals):
        _expect(isinstance(sg, Mapping), f'{where}.subgoals[{j}]: expected an object such as {{"cell": [3, 6]}}')
        label = sg.get("name")
        _expect(
            label is None or (isinstance(label, str) and label.strip() != ""),
            f"{where}.subgoals[{j}].name: expected a non-empty string or null",
        )
        names.append(label)
        try:
            predicates.append(domain.from_page({k: v for k, v in sg.items() if k != "name"}, f"{where}.subgoals[{j}]"))
        except FormError as exc:
            raise RequestError(str(exc)) from None
    order = raw.get("order")
    _expect(order is None or isinstance(order, list), f"{where}.order: expected null (a chain) or a list of pairs")
    if order is None and not any(names):
        return name, {**described, "subgoals": predicates}
    full = [label or f"sg{j + 1}" for j, label in enumerate(names)]
    seen: set[str] = set()
    for label in full:
        _expect(label not in seen, f"request: pattern {name!r}: the subgoal name {label!r} is used twice")
        seen.add(label)
    chain = [[a, b] for a, b in itertools.pairwise(full)]
    return name, {
        **described,
        "subgoals": dict(zip(full, predicates, strict=True)),
        "order": chain if order is None else order,
    }


def _load(data: Mapping[str, Any], source: str, domain: str) -> dict[str, SubgoalSeries]:
    """Write ``data`` as the subgoal file ``source`` would be and load it with :func:`load_patterns`."""
    with tempfile.TemporaryDirectory(prefix="studio-") as tmp:
        path = Path(tmp) / source
        path.write_text(yaml.safe_dump(dict(data), sort_keys=False))
        try:
            return load_patterns(path, domain=domain)
        except SubgoalFileError as exc:
            raise RequestError(str(exc).replace(str(path), source)) from None


def read_drawing(data: Any, domains: Mapping[str, Domain], *, source: str = "drawing.yaml") -> Drawing:
    """Check a drawing (see the module doc) as the subgoal file ``source`` it would be saved as.

    Args:
        data: the decoded request.
        domains: the studio's domains by name.
        source: the file name used in messages.

    Raises:
        RequestError: naming the file (``source``), the pattern and the field.

    Examples:
        >>> from torchrl_subgoal.studio.domains import default_domains
        >>> wall = {"domain": "four_rooms", "patterns": [{"name": "p", "subgoals": [{"cell": [0, 6]}]}]}
        >>> read_drawing(wall, default_domains())
        Traceback (most recent call last):
        ...
        torchrl_subgoal.studio.document.RequestError: drawing.yaml: pattern 'p': subgoals[0].cell: (0, 6) is a wall
    """
    _expect(isinstance(data, Mapping), "request: expected a JSON object with domain, map and patterns")
    unknown = set(data) - {"domain", "map", "patterns", "file", "description"}
    _expect(
        not unknown, f"request: unknown field(s) {sorted(unknown)}; allowed: domain, map, patterns, file, description"
    )
    domain = domains.get(str(data.get("domain")))
    _expect(domain is not None, f"request: domain: expected one of {sorted(domains)}, got {data.get('domain')!r}")
    assert domain is not None
    map_name = ""
    if domain.maps:
        map_name = data.get("map") or next(iter(domain.maps))
        _expect(
            isinstance(map_name, str) and map_name in domain.maps,
            f"request: map: expected one of {list(domain.maps)}, got {map_name!r}",
        )
    raw = data.get("patterns")
    _expect(isinstance(raw, list) and len(raw) > 0, "request: patterns: expected a non-empty list of patterns")
    bodies: dict[str, Any] = {}
    for i, pattern in enumerate(raw):
        name, body = _pattern_body(i, pattern, domain)
        _expect(name not in bodies, f"request: patterns: the name {name!r} is used by two patterns; rename one")
        bodies[name] = body
    described = {"description": data["description"]} if data.get("description") is not None else {}
    patterns = _load({"format": FORMAT, "domain": domain.name, **described, "patterns": bodies}, source, domain.name)
    if domain.map_check is not None:
        for name, series in patterns.items():
            for j, predicate in enumerate(series.predicates):
                problem = domain.map_check(predicate, map_name, domain.maps[map_name])
                if problem:
                    label = f"subgoals.{series.names[j]}" if series.names else f"subgoals[{j}]"
                    raise RequestError(f"{source}: pattern {name!r}: {label}.{predicate.kind}: {problem}")
    for name in patterns:
        _expect(
            not domain.pattern_names or name in domain.pattern_names,
            f"{source}: pattern {name!r}: {domain.title or domain.name} runs each pattern on the task it is "
            f"named after; name it one of {', '.join(domain.pattern_names)}",
        )
    return Drawing(domain, map_name, patterns, described.get("description"))


def save_drawing(drawing: Drawing, path: Path, *, overwrite: bool = False) -> None:
    """Write the drawing's patterns to ``path`` with :func:`save_patterns`: atomically, exclusively and
    never through a link.

    The file is written to a new temporary file in ``path``'s folder, created
    exclusively (``O_CREAT | O_EXCL | O_NOFOLLOW``, a random name). A first save
    (no ``overwrite``) then *links* it to ``path``, which fails if anything of that
    name exists, so of any number of concurrent first saves exactly one creates the
    file and the others get a 409; ``overwrite`` renames it over ``path``. Either
    way ``path`` is the complete old file or the complete new one, and a link
    planted at ``path`` or at any temporary name is replaced or left alone, never
    written through.

    Args:
        drawing: what to save.
        path: the file (in the save folder).
        overwrite: replace an existing ``path``; without it an existing entry of that
            name (a file, a link) is a conflict.

    Raises:
        RequestError: 409 if ``path`` exists (and not ``overwrite``) or is a directory;
            for a folder that cannot be written, the answer of :func:`folder_error`.

    Examples:
        >>> from torchrl_subgoal.studio.domains import default_domains
        >>> from torchrl_subgoal.subgoals import Cell
        >>> from torchrl_subgoal.subgoals import load_patterns
        >>> drawing = Drawing(default_domains()["four_rooms"], "", {"alice": SubgoalSeries([Cell(4, 9)], name="alice")})
        >>> path = Path(tempfile.mkdtemp()) / "alice.yaml"
        >>> save_drawing(drawing, path)
        >>> load_patterns(path)["alice"].to_dict()
        {'subgoals': [{'cell': [4, 9]}]}
        >>> save_drawing(drawing, path)
        Traceback (most recent call last):
        ...
        torchrl_subgoal.studio.document.RequestError: alice.yaml exists in the save folder; choose another name, ...
    """
    exists = RequestError(
        f"{path.name} exists in the save folder; choose another name, or confirm replacing it", status=409
    )
    try:
        mode: int | None = os.lstat(path).st_mode
    except FileNotFoundError:
        mode = None
    except OSError as exc:
        raise folder_error(exc, path.parent, f"save {path.name}") from None
    if mode is not None and not (stat.S_ISREG(mode) or stat.S_ISLNK(mode)):
        raise RequestError(
            f"{path.name}: a directory (or another non-file) of that name is in the save folder; choose another name",
            status=409,
        )
    if mode is not None and not overwrite:
        raise exists
    with tempfile.TemporaryDirectory(prefix="studio-save-") as private:  # ours alone: nothing planted in it
        rendered = Path(private) / path.name
        save_patterns(rendered, drawing.patterns, domain=drawing.domain.name, description=drawing.description)
        text = rendered.read_bytes()
    try:
        _write_new(path, text, overwrite=overwrite)
    except FileExistsError:  # another save of this name won the race
        raise exists from None
    except IsADirectoryError:
        raise RequestError(
            f"{path.name}: a directory of that name is in the save folder; choose another name", 409
        ) from None
    except OSError as exc:
        raise folder_error(exc, path.parent, f"save {path.name}") from None


#: ``link`` errors of file systems without hard links (FAT, some network mounts): claim the name instead.
_NO_LINKS = frozenset({errno.EPERM, errno.ENOTSUP, errno.EOPNOTSUPP, errno.EMLINK})


def _write_new(path: Path, data: bytes, *, overwrite: bool) -> None:
    """Write ``data`` to a fresh temporary file beside ``path`` (created exclusively), then move it to
    ``path``: renamed over it with ``overwrite``, else linked to it (``FileExistsError`` if ``path`` exists)."""
    flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_CLOEXEC", 0)
    for _ in range(100):
        tmp = path.with_name(f".{path.name}.{secrets.token_hex(8)}.tmp")
        try:
            fd = os.open(tmp, flags, 0o666)
        except FileExistsError:  # taken (by chance, or planted): another name
            continue
        break
    else:
        raise FileExistsError(f"no free temporary name beside {path.name}")
    try:
        with os.fdopen(fd, "wb") as handle:
            handle.write(data)
            handle.flush()
            os.fsync(handle.fileno())
        if not overwrite:
            try:
                os.link(tmp, path)  # atomic and exclusive: fails if path exists
                return
            except OSError as exc:
                if exc.errno not in _NO_LINKS:
                    raise
            os.close(os.open(path, flags, 0o666))  # no hard links here: claim the name (exclusive), then fill it
        os.replace(tmp, path)  # replaces a link at path, never follows it
    finally:
        tmp.unlink(missing_ok=True)


def folder_error(exc: OSError, folder: Path, doing: str) -> RequestError:
    """What the page shows when the file system refuses ``doing`` in the save ``folder`` (never a 500).

    503 when the folder is gone (deleted, moved, replaced by a file), 403 when it may not be
    read or written (permissions, a read-only file system), 507 when the disk is full,
    else 503 naming the system's reason.

    Examples:
        >>> folder = Path(tempfile.mkdtemp())
        >>> error = folder_error(PermissionError(errno.EACCES, "Permission denied"), folder, "save a.yaml")
        >>> error.status, str(error).startswith("cannot save a.yaml in the save folder")
        (403, True)
        >>> folder.rmdir()
        >>> folder_error(FileNotFoundError(errno.ENOENT, "No such file"), folder, "list the files").status
        503
    """
    reason = exc.strerror or str(exc)
    if not os.path.isdir(folder):
        return RequestError(
            f"the save folder {folder} is gone (deleted, moved or replaced by a file): create it again, or "
            "restart the studio with --folder DIR",
            status=503,
        )
    where = f"cannot {doing} in the save folder {folder} ({reason})"
    if exc.errno in (errno.EACCES, errno.EPERM, errno.EROFS):
        return RequestError(f"{where}: let this user read and write it, or restart the studio with --folder DIR", 403)
    if exc.errno in (errno.ENOSPC, errno.EDQUOT):
        return RequestError(f"{where}: free some space, then save again", status=507)
    return RequestError(where, status=503)


def read_file(folder: Path, name: str) -> tuple[Path, bytes]:
    """The bytes of the subgoal file ``name`` of ``folder``: a regular file there, or a link to one there.

    The file is opened without following a last link (``O_NOFOLLOW``) after its real
    path was checked to lie directly in ``folder``, so a link swapped in meanwhile is
    refused rather than followed out of the folder. At most one byte more than a
    subgoal file may hold is read (the loader then names the limit).

    Args:
        folder: the save folder.
        name: the file's name in it (as in a request).

    Raises:
        RequestError: 400 for a bad name or a link out of the folder, 404 if there is no such file;
            for a folder that is gone or cannot be read, the answer of :func:`folder_error`.

    Examples:
        >>> import tempfile
        >>> folder = Path(tempfile.mkdtemp())
        >>> _ = (folder / "alice.yaml").write_text("patterns: {}")
        >>> read_file(folder, "alice.yaml")[1]
        b'patterns: {}'
    """
    path = file_path(folder, name)
    root = path.parent
    missing = RequestError(f"{path.name}: no such file in the save folder", status=404)
    try:
        real = path.resolve(strict=True)
    except RuntimeError:  # a loop of links
        raise missing from None
    except OSError as exc:
        if isinstance(exc, (FileNotFoundError, NotADirectoryError)) and os.path.isdir(root):
            raise missing from None
        raise folder_error(exc, root, f"read {path.name}") from None
    if real.parent != root:
        raise RequestError(f"file name {name!r}: must name a file directly in the save folder")
    flags = os.O_RDONLY | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0)
    try:
        fd = os.open(real, flags)
    except FileNotFoundError:
        if not os.path.isdir(root):
            raise folder_error(FileNotFoundError(errno.ENOENT, "gone"), root, f"read {path.name}") from None
        raise missing from None
    except PermissionError as exc:
        raise folder_error(exc, root, f"read {path.name}") from None
    except OSError as exc:  # ELOOP: a link was put there after the check
        raise RequestError(f"{path.name}: cannot open it ({exc.strerror or exc})", status=400) from None
    with os.fdopen(fd, "rb") as handle:
        if not stat.S_ISREG(os.fstat(handle.fileno()).st_mode):
            raise missing
        return path, handle.read(MAX_FILE_BYTES + 1)


def infer_domain(
    patterns: Mapping[str, SubgoalSeries], domains: Mapping[str, Domain], source: str, declared: str | None = None
) -> Domain:
    """The domain a file is for: the one it names (``declared``, its ``domain`` field) when the studio
    has it, else the first whose map check accepts every subgoal of ``patterns`` and whose page can
    edit them, else the first whose map check accepts them (opening it then says what the page cannot
    edit: a pick-and-place box over part of a component).

    Examples:
        >>> from torchrl_subgoal.studio.domains import default_domains
        >>> from torchrl_subgoal.subgoals import Box, Cell
        >>> patterns = {"alice": SubgoalSeries([Cell(4, 9)], name="alice")}
        >>> infer_domain(patterns, default_domains(), "alice.yaml").name
        'four_rooms'
        >>> infer_domain({"p": SubgoalSeries([Box((-1.0,), (0.2,), (0,))])}, default_domains(), "car.yaml").name
        'mountain_car'
    """
    if declared is not None and declared in domains:
        return domains[declared]
    predicates = [p for series in patterns.values() for p in series.predicates]

    def accepts(domain: Domain, predicate: Predicate) -> bool:
        return domain.check_subgoal is None or domain.check_subgoal(predicate) is None

    def editable(domain: Domain, predicate: Predicate) -> bool:
        try:
            domain.to_page(predicate)
        except FormError:
            return False
        return True

    fitting = [domain for domain in domains.values() if all(accepts(domain, p) for p in predicates)]
    for domain in fitting:
        if all(editable(domain, p) for p in predicates):
            return domain
    if fitting:
        return fitting[0]
    kinds = sorted({p.kind for p in predicates})
    raise RequestError(
        f"{source}: its subgoals ({', '.join(kinds)}) fit none of the studio's domains {sorted(domains)}", status=422
    )


def to_document(patterns: Mapping[str, SubgoalSeries], domain: Domain, source: str) -> list[dict[str, Any]]:
    """Patterns as the page edits them (the inverse of :func:`read_drawing`); ``source`` names the file.

    Examples:
        >>> from torchrl_subgoal.studio.domains import default_domains
        >>> from torchrl_subgoal.subgoals import Cell
        >>> patterns = {"alice": SubgoalSeries([Cell(4, 9)], name="alice")}
        >>> to_document(patterns, default_domains()["four_rooms"], "alice.yaml")
        [{'name': 'alice', 'subgoals': [{'name': None, 'cell': [4, 9]}], 'order': None, 'description': None}]
    """
    out = []
    for name, series in patterns.items():
        names: Sequence[str | None] = series.names or [None] * len(series)
        subgoals = []
        for j, (label, p) in enumerate(zip(names, series.predicates, strict=True)):
            try:
                subgoals.append({"name": label, **domain.to_page(p)})
            except FormError as exc:
                raise RequestError(f"{source}: pattern {name!r}: subgoals[{j}]: {exc}", status=422) from None
        order = None
        if series.order is not None:
            full = series.names or [f"sg{j + 1}" for j in range(len(series))]
            order = [[full[a], full[b]] for a, b in series.order]
        out.append({"name": name, "subgoals": subgoals, "order": order, "description": series.description})
    return out

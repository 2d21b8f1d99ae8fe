"""The results store: one directory per sweep, one Parquet file per finished chunk.

Layout of a results directory::

    results_dir/
      config.json                      what was run: domain, methods, config, seed,
                                       chunk layout, package versions; the command,
                                       its settings and the code's version (provenance)
      .lock                            held (``flock``) by the process running the sweep
      chunks/<method>/<index>.parquet  one finished chunk, long format, one row per
                                       (learner, episode)

Every file is written atomically: to a temporary file in the same directory,
flushed and fsync'ed, then renamed over the final name with :func:`os.replace`.
A reader therefore sees either a whole file or none; temporary files left by a
killed process start with ``.`` and end with ``.tmp`` and are removed by
:meth:`ResultsStore.clean_temp_files`.

Each chunk file carries its identity (method, index, seed, learners) and its row
count in the Parquet schema metadata, and is written with page checksums. A
file that cannot be read, whose identity is not the planned chunk's, or whose
row count is wrong is *corrupt*: :func:`load_results` refuses it by name and a
re-run of the sweep recomputes it.
"""

from __future__ import annotations

import contextlib
import json
import os
import platform
import re
import subprocess
import uuid
from collections.abc import Iterator, Mapping, Sequence
from importlib import metadata
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

from torchrl_subgoal.experiments import results
from torchrl_subgoal.experiments.results import (
    Chunk,
    ChunkStatus,
    CorruptChunkError,
    EpisodeTable,
    Results,
    ResultsError,
)

FORMAT_VERSION = 1
CONFIG_FILE = "config.json"
CHUNKS_DIR = "chunks"
LOCK_FILE = ".lock"
_META_KEY = b"torchrl_subgoal.chunk"
_METHOD_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.+-]*$")
_CHUNK_FILE = re.compile(r"^[0-9]{5,}\.parquet(\.corrupt)?$")
#: Fields of config.json that define an experiment; a mismatch on any is an error.
IDENTITY_FIELDS = ("domain", "methods", "config", "seed", "chunk_size", "n_episodes", "chunks")

__all__ = [
    "ResultsStore",
    "check_method_name",
    "code_version",
    "collect_versions",
    "diff_fields",
    "load_frame",
    "load_results",
    "open_manifest",
    "planned_chunks",
    "to_json_data",
]


def check_method_name(name: str) -> str:
    """Return ``name`` if it can name a directory below ``chunks/``; raise otherwise.

    Examples:
        >>> check_method_name("SARSA-RS")
        'SARSA-RS'
        >>> check_method_name("../HRS")
        Traceback (most recent call last):
        ...
        ValueError: method name '../HRS' must start with a letter or digit and use only letters, digits and _ . + -
    """
    if not _METHOD_NAME.match(name):
        raise ValueError(
            f"method name {name!r} must start with a letter or digit and use only letters, digits and _ . + -"
        )
    return name


def collect_versions() -> dict[str, str]:
    """Versions of Python and of the packages that shape a result, for ``config.json``.

    Examples:
        >>> sorted(collect_versions())
        ['numpy', 'python', 'tensordict', 'torch', 'torchrl', 'torchrl_subgoal']
    """
    versions = {"python": platform.python_version()}
    for package in ("torch", "torchrl", "tensordict", "numpy", "torchrl_subgoal"):
        try:
            versions[package] = metadata.version(package)
        except metadata.PackageNotFoundError:
            versions[package] = "not installed"
    return versions


def code_version() -> dict[str, str]:
    """This package's version, and the git commit of its source when it runs from a git checkout
    (``+dirty`` when tracked files differ from it), for ``config.json``'s provenance.

    Examples:
        >>> sorted(code_version())[-1]
        'version'
    """
    out = {"version": metadata.version("torchrl_subgoal")}
    source = Path(__file__).resolve().parents[2]
    try:
        commit = subprocess.run(
            ["git", "-C", str(source), "rev-parse", "--verify", "HEAD"], capture_output=True, text=True, timeout=10
        )
        if commit.returncode == 0 and (source / "torchrl_subgoal").is_dir() and (source / "pyproject.toml").is_file():
            status = subprocess.run(
                ["git", "-C", str(source), "status", "--porcelain", "--untracked-files=no"],
                capture_output=True,
                text=True,
                timeout=10,
            )
            out["commit"] = commit.stdout.strip() + ("+dirty" if status.stdout.strip() else "")
    except (OSError, subprocess.SubprocessError):
        pass  # no git here: the version alone
    return out


def to_json_data(value: Any, what: str = "config") -> Any:
    """``value`` as plain JSON data (tuples become lists); a clear error if it is not JSON.

    Examples:
        >>> to_json_data({"thresholds": (500, 50)})
        {'thresholds': [500, 50]}
        >>> to_json_data({"lr": float("nan")})
        Traceback (most recent call last):
        ...
        TypeError: config must be JSON-serialisable (no NaN): Out of range float values are not JSON compliant...
    """
    try:
        return json.loads(json.dumps(value, allow_nan=False))
    except (TypeError, ValueError) as exc:
        raise TypeError(f"{what} must be JSON-serialisable (no NaN): {exc}") from exc


def diff_fields(stored: Any, requested: Any, prefix: str = "") -> list[str]:
    """Dotted paths where two JSON values differ, e.g. ``['config.lr', 'seed']``.

    Examples:
        >>> old = {"config": {"lr": 0.1, "gamma": 0.99}, "seed": 0}
        >>> new = {"config": {"lr": 0.2, "gamma": 0.99}, "seed": 1}
        >>> diff_fields(old, new)
        ['config.lr', 'seed']
    """
    if isinstance(stored, dict) and isinstance(requested, dict):
        out: list[str] = []
        for key in sorted(set(stored) | set(requested), key=str):
            path = f"{prefix}.{key}" if prefix else str(key)
            if key not in stored or key not in requested:
                out.append(path)
            else:
                out.extend(diff_fields(stored[key], requested[key], path))
        return out
    if isinstance(stored, list) and isinstance(requested, list) and len(stored) == len(requested):
        out = []
        for i, (a, b) in enumerate(zip(stored, requested, strict=True)):
            out.extend(diff_fields(a, b, f"{prefix}[{i}]"))
        return out
    return [] if stored == requested else [prefix or "<root>"]


def _fsync_dir(path: Path) -> None:
    with contextlib.suppress(OSError):  # not every filesystem lets a directory be fsync'ed
        fd = os.open(path, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


@contextlib.contextmanager
def _atomic_file(path: Path) -> Iterator[BinaryIO]:
    """Open a temporary file beside ``path``; on success fsync it and rename it over ``path``."""
    tmp = path.parent / f".{path.name}.{uuid.uuid4().hex}.tmp"  # open() honours the umask
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with open(tmp, "xb") as handle:
            yield handle
            handle.flush()
            os.fsync(handle.fileno())
        os.replace(tmp, path)
    except BaseException as exc:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        if isinstance(exc, OSError):  # disk full, permissions: a message, not a traceback
            raise ResultsError(f"cannot write {path} ({_reason(exc)}); finished chunks are kept") from exc
        raise
    _fsync_dir(path.parent)


class ResultsStore:
    """Reads and writes one results directory (see the module docstring for the layout).

    Args:
        root: the results directory; created on first write.

    Examples:
        >>> import tempfile, numpy as np
        >>> store = ResultsStore(tempfile.mkdtemp())
        >>> chunk = Chunk("HRS", 0, (("p1", 0),), seed=1)
        >>> table = EpisodeTable(np.array([[5, 3]]), np.zeros((1, 2)), np.ones((1, 2), bool))
        >>> _ = store.write_chunk(chunk, table)
        >>> store.read_chunk(chunk).steps.tolist()
        [[5, 3]]
    """

    def __init__(self, root: str | os.PathLike[str]) -> None:
        self.root = Path(root)

    @property
    def config_path(self) -> Path:
        """``results_dir/config.json``."""
        return self.root / CONFIG_FILE

    @property
    def chunks_dir(self) -> Path:
        """``results_dir/chunks``."""
        return self.root / CHUNKS_DIR

    def chunk_path(self, chunk: Chunk) -> Path:
        """Where ``chunk`` is stored."""
        return self.chunks_dir / check_method_name(chunk.method) / f"{chunk.index:05d}.parquet"

    # -- config.json ---------------------------------------------------------------------

    def read_manifest(self) -> dict[str, Any] | None:
        """The parsed ``config.json``, or ``None`` when the directory has none.

        Raises:
            ResultsError: the path is not a directory, or ``config.json`` is unreadable, not
                JSON, or not a results file of this format (missing or malformed fields).
        """
        if self.root.exists() and not self.root.is_dir():
            raise ResultsError(f"{self.root} is a file, not a results directory; choose a directory")
        try:
            text = self.config_path.read_text(encoding="utf-8")
        except FileNotFoundError:
            return None
        except (OSError, UnicodeDecodeError) as exc:
            raise ResultsError(
                f"cannot read {self.config_path} ({_reason(exc)}); choose another results directory"
            ) from exc
        fix = "repair it, or delete the directory to start afresh"
        try:
            data = json.loads(text)
        except json.JSONDecodeError as exc:
            raise ResultsError(f"{self.config_path} is not valid JSON ({exc}); {fix}") from exc
        if not isinstance(data, dict) or data.get("format") != FORMAT_VERSION:
            raise ResultsError(
                f"{self.config_path} is not a torchrl_subgoal results file of format {FORMAT_VERSION}; {fix}"
            )
        problem = _manifest_problem(data)
        if problem:
            raise ResultsError(f"{self.config_path}: {problem}; {fix}")
        return data

    def write_manifest(self, manifest: Mapping[str, Any]) -> None:
        """Write ``config.json`` atomically."""
        text = json.dumps(manifest, indent=1, allow_nan=False) + "\n"
        with _atomic_file(self.config_path) as handle:
            handle.write(text.encode())

    # -- chunks --------------------------------------------------------------------------

    def write_chunk(self, chunk: Chunk, table: EpisodeTable) -> Path:
        """Write one finished chunk atomically; returns its path."""
        if table.n_learners != chunk.n_learners:
            raise ValueError(f"chunk {chunk.name} has {chunk.n_learners} learners, its table {table.n_learners} rows")
        n, e = table.steps.shape
        names, codes = np.unique([pattern for pattern, _ in chunk.learners], return_inverse=True)
        pattern_column = pa.DictionaryArray.from_arrays(
            pa.array(np.repeat(codes.astype(np.int32), e)), pa.array(names.tolist(), pa.string())
        )
        data = pa.table(
            {
                "method": pa.DictionaryArray.from_arrays(
                    pa.array(np.zeros(n * e, dtype=np.int32)), pa.array([chunk.method])
                ),
                "pattern": pattern_column,
                "learning": pa.array(np.repeat([lrn for _, lrn in chunk.learners], e).astype(np.int32)),
                "episode": pa.array(np.tile(np.arange(1, e + 1, dtype=np.int32), n)),
                "steps": pa.array(table.steps.ravel()),
                "return": pa.array(table.returns.ravel()),
                "success": pa.array(table.success.ravel()),
            }
        )
        identity = {**chunk.to_json(), "rows": n * e, "n_episodes": e}
        data = data.replace_schema_metadata({_META_KEY: json.dumps(identity).encode()})
        path = self.chunk_path(chunk)
        with _atomic_file(path) as handle:
            pq.write_table(data, handle, compression="zstd", write_page_checksum=True)
        return path

    def read_chunk(self, chunk: Chunk) -> EpisodeTable:
        """Read and validate a stored chunk.

        Raises:
            FileNotFoundError: the chunk has not been written.
            CorruptChunkError: the file is unreadable, belongs to another chunk, or has the
                wrong number of rows.
        """
        path = self.chunk_path(chunk)
        if not path.exists():
            raise FileNotFoundError(path)
        try:
            data = pq.read_table(path, page_checksum_verification=True)
        except (OSError, pa.ArrowException) as exc:
            raise CorruptChunkError(path, f"unreadable ({exc})") from exc
        raw = (data.schema.metadata or {}).get(_META_KEY)
        if raw is None:
            raise CorruptChunkError(path, "no chunk identity in the Parquet metadata")
        try:
            identity = json.loads(raw)
            stored = Chunk.from_json(identity)
            rows, n_episodes = int(identity["rows"]), int(identity["n_episodes"])
        except (ValueError, KeyError, TypeError) as exc:
            raise CorruptChunkError(path, f"unreadable chunk identity ({exc})") from exc
        if stored != chunk:
            diff = diff_fields(stored.to_json(), chunk.to_json())
            raise CorruptChunkError(path, f"identity differs from the planned chunk in {diff}")
        if rows != chunk.n_learners * n_episodes or data.num_rows != rows:
            raise CorruptChunkError(
                path,
                f"{data.num_rows} rows, expected {chunk.n_learners} learners x {n_episodes} episodes",
            )
        try:
            steps = data.column("steps").to_numpy().reshape(chunk.n_learners, n_episodes)
            returns = data.column("return").to_numpy().reshape(chunk.n_learners, n_episodes)
            success = data.column("success").to_numpy().reshape(chunk.n_learners, n_episodes)
            episode = data.column("episode").to_numpy().reshape(chunk.n_learners, n_episodes)
            learning = data.column("learning").to_numpy()[::n_episodes] if n_episodes else []
        except (KeyError, ValueError, pa.ArrowException) as exc:
            raise CorruptChunkError(path, f"missing or malformed columns ({exc})") from exc
        if not (episode == np.arange(1, n_episodes + 1)).all() or list(learning) != [lrn for _, lrn in chunk.learners]:
            raise CorruptChunkError(path, "episode or learning columns do not match the identity")
        return EpisodeTable(steps, returns, success)

    def check_chunk(self, chunk: Chunk) -> ChunkStatus:
        """Whether ``chunk`` is stored and valid, without raising."""
        try:
            self.read_chunk(chunk)
        except FileNotFoundError:
            return ChunkStatus("missing")
        except CorruptChunkError as exc:
            return ChunkStatus("corrupt", exc.reason)
        return ChunkStatus("done")

    def quarantine(self, chunk: Chunk) -> Path:
        """Move a corrupt chunk file aside to ``<index>.parquet.corrupt``; returns the new path."""
        path = self.chunk_path(chunk)
        target = path.with_name(path.name + ".corrupt")
        os.replace(path, target)
        _fsync_dir(path.parent)
        return target

    def clean_temp_files(self) -> list[Path]:
        """Delete temporary files left by an interrupted write; returns what was removed."""
        removed = []
        if self.root.exists():
            for path in [*self.root.glob(".*.tmp"), *self.chunks_dir.glob("*/.*.tmp")]:
                with contextlib.suppress(FileNotFoundError):
                    path.unlink()
                    removed.append(path)
        return removed

    def foreign_entries(self) -> list[Path]:
        """What the directory holds besides a sweep's own files, when it has no ``config.json``.

        A sweep starts only in a missing or empty directory (its own ``.lock`` and
        temporary files excepted): anything else may be someone's data.
        """
        if not self.root.exists():
            return []
        return sorted(p for p in self.root.iterdir() if p.name != LOCK_FILE and not _is_temp(p))

    def clear(self) -> list[Path]:
        """Remove what a sweep wrote: ``config.json`` and the chunk files below ``chunks/``.

        Only files the store can identify as its own go: ``chunks/<method>/<index>.parquet``
        (and ``.corrupt`` or temporary ones) whose method directory's name is valid.
        Anything else below ``chunks/`` is left alone, as are the directories holding
        it. Returns what was removed.
        """
        removed = []
        with contextlib.suppress(FileNotFoundError):
            self.config_path.unlink()
            removed.append(self.config_path)
        if self.chunks_dir.is_dir():
            for method_dir in self.chunks_dir.iterdir():
                if not (method_dir.is_dir() and _METHOD_NAME.match(method_dir.name)):
                    continue
                for path in method_dir.iterdir():
                    if path.is_file() and (_CHUNK_FILE.match(path.name) or _is_temp(path)):
                        path.unlink()
                        removed.append(path)
                with contextlib.suppress(OSError):  # kept when something else is in it
                    method_dir.rmdir()
            with contextlib.suppress(OSError):
                self.chunks_dir.rmdir()
        return removed

    def sweep_running(self) -> bool:
        """Whether a process holds the directory's lock, i.e. a sweep is writing into it.

        The lock is probed without waiting and released at once; a directory without a
        lock file has no sweep running (nothing is created).

        Examples:
            >>> import tempfile
            >>> store = ResultsStore(tempfile.mkdtemp())
            >>> store.sweep_running()
            False
            >>> with store.lock():
            ...     store.sweep_running()
            True
        """
        import fcntl

        try:
            handle = open(self.root / LOCK_FILE, "rb")  # noqa: SIM115 (closed below)
        except OSError:
            return False
        with handle:
            try:
                fcntl.flock(handle, fcntl.LOCK_SH | fcntl.LOCK_NB)
            except BlockingIOError:
                return True
            except OSError:
                return False
            fcntl.flock(handle, fcntl.LOCK_UN)
            return False

    @contextlib.contextmanager
    def lock(self) -> Iterator[None]:
        """Hold an exclusive lock on the directory; the OS releases it if the process dies."""
        import fcntl

        try:
            self.root.mkdir(parents=True, exist_ok=True)
            handle = open(self.root / LOCK_FILE, "w")  # noqa: SIM115 (closed below)
        except FileExistsError as exc:
            raise ResultsError(f"{self.root} is a file, not a results directory; choose a directory") from exc
        except OSError as exc:
            raise ResultsError(
                f"cannot write the results directory {self.root} ({_reason(exc)}); choose a writable one"
            ) from exc
        with handle:
            try:
                fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError as exc:
                raise ResultsError(
                    f"another process is running a sweep into {self.root}; wait for it or stop it"
                ) from exc
            try:
                yield
            finally:
                fcntl.flock(handle, fcntl.LOCK_UN)


def _reason(exc: BaseException) -> str:
    """An OS error's reason without the repeated path (``Permission denied``), else the message."""
    return getattr(exc, "strerror", None) or str(exc)


def _is_temp(path: Path) -> bool:
    return path.name.startswith(".") and path.name.endswith(".tmp")


def _manifest_problem(data: Mapping[str, Any]) -> str | None:
    """What is wrong with a parsed ``config.json`` of the right format, if anything."""
    kinds: dict[str, type | tuple[type, ...]] = {
        "domain": str,
        "methods": list,
        "config": dict,
        "seed": int,
        "chunk_size": int,
        "chunks": list,
    }
    for key, kind in kinds.items():
        if not isinstance(data.get(key), kind):
            return f"field {key!r} is missing or malformed"
    try:
        names = [str(m["name"]) for m in data["methods"]]
        planned = [Chunk.from_json(item) for item in data["chunks"]]
    except (KeyError, TypeError, ValueError):
        return "fields 'methods' or 'chunks' are malformed"
    for chunk in planned:
        if chunk.method not in names or not _METHOD_NAME.match(chunk.method):
            return f"chunk {chunk.name} belongs to no method of the file"
    return None


def planned_chunks(manifest: Mapping[str, Any]) -> list[Chunk]:
    """The chunk layout recorded in a ``config.json``.

    Examples:
        >>> chunk = Chunk("HRS", 0, (("alice", 0),), seed=7)
        >>> planned_chunks({"chunks": [chunk.to_json()]}) == [chunk]
        True
    """
    return [Chunk.from_json(item) for item in manifest["chunks"]]


def open_manifest(results_dir: str | os.PathLike[str], domain: str | None = None) -> dict[str, Any]:
    """Read ``results_dir/config.json`` and check it belongs to ``domain`` (when given).

    Raises:
        ResultsError: the directory holds no sweep.
        results.DomainMismatchError: it holds a sweep of another domain.

    Examples:
        >>> import tempfile
        >>> try:
        ...     open_manifest(tempfile.mkdtemp())
        ... except ResultsError as error:
        ...     print(type(error).__name__)
        ResultsError
    """
    store = ResultsStore(results_dir)
    manifest = store.read_manifest()
    if manifest is None:
        raise ResultsError(f"{store.root} holds no results ({CONFIG_FILE} not found)")
    if domain is not None and manifest["domain"] != domain:
        raise results.DomainMismatchError(
            f"{store.root} holds results of domain {manifest['domain']!r}, not {domain!r}"
        )
    return manifest


def load_results(
    results_dir: str | os.PathLike[str],
    *,
    domain: str | None = None,
    methods: Sequence[str] | None = None,
    allow_incomplete: bool = False,
) -> Results:
    """Load a results directory.

    Args:
        results_dir: a directory written by :class:`~torchrl_subgoal.experiments.Sweep`.
        domain: when given, the directory must hold results of this domain.
        methods: load only these methods (default: all, in sweep order).
        allow_incomplete: load the chunks that exist instead of raising when some are
            missing (they are listed in :attr:`Results.missing`). Corrupt chunks always raise.

    Raises:
        results.DomainMismatchError: the directory holds another domain's results.
        results.UnknownMethodError: a method in ``methods`` is not in the sweep.
        results.IncompleteResultsError: chunks are missing (unless ``allow_incomplete``).
        CorruptChunkError: a chunk cannot be read.

    Examples:
        >>> results = load_results("results/four_rooms")  # doctest: +SKIP
        >>> results.to_frame().groupby("method")["steps"].mean()  # doctest: +SKIP
    """
    manifest = open_manifest(results_dir, domain)
    store = ResultsStore(results_dir)
    known = [m["name"] for m in manifest["methods"]]
    wanted = known if methods is None else list(methods)
    unknown = [name for name in wanted if name not in known]
    if unknown:
        raise results.UnknownMethodError(f"unknown method(s) {unknown} for {store.root}; it holds {known}")
    by_method: dict[str, list[tuple[Chunk, EpisodeTable]]] = {name: [] for name in wanted}
    missing = []
    for chunk in planned_chunks(manifest):
        if chunk.method not in by_method:
            continue
        try:
            by_method[chunk.method].append((chunk, store.read_chunk(chunk)))
        except FileNotFoundError:
            missing.append(chunk.name)
    if missing and not allow_incomplete:
        raise results.IncompleteResultsError(
            f"{store.root}: {len(missing)} chunk(s) not computed yet (e.g. {missing[0]}); re-run the sweep to finish it"
        )
    loaded = {}
    for name, parts in by_method.items():
        if not parts:
            continue
        episodes = {table.n_episodes for _, table in parts}
        if len(episodes) > 1:
            raise ResultsError(f"{store.root}: method {name} has chunks of {sorted(episodes)} episodes")
        learners = [learner for chunk, _ in parts for learner in chunk.learners]
        loaded[name] = results.MethodResults(
            name=name,
            patterns=np.array([p for p, _ in learners], dtype=str),
            learnings=np.array([lrn for _, lrn in learners], dtype=np.int64),
            table=EpisodeTable.concat([table for _, table in parts]),
        )
    return Results(
        root=store.root,
        domain=manifest["domain"],
        config=manifest["config"],
        methods=loaded,
        missing=tuple(missing),
        manifest=manifest,
    )


def load_frame(results_dir: str | os.PathLike[str], **kwargs: Any) -> pd.DataFrame:
    """:func:`load_results` as a long-format DataFrame (see :meth:`Results.to_frame`).

    Examples:
        >>> frame = load_frame("results/pinball", domain="pinball")  # doctest: +SKIP
    """
    return load_results(results_dir, **kwargs).to_frame()

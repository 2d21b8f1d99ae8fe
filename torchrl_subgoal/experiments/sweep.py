"""Sweeps: methods x subgoal patterns x learnings, run in chunks that resume.

A :class:`Sweep` enumerates learners ``(method, pattern, learning)``, splits each
method's learners into :class:`~torchrl_subgoal.experiments.store.Chunk` s of at most
``chunk_size`` learners, and runs the chunks not yet in the results store through a
backend:

* ``"local"`` (default): a :class:`concurrent.futures.ProcessPoolExecutor` with the
  ``spawn`` start method; each worker runs with one torch thread and exits when its
  parent dies. ``workers=0`` runs the chunks in the calling process (for debugging).
* ``"ray"``: one Ray task per chunk on an existing cluster (``RAY_ADDRESS`` or a
  running local cluster), else on a local Ray instance started for the sweep. Tasks
  *return* their table to the driver, which writes it: the cluster needs no shared
  filesystem, and the store keeps a single writer. A chunk whose worker process or
  node dies runs again, up to :data:`RAY_RETRIES` times, before the sweep stops as
  for any failed chunk.

In both cases the parent process is the only writer: it validates each table and
writes it atomically as soon as its chunk finishes, so an interrupted sweep loses at
most the chunks that were running.
"""

from __future__ import annotations

import hashlib
import multiprocessing as mp
import os
import pickle
import queue as queue_module
import sys
import threading
import time
import warnings
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import FIRST_COMPLETED, CancelledError, Future, ProcessPoolExecutor, wait
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from torchrl_subgoal.experiments.backend import (
    ChunkFailedError,
    Finished,
    ProgressBar,
    RunChunk,
    ThrottledProgress,
    failure,
    limit_threads,
)
from torchrl_subgoal.experiments.results import (
    Chunk,
    ConfigMismatchError,
    DomainMismatchError,
    EpisodeTable,
    Results,
    ResultsError,
    UnknownMethodError,
)
from torchrl_subgoal.experiments.store import (
    CONFIG_FILE,
    FORMAT_VERSION,
    IDENTITY_FIELDS,
    ResultsStore,
    check_method_name,
    collect_versions,
    diff_fields,
    load_results,
    to_json_data,
)

Backend = Literal["local", "ray"]


class CorruptChunkWarning(UserWarning):
    """A stored chunk was corrupt; it is moved aside and recomputed.

    Examples:
        >>> import warnings
        >>> with warnings.catch_warnings(record=True) as caught:
        ...     warnings.simplefilter("always")
        ...     warnings.warn("chunk HRS/00000 moved aside", CorruptChunkWarning)
        >>> caught[0].category.__name__
        'CorruptChunkWarning'
    """


@dataclass(frozen=True)
class MethodSpec:
    """One method of a sweep and the learners it gets.

    Args:
        name: the method's name (letters, digits, ``_ . + -``), e.g. ``"HRS"``.
        patterns: subgoal pattern names; a method without subgoals uses one pseudo-pattern
            such as ``"none"``.
        learnings_per_pattern: independent learnings per pattern.

    Examples:
        >>> spec = MethodSpec("HRS", ["p1", "p2"], learnings_per_pattern=2)
        >>> spec.learners()
        [('p1', 0), ('p1', 1), ('p2', 0), ('p2', 1)]
    """

    name: str
    patterns: Sequence[str]
    learnings_per_pattern: int

    def __post_init__(self) -> None:
        check_method_name(self.name)
        object.__setattr__(self, "patterns", tuple(str(p) for p in self.patterns))
        if not self.patterns:
            raise ValueError(f"method {self.name} has no patterns")
        if len(set(self.patterns)) != len(self.patterns):
            raise ValueError(f"method {self.name} lists a pattern twice: {list(self.patterns)}")
        if self.learnings_per_pattern < 1:
            raise ValueError(f"method {self.name}: learnings_per_pattern must be >= 1")

    def learners(self) -> list[tuple[str, int]]:
        """``(pattern, learning)`` pairs, pattern-major."""
        return [(p, i) for p in self.patterns for i in range(self.learnings_per_pattern)]

    def to_json(self) -> dict[str, Any]:
        """A JSON-ready dict, as stored in ``config.json``."""
        return {
            "name": self.name,
            "patterns": list(self.patterns),
            "learnings_per_pattern": self.learnings_per_pattern,
        }


def select_methods(available: Sequence[MethodSpec], names: Sequence[str] | None) -> list[MethodSpec]:
    """Pick methods by name, in the order given (all of them when ``names`` is None).

    Raises:
        UnknownMethodError: a name is not among ``available``; the message lists them.

    Examples:
        >>> specs = [MethodSpec("HRS", ["p1"], 1), MethodSpec("SARSA", ["none"], 1)]
        >>> [m.name for m in select_methods(specs, ["SARSA"])]
        ['SARSA']
    """
    by_name = {m.name: m for m in available}
    if names is None:
        return list(available)
    unknown = [n for n in names if n not in by_name]
    if unknown:
        raise UnknownMethodError(f"unknown method(s) {unknown}; choose from {list(by_name)}")
    return [by_name[n] for n in names]


def chunk_seed(seed: int, method: str, index: int) -> int:
    """A 63-bit seed for chunk ``index`` of ``method``, independent of everything else.

    Derived with :class:`numpy.random.SeedSequence` from the sweep seed, a stable hash of
    the method name, and the chunk index.

    Examples:
        >>> seed = chunk_seed(0, "HRS", 0)
        >>> seed == chunk_seed(0, "HRS", 0), seed != chunk_seed(0, "HRS", 1), 0 <= seed < 2**63
        (True, True, True)
    """
    sequence = np.random.SeedSequence(entropy=seed, spawn_key=(_name_key(method), index))
    return int(sequence.generate_state(1, np.uint64)[0] >> np.uint64(1))


def learner_seeds(seed: int, chunk: Chunk) -> np.ndarray:
    """One 63-bit seed per learner of ``chunk``, from the sweep seed and the learner's
    ``(method, pattern, learning)`` only: seed each learner's random streams with it and
    its results do not depend on the chunk size, the batch it runs in or the worker count
    (unlike :attr:`Chunk.seed <torchrl_subgoal.experiments.store.Chunk>`, which changes with the chunking).

    Examples:
        >>> a = Chunk("HRS", 0, (("p1", 0), ("p1", 1)), seed=1)
        >>> b = Chunk("HRS", 3, (("p1", 1),), seed=2)
        >>> bool(learner_seeds(0, a)[1] == learner_seeds(0, b)[0])
        True
    """
    method_key = _name_key(chunk.method)
    return np.array(
        [
            np.random.SeedSequence(entropy=seed, spawn_key=(method_key, _name_key(pattern), learning)).generate_state(
                1, np.uint64
            )[0]
            >> np.uint64(1)
            for pattern, learning in chunk.learners
        ],
        dtype=np.int64,
    )


def _name_key(name: str) -> int:
    """A stable 64-bit key of a method or pattern name."""
    return int.from_bytes(hashlib.sha256(name.encode()).digest()[:8], "little")


def plan_chunks(methods: Sequence[MethodSpec], seed: int, chunk_size: int) -> list[Chunk]:
    """Split each method's learners into chunks of at most ``chunk_size``.

    Examples:
        >>> chunks = plan_chunks([MethodSpec("HRS", ["a", "b"], 3)], seed=0, chunk_size=4)
        >>> [c.learners for c in chunks]
        [(('a', 0), ('a', 1), ('a', 2), ('b', 0)), (('b', 1), ('b', 2))]
    """
    if chunk_size < 1:
        raise ValueError("chunk_size must be >= 1")
    chunks = []
    for method in methods:
        learners = method.learners()
        for index, start in enumerate(range(0, len(learners), chunk_size)):
            part = tuple(learners[start : start + chunk_size])
            chunks.append(Chunk(method.name, index, part, chunk_seed(seed, method.name, index)))
    return chunks


# -- workers ---------------------------------------------------------------------------------

_WORKER_SINK: Callable[[tuple[str, int]], None] | None = None


def _exit_when_orphaned(parent_pid: int) -> None:
    while os.getppid() == parent_pid:
        time.sleep(0.5)
    os._exit(1)  # the sweep died (e.g. kill -9): do not keep computing for nobody


def _init_local_worker(progress_queue: Any, parent_pid: int) -> None:
    global _WORKER_SINK
    _WORKER_SINK = progress_queue.put
    threading.Thread(target=_exit_when_orphaned, args=(parent_pid,), daemon=True).start()
    limit_threads()


def _execute_chunk(run_chunk: RunChunk, chunk: Chunk, config: Mapping[str, Any]) -> EpisodeTable:
    progress = ThrottledProgress(chunk.name, _WORKER_SINK)
    table = run_chunk(chunk, config, progress)
    progress.flush()
    return table


# -- backends: each yields (chunk, table) as chunks finish ----------------------------------


def _run_inline(chunks: Sequence[Chunk], run_chunk: RunChunk, config: Mapping[str, Any], bar: ProgressBar) -> Finished:
    for chunk in chunks:
        progress = ThrottledProgress(chunk.name, lambda msg: bar.add(*msg))
        try:
            table = run_chunk(chunk, config, progress)
        except Exception as exc:
            raise failure(chunk, exc) from exc
        progress.flush()
        yield chunk, table


def _drain_local(progress_queue: Any, bar: ProgressBar) -> None:
    while True:
        try:
            name, k = progress_queue.get_nowait()
        except queue_module.Empty:
            return
        bar.add(name, k)


def _run_local(
    chunks: Sequence[Chunk],
    run_chunk: RunChunk,
    config: Mapping[str, Any],
    bar: ProgressBar,
    workers: int,
) -> Finished:
    context = mp.get_context("spawn")
    progress_queue = context.Queue()
    executor = ProcessPoolExecutor(
        max_workers=min(workers, len(chunks)),
        mp_context=context,
        initializer=_init_local_worker,
        initargs=(progress_queue, os.getpid()),
    )
    finished_cleanly = False
    try:
        futures: dict[Future[EpisodeTable], Chunk] = {
            executor.submit(_execute_chunk, run_chunk, chunk, config): chunk for chunk in chunks
        }
        pending: set[Future[EpisodeTable]] = set(futures)
        error: ChunkFailedError | None = None
        while pending:
            done, pending = wait(pending, timeout=0.2, return_when=FIRST_COMPLETED)
            _drain_local(progress_queue, bar)
            for future in done:
                try:
                    table = future.result()
                except CancelledError:
                    continue
                except Exception as exc:
                    if error is None:  # keep the running chunks, start no new ones
                        error = failure(futures[future], exc)
                        error.__cause__ = exc
                        for other in pending:
                            other.cancel()
                    continue
                yield futures[future], table
        finished_cleanly = True
        if error is not None:
            raise error
    finally:
        if finished_cleanly:
            executor.shutdown(wait=True)
        else:  # interrupted: no new workers may start, then stop the running ones now
            processes = dict(getattr(executor, "_processes", None) or {})
            executor.shutdown(wait=False, cancel_futures=True)
            processes.update(getattr(executor, "_processes", None) or {})
            for process in processes.values():
                process.terminate()
            for process in processes.values():
                _wait_for_exit(process)
        progress_queue.close()


def _wait_for_exit(process: Any, grace: float = 2.0) -> None:
    """Wait until a terminated worker has exited and been reaped; SIGKILL it after ``grace`` s.

    ``join`` can return as soon as the child closes its end of the sentinel pipe,
    before the process is gone, so poll ``is_alive`` (which reaps it).
    """
    deadline, killed = time.monotonic() + grace, False
    while process.is_alive():
        if time.monotonic() > deadline:
            if killed:
                return  # the OS will reap it; nothing more a parent can do
            process.kill()  # e.g. still importing torch, not acting on SIGTERM yet
            deadline, killed = time.monotonic() + 10 * grace, True
        time.sleep(0.01)


# -- the sweep -------------------------------------------------------------------------------


def _warm_up(warm: Callable[[], object]) -> None:
    """Run ``warm`` (see :class:`Sweep`), saying what it does and how long it took."""
    start = time.perf_counter()
    print(
        "compiling the engine's numba kernels (some 20 s on a first run after an install; "
        "later runs load them from numba's cache) ...",
        file=sys.stderr,
        flush=True,
    )
    try:
        warm()
    except Exception:
        return  # the chunks run anyway and say what is wrong
    print(f"engine ready in {time.perf_counter() - start:.1f} s", file=sys.stderr, flush=True)


class Sweep:
    """A resumable experiment: methods x patterns x learnings, stored chunk by chunk.

    Args:
        domain: domain name recorded with the results (``"four_rooms"``, ``"pinball"``,
            ``"fetch"``); a directory of another domain is refused.
        results_dir: where ``config.json`` and ``chunks/`` live.
        methods: the methods and their learners.
        run_chunk: module-level function ``(chunk, config, progress) -> EpisodeTable``.
        config: JSON-serialisable settings handed to ``run_chunk``: hyper-parameters,
            ``"patterns"`` (pattern name -> list of subgoal dicts) and a ``"report"``
            section (see :class:`~torchrl_subgoal.experiments.report.ReportSpec`).
        seed: sweep seed; chunk seeds derive from it, the method name and the chunk index.
        chunk_size: at most this many learners per chunk (a chunk never mixes methods).
        n_episodes: episodes per learner, when known: every table is checked against it
            and the progress bar gets a total from the start.
        overwrite: discard results of a different experiment in ``results_dir``
            instead of raising :class:`ConfigMismatchError`.
        runtime: JSON-serialisable settings that change how chunks run but not their results
            (a learner recipe's ``"logger"``): ``run_chunk`` gets them with ``config``; recorded in
            ``config.json``, but a resumed sweep may change them.
        provenance: what made the results (a recipe's command, its settings, the code's version),
            recorded in ``config.json`` when the sweep starts; not compared when it resumes.
        warm_up: called once before the first pending chunk runs, with a line on stderr before and after:
            what compiles the chunks' numba kernels in this process, so that worker processes load them
            from numba's cache instead of each compiling them at 0% of the progress bar. If it raises, the
            chunks run anyway (and report their own failure).

    Re-running the same sweep resumes: finished chunks are kept, temporary files of an
    interrupted write are removed, corrupt chunks are reported
    (:class:`CorruptChunkWarning`), moved aside and recomputed.

    Examples:
        >>> sweep = Sweep(  # doctest: +SKIP
        ...     "four_rooms", "results/four_rooms",
        ...     [MethodSpec("HRS", ["p1", "p2"], 100), MethodSpec("SARSA", ["none"], 1000)],
        ...     run_chunk=my_module.run_chunk, config={"lr": 0.01, "report": {...}},
        ...     seed=0, chunk_size=100, n_episodes=1000,
        ... )
        >>> results = sweep.run(backend="local", workers=2)  # doctest: +SKIP
        >>> frame = results.to_frame()  # doctest: +SKIP
    """

    def __init__(
        self,
        domain: str,
        results_dir: str | os.PathLike[str],
        methods: Sequence[MethodSpec],
        run_chunk: RunChunk,
        config: Mapping[str, Any],
        seed: int = 0,
        chunk_size: int = 100,
        *,
        n_episodes: int | None = None,
        overwrite: bool = False,
        runtime: Mapping[str, Any] | None = None,
        provenance: Mapping[str, Any] | None = None,
        warm_up: Callable[[], object] | None = None,
    ) -> None:
        names = [m.name for m in methods]
        if not methods or len(set(names)) != len(names):
            raise ValueError(f"methods must be non-empty with distinct names, got {names}")
        if n_episodes is not None and n_episodes < 1:
            raise ValueError("n_episodes must be >= 1")
        self.domain = domain
        self.store = ResultsStore(results_dir)
        self.methods = list(methods)
        self.run_chunk = run_chunk
        self.config: dict[str, Any] = to_json_data(dict(config))
        self.runtime: dict[str, Any] = to_json_data(dict(runtime or {}), "runtime")
        self.provenance: dict[str, Any] = to_json_data(dict(provenance or {}), "provenance")
        self.warm_up = warm_up
        self.seed = int(seed)
        self.chunk_size = int(chunk_size)
        self.n_episodes = n_episodes
        self.overwrite = overwrite
        self.chunks = plan_chunks(self.methods, self.seed, self.chunk_size)

    def manifest(self) -> dict[str, Any]:
        """The ``config.json`` this sweep writes."""
        return {
            "format": FORMAT_VERSION,
            "domain": self.domain,
            "methods": [m.to_json() for m in self.methods],
            "config": self.config,
            "seed": self.seed,
            "chunk_size": self.chunk_size,
            "n_episodes": self.n_episodes,
            "chunks": [c.to_json() for c in self.chunks],
            "versions": collect_versions(),
            **({"runtime": self.runtime} if self.runtime else {}),
            **({"provenance": self.provenance} if self.provenance else {}),
        }

    def _check_directory(self) -> dict[str, Any] | None:
        """The stored ``config.json`` (or None); refuse a directory that is not a results directory.

        A sweep writes only into a new or empty directory, or one holding a sweep's
        ``config.json``: files it cannot identify as its own are never touched.
        """
        stored = self.store.read_manifest()
        if stored is None:
            foreign = self.store.foreign_entries()
            if foreign:
                shown = ", ".join(p.name for p in foreign[:3]) + (" ..." if len(foreign) > 3 else "")
                raise ResultsError(
                    f"{self.store.root} is not empty ({shown}) and is not a results directory "
                    f"(no {CONFIG_FILE}); choose a new or empty directory"
                )
        return stored

    def finished_chunks(self) -> int:
        """How many chunk files the store holds (valid or not; they are checked on resume)."""
        return sum(1 for _ in self.store.chunks_dir.glob("*/*.parquet"))

    def _open_store(self) -> None:
        """Write config.json, or check the existing one matches this sweep.

        A stored experiment that differs is replaced only with ``overwrite``, or when
        it has no finished chunk (nothing to lose).
        """
        requested = self.manifest()
        stored = self._check_directory()
        root = self.store.root
        if stored is not None and not self.overwrite and self.finished_chunks():
            if stored["domain"] != self.domain:
                raise DomainMismatchError(
                    f"{root} holds results of domain {stored['domain']!r}, not {self.domain!r}; "
                    "choose another results dir (or pass overwrite to discard them)"
                )
            differing = [path for key in IDENTITY_FIELDS for path in diff_fields(stored.get(key), requested[key], key)]
            if differing:
                shown = ", ".join(differing[:12]) + (" ..." if len(differing) > 12 else "")
                raise ConfigMismatchError(
                    f"{root} holds a different experiment; differing fields: {shown}. "
                    "Use another results dir, or pass overwrite to discard the stored results."
                )
            versions = diff_fields(stored.get("versions"), requested["versions"], "versions")
            if versions:
                warnings.warn(
                    f"resuming {root} with other package versions ({', '.join(versions)}) "
                    "than the ones that started it",
                    stacklevel=3,
                )
            return
        told = ("runtime", "provenance")  # how this attempt runs, who asked: not the experiment
        if stored is not None and {k: v for k, v in stored.items() if k not in told} == {
            k: v for k, v in requested.items() if k not in told
        }:
            return  # nothing finished yet, the same experiment: keep its config.json
        self.store.clear()
        self.store.write_manifest(requested)

    def _resume_advice(self) -> str:
        """What to do after a chunk failed, given what the store holds."""
        saved = self.finished_chunks()
        if not saved:
            return "No chunk was finished; fix the cause and run the command again."
        return (
            f"{saved} finished chunk(s) are saved in {self.store.root}: fix the cause and run the "
            "same command again to compute the rest (a fix that changes a setting or the subgoals "
            "makes a different experiment: use another results dir, or pass overwrite to discard them)."
        )

    def pending(self) -> list[Chunk]:
        """Chunks not (validly) stored yet; corrupt ones are reported and moved aside."""
        todo = []
        for chunk in self.chunks:
            status = self.store.check_chunk(chunk)
            if status.state == "corrupt":
                moved = self.store.quarantine(chunk)
                warnings.warn(
                    f"corrupt chunk file {self.store.chunk_path(chunk)} ({status.reason}); "
                    f"moved to {moved.name} and recomputing",
                    CorruptChunkWarning,
                    stacklevel=2,
                )
            if status.state != "done":
                todo.append(chunk)
        return todo

    def _check_table(self, chunk: Chunk, table: Any) -> EpisodeTable:
        if not isinstance(table, EpisodeTable):
            raise TypeError(f"run_chunk returned {type(table).__name__} for {chunk.name}, not EpisodeTable")
        if table.n_learners != chunk.n_learners:
            raise ValueError(
                f"run_chunk returned {table.n_learners} rows for {chunk.name}, which has {chunk.n_learners} learners"
            )
        if self.n_episodes is not None and table.n_episodes != self.n_episodes:
            raise ValueError(
                f"run_chunk returned {table.n_episodes} episodes for {chunk.name}, "
                f"the sweep has n_episodes={self.n_episodes}"
            )
        return table

    def run(self, backend: Backend = "local", workers: int = 2, progress: bool = True) -> Results:
        """Run every chunk not yet stored, writing each as it finishes; return all results.

        Args:
            backend: ``"local"`` (process pool, spawn) or ``"ray"``.
            workers: local worker processes (``0`` = run in this process); for a local Ray
                instance started by the sweep, its number of CPUs.
            progress: show a tqdm bar over learner-episodes.

        Raises:
            ConfigMismatchError, DomainMismatchError: ``results_dir`` holds another experiment.
            ChunkFailedError: ``run_chunk`` raised; finished chunks are kept. Locally, chunks
                already running still finish and are written; on Ray the remaining tasks are
                cancelled.
            BackendUnavailableError: ``backend="ray"`` and nothing answers at ``RAY_ADDRESS``
                (nothing is written).
        """
        if backend not in ("local", "ray"):
            raise ValueError(f"unknown backend {backend!r}; choose 'local' or 'ray'")
        if workers < 0:
            raise ValueError("workers must be >= 0")
        if backend == "local" and workers > 0:  # Ray pickles functions by value itself
            try:
                pickle.dumps(self.run_chunk)
            except Exception as exc:
                raise TypeError(
                    "run_chunk must be picklable: define it at module level in an importable module"
                ) from exc
        if backend == "ray":
            from torchrl_subgoal.experiments._ray import check_ray_address

            check_ray_address()  # before anything is written
        self._check_directory()  # before the lock file is created in a directory that is not ours
        with self.store.lock():
            self._open_store()
            self.store.clean_temp_files()
            todo = self.pending()
            if todo and self.warm_up is not None:
                _warm_up(self.warm_up)
            if todo:
                bar = ProgressBar(todo, self.n_episodes, progress)
                config = {**self.config, **self.runtime}
                finished: Finished
                if backend == "ray":
                    from torchrl_subgoal.experiments._ray import run_ray

                    finished = run_ray(todo, self.run_chunk, config, bar, workers)
                elif workers == 0:
                    finished = _run_inline(todo, self.run_chunk, config, bar)
                else:
                    finished = _run_local(todo, self.run_chunk, config, bar, workers)
                try:
                    for chunk, table in finished:
                        table = self._check_table(chunk, table)
                        self.store.write_chunk(chunk, table)
                        bar.done(chunk, table.n_episodes)
                except ChunkFailedError as exc:
                    raise ChunkFailedError(f"{exc} {self._resume_advice()}") from exc.__cause__
                finally:
                    finished.close()  # on an error here: stops the backend's workers
                    bar.close()
        return load_results(self.store.root, domain=self.domain)

"""What every backend of a :class:`~torchrl_subgoal.experiments.sweep.Sweep` shares: the chunk runner's
protocol, its errors, the progress it reports and the bar that shows it."""

from __future__ import annotations

import time
from collections.abc import Callable, Generator, Mapping, Sequence
from typing import Any, Protocol

from tqdm.auto import tqdm

from torchrl_subgoal.experiments.results import Chunk, EpisodeTable

__all__ = [
    "RAY_RETRIES",
    "BackendUnavailableError",
    "ChunkFailedError",
    "Finished",
    "Progress",
    "ProgressBar",
    "RunChunk",
    "ThrottledProgress",
    "failure",
    "limit_threads",
]

Progress = Callable[[int], None]
#: How often Ray runs a chunk again whose worker process or node died (a ``run_chunk`` that raises is not
#: run again: it would raise again).
RAY_RETRIES = 3


class RunChunk(Protocol):
    """The user-supplied, picklable (module-level) function that runs one chunk.

    It trains every learner of ``chunk`` (seeding all randomness from ``chunk.seed``)
    and returns their per-episode records, one row per learner in ``chunk.learners``
    order. ``progress(k)`` reports ``k`` more learner-episodes finished.

    Examples:
        >>> import numpy as np
        >>> def run_chunk(chunk, config, progress):  # a RunChunk: every learner takes 7 steps per episode
        ...     episodes = config["episodes"]
        ...     progress(chunk.n_learners * episodes)
        ...     shape = (chunk.n_learners, episodes)
        ...     return EpisodeTable(np.full(shape, 7), np.zeros(shape), np.ones(shape, bool))
        >>> done = []
        >>> table = run_chunk(Chunk("HRS", 0, (("alice", 0), ("alice", 1)), seed=1), {"episodes": 3}, done.append)
        >>> table.n_learners, table.n_episodes, done
        (2, 3, [6])
    """

    def __call__(self, chunk: Chunk, config: Mapping[str, Any], progress: Progress, /) -> EpisodeTable: ...


class ChunkFailedError(RuntimeError):
    """``run_chunk`` raised (or its worker died); finished chunks are kept for a re-run.

    Examples:
        >>> issubclass(ChunkFailedError, RuntimeError), str(ChunkFailedError("HRS/00000: worker died"))
        (True, 'HRS/00000: worker died')
    """


class BackendUnavailableError(RuntimeError):
    """The Ray cluster ``RAY_ADDRESS`` names does not answer; raised before anything is written.

    Examples:
        >>> issubclass(BackendUnavailableError, RuntimeError)
        True
    """


# -- progress -------------------------------------------------------------------------------


class ThrottledProgress:
    """The ``progress`` callable handed to ``run_chunk``: batches counts before sending.

    Examples:
        >>> sent = []
        >>> progress = ThrottledProgress("HRS/00000", sent.append)
        >>> progress(3), progress(4), sent
        (None, None, [])
        >>> progress.flush()
        >>> sent
        [('HRS/00000', 7)]
    """

    def __init__(self, chunk_name: str, sink: Callable[[tuple[str, int]], None] | None) -> None:
        self.chunk_name = chunk_name
        self.sink = sink
        self.pending = 0
        self.last = time.monotonic()

    def __call__(self, k: int) -> None:
        self.pending += int(k)
        if time.monotonic() - self.last > 0.25:
            self.flush()

    def flush(self) -> None:
        if self.sink is not None and self.pending:
            self.sink((self.chunk_name, self.pending))
        self.pending = 0
        self.last = time.monotonic()


class ProgressBar:
    """A tqdm bar over learner-episodes, fed by chunk progress messages.

    Examples:
        >>> chunk = Chunk("HRS", 0, (("alice", 0),), seed=1)
        >>> bar = ProgressBar([chunk], n_episodes=3, enabled=False)
        >>> bar.add("HRS/00000", 2)
        >>> bar.add("HRS/00000", 5)  # a learner runs 3 episodes: counted up to that
        >>> bar.reported
        {'HRS/00000': 3}
        >>> bar.close()
    """

    def __init__(self, chunks: Sequence[Chunk], n_episodes: int | None, enabled: bool) -> None:
        self.n_episodes = n_episodes
        self.learners = {c.name: c.n_learners for c in chunks}
        self.reported: dict[str, int] = dict.fromkeys(self.learners, 0)
        total = sum(self.learners.values()) * n_episodes if n_episodes else None
        self.bar = tqdm(total=total, unit="ep", desc="learner-episodes", disable=not enabled)

    def _cap(self, name: str) -> int | None:
        return self.learners[name] * self.n_episodes if self.n_episodes else None

    def add(self, name: str, k: int) -> None:
        if name not in self.reported:  # a late message for a chunk already counted
            return
        cap = self._cap(name)
        if cap is not None:
            k = max(0, min(k, cap - self.reported[name]))
        self.reported[name] += k
        self.bar.update(k)

    def done(self, chunk: Chunk, n_episodes: int) -> None:
        if self.n_episodes is None:
            self.n_episodes = n_episodes
            self.bar.total = sum(self.learners.values()) * n_episodes
        self.add(chunk.name, chunk.n_learners * n_episodes)
        self.reported.pop(chunk.name, None)
        self.bar.refresh()

    def close(self) -> None:
        self.bar.close()


def limit_threads() -> None:
    """One torch thread in a worker process: the workers, not the threads, use the cores.

    Examples:
        >>> import torch
        >>> before = torch.get_num_threads()
        >>> limit_threads()
        >>> torch.get_num_threads()
        1
        >>> torch.set_num_threads(before)
    """
    import torch

    torch.set_num_threads(1)


def failure(chunk: Chunk, exc: BaseException, note: str = "") -> ChunkFailedError:
    """The error for a chunk whose ``run_chunk`` raised; :meth:`Sweep.run` adds what to do next.

    Examples:
        >>> failure(Chunk("HRS", 0, (("alice", 0),), seed=1), ValueError("bad\\nfile."))
        ChunkFailedError('chunk HRS/00000 failed: ValueError: bad file.')
    """
    reason = " ".join(str(exc).split()).rstrip(".") or "(no message)"  # one line, however the cause wrote it
    return ChunkFailedError(f"chunk {chunk.name} failed: {type(exc).__name__}: {reason}{note}.")


Finished = Generator[tuple[Chunk, EpisodeTable], None, None]

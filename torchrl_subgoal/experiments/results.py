"""What a sweep's results are: the errors of the results store, and the records of chunks, episodes and
methods (see :mod:`torchrl_subgoal.experiments.store` for the files)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np
import numpy.typing as npt
import pandas as pd

#: The per-episode metrics an :class:`EpisodeTable` holds, by their column names.
METRICS = ("steps", "return", "success")


class ResultsError(Exception):
    """Base class of the errors raised about a results directory.

    Examples:
        >>> try:
        ...     raise DomainMismatchError("results/x holds pinball, not four_rooms")
        ... except ResultsError as exc:
        ...     print(exc)
        results/x holds pinball, not four_rooms
    """


class ConfigMismatchError(ResultsError):
    """A sweep was started into a directory holding a different experiment.

    Examples:
        >>> issubclass(ConfigMismatchError, ResultsError), str(ConfigMismatchError("config differs: seed"))
        (True, 'config differs: seed')
    """


class DomainMismatchError(ResultsError):
    """A results directory belongs to another domain than the one asked for.

    Examples:
        >>> issubclass(DomainMismatchError, ResultsError), str(DomainMismatchError("domain is pinball"))
        (True, 'domain is pinball')
    """


class UnknownMethodError(ResultsError, KeyError):
    """A method name is not part of the sweep or results directory.

    Examples:
        >>> str(UnknownMethodError("unknown method 'XYZ'"))  # not quoted as a KeyError's would be
        "unknown method 'XYZ'"
        >>> issubclass(UnknownMethodError, KeyError)
        True
    """

    def __str__(self) -> str:  # KeyError would quote the whole message
        return str(self.args[0]) if self.args else ""


class CorruptChunkError(ResultsError):
    """A chunk file exists but cannot be trusted (unreadable, wrong identity or size).

    Examples:
        >>> error = CorruptChunkError(Path("chunks/HRS/00000.npz"), "wrong size")
        >>> str(error), error.reason
        ('corrupt chunk file chunks/HRS/00000.npz: wrong size', 'wrong size')
    """

    def __init__(self, path: Path, reason: str) -> None:
        super().__init__(f"corrupt chunk file {path}: {reason}")
        self.path = path
        self.reason = reason


class IncompleteResultsError(ResultsError):
    """Some chunks of the sweep have not been computed yet.

    Examples:
        >>> issubclass(IncompleteResultsError, ResultsError), str(IncompleteResultsError("2 chunks missing"))
        (True, '2 chunks missing')
    """


class SweepRunningError(ResultsError):
    """A sweep holds the results directory's lock: it is writing into it, so its results are not final.

    Examples:
        >>> issubclass(SweepRunningError, ResultsError)
        True
    """


@dataclass(frozen=True)
class Chunk:
    """A unit of work: consecutive learners of one method, run by one call of ``run_chunk``.

    Args:
        method: name of the method all learners of the chunk use.
        index: position of the chunk among the method's chunks (0-based).
        learners: ``(pattern, learning)`` pairs, in the order the result rows must follow.
        seed: a 63-bit seed derived from (sweep seed, method, index); seed every random
            source of the chunk from it and the results do not depend on the backend or
            on the order chunks run in.

    Examples:
        >>> chunk = Chunk("HRS", 0, (("p1", 0), ("p1", 1)), seed=123)
        >>> chunk.name, chunk.n_learners
        ('HRS/00000', 2)
    """

    method: str
    index: int
    learners: tuple[tuple[str, int], ...]
    seed: int

    @property
    def n_learners(self) -> int:
        """Number of learners in the chunk."""
        return len(self.learners)

    @property
    def name(self) -> str:
        """``<method>/<index>``, also the chunk file's path below ``chunks/``."""
        return f"{self.method}/{self.index:05d}"

    def to_json(self) -> dict[str, Any]:
        """A JSON-ready dict; learners are run-length encoded as ``[pattern, first, stop]``."""
        runs: list[list[Any]] = []
        for pattern, learning in self.learners:
            if runs and runs[-1][0] == pattern and runs[-1][2] == learning:
                runs[-1][2] = learning + 1
            else:
                runs.append([pattern, learning, learning + 1])
        return {"method": self.method, "index": self.index, "seed": self.seed, "learners": runs}

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> Chunk:
        """Inverse of :meth:`to_json`."""
        learners = tuple(
            (str(pattern), learning)
            for pattern, first, stop in data["learners"]
            for learning in range(int(first), int(stop))
        )
        return cls(str(data["method"]), int(data["index"]), learners, int(data["seed"]))


@dataclass(frozen=True, init=False, eq=False)
class EpisodeTable:
    """Per-episode records of the learners of one chunk (or of a whole method).

    Row ``i`` belongs to the chunk's ``i``-th learner, column ``j`` to its episode
    ``j + 1``. Arrays are converted on construction (torch CPU tensors are accepted).

    Args:
        steps: int array ``[n_learners, n_episodes]``, steps taken in each episode.
        returns: float array of the same shape, undiscounted environment return.
        success: array of the same shape: whether the episode reached the goal (bool), or
            the fraction of a row's test episodes that did (e.g. one row per training epoch);
            stored as a float in [0, 1].

    Examples:
        >>> import numpy as np
        >>> table = EpisodeTable(np.full((2, 3), 7), np.zeros((2, 3)), np.ones((2, 3), bool))
        >>> table.n_learners, table.n_episodes, table.metric("steps").dtype
        (2, 3, dtype('float64'))
    """

    steps: npt.NDArray[np.int64]
    returns: npt.NDArray[np.float64]
    success: npt.NDArray[np.float64]

    def __init__(self, steps: npt.ArrayLike, returns: npt.ArrayLike, success: npt.ArrayLike) -> None:
        steps_ = np.asarray(steps)
        if steps_.ndim != 2:
            raise ValueError(f"steps must be 2-D [n_learners, n_episodes], got shape {steps_.shape}")
        if not np.issubdtype(steps_.dtype, np.integer) and not np.array_equal(steps_, np.round(steps_)):
            raise ValueError("steps must hold whole numbers")
        object.__setattr__(self, "steps", steps_.astype(np.int64))
        object.__setattr__(self, "returns", np.asarray(returns, dtype=np.float64))
        success_ = np.asarray(success, dtype=np.float64)
        if success_.size and not ((success_ >= 0) & (success_ <= 1)).all():
            raise ValueError("success must be a bool or a fraction in [0, 1]")
        object.__setattr__(self, "success", success_)
        for name in ("returns", "success"):
            shape = getattr(self, name).shape
            if shape != steps_.shape:
                raise ValueError(f"{name} has shape {shape}, steps has {steps_.shape}")

    @property
    def n_learners(self) -> int:
        """Number of rows (learners)."""
        return int(self.steps.shape[0])

    @property
    def n_episodes(self) -> int:
        """Number of columns (episodes per learner)."""
        return int(self.steps.shape[1])

    def metric(self, name: str) -> npt.NDArray[np.float64]:
        """One metric as a float array ``[n_learners, n_episodes]``.

        Args:
            name: ``"steps"``, ``"return"`` (or ``"returns"``) or ``"success"``.
        """
        arrays: dict[str, npt.NDArray[Any]] = {"steps": self.steps, "success": self.success}
        arrays["return"] = arrays["returns"] = self.returns
        if name not in arrays:
            raise ValueError(f"unknown metric {name!r}; choose one of {METRICS}")
        return arrays[name].astype(np.float64)

    @classmethod
    def concat(cls, tables: Sequence[EpisodeTable]) -> EpisodeTable:
        """Stack tables with the same number of episodes along the learner axis."""
        if not tables:
            raise ValueError("nothing to concatenate")
        return cls(
            np.concatenate([t.steps for t in tables]),
            np.concatenate([t.returns for t in tables]),
            np.concatenate([t.success for t in tables]),
        )


@dataclass(frozen=True)
class ChunkStatus:
    """State of one planned chunk in the store.

    Examples:
        >>> ChunkStatus("corrupt", "wrong size")
        ChunkStatus(state='corrupt', reason='wrong size')
    """

    state: Literal["done", "missing", "corrupt"]
    reason: str = ""


@dataclass(frozen=True, eq=False)
class MethodResults:
    """All finished learners of one method, in sweep order.

    Attributes:
        name: the method's name.
        patterns: pattern name of each learner, shape ``[n_learners]``.
        learnings: learning index of each learner within its pattern.
        table: the episode records, one row per learner.

    Examples:
        >>> table = EpisodeTable(np.full((2, 3), 7), np.zeros((2, 3)), np.ones((2, 3), bool))
        >>> results = MethodResults("HRS", np.array(["alice", "alice"]), np.array([0, 1]), table)
        >>> results.name, results.table.n_learners
        ('HRS', 2)
    """

    name: str
    patterns: npt.NDArray[np.str_]
    learnings: npt.NDArray[np.int64]
    table: EpisodeTable


@dataclass(frozen=True, eq=False)
class Results:
    """The contents of a results directory, as loaded by :func:`load_results`.

    Attributes:
        root: the results directory.
        domain: domain name recorded by the sweep.
        config: the sweep's ``config`` mapping (hyper-parameters, patterns, report section).
        methods: per-method results, in the sweep's method order.
        missing: names of planned chunks not (yet) in the store, when loaded with
            ``allow_incomplete=True``.
        manifest: the whole ``config.json``.

    Examples:
        >>> table = EpisodeTable(np.full((2, 3), 7), np.zeros((2, 3)), np.ones((2, 3), bool))
        >>> method = MethodResults("HRS", np.array(["alice", "alice"]), np.array([0, 1]), table)
        >>> results = Results(Path("results/four_rooms"), "four_rooms", {}, {"HRS": method})
        >>> results.to_frame().shape[0]  # one row per learner and episode
        6
    """

    root: Path
    domain: str
    config: Mapping[str, Any]
    methods: Mapping[str, MethodResults]
    missing: tuple[str, ...] = ()
    manifest: Mapping[str, Any] = field(default_factory=dict)

    def to_frame(self) -> pd.DataFrame:
        """Long format: one row per (method, pattern, learning, episode).

        Columns: ``method``, ``pattern`` (categoricals), ``learning``, ``episode``
        (1-based), ``steps``, ``return``, ``success``.
        """
        columns = ["method", "pattern", "learning", "episode", "steps", "return", "success"]
        if not self.methods:
            return pd.DataFrame(columns=columns)
        results = list(self.methods.values())
        sizes = [res.table.steps.size for res in results]
        episodes = [res.table.n_episodes for res in results]
        patterns, pattern_codes = np.unique(np.concatenate([res.patterns for res in results]), return_inverse=True)
        method_codes = np.repeat(np.arange(len(results)), sizes)
        frame = pd.DataFrame(
            {
                "method": pd.Categorical.from_codes(method_codes, categories=pd.Index(list(self.methods))),
                "pattern": pd.Categorical.from_codes(
                    np.repeat(pattern_codes, np.repeat(episodes, [r.table.n_learners for r in results])),
                    categories=pd.Index(patterns.tolist()),
                ),
                "learning": np.concatenate([np.repeat(r.learnings, r.table.n_episodes) for r in results]),
                "episode": np.concatenate(
                    [np.tile(np.arange(1, e + 1), r.table.n_learners) for r, e in zip(results, episodes, strict=True)]
                ),
                "steps": np.concatenate([r.table.steps.ravel() for r in results]),
                "return": np.concatenate([r.table.returns.ravel() for r in results]),
                "success": np.concatenate([r.table.success.ravel() for r in results]),
            },
            columns=columns,
        )
        return frame

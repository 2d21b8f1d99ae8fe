"""The experiment engine every domain's recipe shares.

* :mod:`~torchrl_subgoal.experiments.sweep`: methods x patterns x learnings, run in
  chunks on local processes or Ray, resumable;
* :mod:`~torchrl_subgoal.experiments.store`: the results directory (atomic Parquet
  chunks, ``config.json``) and its loaders;
* :mod:`~torchrl_subgoal.experiments.stats`: the paper's statistics and robust extras;
* :mod:`~torchrl_subgoal.experiments.report`: ``report.md``, ``summary.json`` and plots
  (also the ``torchrl-subgoal-report`` command);
* :mod:`~torchrl_subgoal.experiments.paper`: the paper's published numbers.

The report side (matplotlib, statsmodels) is imported only when first used, so
sweep workers start quickly.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from torchrl_subgoal.experiments.backend import BackendUnavailableError, ChunkFailedError, RunChunk
from torchrl_subgoal.experiments.results import (
    Chunk,
    ConfigMismatchError,
    CorruptChunkError,
    DomainMismatchError,
    EpisodeTable,
    IncompleteResultsError,
    MethodResults,
    Results,
    ResultsError,
    SweepRunningError,
    UnknownMethodError,
)
from torchrl_subgoal.experiments.store import load_frame, load_results
from torchrl_subgoal.experiments.sweep import (
    CorruptChunkWarning,
    MethodSpec,
    Sweep,
    learner_seeds,
    plan_chunks,
    select_methods,
)

if TYPE_CHECKING:
    from torchrl_subgoal.experiments.report import ReportSpec, write_report

__all__ = [
    "BackendUnavailableError",
    "Chunk",
    "ChunkFailedError",
    "ConfigMismatchError",
    "CorruptChunkError",
    "CorruptChunkWarning",
    "DomainMismatchError",
    "EpisodeTable",
    "IncompleteResultsError",
    "MethodResults",
    "MethodSpec",
    "ReportSpec",
    "Results",
    "ResultsError",
    "RunChunk",
    "Sweep",
    "SweepRunningError",
    "UnknownMethodError",
    "learner_seeds",
    "load_frame",
    "load_results",
    "plan_chunks",
    "select_methods",
    "write_report",
]


def __getattr__(name: str) -> Any:
    if name in ("ReportSpec", "write_report"):
        from torchrl_subgoal.experiments import report

        return getattr(report, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")

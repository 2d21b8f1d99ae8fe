"""Pool one method's learners over several results directories and compare two such pools.

A cell of docs/does_it_help.md often gathers a method's learners from two runs (two sweep
seeds, or a run resumed later). This prints, for the pooled learners of ``BASELINE`` and of
``OTHER``, what the report gives for one directory: at each threshold of the runs' report
section the mean time to get there (in frames when the runs record frames per column, a
learner that never gets there counting as the budget), how many learners got there, the ratio
``BASELINE / OTHER`` (above 1: ``OTHER`` is sooner), Welch's p and Holm's correction over the
thresholds; then the mean final metric over the report's final window and its Welch p.

Each pool is a comma-separated list of ``RESULTS_DIR:METHOD``; the directories must hold the
same domain, report section and episodes per learner.

    python tools/pool_runs.py results/ddpg_point_maze_medium:DDPG,results/ddpg_point_maze_medium_seed1:DDPG \\
        results/ddpg_point_maze_medium:HRS,results/ddpg_point_maze_medium_seed1:HRS
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import NamedTuple

import numpy as np
from scipy import stats as sps
from statsmodels.stats.multitest import multipletests

from torchrl_subgoal.experiments import load_results, stats
from torchrl_subgoal.experiments.report import ReportSpec
from torchrl_subgoal.experiments.results import ResultsError


class Pool(NamedTuple):
    """The learners of one method gathered from several results directories."""

    label: str
    curves: np.ndarray  # [n_learners, n_episodes] of the report's metric
    domain: str
    spec: ReportSpec


def load_pool(text: str) -> Pool:
    """Read ``DIR:METHOD,DIR:METHOD,…`` into one pool.

    Raises:
        SystemExit: an entry is malformed, a directory cannot be read or lacks the method, or
            the directories differ in domain, report section or episodes per learner.
    """
    parts, first = [], None
    for entry in text.split(","):
        directory, sep, method = entry.rpartition(":")
        if not sep or not directory or not method:
            raise SystemExit(f"{entry!r}: expected RESULTS_DIR:METHOD")
        try:
            results = load_results(Path(directory), methods=[method])
        except ResultsError as exc:
            raise SystemExit(f"{directory}: {exc}") from None
        spec = ReportSpec.from_config(results.config)
        curves = results.methods[method].table.metric(spec.metric)
        if first is None:
            first = (directory, results.domain, spec, curves.shape[1])
        elif (results.domain, spec, curves.shape[1]) != first[1:]:
            raise SystemExit(
                f"{directory}: its domain, report section or episodes per learner differ from {first[0]}'s"
            )
        parts.append(curves)
    assert first is not None
    return Pool(text, np.concatenate(parts), first[1], first[2])


def compare(baseline: Pool, other: Pool) -> str:
    """The comparison as Markdown (two tables)."""
    if (baseline.domain, baseline.spec, baseline.curves.shape[1]) != (
        other.domain,
        other.spec,
        other.curves.shape[1],
    ):
        raise SystemExit("the two pools differ in domain, report section or episodes per learner")
    spec = baseline.spec
    scale = spec.frames_per_unit or 1
    unit = "frames" if spec.frames_per_unit else f"{spec.unit}s"
    rows, pvalues = [], []
    for threshold in spec.thresholds:
        times = [
            stats.time_to_threshold(p.curves, threshold, window=spec.window, lower_is_better=spec.lower_is_better)
            for p in (baseline, other)
        ]
        a, b = (t.episodes.astype(np.float64) * scale for t in times)
        pvalues.append(float(sps.ttest_ind(a, b, equal_var=False).pvalue))
        reached = " / ".join(f"{int(t.reached.sum())} of {t.reached.size}" for t in times)
        rows.append((threshold, a.mean(), b.mean(), a.mean() / b.mean(), reached))
    holm = multipletests(pvalues, method="holm")[1] if pvalues else []
    lines = [
        f"baseline: {baseline.label} ({baseline.curves.shape[0]} learners)",
        f"other: {other.label} ({other.curves.shape[0]} learners)",
        "",
        f"| threshold | baseline, {unit} | other, {unit} | baseline / other | got there | Welch p | Holm p |",
        "|---|---|---|---|---|---|---|",
    ]
    for (threshold, a_mean, b_mean, ratio, reached), p, h in zip(rows, pvalues, holm, strict=True):
        lines.append(
            f"| {threshold:g} | {a_mean:,.0f} | {b_mean:,.0f} | {ratio:.2f}x | {reached} | {p:.3g} | {h:.3g} |"
        )
    window = spec.final_window(baseline.curves.shape[1])
    finals = [stats.asymptotic_performance(p.curves, window) for p in (baseline, other)]
    p_final = float(sps.ttest_ind(finals[0], finals[1], equal_var=False).pvalue)
    lines += [
        "",
        f"| final {spec.metric} (episodes {window[0] + 1} to {window[1]}) | baseline | other | Welch p |",
        "|---|---|---|---|",
        f"| mean | {finals[0].mean():.1f} | {finals[1].mean():.1f} | {p_final:.3g} |",
    ]
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("baseline", help="RESULTS_DIR:METHOD,… (e.g. the unshaped learner's runs)")
    parser.add_argument("other", help="RESULTS_DIR:METHOD,… (e.g. the shaped learner's runs)")
    args = parser.parse_args(argv)
    print(compare(load_pool(args.baseline), load_pool(args.other)))
    return 0


if __name__ == "__main__":
    sys.exit(main())

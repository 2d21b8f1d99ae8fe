"""tools/pool_runs.py: a method's learners pooled over results directories, two pools compared."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy import stats as sps

from tests.experiments import toy_domain
from tests.tools import load_tool
from torchrl_subgoal.experiments import Sweep, load_results, stats


def _run(path: Path, seed: int, n_episodes: int = 40) -> Path:
    methods = toy_domain.toy_methods(2, ("HRS", "NRS", "STUCK"))
    config = toy_domain.toy_config(n_episodes)
    Sweep("toy", path, methods, toy_domain.run_chunk, config, seed=seed, chunk_size=4).run(workers=0, progress=False)
    return path


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    root = tmp_path_factory.mktemp("pool")
    return _run(root / "a", 0), _run(root / "b", 1)


def test_the_pooled_comparison_equals_the_statistics_of_the_concatenated_learners(runs, capsys) -> None:
    tool = load_tool("pool_runs")
    a, b = runs
    assert tool.main([f"{a}:NRS,{b}:NRS", f"{a}:HRS,{b}:HRS"]) == 0
    printed = capsys.readouterr().out
    curves = {m: np.concatenate([load_results(d).methods[m].table.steps for d in runs]) for m in ("NRS", "HRS")}
    nrs, hrs = (stats.time_to_threshold(curves[m], 100).episodes.astype(float) for m in ("NRS", "HRS"))
    assert nrs.size == hrs.size == 8 and nrs.mean() > hrs.mean()  # the toy HRS learns faster
    p = sps.ttest_ind(nrs, hrs, equal_var=False).pvalue
    assert (
        f"| 100 | {nrs.mean():,.0f} | {hrs.mean():,.0f} | {nrs.mean() / hrs.mean():.2f}x | 8 of 8 / 8 of 8 | {p:.3g} |"
        in printed
    )
    finals = [stats.asymptotic_performance(curves[m], (35, 40)).mean() for m in ("NRS", "HRS")]
    assert f"| mean | {finals[0]:.1f} | {finals[1]:.1f} |" in printed
    assert "(8 learners)" in printed and "final steps (episodes 36 to 40)" in printed


def test_a_learner_that_never_gets_there_counts_as_the_budget(runs, capsys) -> None:
    tool = load_tool("pool_runs")
    a, b = runs
    tool.main([f"{a}:STUCK,{b}:STUCK", f"{a}:HRS"])
    printed = capsys.readouterr().out
    assert "| 100 | 40 | " in printed and "| 0 of 8 / 4 of 4 |" in printed  # 40 episodes: the budget


def test_what_cannot_be_pooled_is_named(runs, tmp_path) -> None:
    tool = load_tool("pool_runs")
    a, _ = runs
    with pytest.raises(SystemExit, match="expected RESULTS_DIR:METHOD"):
        tool.main([str(a), f"{a}:HRS"])
    with pytest.raises(SystemExit, match=r"a: .*DQN"):
        tool.main([f"{a}:DQN", f"{a}:HRS"])
    shorter = _run(tmp_path / "short", 0, n_episodes=30)
    with pytest.raises(
        SystemExit, match=r"short: its domain, report section or episodes per learner differ from .*a's"
    ):
        tool.main([f"{a}:HRS,{shorter}:HRS", f"{a}:NRS"])
    with pytest.raises(SystemExit, match="the two pools differ"):
        tool.main([f"{a}:HRS", f"{shorter}:NRS"])

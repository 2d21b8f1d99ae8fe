""" "Try it": both methods on the same seeds through the fused engine, progress, cancelling, bounds."""

from __future__ import annotations

import threading
from typing import Any

import pytest
import torch

from torchrl_subgoal.studio.jobs import Cancelled, JobError, Jobs
from torchrl_subgoal.studio.training import TrySettings, try_pattern
from torchrl_subgoal.subgoals import Cell, Circle, SubgoalSeries

HALLWAYS = SubgoalSeries([Cell(3, 6), Cell(7, 9)], name="hallways")
CIRCLES = SubgoalSeries([Circle((0.5877, 0.6486), 0.04), Circle((0.6442, 0.3202), 0.04)], name="p1")


@pytest.mark.parametrize(
    ("domain", "series", "map_"),
    [
        ("four_rooms", HALLWAYS, None),
        ("pinball", CIRCLES, "simple"),
        ("pinball", CIRCLES, "hard"),
    ],
)
def test_both_curves_progress_and_potential(domain: str, series: SubgoalSeries, map_: str | None) -> None:
    settings = TrySettings(episodes=4, learners=3, max_steps=200)
    done: list[int] = []
    result = try_pattern(domain, series, settings, map=map_, progress=done.append)
    assert sum(done) == 2 * 3 * 4  # every learner-episode of both methods, once
    for curve in (result.shaped, result.baseline):
        assert len(curve.mean) == len(curve.sem) == 4
        assert all(1 <= m <= 200 for m in curve.mean) and 0.0 <= curve.success <= 1.0
    assert len(result.potential) == len(result.potential_sem) == 3
    assert result.settings["domain"] == domain


def test_same_seeds_same_baseline_and_shaping_changes_the_learning() -> None:
    settings = TrySettings(episodes=30, learners=4)
    a = try_pattern("four_rooms", HALLWAYS, settings)
    b = try_pattern("four_rooms", SubgoalSeries([Cell(10, 6)], name="door"), settings)
    assert a.baseline.mean == b.baseline.mean  # the unshaped run does not depend on the pattern
    assert a.shaped.mean != a.baseline.mean
    assert any(v != 0.0 for v in a.potential)  # the potential was learned


def test_the_potential_is_the_learned_table_mean(monkeypatch: pytest.MonkeyPatch) -> None:
    from torchrl_subgoal.methods import shaping_transform
    from torchrl_subgoal.studio import training

    tables: list[torch.Tensor] = []

    def spy(*args: Any, **kwargs: Any) -> Any:
        transform = shaping_transform(*args, **kwargs)
        tables.append(transform.potential.table)  # type: ignore[union-attr]
        return transform

    monkeypatch.setattr(training, "shaping_transform", spy)
    result = try_pattern("four_rooms", HALLWAYS, TrySettings(episodes=10, learners=5))
    expected = tables[0].detach().double().mean(0)
    assert torch.allclose(torch.tensor(result.potential, dtype=torch.float64), expected)
    assert expected.abs().sum() > 0


def test_a_progress_callback_that_raises_stops_the_learning() -> None:
    calls = []

    def stop(units: int) -> None:
        calls.append(units)
        raise Cancelled

    with pytest.raises(Cancelled):
        try_pattern("four_rooms", HALLWAYS, TrySettings(episodes=50, learners=2), progress=stop)
    assert len(calls) == 1


def test_unknown_domain() -> None:
    with pytest.raises(ValueError, match="unknown domain 'chess'"):
        try_pattern("chess", HALLWAYS, TrySettings(1, 1))


def test_a_domain_without_a_learner_is_named() -> None:
    """The learner comes from the domain's registration; pick-and-place registers none."""
    with pytest.raises(
        ValueError,
        match=r"^no learner \(StudioDomain.learner\) for domain 'pick_and_place'; known: "
        r"\['four_rooms', 'pinball'",
    ):
        try_pattern("pick_and_place", HALLWAYS, TrySettings(1, 1))


def test_jobs_one_per_key_bounded_cancel_and_forget() -> None:
    gate = threading.Event()

    def work(progress: Any) -> dict[str, Any]:
        while not gate.wait(0.01):
            progress(1)
        return {"ok": True}

    jobs = Jobs(max_running=2, keep=1)
    a = jobs.start("a", 10, work)
    with pytest.raises(JobError, match="already running") as same:
        jobs.start("a", 10, work)
    assert same.value.status == 409
    b = jobs.start("b", 10, work)
    with pytest.raises(JobError, match="2 learnings are running") as busy:
        jobs.start("c", 10, work)
    assert busy.value.status == 429
    jobs.cancel(a.id)
    assert jobs.wait(a.id, 60).state == "cancelled"
    gate.set()
    done = jobs.wait(b.id, 60)
    assert done.state == "done" and done.result == {"ok": True} and done.status()["progress"] == 1.0
    c = jobs.start("c", 1, lambda progress: {})
    assert jobs.wait(c.id, 60).state == "done"
    assert jobs.get(a.id) is None  # only `keep` finished jobs are remembered

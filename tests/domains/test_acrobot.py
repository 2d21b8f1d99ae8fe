"""The Acrobot domain plugin: registration, subgoal check, the learners' defaults, the report map."""

from __future__ import annotations

from pathlib import Path

import pytest

from torchrl_subgoal import Box, Cell, Circle, domains, load_patterns
from torchrl_subgoal.experiments.plots import plot_pattern_maps
from torchrl_subgoal.training import DQNConfig, LearnerDomain


def test_acrobot_registers_a_learner_set_up_and_a_map() -> None:
    learners = domains.part("acrobot", LearnerDomain)
    assert learners.defaults["dqn"] == DQNConfig(total_frames=100_000, record_window=2)  # TorchRL's DQN example
    assert set(learners.defaults) == {"a2c", "ppo", "dqn"}  # three discrete actions
    assert learners.make_env(2).batch_size == (2,)
    assert list(load_patterns(learners.participants, domain="acrobot")) == ["swing_out"]


@pytest.mark.parametrize("learner", ["a2c", "ppo", "dqn"])
def test_time_outs_all_at_once_read_as_no_shorter_than_the_thresholds(learner: str) -> None:
    """Until a learner reaches the goal, all its envs time out at step 500 together; the recorded episode
    length over a window of ``W`` steps per env then reads as low as ``W / ceil(W / 500)``, above every
    threshold."""
    domain = domains.part("acrobot", LearnerDomain)
    config = domain.defaults[learner]
    window = config.record_window * config.frames_per_batch // config.num_envs
    lowest = 500 if window % 500 == 0 else window / -(-window // 500)
    assert window >= 500 and lowest > max(domain.thresholds)


@pytest.mark.parametrize(
    ("predicate", "message"),
    [
        (Box((-0.25,), (0.75,), (0,)), None),
        (Box((0.0, 5.0), (0.5, 1.0), (0, 4)), None),
        (Box((2.0,), (0.5,), (0,)), "cos θ1: the box [1.5, 2.5] lies outside [-1.0, 1.0]"),
        (Box((0.0,), (0.1,), (6,)), "an Acrobot box covers observation entries 0 to 5, not dims [6]"),
        (Circle((0.0, 0.0), 0.1), "Acrobot subgoals are boxes over the observation, not circle"),
        (Cell(1, 1), "Acrobot subgoals are boxes over the observation, not cell"),
    ],
)
def test_subgoal_check(predicate: object, message: str | None) -> None:
    assert domains.get("acrobot").check_subgoal(predicate) == message  # type: ignore[misc,arg-type]


def test_the_report_map_draws_the_arcs(tmp_path: Path) -> None:
    learners = domains.part("acrobot", LearnerDomain)
    patterns = {n: s.to_dict() for n, s in load_patterns(learners.participants).items()}
    figure = plot_pattern_maps("acrobot", patterns, tmp_path / "maps.png")
    assert figure.path is not None and figure.path.stat().st_size > 5_000, figure.note

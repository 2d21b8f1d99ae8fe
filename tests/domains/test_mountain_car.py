"""The MountainCar domain plugin: registration, subgoal check, the learners' defaults, the report map."""

from __future__ import annotations

from pathlib import Path

import pytest

from torchrl_subgoal import Box, Cell, Circle, domains, load_patterns
from torchrl_subgoal.experiments.plots import ReportMap, plot_pattern_maps
from torchrl_subgoal.training import DQNConfig, LearnerDomain


def test_mountain_car_registers_a_learner_set_up_and_a_map() -> None:
    domain = domains.get("mountain_car")
    learners = domain.part(LearnerDomain)
    assert learners is not None and domain.part(ReportMap) is not None
    assert learners.defaults["dqn"] == DQNConfig.preset("mountain_car")  # rl-baselines3-zoo's tuned DQN
    assert set(learners.defaults) == {"a2c", "ppo", "dqn"}  # three discrete actions
    assert learners.make_env(2).batch_size == (2,)
    assert list(load_patterns(learners.participants, domain="mountain_car")) == ["swing_then_speed"]


@pytest.mark.parametrize("learner", ["a2c", "ppo", "dqn"])
def test_time_outs_all_at_once_read_as_no_shorter_than_the_thresholds(learner: str) -> None:
    """Until a learner reaches the flag, all its envs time out at step 200 together. The recorded episode length
    (frames per finished episode over the last ``record_window`` batches, ``W`` steps per env) then reads
    ``W / n`` with ``n`` the time-outs inside the window: exactly 200 when ``W`` is a multiple of 200, else as low as
    ``W / ceil(W / 200)``, which must stay above every threshold."""
    domain = domains.part("mountain_car", LearnerDomain)
    config = domain.defaults[learner]
    window = config.record_window * config.frames_per_batch // config.num_envs
    lowest = 200 if window % 200 == 0 else window / -(-window // 200)
    assert window >= 200 and lowest > max(domain.thresholds)


@pytest.mark.parametrize("learner", ["a2c", "ppo"])
def test_the_actor_critics_learn_returns_of_order_one(learner: str) -> None:
    """Adam moves each weight of the linear critic by about its learning rate per step, so the −1 step cost is
    scaled by 1 − γ: the discounted returns lie in [−1, 0] (unscaled, a critic learning returns down to −87 got no
    further than −15 in the budget)."""
    config = domains.part("mountain_car", LearnerDomain).defaults[learner]
    assert config.reward_scale / (1 - config.gamma) == pytest.approx(1.0)
    assert (config.features, config.hidden) == ("fourier", ())


@pytest.mark.parametrize(
    ("predicate", "message"),
    [
        (Box((-1.025,), (0.175,), (0,)), None),
        (Box((0.15, 0.0525), (0.45, 0.0175), (0, 1)), None),
        (Box((2.0,), (0.1,), (0,)), "position: the box [1.9, 2.1] lies outside [-1.2, 0.6]"),
        (Box((0.0, 0.5), (0.1, 0.1), (0, 1)), "velocity: the box [0.4, 0.6] lies outside [-0.07, 0.07]"),
        (Box((0.0,), (0.1,), (2,)), "a MountainCar box covers position (0) and velocity (1), not dims [2]"),
        (Circle((0.0, 0.0), 0.1), "MountainCar subgoals are boxes over (position, velocity), not circle"),
        (Cell(1, 1), "MountainCar subgoals are boxes over (position, velocity), not cell"),
    ],
)
def test_subgoal_check(predicate: object, message: str | None) -> None:
    assert domains.get("mountain_car").check_subgoal(predicate) == message  # type: ignore[misc,arg-type]


def test_the_report_map_draws_the_boxes(tmp_path: Path) -> None:
    learners = domains.part("mountain_car", LearnerDomain)
    patterns = {n: s.to_dict() for n, s in load_patterns(learners.participants).items()}
    figure = plot_pattern_maps("mountain_car", patterns, tmp_path / "maps.png")
    assert figure.path is not None and figure.path.stat().st_size > 5_000, figure.note

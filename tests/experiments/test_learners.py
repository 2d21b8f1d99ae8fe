"""The learner recipes' machinery: settings from the domain's defaults and the flags, the methods' names,
and the plan's stored configuration."""

from __future__ import annotations

import pytest

from torchrl_subgoal import domains
from torchrl_subgoal.experiments.cli import ConfigError
from torchrl_subgoal.experiments.learners import (
    LearnerRecipeConfig,
    learner_methods,
    learner_plan,
    learner_settings,
)
from torchrl_subgoal.training import DQNConfig, LearnerDomain


def test_flags_left_at_zero_keep_the_domains_defaults() -> None:
    mountain_car = domains.part("mountain_car", LearnerDomain)
    settings = learner_settings(LearnerRecipeConfig(), "dqn", mountain_car)
    assert settings == DQNConfig.preset("mountain_car")  # value_lr 0.05 and the rest as the preset's
    changed = learner_settings(
        LearnerRecipeConfig(total_frames=3200, lr=1e-3, sees_subgoal="no", reshape_samples=True), "dqn", mountain_car
    )
    assert (changed.total_frames, changed.lr, changed.sees_subgoal) == (3200, 1e-3, False) and changed.reshape_samples
    assert changed.gradient_steps == 8  # the preset's, untouched


def test_a_learner_without_defaults_for_the_domain_takes_its_own() -> None:
    umaze = domains.part("point_maze_umaze", LearnerDomain)
    assert "a2c" not in umaze.defaults
    assert learner_settings(LearnerRecipeConfig(), "a2c", umaze).frames_per_batch == 256  # A2CConfig's


def test_a_setting_the_learner_refuses_is_a_config_error() -> None:
    four_rooms = domains.part("four_rooms", LearnerDomain)
    with pytest.raises(ConfigError, match=r"^minibatch_size \(64\) must divide frames_per_batch \(96\)$"):
        learner_settings(LearnerRecipeConfig(frames_per_batch=96, num_envs=16), "ppo", four_rooms)
    with pytest.raises(ConfigError, match=r"^--total-frames: 128 is less than one batch of 256 frames"):
        learner_settings(LearnerRecipeConfig(total_frames=128), "ppo", four_rooms)


def test_the_unshaped_method_is_named_after_the_learner() -> None:
    assert [list(learner_methods(algo))[2] for algo in ("a2c", "ppo", "dqn", "ddpg")] == ["A2C", "PPO", "DQN", "DDPG"]


def test_the_plan_stores_the_learner_and_reports_frames() -> None:
    plan = learner_plan(LearnerRecipeConfig(domain="mountain_car", total_frames=1600, results="r"), "dqn")
    assert plan.domain == "dqn_mountain_car" and plan.episodes == 100 and plan.chunk_size == 1
    assert [spec.name for spec in plan.specs] == ["DQN", "HRS", "NRS"]  # in --methods order
    config = plan.config
    assert (
        config["algo"] == "dqn"
        and config["learner"]["total_frames"] == 1600
        and config["routes"] == ["swing_then_speed"]
    )
    assert config["report"]["frames_per_unit"] == 16 and config["report"]["asymptotic_window"] == [90, 100]


@pytest.mark.parametrize("monotone", [False, True])
def test_monotone_potential_reaches_the_shaped_learners_table(
    monotone: bool, tmp_path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from torchrl_subgoal.experiments import learners
    from torchrl_subgoal.experiments.store import Chunk

    made = []

    def recording(*args, **kwargs):
        parts = shaping_parts(*args, **kwargs)
        made.append(parts[1] if parts is not None else None)
        return parts

    shaping_parts = learners.shaping_parts
    monkeypatch.setattr(learners, "shaping_parts", recording)
    cfg = LearnerRecipeConfig(methods="A2C,HRS", total_frames=256, results=str(tmp_path), monotone_potential=monotone)
    plan = learner_plan(cfg, "a2c")
    assert ("monotone_potential" in plan.config) == monotone  # absent by default: older results still resume
    for spec in plan.specs:  # A2C (pattern "none"), HRS (the first participant's)
        chunk = Chunk(spec.name, 0, ((spec.patterns[0], 0),), seed=1)
        learners.run_learner_chunk(chunk, plan.config, lambda done: None)
    assert made[0] is None and made[1].monotone == monotone


def test_the_learner_sees_z_by_its_own_default_unless_told() -> None:
    """DQN reads z whenever shaped (its default), the others do not; --sees-subgoal yes / no overrides."""
    four_rooms = domains.part("four_rooms", LearnerDomain)
    default = {algo: learner_settings(LearnerRecipeConfig(), algo, four_rooms).sees_subgoal for algo in ("dqn", "ppo")}
    assert default == {"dqn": None, "ppo": False}
    assert learner_settings(LearnerRecipeConfig(sees_subgoal="no"), "dqn", four_rooms).sees_subgoal is False
    assert learner_settings(LearnerRecipeConfig(sees_subgoal="yes"), "ppo", four_rooms).sees_subgoal is True

"""Every learner's settings refuse the same values the same way: one rule per field name, for all of them."""

from __future__ import annotations

import dataclasses

import pytest

from torchrl_subgoal.training import (
    LEARNERS,
    A2CConfig,
    DDPGTrainConfig,
    DQNConfig,
    LearnerConfig,
    PPOConfig,
    Settings,
)
from torchrl_subgoal.training.config import RULES, frames_of
from torchrl_subgoal.training.qlearning import QLearningConfig

CONFIGS = [A2CConfig, PPOConfig, DQNConfig, DDPGTrainConfig, QLearningConfig]

#: Values some config refused before the shared rules (or ought to): every config with the field refuses each.
BAD: dict[str, list[object]] = {
    "gamma": [2.0, 0.0, -0.5],
    "lr": [0.0, -1e-3, 1.5],
    "value_lr": [-1.0, 0.0, 2.0],
    "reward_scale": [0.0, -1.0],
    "num_envs": [0],
    "frames_per_batch": [0],
    "total_frames": [0],
    "record_window": [0],
    "episodes": [0],
    "env_workers": [-1],
    "collector_workers": [-1],
    "max_frames": [-1],
    "device": ["gpu0", "tpu"],
    "value_optimizer": ["rmsprop"],
    "features": ["cnn"],
    "hidden": [(0,), (64, -1)],
    "loss_function": ["huber"],
    "loss_critic_type": ["huber"],
    "max_grad_norm": [-1.0],
    "entropy_coeff": [-0.1],
    "critic_coeff": [-0.1],
    "gae_lambda": [1.5, -0.1],
    "epochs": [0],
    "minibatch_size": [0],
    "clip_epsilon": [0.0],
    "adam_eps": [0.0],
    "batch_size": [0],
    "buffer_size": [0],
    "gradient_steps": [0],
    "updates_per_batch": [0],
    "learning_starts": [-1, 2.5],
    "exploration_frames": [0, -0.5],
    "eps_init": [1.5],
    "eps_end": [-0.1],
    "epsilon": [1.5],
    "tau": [0.0, 1.5],
    "target_update": ["slow"],
    "target_update_interval": [0],
    "polyak": [1.5],
    "random_eps": [-0.1],
    "noise_eps": [-0.1],
    "target_noise": [-0.1],
    "noise_clip": [-0.1],
    "policy_delay": [0],
    "norm_clip": [0.0],
    "action_l2": [-1.0],
    "fourier_order": [-1],
    "polyak_every": ["episode"],
    "clip_return": [0.0, -50.0],
}

CASES = [
    (config, name, value)
    for config in CONFIGS
    for name, values in BAD.items()
    if name in {f.name for f in dataclasses.fields(config)}
    for value in values
]


@pytest.mark.parametrize(("config", "name", "value"), CASES, ids=[f"{c.__name__}-{n}={v}" for c, n, v in CASES])
def test_every_config_refuses_a_bad_value_of_its_fields_naming_the_field(
    config: type, name: str, value: object
) -> None:
    with pytest.raises(ValueError, match=f"^{name} (must|is)"):
        config(**{name: value})


def test_the_shared_checks_cover_every_config_and_the_issue_s_example() -> None:
    assert {c for c in CONFIGS} >= {learner.config for learner in LEARNERS.values()}
    for config in CONFIGS:
        assert issubclass(config, Settings)
        with pytest.raises(ValueError, match=r"^gamma must lie in \(0, 1\], got 2.0$"):
            config(gamma=2.0)
    with pytest.raises(ValueError, match=r"^gamma"):  # the first bad field in declaration order
        A2CConfig(gamma=2.0, value_lr=-1, reward_scale=0)
    with pytest.raises(ValueError, match=r"^value_lr"):
        A2CConfig(value_lr=-1)
    with pytest.raises(ValueError, match=r"^reward_scale"):
        A2CConfig(reward_scale=0)


def test_every_numeric_or_named_field_has_a_rule() -> None:
    """A field a config adds gets a rule (or is a flag / a free number by design)."""
    free = {"init", "online_potential", "sees_subgoal", "normalize_advantage", "anneal_lr", "double_dqn", "td3",
            "reshape_samples", "clip_positive"}  # fmt: skip
    for config in CONFIGS:
        for f in dataclasses.fields(config):
            assert f.name in RULES or f.name in free, f"{config.__name__}.{f.name} has no rule"


def test_the_shared_fields_live_once_in_the_base() -> None:
    shared = {f.name for f in dataclasses.fields(LearnerConfig)}
    for learner in LEARNERS.values():
        assert shared <= {f.name for f in dataclasses.fields(learner.config)}
    assert {"gamma", "device"} <= {f.name for f in dataclasses.fields(QLearningConfig)}


def test_a_replaced_config_is_checked_again() -> None:
    with pytest.raises(ValueError, match=r"^lr"):
        dataclasses.replace(PPOConfig(), lr=0.0)


def test_cross_field_checks_name_the_fields() -> None:
    with pytest.raises(ValueError, match=r"^frames_per_batch \(30\) must be a multiple of num_envs"):
        DQNConfig(num_envs=4, frames_per_batch=30)
    with pytest.raises(ValueError, match=r"^eps_end \(0.5\) must not exceed eps_init \(0.2\)"):
        DQNConfig(eps_init=0.2, eps_end=0.5)
    with pytest.raises(ValueError, match=r"^minibatch_size"):
        PPOConfig(frames_per_batch=256, minibatch_size=100)
    with pytest.raises(ValueError, match=r"^action_l2"):
        DDPGTrainConfig(td3=True, action_l2=1.0)


def test_schedules_scale_with_the_budget() -> None:
    """The off-policy warm-up and DQN's exploration are fractions of the frames by default; frames when
    given as frames (the presets that published figures used keep theirs)."""
    small, large = DQNConfig(total_frames=20_000), DQNConfig(total_frames=500_000)
    assert (small.warmup_frames, small.exploration_steps) == (400, 10_000)
    assert (large.warmup_frames, large.exploration_steps) == (10_000, 250_000)  # TorchRL's example's
    car = DQNConfig.preset("mountain_car")
    assert (car.warmup_frames, car.exploration_steps) == (1_000, 24_000)
    assert DDPGTrainConfig().warmup_frames == 25_000 and DDPGTrainConfig(total_frames=40_000).warmup_frames == 1_000
    assert frames_of(0.5, 101) == 50 and frames_of(3, 101) == 3

"""PPO building block: it learns a tiny corridor, discrete and continuous; settings are checked."""

from __future__ import annotations

import pytest
import torch

from torchrl_subgoal import Box, SubgoalSeries, TabularPotential
from torchrl_subgoal.training import PPOConfig, Shaping, SuccessSignal, train_ppo

from .corridor import continuous_corridor, discrete_corridor

# the corridor's position / length past 1/4, then past 1/2
SERIES = SubgoalSeries([Box((0.625,), (0.375,), (0,)), Box((0.75,), (0.25,), (0,))])


def _config(**changes: object) -> PPOConfig:
    settings: dict = {
        "num_envs": 8,
        "frames_per_batch": 256,
        "minibatch_size": 64,
        "epochs": 4,
        "lr": 3e-3,
        "hidden": (32,),
        "total_frames": 5120,
    }
    return PPOConfig(**{**settings, **changes})


@pytest.mark.parametrize("make_env", [discrete_corridor, continuous_corridor], ids=["categorical", "tanh_normal"])
def test_ppo_learns_the_corridor(make_env) -> None:  # type: ignore[no-untyped-def]
    """A random policy rarely reaches the end within the 40-step cap; the optimum takes 8 steps (5 in the
    continuous corridor)."""
    torch.set_num_threads(1)
    curve = train_ppo(make_env, _config(), success=SuccessSignal(min_return=1.0)).curve
    assert len(curve.frames) == 20 and curve.frames[-1] == 5120
    assert curve.episode_length[0] > 30  # untrained: mostly capped
    assert curve.episode_length[-1] < 12 and curve.success[-1] > 0.8  # the reward of 1 at the end


def test_shaped_ppo_that_sees_z_learns_and_trains_the_potential() -> None:
    torch.set_num_threads(1)
    potential = TabularPotential(SERIES.num_abstract_states)
    shaping = Shaping(SERIES, potential)
    curve = train_ppo(discrete_corridor, _config(sees_subgoal=True, value_lr=0.1), shaping=shaping, seeds=[1]).curve
    assert curve.episode_length[-1] < 12
    assert bool((potential.table.detach() > 0.3).all())  # V(z) learned from the goal reward


@pytest.mark.parametrize("make_env", [discrete_corridor, continuous_corridor], ids=["categorical", "tanh_normal"])
def test_ppo_learners_as_a_batch_each_learn_the_corridor(make_env) -> None:  # type: ignore[no-untyped-def]
    """Three shaped PPO learners seeing z as one batch (continuous: each with its own learned
    state-independent scale): each learns."""
    torch.set_num_threads(1)
    shapings = [Shaping(SERIES, TabularPotential(SERIES.num_abstract_states)) for _ in range(3)]
    config = _config(sees_subgoal=True, value_lr=0.1)
    curves = train_ppo(
        make_env, config, seeds=[0, 1, 2], shaping=shapings, success=SuccessSignal(min_return=1.0)
    ).curves
    for curve in curves:
        assert len(curve.frames) == 20 and curve.frames[-1] == 5120
        assert curve.episode_length[0] > 30 and curve.episode_length[-1] < 12 and curve.success[-1] > 0.8


@pytest.mark.parametrize(
    "bad, message",
    [
        ({"minibatch_size": 100}, "minibatch_size"),
        ({"epochs": 0}, "epochs"),
        ({"clip_epsilon": 0.0}, "clip_epsilon"),
        ({"gae_lambda": 1.5}, "gae_lambda"),
        ({"num_envs": 3}, "frames_per_batch"),
        ({"features": "cnn"}, "features"),
    ],
)
def test_bad_settings_name_the_field(bad: dict, message: str) -> None:
    with pytest.raises(ValueError, match=f"^{message}"):
        _config(**bad)

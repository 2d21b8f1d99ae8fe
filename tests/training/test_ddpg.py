"""DDPG building block for any continuous-action env: DDPG and TD3 learn a tiny corridor; settings."""

from __future__ import annotations

import pytest
import torch

from torchrl_subgoal import Box, SubgoalSeries, TabularPotential
from torchrl_subgoal.training import DDPGTrainConfig, Shaping, SuccessSignal, train_ddpg

from .corridor import continuous_corridor

# the corridor's position / length past 1/4, then past 1/2
SERIES = SubgoalSeries([Box((0.625,), (0.375,), (0,)), Box((0.75,), (0.25,), (0,))])


def _config(**changes: object) -> DDPGTrainConfig:
    # DDPG's deterministic policy learns nothing before its replay holds the goal: 1,024 random frames first
    settings: dict = {
        "num_envs": 4,
        "frames_per_batch": 32,
        "total_frames": 2560,
        "learning_starts": 1024,
        "updates_per_batch": 16,
        "batch_size": 64,
        "hidden": (32, 32),
        "lr": 1e-3,
        "gamma": 0.95,
        "polyak": 0.95,
        "noise_eps": 0.3,
    }
    return DDPGTrainConfig(**{**settings, **changes})


@pytest.mark.parametrize("changes", [{}, {"td3": True}], ids=["ddpg", "td3"])
def test_ddpg_learns_the_continuous_corridor(changes: dict) -> None:
    """Uniform random actions rarely reach the end (5) within the 40-step cap; the optimum takes 5 steps."""
    torch.set_num_threads(1)
    curve = train_ddpg(continuous_corridor, _config(**changes), success=SuccessSignal(min_return=1.0)).curve
    assert len(curve.frames) == 80 and curve.frames[-1] == 2560
    assert curve.episode_length[0] > 30
    assert curve.episode_length[-1] < 9 and curve.success[-1] > 0.8  # the reward of 1 at the end


def test_shaped_ddpg_that_sees_z_with_reshaped_samples_learns_and_trains_the_potential() -> None:
    torch.set_num_threads(1)
    potential = TabularPotential(SERIES.num_abstract_states)
    curve = train_ddpg(
        continuous_corridor,
        _config(sees_subgoal=True, reshape_samples=True, value_lr=0.1),
        shaping=Shaping(SERIES, potential),
    ).curve
    assert curve.episode_length[-1] < 9
    assert bool((potential.table.detach() > 0.3).all())


@pytest.mark.parametrize(
    "bad, field",
    [
        ({"polyak": 1.5}, "polyak"),
        ({"updates_per_batch": 0}, "updates_per_batch"),
        ({"noise_clip": -1.0}, "noise_clip"),
        ({"frames_per_batch": 30}, "frames_per_batch"),
    ],
)
def test_bad_settings_name_the_field(bad: dict, field: str) -> None:
    with pytest.raises(ValueError, match=f"^{field}"):
        _config(**bad)

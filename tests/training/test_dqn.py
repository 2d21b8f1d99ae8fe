"""DQN building block: it learns a tiny corridor (plain, double, shaped with re-shaped samples, in a
worker process); presets and settings."""

from __future__ import annotations

import pytest
import torch

from torchrl_subgoal import Box, SubgoalSeries, TabularPotential
from torchrl_subgoal.envs import FourRoomsEnv
from torchrl_subgoal.training import DQN_PRESETS, DQNConfig, Shaping, SuccessSignal, q_network, train_dqn

from .corridor import discrete_corridor

SERIES = SubgoalSeries([Box((0.625,), (0.375,), (0,)), Box((0.75,), (0.25,), (0,))])


def _config(**changes: object) -> DQNConfig:
    settings: dict = {
        "num_envs": 4,
        "frames_per_batch": 32,
        "total_frames": 3072,
        "learning_starts": 256,
        "gradient_steps": 8,
        "batch_size": 64,
        "buffer_size": 5000,
        "lr": 1e-3,
        "gamma": 0.95,
        "exploration_frames": 1536,
        "target_update_interval": 50,
        "hidden": (32,),
    }
    return DQNConfig(**{**settings, **changes})


@pytest.mark.parametrize(
    "changes", [{}, {"double_dqn": True, "target_update": "soft", "tau": 0.05}], ids=["dqn", "double_soft"]
)
def test_dqn_learns_the_corridor(changes: dict) -> None:
    """A random policy rarely reaches the end within the 40-step cap; the optimum takes 8 steps (ε = 0.05
    at the end)."""
    torch.set_num_threads(1)
    curve = train_dqn(discrete_corridor, _config(**changes), success=SuccessSignal(min_return=1.0)).curve
    assert len(curve.frames) == 96 and curve.frames[-1] == 3072
    assert curve.episode_length[0] > 30
    assert curve.episode_length[-1] < 12 and curve.success[-1] > 0.8  # the reward of 1 at the end


def test_shaped_dqn_that_sees_z_with_reshaped_samples_learns_and_trains_the_potential() -> None:
    torch.set_num_threads(1)
    potential = TabularPotential(SERIES.num_abstract_states)
    curve = train_dqn(
        discrete_corridor,
        _config(sees_subgoal=True, reshape_samples=True, value_lr=0.1),
        shaping=Shaping(SERIES, potential),
    ).curve
    assert curve.episode_length[-1] < 12
    assert bool((potential.table.detach() > 0.3).all())


@pytest.mark.slow
def test_dqn_in_a_collector_worker_explores_with_the_annealed_epsilon() -> None:
    """Envs in a MultiSyncCollector worker: the Q-network's weights and ε reach the worker, so it ends
    greedy enough to walk the corridor."""
    torch.set_num_threads(1)
    curve = train_dqn(discrete_corridor, _config(collector_workers=1)).curve
    assert curve.episode_length[-1] < 12


def test_one_hot_features_without_hidden_layers_make_a_q_table_without_bias() -> None:
    env = FourRoomsEnv(2)

    def shapes(net: torch.nn.Module) -> list[tuple[int, ...]]:
        return [tuple(p.shape) for p in net.parameters()]

    assert shapes(q_network(env, features="one_hot", hidden=())) == [(4, 104)]  # one value per (cell, action)
    assert shapes(q_network(env, features="one_hot", hidden=(8,)))[-1] == (4,)  # an MLP keeps its output bias


def test_mountain_car_preset_is_rl_zoo_s() -> None:
    config = DQNConfig.preset("mountain_car")
    zoo = {
        "lr": 4e-3,
        "batch_size": 128,
        "buffer_size": 10_000,
        "learning_starts": 1_000,
        "gamma": 0.98,
        "gradient_steps": 8,
        "frames_per_batch": 16,
        "eps_end": 0.07,
        "exploration_frames": 24_000,
        "hidden": (256, 256),
        "total_frames": 120_000,
    }
    assert {k: getattr(config, k) for k in zoo} == zoo
    assert config.target_update_interval * config.frames_per_batch // config.gradient_steps == 600  # frames
    assert DQNConfig.preset("mountain_car", lr=1e-3).lr == 1e-3 and set(DQN_PRESETS) >= {"torchrl", "mountain_car"}
    with pytest.raises(ValueError, match="unknown DQN preset 'cartpole'"):
        DQNConfig.preset("cartpole")


@pytest.mark.parametrize(
    "bad, field",
    [
        ({"eps_end": 1.5}, "eps_end"),
        ({"gradient_steps": 0}, "gradient_steps"),
        ({"target_update": "slow"}, "target_update"),
        ({"value_lr": 0.0}, "value_lr"),
        ({"learning_starts": -1}, "learning_starts"),
    ],
)
def test_bad_settings_name_the_field(bad: dict, field: str) -> None:
    with pytest.raises(ValueError, match=f"^{field}"):
        _config(**bad)


def test_dqn_reads_z_by_default_when_shaped_and_not_otherwise() -> None:
    from torchrl_subgoal import Cell
    from torchrl_subgoal.training import subgoal_states

    shaping = Shaping(SubgoalSeries([Cell(3, 6), Cell(7, 9)]), TabularPotential(3))
    assert DQNConfig().sees_subgoal is None
    assert subgoal_states(DQNConfig(), shaping) == 3 and subgoal_states(DQNConfig(), None) == 0
    assert subgoal_states(DQNConfig(sees_subgoal=False), shaping) == 0
    with pytest.raises(ValueError, match="sees_subgoal needs shaping"):
        subgoal_states(DQNConfig(sees_subgoal=True), None)

"""The two options every deep learner has: it sees z (an input wiring), and replay samples re-shaped."""

from __future__ import annotations

import pytest
import torch
from tensordict import TensorDict
from torchrl.collectors import Collector
from torchrl.data import Bounded, LazyTensorStorage, ReplayBuffer
from torchrl.envs import ExplorationType, set_exploration_type

from torchrl_subgoal import Box, SubgoalSeries, TabularPotential
from torchrl_subgoal.training import (
    DDPGTrainConfig,
    DQNConfig,
    PPOConfig,
    SampleReshaper,
    Shaping,
    actor_critic,
    close_collector,
    ppo_actor_critic,
    q_network,
    shaped_env,
    train_dqn,
    train_ppo,
)
from torchrl_subgoal.training.ddpg_parts import DDPGAgent, DDPGConfig

from .corridor import Corridor, continuous_corridor, discrete_corridor

GAMMA = 0.9
# the corridor's position / length past 1/4, then past 1/2 (a Box over entry 0 of the observation)
SERIES = SubgoalSeries([Box((0.625,), (0.375,), (0,)), Box((0.75,), (0.25,), (0,))])


def _randomise_heads(module: torch.nn.Module) -> None:
    """Output layers start at zero (every input gives the same output): give them weights."""
    gen = torch.Generator().manual_seed(0)
    with torch.no_grad():
        for p in module.parameters():
            p.copy_(torch.randn(p.shape, generator=gen))


def _td(obs: torch.Tensor, z: int) -> TensorDict:
    return TensorDict({"observation": obs, "subgoal_index": torch.full((obs.shape[0], 1), z)}, [obs.shape[0]])


@pytest.mark.parametrize(("features", "hidden"), [("fourier", ()), ("mlp", ()), ("fourier", (8,)), ("mlp", (8,))])
def test_a2c_and_ppo_networks_read_z_one_hot(features: str, hidden: tuple[int, ...]) -> None:
    """With subgoal_states, policy and value network read "subgoal_index": the same observation with
    another z gives other outputs. With hidden layers z is concatenated to the features; a linear network
    reads their product, one linear function of the features per z, so that a shaped critic can learn
    V(s) − Φ(s, z) of a potential that also varies within a segment, not only V(s) − Φ(z)."""
    env = Corridor(2)
    actor, critic = actor_critic(env, features=features, hidden=hidden, fourier_order=2, subgoal_states=3)
    assert list(actor.in_keys) == ["observation", "subgoal_index"] and critic.in_keys == [
        "observation",
        "subgoal_index",
    ]
    first = next(m for m in critic.module.modules() if isinstance(m, torch.nn.Linear))
    n_features = 3 if features == "fourier" else 1  # Fourier order 2 over one entry: cos(0), cos(πx), cos(2πx)
    assert first.in_features == (n_features + 3 if hidden else n_features * 3)
    _randomise_heads(critic)
    obs = torch.tensor([[0.5], [0.5]])
    values = [critic(_td(obs, z))["state_value"][0].item() for z in range(3)]
    assert len(set(values)) == 3
    if not hidden:  # V(s, z) = w_z·φ(s) + b: each z its own weights (features entry i of z at i·3 + z)
        weight, bias = first.weight.detach()[0], float(first.bias.detach()[0])
        phi = critic.module[0].features(obs)[0]  # the features before the join
        assert values[1] == pytest.approx(float(weight[1::3] @ phi) + bias, abs=1e-5)


def test_one_hot_features_without_hidden_layers_read_a_table_over_s_and_z() -> None:
    from torchrl_subgoal.envs import FourRoomsEnv

    env = FourRoomsEnv(2)
    _, critic = actor_critic(env, features="one_hot", hidden=(), subgoal_states=3)
    first = next(m for m in critic.module.modules() if isinstance(m, torch.nn.Linear))
    cells = int(env.observation_spec["observation"].space.n)
    assert first.in_features == cells * 3  # one copy of the one-hot cell per z
    _randomise_heads(critic)
    cell = torch.tensor([5, 5])
    td = TensorDict({"observation": cell, "subgoal_index": torch.tensor([[1], [1]])}, [2])
    weight, bias = first.weight.detach()[0], first.bias.detach()[0]
    assert critic(td)["state_value"][0].item() == pytest.approx(float(weight[5 * 3 + 1] + bias), abs=1e-6)


def test_ppo_gaussian_policy_and_dqn_and_ddpg_read_z() -> None:
    obs = torch.tensor([[0.25], [0.25]])
    actor, critic = ppo_actor_critic(Corridor(2, continuous=True), hidden=(8,), subgoal_states=3)
    assert "subgoal_index" in actor.in_keys and "subgoal_index" in critic.in_keys
    _randomise_heads(actor)
    with set_exploration_type(ExplorationType.DETERMINISTIC):
        actions = [actor(_td(obs, z))["action"][0].item() for z in range(3)]
    assert len(set(actions)) == 3

    q = q_network(Corridor(2), hidden=(8,), subgoal_states=3)
    assert q.in_keys == ["observation", "subgoal_index"]
    values = [tuple(q(_td(obs, z))["action_value"][0].tolist()) for z in range(3)]
    assert len(set(values)) == 3

    agent = DDPGAgent(1, Bounded(-1.0, 1.0, shape=(1,)), DDPGConfig(hidden=(8,)), subgoal_states=3)
    assert agent.policy.in_keys == ["observation", "subgoal_index"] and "subgoal_index" in agent.critic.in_keys
    with set_exploration_type(ExplorationType.DETERMINISTIC):
        actions = [agent.policy(_td(obs, z))["action"][0].item() for z in range(3)]
        greedy = [agent.greedy(_td(obs, z))["action"][0].item() for z in range(3)]
    assert len(set(actions)) == 3 and actions == pytest.approx(greedy)
    q_values = [
        agent.critic(_td(obs, z).set("observation_normalized", obs).set("action", torch.zeros(2, 1)))[
            "state_action_value"
        ][0].item()
        for z in range(3)
    ]
    assert len(set(q_values)) == 3
    assert ("next", "subgoal_index") in agent.keys  # the replay keeps z' for the target


@pytest.mark.parametrize(
    "train, config",
    [
        (train_ppo, PPOConfig(num_envs=2, frames_per_batch=16, minibatch_size=8, total_frames=16, sees_subgoal=True)),
        (train_dqn, DQNConfig(num_envs=2, frames_per_batch=16, total_frames=16, sees_subgoal=True)),
    ],
)
def test_seeing_z_needs_shaping(train, config) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(ValueError, match="sees_subgoal needs shaping"):
        train(discrete_corridor, config)


def test_reshape_samples_needs_shaping() -> None:
    from torchrl_subgoal.training import train_ddpg

    with pytest.raises(ValueError, match="reshape_samples needs shaping"):
        train_ddpg(continuous_corridor, DDPGTrainConfig(frames_per_batch=8, total_frames=8, reshape_samples=True))


def _collect(potential: TabularPotential, options: dict, num_envs: int = 4, frames: int = 1200) -> TensorDict:
    """Random-policy data of a short corridor (episodes reach both subgoals and the goal), shaped with a
    fixed potential, from a collector over a batch of envs."""
    shaping = Shaping(SERIES, potential, options)
    env = shaped_env(lambda n: Corridor(n, length=3, max_steps=12), num_envs, shaping=shaping, gamma=GAMMA)
    collector = Collector(env, None, frames_per_batch=frames, total_frames=frames)
    collector.set_seed(0)
    try:
        return next(iter(collector))
    finally:
        close_collector(collector)


@pytest.mark.parametrize(
    "options, per_env", [({}, False), ({"start_potential": "value"}, False), ({"zero_terminal_potential": False}, True)]
)
def test_reshaping_a_replay_sample_equals_the_online_shaping_under_a_fixed_potential(
    options: dict, per_env: bool
) -> None:
    """Rows of a multi-env collector, shuffled by a replay buffer, re-shaped with the potential that
    shaped them online: the stored shaped reward, row for row (one shared table, or one per env found by
    the learner key). Then with another potential: r + γΦ'(z') − Φ'(z) with the stored z and z'."""
    potential = TabularPotential(3, (4,) if per_env else ())
    table = torch.tensor([0.7, -1.3, 2.1])
    with torch.no_grad():
        potential.table.copy_(table.expand_as(potential.table))
    data = _collect(potential, options)
    nxt = data["next"]
    assert bool((nxt["subgoal_index"] == 2).any() and nxt["terminated"].any())  # both subgoals and the goal
    reshaper = SampleReshaper(Shaping(SERIES, potential, options).transform(potential, GAMMA, None))
    buffer = ReplayBuffer(storage=LazyTensorStorage(data.numel()), batch_size=256)
    buffer.extend(data.select(*reshaper.keys, ("next", "reward"), ("next", "subgoal_index")).reshape(-1))
    sample = buffer.sample()
    assert sample["subgoal_index"].unique().numel() == 3  # shuffled rows from every abstract state
    again = reshaper(sample.clone())
    assert torch.allclose(again["next", "reward"], sample["next", "reward"], atol=1e-6)
    assert torch.equal(again["next", "subgoal_index"], sample["next", "subgoal_index"])

    new = torch.tensor([1.5, -2.0, 5.5])
    with torch.no_grad():
        potential.table.copy_(new.expand_as(potential.table))
    reshaped = reshaper(sample.clone())
    z, z_next, terminated = sample["subgoal_index"], sample["next", "subgoal_index"], sample["next", "terminated"]
    phi_next = new[z_next]
    if options.get("zero_terminal_potential", True):
        phi_next = phi_next.masked_fill(terminated, 0.0)
    shift = 0.0 if options.get("start_potential") == "value" else max(float(new[0]), 0.0)  # "nonpositive"
    expected = sample["next", "env_reward"] + GAMMA * (phi_next - shift * ~terminated) - (new[z] - shift)
    if not options.get("zero_terminal_potential", True):
        expected = sample["next", "env_reward"] + GAMMA * (new[z_next] - shift) - (new[z] - shift)
    assert torch.allclose(reshaped["next", "reward"], expected, atol=1e-5)
    assert not torch.allclose(reshaped["next", "reward"], sample["next", "reward"])

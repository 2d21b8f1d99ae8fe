"""SubgoalPotentialTransform as a TorchRL transform: TorchRL's transform test matrix (single, serial,
parallel, no env, in a Compose, before a module, on a replay buffer, inverse), keys from the parent env
(nested, multi-agent), carried state in the specs, native auto-reset, two transforms on one env, and
stored samples shaped whatever their order when the rows' learners do not matter."""

from __future__ import annotations

import pytest
import torch
from tensordict import TensorDict
from torchrl.data import LazyTensorStorage, ReplayBuffer
from torchrl.envs import Compose, ParallelEnv, SerialEnv, TransformedEnv
from torchrl.envs.utils import check_env_specs, step_mdp

from torchrl_subgoal import Cell, State, SubgoalKeys, SubgoalPotentialTransform, SubgoalSeries, TabularPotential
from torchrl_subgoal.envs import FourRoomsEnv

from .agents_env import AgentsLineEnv, AutoResetLineEnv
from .line_env import LineEnv

HALLWAYS = SubgoalSeries([Cell(3, 6), Cell(7, 9)], name="hallways")
LINE = SubgoalSeries([State(1), State(3)], name="line")


def shaping(**kwargs) -> SubgoalPotentialTransform:
    """The two hallways, one shared table with fixed values (so the shaping is visible)."""
    v = TabularPotential(3)
    with torch.no_grad():
        v.table.copy_(torch.tensor([-1.0, 0.5, 2.0]))
    return SubgoalPotentialTransform(HALLWAYS, v, gamma=0.9, observation_key="cell", **kwargs)


def shaped_four_rooms() -> TransformedEnv:
    """An env with its own transform (importable by spawned workers)."""
    return TransformedEnv(FourRoomsEnv(), shaping())


def assert_state_carried(data: TensorDict) -> None:
    """k counts the steps since z was entered: the state went from each step to the next."""
    z, k, nxt = data["subgoal_index"], data["subgoal_steps"], data["next"]
    closed = (nxt["subgoal_index"] != z) | nxt["done"]
    assert torch.equal(nxt["subgoal_steps"][~closed], (k + 1)[~closed]) and (nxt["subgoal_steps"][closed] == 0).all()
    assert k.max() > 5


def expected_reward(data: TensorDict, table: torch.Tensor, gamma: float = 0.9) -> torch.Tensor:
    """``r + γ Φ(z') − Φ(z)``, ``Φ = V − max(V(0), 0)``, ``Φ(z') = 0`` at a terminal state."""
    phi = table - table[0].clamp(min=0)
    nxt = data["next"]
    phi_next = phi[nxt["subgoal_index"]].masked_fill(nxt["terminated"], 0.0)
    return nxt["env_reward"] + gamma * phi_next - phi[data["subgoal_index"]]


# ----------------------------------------------------------------- TorchRL's matrix


def test_single_env_check() -> None:
    env = TransformedEnv(FourRoomsEnv(3), shaping())
    check_env_specs(env)
    for key in ("subgoal_index", "subgoal_return", "subgoal_steps"):  # carried from step to step: state
        assert key in env.full_state_spec and key in env.full_observation_spec


def test_serial_env_of_transformed_envs_check() -> None:
    env = SerialEnv(2, shaped_four_rooms)
    check_env_specs(env)
    assert_state_carried(env.rollout(40, break_when_any_done=False))


def test_parallel_env_of_transformed_envs_check() -> None:
    env = ParallelEnv(2, shaped_four_rooms, mp_start_method="spawn")
    try:
        check_env_specs(env)
        assert_state_carried(env.rollout(40, break_when_any_done=False))  # the carried state reaches the workers
    finally:
        env.close()


def test_transformed_serial_and_parallel_env_check() -> None:
    for base in (SerialEnv(2, FourRoomsEnv), ParallelEnv(2, FourRoomsEnv, mp_start_method="spawn")):
        env = TransformedEnv(base, shaping())
        try:
            check_env_specs(env)
        finally:
            env.close()


def stored_line(n: int = 2, steps: int = 8) -> tuple[SubgoalPotentialTransform, TensorDict]:
    """Line data collected through a transform (z, r_h, k and the shaped reward), and that transform."""
    t = SubgoalPotentialTransform(LINE, TabularPotential(3), gamma=0.9)
    with torch.no_grad():
        t.potential.table.copy_(torch.tensor([0.0, 1.0, 3.0]))
    env = TransformedEnv(LineEnv(n), t)
    actions = torch.tensor([[1, 1, 0, 1, 1, 1, 0, 1], [1, 0, 1, 1, 1, 0, 1, 1]])[:n, :steps]
    td, steps_out = env.reset(), []
    for a in actions.T:
        td["action"] = a
        out, td = env.step_and_maybe_reset(td)
        steps_out.append(out)
    return t, torch.stack(steps_out, 1)


def test_transform_no_env() -> None:
    """On data alone (no parent env), the transform shapes trajectories [B, T] as the env did."""
    online, data = stored_line()
    alone = SubgoalPotentialTransform(LINE, online.potential, gamma=0.9)
    shaped = alone(data.exclude(("next", "reward"), ("next", "subgoal_index")).clone())
    assert torch.allclose(shaped["next", "reward"], data["next", "reward"])
    assert torch.equal(shaped["next", "subgoal_index"], data["next", "subgoal_index"])


def test_transform_compose() -> None:
    online, data = stored_line()
    composed = Compose(SubgoalPotentialTransform(LINE, online.potential, gamma=0.9))
    shaped = composed(data.exclude(("next", "reward")).clone())
    assert torch.allclose(shaped["next", "reward"], data["next", "reward"])


def test_transform_env() -> None:
    """reset writes the initial abstract state; step advances it and shapes the reward."""
    t = shaping()
    env = TransformedEnv(FourRoomsEnv(2), t)
    td = env.reset()
    assert td["subgoal_index"].tolist() == [[0], [0]] and td["subgoal_steps"].tolist() == [[0], [0]]
    data = env.rollout(200, break_when_any_done=False, tensordict=td)
    assert torch.allclose(data["next", "reward"], expected_reward(data, t.potential.table.detach()), atol=1e-6)


def test_transform_model() -> None:
    """Before a module that reads its output, as TorchRL's matrix puts it."""
    online, data = stored_line()

    class Return(torch.nn.Module):  # reads the shaped reward
        def forward(self, td: TensorDict) -> torch.Tensor:
            return td["next", "reward"].sum()

    model = torch.nn.Sequential(SubgoalPotentialTransform(LINE, online.potential, gamma=0.9), Return())
    assert torch.isclose(model(data.exclude(("next", "reward")).clone()), data["next", "reward"].sum())


def test_transform_rb() -> None:
    """On a replay buffer of whole trajectories: each sample shaped as it was collected."""
    online, data = stored_line()
    rb = ReplayBuffer(
        storage=LazyTensorStorage(10),
        transform=SubgoalPotentialTransform(LINE, online.potential, gamma=0.9),
        batch_size=2,
    )
    rb.extend(data.exclude(("next", "reward")))
    sample = rb.sample()
    assert sample.shape == data.shape
    rows = [int(torch.nonzero((data["observation"] == s["observation"]).all(-1))[0]) for s in sample]
    assert torch.allclose(sample["next", "reward"], data["next", "reward"][rows])


def test_transform_inverse() -> None:
    """The transform has no inverse: ``inv`` leaves the data as it is."""
    _, data = stored_line()
    assert (SubgoalPotentialTransform(LINE, TabularPotential(3), gamma=0.9).inv(data.clone()) == data).all()


# ----------------------------------------------------------------- keys, state, resets


def test_in_and_out_keys_are_what_the_step_reads_and_writes() -> None:
    t = shaping(keys=SubgoalKeys(transitions="smdp"))
    env = TransformedEnv(FourRoomsEnv(2), t)
    base = FourRoomsEnv(2)
    written = set(env.rand_step(env.reset())["next"].keys(True, True)) - set(
        base.rand_step(base.reset())["next"].keys(True, True)
    )
    assert t.in_keys == ["reward", "done", "terminated", "cell"]
    assert {k for k in t.out_keys if k != "reward"} == {k if isinstance(k, str) else k[0] for k in written}
    with pytest.raises(KeyError, match=r"the stored data has no \[\('next', 'cell'\)\]; store the steps' entries"):
        t(env.rollout(3).exclude(("next", "cell")))


def test_nested_multi_agent_keys() -> None:
    """Keys from the parent env: each agent's reward is shaped by its own abstract state, kept in the
    "agents" group and reset with that agent."""
    t = SubgoalPotentialTransform(LINE, TabularPotential(3), gamma=0.9, observation_key=("agents", "observation"))
    env = TransformedEnv(AgentsLineEnv(2, agents=3), t)
    check_env_specs(env)
    assert t.in_keys == [("agents", "reward"), ("agents", "done"), ("agents", "terminated"), ("agents", "observation")]
    with torch.no_grad():
        t.potential.table.copy_(torch.tensor([0.0, 1.0, 3.0]))
    td = env.reset()
    td["agents", "action"] = torch.tensor([[1, 1, 0], [1, 0, 1]])
    out, td = env.step_and_maybe_reset(td)
    nxt = out["next", "agents"]
    assert nxt["subgoal_index"].squeeze(-1).tolist() == [[1, 1, 0], [1, 0, 1]]  # position 1 achieves State(1)
    assert torch.allclose(nxt["reward"].squeeze(-1), torch.tensor([[1.9, 1.9, 1.0], [1.9, 1.0, 1.9]]))
    assert nxt["env_reward"].shape == (2, 3, 1) and td["agents", "subgoal_steps"].tolist() == [
        [[0], [0], [1]],
        [[0], [1], [0]],
    ]


def test_a_reward_with_more_rows_than_the_episodes_is_refused_in_one_line() -> None:
    from torchrl.data import Unbounded

    base = LineEnv(2)
    base.reward_spec = Unbounded(shape=(2, 3))  # three rewards per env, one done per env
    with pytest.raises(
        ValueError,
        match=r"^SubgoalPotentialTransform: the reward 'reward' has shape \(2, 3\) but "
        r"episodes end by 'done' of shape \(2, 1\): one reward per episode row",
    ):
        _ = TransformedEnv(base, SubgoalPotentialTransform(LINE, TabularPotential(3), gamma=0.9)).reward_spec


def test_native_auto_reset_restarts_the_abstract_state_of_the_envs_that_reset() -> None:
    t = SubgoalPotentialTransform(LINE, TabularPotential(3), gamma=0.9)
    env = TransformedEnv(AutoResetLineEnv(2, length=2), t)
    td = env.reset()
    for action in ([1, 1], [1, 0]):  # env 0 reaches the goal (2) and resets itself; env 1 goes 1 -> 0
        td["action"] = torch.tensor(action)
        out, td = env.step_and_maybe_reset(td)
    assert out["next", "done"].squeeze(-1).tolist() == [True, False]
    assert td["subgoal_index"].squeeze(-1).tolist() == [0, 1]  # env 0 starts again, env 1 keeps z = 1
    assert td["subgoal_steps"].squeeze(-1).tolist() == [0, 1]
    assert td["observation"].tolist() == [0, 0]


def test_two_transforms_with_the_same_prefix_are_refused_in_one_line() -> None:
    env = TransformedEnv(FourRoomsEnv(2), Compose(shaping(), shaping()))
    with pytest.raises(
        ValueError,
        match=r"^SubgoalPotentialTransform: 'subgoal_index' is kept already by another "
        r"transform on this env; give this one another prefix \(prefix='room'\)",
    ):
        env.reset()


def test_two_transforms_with_their_own_prefixes_are_independent() -> None:
    """Each shapes as it would alone: the first's entries are those of the same transform alone."""
    alone = TransformedEnv(FourRoomsEnv(2), shaping())
    second = SubgoalPotentialTransform(
        SubgoalSeries([Cell(1, 2)]),
        TabularPotential(2, index_key="room_index"),
        gamma=0.9,
        observation_key="cell",
        keys=SubgoalKeys("room"),
    )
    both = TransformedEnv(FourRoomsEnv(2), Compose(shaping(), second))
    check_env_specs(both)
    torch.manual_seed(0)
    a = alone.rollout(300, break_when_any_done=False)
    torch.manual_seed(0)
    b = both.rollout(300, break_when_any_done=False)
    for key in ("subgoal_index", "subgoal_return", "subgoal_steps"):
        assert torch.equal(a["next", key], b["next", key]), key
    assert (b["next", "subgoal_index"] > 0).any() and (b["next", "room_index"] > 0).any()


# ----------------------------------------------------------------- stored samples


def test_forward_shapes_a_shuffled_multi_env_replay_sample_with_one_table() -> None:
    """One shared table and one series: no row's learner matters, so rows of any envs in any order shape as
    they were collected."""
    t = shaping()
    env = TransformedEnv(FourRoomsEnv(8, max_steps=50), t)
    torch.manual_seed(1)
    data = env.rollout(60, break_when_any_done=False)  # [8 envs, 60 steps]
    rb = ReplayBuffer(storage=LazyTensorStorage(8), batch_size=5)
    rb.extend(data.exclude(("next", "reward"), *[("next", k) for k in t.state_keys]))
    sample = rb.sample()  # 5 trajectories of random envs, in random order
    rows = [int(torch.nonzero((data["cell"] == s["cell"]).all(-1).all(-1))[0]) for s in sample]
    shaped = t(sample.clone())
    assert torch.allclose(shaped["next", "reward"], data["next", "reward"][rows], atol=1e-6)
    assert torch.equal(shaped["next", "subgoal_index"], data["next", "subgoal_index"][rows])
    flat = step_mdp(data)  # a sample of steps from the middle of episodes, shuffled: the stored entries continue
    assert t(data[torch.randperm(8)[:3]].clone())["next", "subgoal_index"].shape == (3, 60, 1) and flat.numel()


def test_forward_refuses_in_one_line_when_rows_have_their_own_tables_and_no_learner_entry() -> None:
    t = SubgoalPotentialTransform(HALLWAYS, TabularPotential(3, (4,)), gamma=0.9, observation_key="cell")
    data = TransformedEnv(FourRoomsEnv(4), t).rollout(5)
    with pytest.raises(
        ValueError,
        match=r"^data of batch shape \(3,\) \(time excluded\) from 4 learners with their "
        r"own patterns or tables: each row's learner is unknown",
    ):
        t(data[:3].exclude("subgoal_learner", ("next", "subgoal_learner")).clone())

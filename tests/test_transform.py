"""SubgoalPotentialTransform: SMDP arithmetic, shaping, specs across env kinds, partial resets."""

from __future__ import annotations

import pytest
import torch
from tensordict import TensorDict
from torchrl.envs import Compose, ParallelEnv, RewardSum, SerialEnv, StepCounter, TransformedEnv
from torchrl.envs.utils import check_env_specs

from torchrl_subgoal import (
    Box,
    Cell,
    Circle,
    NaivePotential,
    NeuralPotential,
    State,
    StateAggregation,
    SubgoalFileError,
    SubgoalPotentialTransform,
    SubgoalSeries,
    SubgoalValueLoss,
    TabularPotential,
    ValueUpdate,
)
from torchrl_subgoal.envs import FourRoomsEnv
from torchrl_subgoal.envs.four_rooms import room_aggregation
from torchrl_subgoal.transform import SubgoalKeys

from .line_env import LineEnv, make_four_rooms

HALLWAYS = SubgoalSeries([Cell(3, 6), Cell(7, 9)], name="hallways")


@pytest.fixture(params=["compiled", "torch"])
def backend(request: pytest.FixtureRequest) -> str:
    """Run a test through the compiled kernels and through torch operations only."""
    return request.param


def step(env: TransformedEnv, td: TensorDict, action: list[int]) -> tuple[TensorDict, TensorDict]:
    td["action"] = torch.tensor(action)
    return env.step_and_maybe_reset(td)


# ----------------------------------------------------------------- arithmetic by hand


@pytest.mark.parametrize("start", ["value", "nonpositive", "zero"])
def test_smdp_arithmetic_by_hand(backend: str, start: str) -> None:
    """Line 0..4, subgoals at 1 then 3, reward 1 per step and 10 at the goal.

    γ = γ_v = 0.9, α_v = 0.5, V = [0.1, 0.2, 0.3] before the episode. With
    ``start_potential`` "nonpositive" or "zero", Φ = V − V(0) (V(0) > 0 here):
    every step earns (1 − γ) V(0) more and the goal step V(0) more.
    """
    v = TabularPotential(3)
    with torch.no_grad():
        v.table.copy_(torch.tensor([0.1, 0.2, 0.3]))
    paper = ValueUpdate(0.5, SubgoalValueLoss(v, expectile=0.5).make_value_estimator(gamma=0.9))
    t = SubgoalPotentialTransform(
        SubgoalSeries([State(1), State(3)]),
        v,
        gamma=0.9,
        value_update=paper,
        start_potential=start,  # type: ignore[arg-type]
        keys=SubgoalKeys(transitions="smdp"),
    ).use_backend(backend)
    env = TransformedEnv(LineEnv(1), t)
    td = env.reset()
    expected = [
        # z', r_h (transition), k, emitted, V after the step, shaped reward
        (1, 1.0, 1, True, [0.64, 0.2, 0.3], 1 + 0.9 * 0.2 - 0.64),
        (1, 1.0, 1, False, [0.64, 0.2, 0.3], 1 + 0.9 * 0.2 - 0.2),
        (2, 1.9, 2, True, [0.64, 1.1715, 0.3], 1 + 0.9 * 0.3 - 1.1715),
        (2, 10.0, 1, True, [0.64, 1.1715, 5.15], 10 + 0.0 - 5.15),  # terminal: Φ(goal) = 0
    ]
    for z_next, r_h, k, emitted, table, shaped in expected:
        data, td = step(env, td, [1])
        nxt = data["next"]
        assert int(nxt["subgoal_index"]) == z_next
        smdp = nxt["smdp"]
        assert bool(smdp["mask"]) == emitted
        assert smdp["next", "reward"].item() == pytest.approx(r_h)
        assert int(smdp["steps_to_next_obs"]) == k
        assert v.table.tolist() == pytest.approx(table)
        shift = 0.0 if start == "value" else table[0] * (1.0 if int(nxt["terminated"]) else 1 - 0.9)
        assert nxt["reward"].item() == pytest.approx(shaped + shift, abs=1e-6)
        assert nxt["env_reward"].item() == (10.0 if z_next == 2 and r_h == 10.0 else 1.0)
    # after the goal the env was reset: the accumulators start again
    assert int(td["subgoal_index"]) == 0 and int(td["subgoal_steps"]) == 0


def test_accumulators_reset_on_emission(backend: str) -> None:
    t = SubgoalPotentialTransform(
        SubgoalSeries([State(3)]), TabularPotential(2), gamma=0.5, keys=SubgoalKeys(transitions="smdp")
    ).use_backend(backend)
    env = TransformedEnv(LineEnv(1, length=6), t)
    td = env.reset()
    rewards = []
    for a in [1, 1, 0, 1, 1]:  # positions 1, 2, 1, 2, 3 -> achieved at the 5th step
        data, td = step(env, td, [a])
        rewards.append(data["next", "smdp", "next", "reward"].item())
    assert data["next", "smdp", "mask"].item()
    assert rewards[-1] == pytest.approx(sum(0.5**i for i in range(5)))
    assert int(data["next", "smdp", "steps_to_next_obs"]) == 5
    assert int(td["subgoal_steps"]) == 0 and td["subgoal_return"].item() == 0.0


def test_truncation_bootstraps_and_termination_does_not() -> None:
    t = SubgoalPotentialTransform(
        SubgoalSeries([State(2)]), TabularPotential(2), gamma=0.9, keys=SubgoalKeys(transitions="smdp")
    )
    env = TransformedEnv(LineEnv(2, length=5), StepCounter(max_steps=2))
    env.append_transform(t)
    td = env.reset()
    data, td = step(env, td, [1, 0])
    data, td = step(env, td, [1, 0])  # env 0 achieves, both truncate at step 2
    smdp = data["next", "smdp"]
    assert smdp["mask"].tolist() == [[True], [True]]
    assert smdp["next", "terminated"].tolist() == [[False], [False]]
    assert smdp["next", "subgoal_index"].tolist() == [[1], [0]]  # truncated env 1 bootstraps from its own z


# ----------------------------------------------------------------- shaping definition


@pytest.mark.parametrize("start", ["value", "zero", "nonpositive"])
@pytest.mark.parametrize("zero_terminal", [True, False])
def test_shaped_reward_is_r_plus_gamma_v_next_minus_v(backend: str, zero_terminal: bool, start: str) -> None:
    n = 8
    patterns = [HALLWAYS, SubgoalSeries([Cell(6, 2), Cell(10, 6)]), SubgoalSeries([Cell(1, 2)])]
    v = TabularPotential(3, batch_shape=(n,))
    with torch.no_grad():
        v.table.copy_(torch.randn(n, 3))
    t = SubgoalPotentialTransform(
        [patterns[i % 3] for i in range(n)],
        v,
        gamma=0.95,
        observation_key="cell",
        zero_terminal_potential=zero_terminal,
        start_potential=start,  # type: ignore[arg-type]
    ).use_backend(backend)
    env = TransformedEnv(FourRoomsEnv(n, max_steps=40), t)
    torch.manual_seed(0)
    data = env.rollout(120, break_when_any_done=False)
    table = v.table.detach()
    if start != "value":  # Φ = V − V(0), or V − max(V(0), 0)
        table = table - (table[:, :1] if start == "zero" else table[:, :1].clamp(min=0.0))
    z, z_next = data["subgoal_index"], data["next", "subgoal_index"]
    rows = torch.arange(n)[:, None, None].expand_as(z)
    phi, phi_next = table[rows, z], table[rows, z_next]
    if zero_terminal:
        phi_next = phi_next.masked_fill(data["next", "terminated"], 0.0)
    expected = data["next", "env_reward"] + 0.95 * phi_next - phi
    assert torch.allclose(data["next", "reward"], expected, atol=1e-6)
    assert (z_next > 0).any() and (data["next", "done"]).any()  # subgoals achieved, episodes ended
    # the transitions are consistent with the state
    emitted = (z_next != z) | data["next", "done"]
    assert torch.equal(t.transitions(data)["next", "subgoal_index"], z_next[emitted].unsqueeze(-1))


def test_naive_potential_pulse(backend: str) -> None:
    t = SubgoalPotentialTransform(SubgoalSeries([State(1)]), NaivePotential(10.0), gamma=0.9).use_backend(backend)
    env = TransformedEnv(LineEnv(1, length=4, step_reward=0.0, goal_reward=0.0), t)
    td = env.reset()
    shaped = []
    for _ in range(3):
        data, td = step(env, td, [1])
        shaped.append(data["next", "reward"].item())
    assert shaped == pytest.approx([9.0, -10.0, 0.0])  # γη on achieving, then −η, then nothing


def test_compiled_and_torch_backends_agree() -> None:
    def run(backend: str) -> tuple[TensorDict, torch.Tensor]:
        n = 16
        v = TabularPotential(3, batch_shape=(n,))
        with torch.no_grad():
            v.table.copy_(torch.randn(n, 3, generator=torch.Generator().manual_seed(3)))
        start = v.table.detach().clone()
        patterns = [HALLWAYS, SubgoalSeries([Cell(6, 2), Cell(10, 6)])]
        t = SubgoalPotentialTransform(
            [patterns[i % 2] for i in range(n)],
            v,
            gamma=0.99,
            observation_key="cell",
            value_update=0.3,
            keys=SubgoalKeys(transitions="smdp"),
        ).use_backend(backend)  # type: ignore[arg-type]
        env = TransformedEnv(FourRoomsEnv(n, max_steps=60), t)
        torch.manual_seed(1)
        data = env.rollout(300, break_when_any_done=False)
        assert not torch.allclose(v.table.detach(), start)  # the potential was trained
        assert t._online is not None and t._online.compiled == (backend == "compiled")
        return data, v.table.detach().clone()

    compiled, v_compiled = run("compiled")
    eager, v_eager = run("torch")
    assert torch.allclose(v_compiled, v_eager, atol=1e-5)
    for key in [
        ("next", "reward"),
        ("next", "subgoal_index"),
        ("next", "subgoal_return"),
        ("next", "subgoal_steps"),
        ("next", "smdp", "mask"),
        ("next", "smdp", "next", "reward"),
    ]:
        assert torch.allclose(compiled[key].float(), eager[key].float(), atol=1e-5), key


@pytest.mark.parametrize("shared", [False, True])
@pytest.mark.parametrize("option", [{"prior_weight": 3.0}, {"achievement_reward": 0.5}])
def test_the_backends_agree_on_a_prior_weight_and_an_achievement_reward(option: dict, shared: bool) -> None:
    """The candidates of the potential's update (a prior handed over by counts; a target that counts the
    subgoals achieved) train the same tables, counts and rewards through the compiled step and through torch,
    with a table per learner and with one table shared by the batch."""

    def run(backend: str) -> tuple[TensorDict, TabularPotential]:
        n = 8
        v = TabularPotential.for_subgoals(HALLWAYS, batch_shape=() if shared else (n,), interpolate=False)
        loss = SubgoalValueLoss(v, achievement_reward=option.get("achievement_reward", 0.0))
        update = ValueUpdate(0.05, loss.make_value_estimator(gamma=0.99), prior_weight=option.get("prior_weight", 0.0))
        t = SubgoalPotentialTransform(HALLWAYS, v, gamma=0.99, observation_key="cell", value_update=update)
        env = TransformedEnv(FourRoomsEnv(n, max_steps=50), t.use_backend(backend))  # type: ignore[arg-type]
        torch.manual_seed(2)
        data = env.rollout(400, break_when_any_done=False)
        assert t._online is not None and t._online.compiled == (backend == "compiled")
        return data, v

    (compiled, v_compiled), (eager, v_eager) = run("compiled"), run("torch")
    assert torch.allclose(v_compiled.table.detach(), v_eager.table.detach(), atol=1e-5)
    assert torch.equal(v_compiled.updates, v_eager.updates)
    assert torch.allclose(compiled["next", "reward"], eager["next", "reward"], atol=1e-5)
    if "prior_weight" in option:
        assert v_compiled.updates.sum() > 0  # counted: the transitions that trained the table
    else:
        assert v_compiled.updates.sum() == 0  # counted only where a step size depends on it


def test_compiled_backend_refuses_what_it_cannot_shape_in_one_line() -> None:
    t = SubgoalPotentialTransform(
        HALLWAYS, NeuralPotential(torch.nn.Linear(2, 1)), gamma=0.9, observation_key="cell"
    ).use_backend("compiled")
    with pytest.raises(
        TypeError,
        match=r"backend 'compiled': it shapes with a TabularPotential or a "
        r"NaivePotential, not NeuralPotential; use the backend 'torch' or 'auto'",
    ):
        TransformedEnv(FourRoomsEnv(2), t).reset()
    with pytest.raises(ValueError, match="backend must be 'auto', 'compiled' or 'torch', got 'numba'"):
        SubgoalPotentialTransform(HALLWAYS, TabularPotential(3), gamma=0.9).use_backend("numba")  # type: ignore[arg-type]


# ----------------------------------------------------------------- env kinds and specs


def transform_for(batch: tuple[int, ...], **kwargs) -> SubgoalPotentialTransform:
    v = TabularPotential(3, batch_shape=batch)
    return SubgoalPotentialTransform(HALLWAYS, v, gamma=0.99, observation_key="cell", value_update=0.25, **kwargs)


def test_single_unbatched_env() -> None:
    env = TransformedEnv(FourRoomsEnv(), transform_for(()))
    check_env_specs(env)
    data = env.rollout(50)
    assert data["next", "subgoal_index"].shape == (50, 1)


@pytest.mark.parametrize("write", [True, False])
def test_batched_env_specs(write: bool) -> None:
    env = TransformedEnv(FourRoomsEnv(5), transform_for((5,), keys=SubgoalKeys(transitions="smdp" if write else None)))
    check_env_specs(env)
    assert ("smdp" in list(env.observation_spec.keys())) == write


def test_serial_env() -> None:
    env = TransformedEnv(SerialEnv(2, make_four_rooms), transform_for((2,)))
    check_env_specs(env)


def test_parallel_env() -> None:
    env = TransformedEnv(ParallelEnv(2, make_four_rooms, mp_start_method="spawn"), transform_for((2,)))
    try:
        check_env_specs(env)
        data = env.rollout(30)
        assert data["next", "subgoal_index"].shape == (2, 30, 1)
    finally:
        env.close()


def test_in_a_compose_with_other_transforms() -> None:
    t = transform_for((3,))
    env = TransformedEnv(FourRoomsEnv(3), Compose(StepCounter(max_steps=20), t, RewardSum()))
    check_env_specs(env)
    data = env.rollout(25, break_when_any_done=False)
    # RewardSum after the transform sums the shaped reward; env_reward is untouched
    assert torch.allclose(data["next", "episode_reward"][:, 0], data["next", "reward"][:, 0])


def test_partial_resets_keep_other_envs_state(backend: str) -> None:
    t = SubgoalPotentialTransform(
        SubgoalSeries([State(1), State(2)]), TabularPotential(3, (3,)), gamma=0.9
    ).use_backend(backend)
    env = TransformedEnv(LineEnv(3, length=3), t)
    td = env.reset()
    for actions in ([1, 1, 0], [1, 1, 1]):
        _, td = step(env, td, actions)
    assert td["subgoal_index"].tolist() == [[2], [2], [1]]
    data, td = step(env, td, [1, 0, 0])  # env 0 reaches the goal and resets
    assert data["next", "done"].tolist() == [[True], [False], [False]]
    assert td["subgoal_index"].tolist() == [[0], [2], [1]]
    assert td["subgoal_steps"].tolist() == [[0], [1], [1]]
    assert td["observation"].tolist() == [0, 1, 0]


# ----------------------------------------------------------------- other envs


def test_on_a_gymnasium_env_that_is_not_ours() -> None:
    from torchrl.envs import GymEnv

    # CartPole: a subgoal on the cart position (observation entry 0), then on the pole angle
    series = SubgoalSeries([Box((0.02,), (0.01,), (0,)), Box((0.0,), (0.02,), (2,))])
    t = SubgoalPotentialTransform(series, TabularPotential(3), gamma=0.99, value_update=0.1)
    env = TransformedEnv(GymEnv("CartPole-v1"), t)
    check_env_specs(env)
    env.set_seed(0)
    data = env.rollout(200, break_when_any_done=False)
    assert torch.equal(data["next", "env_reward"], torch.ones_like(data["next", "env_reward"]))
    assert (data["next", "subgoal_index"] > 0).any()
    assert not torch.equal(data["next", "reward"], data["next", "env_reward"])


def test_one_hot_observation_of_frozen_lake() -> None:
    from torchrl.envs import GymEnv

    t = SubgoalPotentialTransform(SubgoalSeries([State(1)]), TabularPotential(2), gamma=0.9)
    env = TransformedEnv(GymEnv("FrozenLake-v1", is_slippery=False), t)
    check_env_specs(env)
    td = env.reset()
    td["action"] = torch.nn.functional.one_hot(torch.tensor(2), 4)  # right: state 0 -> 1
    data = env.step(td)
    assert int(data["next", "subgoal_index"]) == 1


def test_neural_potential_keeps_the_anchor() -> None:
    net = torch.nn.Linear(2, 1)
    t = SubgoalPotentialTransform(HALLWAYS, NeuralPotential(net), gamma=0.99, observation_key="cell", value_update=0.01)
    env = TransformedEnv(FourRoomsEnv(4), t)
    check_env_specs(env)
    data = env.rollout(30)
    # the anchor changes only when a subgoal is achieved, to that observation
    anchor, nxt_anchor = data["subgoal_anchor"], data["next", "subgoal_anchor"]
    changed = (anchor != nxt_anchor).any(-1, keepdim=True)
    achieved = data["next", "subgoal_index"] != data["subgoal_index"]
    assert torch.equal(changed & ~data["next", "done"], achieved & changed & ~data["next", "done"])
    assert torch.equal(data["subgoal_anchor"][:, 0], data["cell"][:, 0].float())


def test_aggregation_sarsa_rs() -> None:
    agg = room_aggregation()
    t = SubgoalPotentialTransform(agg, TabularPotential(4, (2,)), gamma=0.99, value_update=0.25)
    env = TransformedEnv(FourRoomsEnv(2), t)
    check_env_specs(env)
    data = env.rollout(40)
    rooms = agg.mapping[data["next", "observation"]]
    assert torch.equal(data["next", "subgoal_index"].squeeze(-1), rooms)


def test_offline_forward_matches_online() -> None:
    v = TabularPotential(3, batch_shape=(4,))
    with torch.no_grad():
        v.table.copy_(torch.randn(4, 3))
    t = SubgoalPotentialTransform(HALLWAYS, v, gamma=0.95, observation_key="cell")
    env = TransformedEnv(FourRoomsEnv(4, max_steps=30), t)
    torch.manual_seed(2)
    data = env.rollout(100, break_when_any_done=False)
    stored = data.exclude(("next", "reward"), ("next", "subgoal_index"))
    stored["next", "reward"] = data["next", "env_reward"]
    offline = t(stored.clone())
    assert torch.allclose(offline["next", "reward"], data["next", "reward"], atol=1e-6)
    assert torch.equal(offline["next", "subgoal_index"], data["next", "subgoal_index"])


@pytest.mark.parametrize("start", ["value", "zero", "nonpositive"])
def test_start_potential_under_a_step_cost(backend: str, start: str) -> None:
    """V < 0 (a step cost): "nonpositive" shapes as "value" does; "zero" shifts Φ by −V(0).

    Line 0..4, subgoals at 1 then 3, −1 per step and 0 at the goal, γ = 0.9,
    V = [−3, −2, −1] fixed; the terminal potential is zeroed.
    """
    v = TabularPotential(3)
    with torch.no_grad():
        v.table.copy_(torch.tensor([-3.0, -2.0, -1.0]))
    t = SubgoalPotentialTransform(SubgoalSeries([State(1), State(3)]), v, gamma=0.9, start_potential=start).use_backend(
        backend
    )  # type: ignore[arg-type]
    env = TransformedEnv(LineEnv(1, step_reward=-1.0, goal_reward=0.0), t)
    td = env.reset()
    raw = [-1 + 0.9 * -2 + 3, -1 + 0.9 * -2 + 2, -1 + 0.9 * -1 + 2, 0 - 0 + 1]  # z: 0→1, 1→1, 1→2, 2→goal
    shift = [0.1 * -3] * 3 + [-3.0] if start == "zero" else [0.0] * 4
    for expected, extra in zip(raw, shift, strict=True):
        data, td = step(env, td, [1])
        assert data["next", "reward"].item() == pytest.approx(expected + extra, abs=1e-6)
    assert bool(data["next", "terminated"])


@pytest.mark.parametrize("start", ["zero", "nonpositive"])
def test_neural_start_potential_reads_the_reset_observation(start: str) -> None:
    torch.manual_seed(0)
    net = torch.nn.Linear(2, 1)
    with torch.no_grad():
        net.bias.fill_(0.5 if start == "nonpositive" else -0.5)
    t = SubgoalPotentialTransform(
        HALLWAYS, NeuralPotential(net), gamma=0.9, observation_key="cell", start_potential=start
    )  # type: ignore[arg-type]
    env = TransformedEnv(FourRoomsEnv(3, max_steps=40), t)
    check_env_specs(env)
    data = env.rollout(60, break_when_any_done=False)
    assert torch.equal(data["subgoal_start"], data["cell"][:, :1].float().expand_as(data["subgoal_start"]))
    with torch.no_grad():
        v_start = net(data["subgoal_start"])
        shift = v_start if start == "zero" else v_start.clamp(min=0.0)
        phi = net(data["subgoal_anchor"]) - shift
        phi_next = (net(data["next", "subgoal_anchor"]) - shift).masked_fill(data["next", "terminated"], 0.0)
    expected = data["next", "env_reward"] + 0.9 * phi_next - phi
    assert torch.allclose(data["next", "reward"], expected, atol=1e-5)
    assert start == "zero" or bool((v_start > 0).all())  # the shift applied


@pytest.mark.parametrize("start", ["zero", "nonpositive"])
def test_start_potential_of_an_aggregation_is_that_of_the_reset_state(backend: str, start: str) -> None:
    """Line 0..4 with g(0) = 1 and g(s) = 0 elsewhere: episodes start in z = 1, whose potential sets the level."""
    from torchrl_subgoal import StateAggregation

    v = TabularPotential(2, (2,))
    with torch.no_grad():
        v.table.copy_(torch.tensor([[-1.0, 2.0], [-1.0, -3.0]]))
    starts_in_1 = StateAggregation(torch.tensor([1, 0, 0, 0, 0]), num_states=2)
    t = SubgoalPotentialTransform(starts_in_1, v, gamma=0.9, start_potential=start).use_backend(backend)  # type: ignore[arg-type]
    env = TransformedEnv(LineEnv(2, step_reward=0.0), t)
    check_env_specs(env)
    td = env.reset()
    assert td["subgoal_start"].tolist() == [[1], [1]]
    data, td = step(env, td, [1, 1])  # z: 1 -> 0 for both
    shift = torch.tensor([2.0, -3.0 if start == "zero" else 0.0])
    expected = 0.9 * (torch.tensor([-1.0, -1.0]) - shift) - (torch.tensor([2.0, -3.0]) - shift)
    assert torch.allclose(data["next", "reward"].squeeze(-1), expected)
    assert data["next", "subgoal_start"].tolist() == [[1], [1]]  # kept through the episode
    with pytest.raises(ValueError, match="start_potential must be one of"):
        SubgoalPotentialTransform(HALLWAYS, TabularPotential(3), gamma=0.9, start_potential="max").use_backend(backend)  # type: ignore[arg-type]


# ----------------------------------------------------------------- bad input


def test_unknown_observation_key() -> None:
    t = SubgoalPotentialTransform(HALLWAYS, TabularPotential(3), gamma=0.9, observation_key="pos")
    with pytest.raises(KeyError, match="observation_key 'pos' is not an observation"):
        _ = TransformedEnv(FourRoomsEnv(2), t).observation_spec


def test_observation_too_small_for_the_predicate() -> None:
    series = SubgoalSeries([Cell(3, 6, (1, 2))], name="wide", source="wide.yaml")
    env = TransformedEnv(
        FourRoomsEnv(2), SubgoalPotentialTransform(series, TabularPotential(2), gamma=0.9, observation_key="cell")
    )
    with pytest.raises(SubgoalFileError, match=r"wide\.yaml: pattern 'wide'.*has 2 entries"):
        env.reset()


def test_potential_batch_mismatch() -> None:
    env = TransformedEnv(FourRoomsEnv(3), transform_for((4,)))
    with pytest.raises(ValueError, match=r"batch_shape \(4,\) but the env batch has 3 envs"):
        env.reset()


def test_wrong_number_of_patterns() -> None:
    t = SubgoalPotentialTransform([HALLWAYS, HALLWAYS], TabularPotential(3), gamma=0.9, observation_key="cell")
    with pytest.raises(
        ValueError, match="2 subgoal series for a batch of 3 envs: give one series for every env, or one per env"
    ):
        TransformedEnv(FourRoomsEnv(3), t).reset()


@pytest.mark.parametrize("kwargs", [{"gamma": 1.5}, {"gamma": 0.9, "value_update": -1.0}])
def test_bad_hyper_parameters(kwargs: dict) -> None:
    with pytest.raises(ValueError):
        SubgoalPotentialTransform(HALLWAYS, TabularPotential(3), **kwargs)


# ----------------------------------------------------------------- stored data (forward)


def fixed_table(v: TabularPotential, seed: int = 0) -> TabularPotential:
    with torch.no_grad():
        v.table.copy_(torch.randn(v.table.shape, generator=torch.Generator().manual_seed(seed)))
    return v


def assert_forward_matches(t: SubgoalPotentialTransform, data: TensorDict) -> None:
    """forward() on the stored data (shaped reward dropped) recomputes the online pass."""
    stored = data.exclude(("next", "reward"), *[("next", k) for k in t.state_keys])
    offline = t(stored.clone())
    assert torch.allclose(offline["next", "reward"], data["next", "reward"], atol=1e-6)
    for key in t.state_keys:
        assert torch.equal(offline["next", key], data["next", key]), key


def test_forward_equals_online_on_categorical_observations(backend: str) -> None:
    t = SubgoalPotentialTransform(
        SubgoalSeries([State(1), State(3)]), fixed_table(TabularPotential(3, (3,))), gamma=0.9
    ).use_backend(backend)
    env = TransformedEnv(LineEnv(3, length=4), t)
    torch.manual_seed(0)
    data = env.rollout(60, break_when_any_done=False)
    assert (data["next", "subgoal_index"] == 2).any() and data["next", "done"].any()
    assert_forward_matches(t, data)


def test_forward_equals_online_on_one_hot_observations() -> None:
    from torchrl.envs import GymEnv

    v = fixed_table(TabularPotential(3))
    t = SubgoalPotentialTransform(SubgoalSeries([State(1), State(2)]), v, gamma=0.9)
    env = TransformedEnv(GymEnv("FrozenLake-v1", is_slippery=False), t)
    env.set_seed(0)
    actions = torch.nn.functional.one_hot(torch.tensor([2, 2, 1, 0, 2, 2, 1, 1, 2, 2]), 4)
    td = env.reset()
    steps = []
    for a in actions:
        td["action"] = a
        step_data, td = env.step_and_maybe_reset(td)
        steps.append(step_data)
    data = torch.stack(steps, 0)
    assert int(data["next", "subgoal_index"].max()) == 2  # z advanced on one-hot states 1 then 2
    assert_forward_matches(t, data)
    # a transform that never saw the env (no spec) reads the one-hot layout from the data
    alone = SubgoalPotentialTransform(SubgoalSeries([State(1), State(2)]), v, gamma=0.9)
    assert_forward_matches(alone, data)


def test_forward_equals_online_on_continuous_observations(backend: str) -> None:
    from torchrl_subgoal.envs import PinBallEnv

    series = SubgoalSeries([Circle((0.2, 0.85), 0.06), Circle((0.3, 0.8), 0.06)])
    t = SubgoalPotentialTransform(series, fixed_table(TabularPotential(3, (4,))), gamma=0.99).use_backend(backend)
    env = TransformedEnv(PinBallEnv(4, max_steps=40, seed=0), t)
    torch.manual_seed(0)
    data = env.rollout(120, break_when_any_done=False)
    assert (data["next", "subgoal_index"] > 0).any()
    assert_forward_matches(t, data)


@pytest.mark.parametrize("batch", [64, 1])
def test_forward_on_a_replay_sample_of_another_batch_shape(backend: str, batch: int) -> None:
    """Regression: a [64, T] (or [1, T]) sample after a 2-env rollout once crashed the interpreter."""
    from torchrl.data import LazyTensorStorage, ReplayBuffer

    v = fixed_table(TabularPotential(3, (2,)))
    patterns = [HALLWAYS, SubgoalSeries([Cell(6, 2), Cell(10, 6)])]
    t = SubgoalPotentialTransform(patterns, v, gamma=0.95, observation_key="cell").use_backend(backend)
    env = TransformedEnv(FourRoomsEnv(2, max_steps=80), t)
    torch.manual_seed(3)
    data = env.rollout(200, break_when_any_done=False)
    assert (data["next", "subgoal_index"] > 0).any() and data["next", "done"].any()
    buffer = ReplayBuffer(storage=LazyTensorStorage(10), batch_size=batch)
    buffer.extend(data.exclude(("next", "reward")))
    sample, info = buffer.sample(return_info=True)
    assert sample.shape == (batch, 200)
    before = v.table.detach().clone()
    offline = t(sample.clone())
    rows = torch.as_tensor(info["index"])
    assert torch.allclose(offline["next", "reward"], data["next", "reward"][rows], atol=1e-6)
    assert torch.equal(offline["next", "subgoal_index"], data["next", "subgoal_index"][rows])
    assert torch.equal(v.table.detach(), before)


def test_forward_never_changes_parameters(backend: str) -> None:
    v = fixed_table(TabularPotential(3, (4,)))
    start = v.table.detach().clone()
    t = SubgoalPotentialTransform(HALLWAYS, v, gamma=0.99, observation_key="cell", value_update=0.5).use_backend(
        backend
    )
    env = TransformedEnv(FourRoomsEnv(4, max_steps=50), t)
    env.set_seed(0)  # with the suite's seeded actions, a walk that reaches a hallway (about 6% of draws reach none)
    data = env.rollout(150, break_when_any_done=False)
    assert not torch.equal(v.table.detach(), start)  # the online pass trained it
    before = v.table.detach().clone()
    t(data.clone())
    t(data[:1].clone())
    assert torch.equal(v.table.detach(), before)


def test_forward_without_the_learner_entry_of_per_env_tables_is_a_clear_error() -> None:
    t = SubgoalPotentialTransform(HALLWAYS, TabularPotential(3, (4,)), gamma=0.99, observation_key="cell")
    data = TransformedEnv(FourRoomsEnv(4), t).rollout(5)
    with pytest.raises(ValueError, match="subgoal_learner"):
        t(data[:3].exclude("subgoal_learner", ("next", "subgoal_learner")).clone())


def test_kernel_boundaries_check_shapes() -> None:
    """Inputs that do not fit the compiled tables are a ValueError, never a wrong read."""
    from torchrl_subgoal.subgoals import SubgoalTables

    tables = SubgoalTables([HALLWAYS], torch.zeros(4, dtype=torch.long), 2)
    with pytest.raises(ValueError, match="does not fit the subgoal tables compiled for 4 learners x 2"):
        tables.advance(torch.zeros(4, 1, dtype=torch.long), torch.zeros(64, 2))
    with pytest.raises(ValueError, match="3 abstract states for subgoal tables compiled for 4"):
        tables.advance(torch.zeros(3, 1, dtype=torch.long), torch.zeros(4, 2))
    with pytest.raises(ValueError, match="does not fit"):
        tables.advance(torch.zeros(4, 1, dtype=torch.long), torch.zeros(4, 1))


def test_transitions_rebuilt_equal_the_written_ones(backend: str) -> None:
    v = fixed_table(TabularPotential(3, (6,)))
    t = SubgoalPotentialTransform(
        HALLWAYS, v, gamma=0.97, observation_key="cell", keys=SubgoalKeys(transitions="smdp")
    ).use_backend(backend)
    data = TransformedEnv(FourRoomsEnv(6, max_steps=60), t).rollout(200, break_when_any_done=False)
    written = data["next", "smdp"].reshape(-1)
    written = written[written["mask"].reshape(-1)]
    rebuilt = t.transitions(data)
    assert rebuilt.numel() == written.numel() > 10
    for key in (
        "subgoal_index",
        "subgoal_learner",
        "steps_to_next_obs",
        ("next", "subgoal_index"),
        ("next", "subgoal_learner"),
        ("next", "terminated"),
        ("next", "done"),
    ):
        assert torch.equal(rebuilt[key], written[key]), key
    assert torch.allclose(rebuilt["next", "reward"], written["next", "reward"], atol=1e-6)


# ----------------------------------------------------------------- TorchRL pipelines


def test_two_transforms_on_one_env(backend: str) -> None:
    halves = StateAggregation(torch.tensor([0, 0, 1, 1, 2]), num_states=3)
    # Φ = V (start_potential="value") keeps the expected rewards below a plain table look-up
    first = SubgoalPotentialTransform(
        SubgoalSeries([State(1), State(3)]),
        fixed_table(TabularPotential(3), 1),
        gamma=0.9,
        start_potential="value",
    ).use_backend(backend)
    second_potential = fixed_table(TabularPotential(3, index_key="half_index"), 2)
    second = SubgoalPotentialTransform(
        halves, second_potential, gamma=0.9, start_potential="value", keys=SubgoalKeys("half")
    ).use_backend(backend)
    env = TransformedEnv(LineEnv(3, length=4), Compose(first, second))
    check_env_specs(env)
    torch.manual_seed(0)
    data = env.rollout(100, break_when_any_done=False)
    nxt = data["next"]
    table_1, table_2 = first.potential.table.detach(), second_potential.table.detach()
    terminated = nxt["terminated"]
    f_1 = 0.9 * table_1[nxt["subgoal_index"]].masked_fill(terminated, 0) - table_1[data["subgoal_index"]]
    f_2 = 0.9 * table_2[nxt["half_index"]].masked_fill(terminated, 0) - table_2[data["half_index"]]
    assert torch.allclose(nxt["reward"], nxt["env_reward"] + f_1 + f_2, atol=1e-5)
    # each keeps its own abstract state, and both accumulate the env reward (1 per step, 10 at the goal)
    assert torch.equal(nxt["half_index"].squeeze(-1), halves.mapping[nxt["observation"]])
    assert (nxt["subgoal_index"] == 2).any() and terminated.any()
    for t in (first, second):
        real = t.transitions(data)
        k = real["steps_to_next_obs"]
        goal = real["next", "terminated"]
        expected = torch.where(goal, (1 - 0.9 ** (k - 1)) / 0.1 + 10 * 0.9 ** (k - 1), (1 - 0.9**k) / 0.1)
        assert goal.any() and torch.allclose(real["next", "reward"], expected, atol=1e-4)


def test_condition_predicates_on_a_dict_observation_in_a_collector_over_parallel_env() -> None:
    from torchrl.collectors import Collector

    from .dict_env import at_door, carrying_key, make_key_door

    series = SubgoalSeries([carrying_key, at_door], name="key_then_door")  # plain functions of the TensorDict
    v = fixed_table(TabularPotential(3))
    t = SubgoalPotentialTransform(series, v, gamma=0.9, observation_key="position", start_potential="value")
    env = TransformedEnv(ParallelEnv(2, make_key_door, mp_start_method="spawn"), t)
    collector = Collector(env, None, frames_per_batch=200, total_frames=400)
    try:
        for data in collector:
            nxt = data["next"]
            z, z_next = data["subgoal_index"], nxt["subgoal_index"]
            has_key = nxt["has_key"].bool()
            # z moves 0 -> 1 exactly when the key is first held, 1 -> 2 at the door
            assert torch.equal((z == 0) & (z_next == 1), (z == 0) & has_key)
            assert torch.equal((z == 1) & (z_next == 2), (z == 1) & (nxt["position"] >= 5))
            table = v.table.detach()
            expected = nxt["env_reward"] + 0.9 * table[z_next].masked_fill(nxt["terminated"], 0) - table[z]
            assert torch.allclose(nxt["reward"], expected, atol=1e-6)
        assert (z_next == 2).any()
    finally:
        collector.shutdown()


def test_arbitrary_tensordict_module_as_the_potential() -> None:
    from tensordict.nn import TensorDictModule, TensorDictSequential

    torch.manual_seed(0)
    embed = TensorDictModule(torch.nn.Linear(2, 8), in_keys=["subgoal_anchor"], out_keys=["hidden"])
    head = TensorDictModule(
        torch.nn.Sequential(torch.nn.Tanh(), torch.nn.Linear(8, 1)), in_keys=["hidden"], out_keys=["subgoal_value"]
    )
    potential = TensorDictSequential(embed, head)
    before = [p.detach().clone() for p in potential.parameters()]
    # random walks of 40 steps mostly time out inside z: bootstrapped, they train the module too
    update = ValueUpdate(0.01, SubgoalValueLoss(potential, bootstrap_truncated=True).make_value_estimator(gamma=0.9))
    t = SubgoalPotentialTransform(HALLWAYS, potential, gamma=0.9, observation_key="cell", value_update=update)
    env = TransformedEnv(FourRoomsEnv(4, max_steps=40), t)
    check_env_specs(env)
    data = env.rollout(100, break_when_any_done=False)
    assert any(not torch.equal(a, b) for a, b in zip(before, potential.parameters(), strict=True))  # trained
    # forward() with the trained module reproduces F = γΦ(anchor') − Φ(anchor) and trains nothing
    frozen = [p.detach().clone() for p in potential.parameters()]
    offline = t(data.clone())
    nxt = offline["next"]
    with torch.no_grad():
        phi = potential(offline.select("subgoal_anchor").clone())["subgoal_value"]
        phi_next = potential(nxt.select("subgoal_anchor").clone())["subgoal_value"]
    expected = nxt["env_reward"] + 0.9 * phi_next.masked_fill(nxt["terminated"], 0) - phi
    assert torch.allclose(nxt["reward"], expected, atol=1e-5)
    assert all(torch.equal(a, b) for a, b in zip(frozen, potential.parameters(), strict=True))


def test_potential_reading_entries_the_transform_does_not_keep() -> None:
    from tensordict.nn import TensorDictModule

    bad = TensorDictModule(torch.nn.Linear(2, 1), in_keys=["cell"], out_keys=["subgoal_value"])
    with pytest.raises(ValueError, match=r"reads \['cell'\], which this transform does not keep"):
        SubgoalPotentialTransform(HALLWAYS, bad, gamma=0.9, observation_key="cell")


def test_neural_potential_with_the_wrong_output_shape() -> None:
    t = SubgoalPotentialTransform(HALLWAYS, NeuralPotential(torch.nn.Linear(2, 3)), gamma=0.9, observation_key="cell")
    env = TransformedEnv(FourRoomsEnv(2), t)
    with pytest.raises(ValueError, match=r"returned values of shape \(2, 3\).*output size is 1"):
        env.rollout(3)


class _CountingNet(torch.nn.Module):
    """A linear value network that counts its evaluations."""

    def __init__(self) -> None:
        super().__init__()
        self.net = torch.nn.Linear(2, 1)
        self.calls = 0

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        self.calls += 1
        return self.net(x)


@pytest.mark.parametrize("change", ["none", "optimizer", "data", "shared"])
def test_potential_value_is_reused_only_while_inputs_and_parameters_are_unchanged(change: str) -> None:
    """Φ(z) of a step is the previous step's Φ(z'), Φ(z') is Φ(z) until a subgoal is achieved and Φ(z_0)
    that of the episode, without evaluating the potential again; any change of the parameters (an optimiser step,
    an in-place ``.data`` write that moves no version counter, shared memory written by another process) is seen."""
    torch.manual_seed(0)
    net = _CountingNet()
    if change == "shared":
        net.share_memory()
    t = SubgoalPotentialTransform(
        HALLWAYS, NeuralPotential(net), gamma=0.9, observation_key="cell", start_potential="zero"
    )
    env = TransformedEnv(FourRoomsEnv(8, max_steps=1000), t)
    optimizer = torch.optim.SGD(net.parameters(), lr=0.1)
    td = env.reset()
    was_reset = True
    evaluated: list[bool] = []
    for _ in range(200):
        td["action"] = env.action_spec.rand()
        before = td.clone()
        net.calls = 0
        out, td = env.step_and_maybe_reset(td)
        nxt = out["next"]
        with torch.no_grad():
            shift = net.net(before["subgoal_start"])
            phi = net.net(before["subgoal_anchor"]) - shift
            phi_next = (net.net(nxt["subgoal_anchor"]) - shift).masked_fill(nxt["terminated"], 0.0)
        assert torch.allclose(nxt["reward"], nxt["env_reward"] + 0.9 * phi_next - phi, atol=1e-6)
        moved = bool((nxt["subgoal_anchor"] != before["subgoal_anchor"]).any())  # a subgoal achieved
        if change == "none" and not was_reset:
            assert net.calls == int(moved)  # Φ(z') where a subgoal was achieved, else nothing
            evaluated.append(moved)
        elif change != "none":
            assert net.calls == 2 + int(moved)  # Φ(z), Φ(z_0) (the parameters changed), Φ(z') if moved
            evaluated.append(moved)
        was_reset = bool(nxt["done"].any())
        if change == "optimizer":
            optimizer.zero_grad()
            net.net(td["subgoal_anchor"]).sum().backward()
            optimizer.step()
        elif change in ("data", "shared"):
            net.net.bias.data.add_(0.1)
    assert any(evaluated) and not all(evaluated)  # both kinds of step were seen


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64, torch.bfloat16])
def test_value_cache_sees_one_changed_entry_of_a_large_parameter(dtype: torch.dtype) -> None:
    """Large CPU tensors are compared through numpy (others by torch): one changed entry of 8,192, a NaN
    (equal to nothing) and a negative zero (equal to zero) are seen as by ``torch.equal``."""
    from torchrl_subgoal.transform.cache import ValueCache

    net = NeuralPotential(torch.nn.Linear(64, 128).to(dtype))
    cache = ValueCache()
    cache.check(net)
    inputs = {"x": torch.zeros(2, 1)}
    cache.put("z", inputs, torch.ones(2, 1))
    cache.check(net)
    assert cache.get("z", inputs) is not None  # unchanged
    weight = next(p for p in net.parameters() if p.numel() == 64 * 128)
    for value, seen in ((0.5, True), (float("nan"), True), (-0.0, False)):
        if value == -0.0:
            weight.data[3, 7] = 0.0
            cache.check(net)
            cache.put("z", inputs, torch.ones(2, 1))
        weight.data[3, 7] = value  # .data: no version counter moves
        cache.check(net)
        assert (cache.get("z", inputs) is None) == seen, value
        cache.put("z", inputs, torch.ones(2, 1))


def test_fused_step_reads_state_entries_written_in_place_or_moved_to_other_memory() -> None:
    # the step reuses the numpy views of last step's outputs: writes into them, and a storage swapped
    # under the same tensor object, must still be what the kernel reads
    t = SubgoalPotentialTransform(
        SubgoalSeries([Cell(3, 6), Cell(7, 9)]), TabularPotential(3), gamma=0.9, observation_key="cell"
    )
    env = TransformedEnv(FourRoomsEnv(4), t)
    td = env.reset()
    td["action"] = torch.zeros(4, dtype=torch.long)
    _, td = env.step_and_maybe_reset(td)
    steps, ret = td["subgoal_steps"], td["subgoal_return"]
    steps.set_(torch.full_like(steps, 7))  # same object, other memory
    ret.fill_(0.5)  # same memory, written in place
    td["action"] = torch.zeros(4, dtype=torch.long)
    out, _ = env.step_and_maybe_reset(td)
    nxt = out["next"]
    kept = (nxt["subgoal_index"] == out["subgoal_index"]) & ~nxt["done"]
    assert kept.any()
    assert (nxt["subgoal_steps"][kept] == 8).all()
    expected = 0.5 + 0.9**7 * nxt["env_reward"][kept]
    assert torch.allclose(nxt["subgoal_return"][kept], expected)


# ----------------------------------------------------------------- a monotone table


def monotone_run(
    monotone: bool, table: torch.Tensor, backend: str = "auto", **kwargs
) -> tuple[TensorDict, SubgoalPotentialTransform]:
    """A random walk of 8 four-rooms envs under three patterns (one of a single subgoal), per-env tables."""
    n = 8
    patterns = [HALLWAYS, SubgoalSeries([Cell(6, 2), Cell(10, 6)]), SubgoalSeries([Cell(1, 2)])]
    v = TabularPotential(3, batch_shape=(n,), monotone=monotone)
    with torch.no_grad():
        v.table.copy_(table)
    t = SubgoalPotentialTransform(
        [patterns[i % 3] for i in range(n)], v, gamma=0.95, observation_key="cell", **kwargs
    ).use_backend(backend)
    env = TransformedEnv(FourRoomsEnv(n, max_steps=40), t)
    torch.manual_seed(0)
    return env.rollout(150, break_when_any_done=False), t


@pytest.mark.parametrize("backend", ["compiled", "torch"])
def test_a_monotone_table_shapes_each_state_at_the_largest_value_before_it(backend: str) -> None:
    table = torch.randn(8, 3, generator=torch.Generator().manual_seed(5))
    data, t = monotone_run(True, table, backend)
    assert t._online is not None and t._online.compiled == (backend == "compiled")
    lifted = table.clone()
    for row in range(8):
        length = 2 if row % 3 == 2 else 3  # the single-subgoal pattern has z = 0, 1
        lifted[row, :length] = table[row, :length].cummax(0).values
    assert not torch.allclose(lifted, table)  # some rows were out of order
    phi_table = lifted - lifted[:, :1].clamp(min=0.0)  # the default start level
    z, z_next = data["subgoal_index"], data["next", "subgoal_index"]
    rows = torch.arange(8)[:, None, None].expand_as(z)
    phi, phi_next = phi_table[rows, z], phi_table[rows, z_next].masked_fill(data["next", "terminated"], 0.0)
    assert (z_next > 0).any() and data["next", "done"].any()
    assert torch.allclose(data["next", "reward"], data["next", "env_reward"] + 0.95 * phi_next - phi, atol=1e-5)
    assert torch.equal(t.potential(z[:, 0], torch.arange(8)[:, None]), table.gather(1, z[:, 0]))  # V reads as learned
    assert_forward_matches(t, data)  # stored data (a replay sample) shaped the same way


def test_a_table_already_in_order_shapes_as_without_monotone() -> None:
    table = torch.randn(8, 3, generator=torch.Generator().manual_seed(5)).sort(dim=-1).values
    monotone, _ = monotone_run(True, table, "torch")
    plain, t = monotone_run(False, table)
    assert t._online is not None and t._online.compiled
    assert torch.allclose(monotone["next", "reward"], plain["next", "reward"], atol=1e-6)


def test_a_monotone_table_trains_as_the_plain_one() -> None:
    """The online update reads the table as it is: the same walk trains the same table."""
    table = torch.randn(8, 3, generator=torch.Generator().manual_seed(6))
    _, monotone = monotone_run(True, table, value_update=0.3)
    _, plain = monotone_run(False, table, value_update=0.3)
    assert not torch.allclose(plain.potential.table, table)
    assert torch.allclose(monotone.potential.table, plain.potential.table, atol=1e-5)


def test_a_monotone_table_needs_subgoal_series() -> None:
    with pytest.raises(ValueError, match=r"monotone=True\): the shaping needs subgoal series"):
        SubgoalPotentialTransform(room_aggregation(), TabularPotential(4, monotone=True), gamma=0.9)


def test_a_monotone_table_over_a_partial_order_lifts_each_state_to_its_parents() -> None:
    """A diamond (two first subgoals in either order, then a third): the join is shaped at least at the value
    of either branch, whichever an episode came through."""
    diamond = SubgoalSeries([Cell(3, 6), Cell(6, 2), Cell(7, 9)], order=[(0, 2), (1, 2)])
    v = TabularPotential(4, monotone=True)
    with torch.no_grad():
        v.table.copy_(torch.tensor([0.0, 0.6, 0.2, 0.1]))
    t = SubgoalPotentialTransform(diamond, v, gamma=0.9, observation_key="cell", start_potential="value")
    data = TransformedEnv(FourRoomsEnv(2), t).rollout(3)
    assert t._online is not None and t._online.compiled
    ancestors = t._online.ancestors
    assert ancestors is not None and ancestors[0, 3].tolist() == [True, True, True, True]
    lifted = torch.tensor([0.0, 0.6, 0.2, 0.6])
    z, z_next = data["subgoal_index"], data["next", "subgoal_index"]
    expected = data["next", "env_reward"] + 0.9 * lifted[z_next] - lifted[z]
    assert torch.allclose(data["next", "reward"], expected)


def test_a_monotone_table_in_a_collector_over_a_parallel_env() -> None:
    """The TorchRL path: the transform on the outer env of a ParallelEnv, a Collector collecting."""
    from torchrl.collectors import Collector

    v = TabularPotential(3, monotone=True)  # one table shared by both envs
    with torch.no_grad():
        v.table.copy_(torch.tensor([-1.0, -3.0, -0.5]))  # shaped as −1, −1, −0.5
    t = SubgoalPotentialTransform(HALLWAYS, v, gamma=0.9, observation_key="cell", start_potential="value")
    env = TransformedEnv(ParallelEnv(2, make_four_rooms, mp_start_method="spawn"), t)
    collector = Collector(env, None, frames_per_batch=200, total_frames=400)
    try:
        for data in collector:
            phi = torch.tensor([-1.0, -1.0, -0.5])
            z, z_next = data["subgoal_index"], data["next", "subgoal_index"]
            phi_next = phi[z_next].masked_fill(data["next", "terminated"], 0.0)
            assert torch.allclose(data["next", "reward"], data["next", "env_reward"] + 0.9 * phi_next - phi[z])
    finally:
        collector.shutdown()  # closes the env too


def test_learners_sharing_tables_in_one_env_batch_equal_each_learner_alone(backend: str) -> None:
    """``TabularPotential(envs_per_table=M)``: K learners of M envs each as one env batch of K·M envs, one table
    per learner trained online, give each learner the rewards and the table it gets alone (M envs, one shared
    table), bit for bit (four-rooms is deterministic given the actions)."""
    learners, envs, steps = 3, 4, 120
    actions = torch.randint(0, 4, (steps, learners * envs), generator=torch.Generator().manual_seed(3))

    def run(n: int, potential: TabularPotential, acts: torch.Tensor) -> torch.Tensor:
        t = SubgoalPotentialTransform(
            HALLWAYS, potential, gamma=0.99, observation_key="cell", value_update=0.5
        ).use_backend(backend)
        env = TransformedEnv(FourRoomsEnv(n, max_steps=40, step_reward=-1.0), t)
        td, rewards = env.reset(), []
        for a in acts:
            out, td = step(env, td, a.tolist())
            rewards.append(out["next", "reward"].reshape(-1))
        return torch.stack(rewards)

    batch = TabularPotential(3, (learners,), envs_per_table=envs)
    together = run(learners * envs, batch, actions)
    for k in range(learners):
        alone = TabularPotential(3)
        rewards = run(envs, alone, actions[:, k * envs : (k + 1) * envs])
        assert torch.equal(together[:, k * envs : (k + 1) * envs], rewards)
        assert torch.equal(batch.table[k].detach(), alone.table.detach())
    assert not torch.equal(batch.table[0], batch.table[1])  # the learners' tables differ: each learned its own


def test_tables_shared_by_envs_must_fit_the_env_batch() -> None:
    with pytest.raises(ValueError, match="batch_shape \\(3,\\) of 4 envs each but the env batch has 8 envs"):
        TransformedEnv(
            FourRoomsEnv(8),
            SubgoalPotentialTransform(
                HALLWAYS, TabularPotential(3, (3,), envs_per_table=4), gamma=0.99, observation_key="cell"
            ),
        ).rollout(2)
    with pytest.raises(ValueError, match="envs_per_table needs a batch of tables"):
        TabularPotential(3, envs_per_table=2)


def test_stored_rows_of_learners_sharing_tables_read_their_learners_table(backend: str) -> None:
    """Re-shaping collected data (in env order, or shuffled rows with their learner entries) reads each row's
    table as the online pass did."""
    v = TabularPotential(3, (2,), envs_per_table=3)
    with torch.no_grad():
        v.table.copy_(torch.tensor([[0.0, 0.5, 0.75], [-1.0, -0.5, 0.25]]))
    t = SubgoalPotentialTransform(HALLWAYS, v, gamma=0.9, observation_key="cell").use_backend(backend)
    data = TransformedEnv(FourRoomsEnv(6, max_steps=50), t).rollout(150, break_when_any_done=False)
    assert data["next", "subgoal_index"].max() > 0
    offline = t(data.clone())
    assert torch.equal(offline["next", "reward"], data["next", "reward"])
    rows = torch.randperm(6)
    shuffled = t(data[rows].clone())
    assert torch.equal(shuffled["next", "reward"], data["next", "reward"][rows])


# ----------------------------------------------------------------- device moves and empty samples


@pytest.mark.parametrize(("backend", "potential"), [("compiled", "table"), ("torch", "table"), ("torch", "network")])
def test_a_device_move_it_cannot_follow_is_a_clear_error(backend: str, potential: str) -> None:
    """``transform.to("meta")`` left the compiled step shaping with the table from before the move."""
    v = TabularPotential(3) if potential == "table" else NeuralPotential(torch.nn.Linear(2, 1))
    t = SubgoalPotentialTransform(HALLWAYS, v, gamma=0.9, observation_key="cell", value_update=0.1).use_backend(backend)
    env = TransformedEnv(FourRoomsEnv(4, max_steps=20), t)
    data = env.rollout(10, break_when_any_done=False)
    t.to("meta")
    message = "the potential is on meta but the data it shapes on cpu; keep them on one device"
    with pytest.raises(ValueError, match=message):
        env.rollout(10, break_when_any_done=False)
    with pytest.raises(ValueError, match=message):
        t(data.clone())  # stored data likewise


@pytest.mark.parametrize("change", ["replaced", "moved"])
def test_a_table_replaced_or_moved_is_followed_on_both_backends(change: str) -> None:
    """A move of the transform that gives the potential new parameters (as ``.to("meta")`` does; here a
    round trip through float64 with torch's ``overwrite_module_params_on_conversion``), or new memory under
    the same one (``.share_memory_()``, ``.to("cuda")``): both backends shape with it, train it, and agree."""

    def run(backend: str) -> tuple[TensorDict, torch.Tensor, torch.Tensor]:
        v = TabularPotential(3)
        t = SubgoalPotentialTransform(HALLWAYS, v, gamma=0.9, observation_key="cell", value_update=0.1).use_backend(
            backend
        )
        env = TransformedEnv(FourRoomsEnv(8, max_steps=30), t)
        torch.manual_seed(0)
        env.rollout(40, break_when_any_done=False)
        new, old = torch.tensor([-3.0, -2.0, -1.0]), v.table
        if change == "replaced":
            torch.__future__.set_overwrite_module_params_on_conversion(True)
            try:
                t.to(torch.float64).to(torch.float32)
            finally:
                torch.__future__.set_overwrite_module_params_on_conversion(False)
            assert v.table is not old
            with torch.no_grad():
                v.table.copy_(new)
        else:
            v.table.data = new.clone()
        data = env.rollout(200, break_when_any_done=False)
        return data, new, v.table.detach().clone()

    compiled, new, v_compiled = run("compiled")
    eager, _, v_eager = run("torch")
    assert not torch.equal(v_compiled, new)  # the table shaping reads now was trained
    assert torch.allclose(v_compiled, v_eager, atol=1e-5)
    for key in [("next", "reward"), ("next", "subgoal_index")]:
        assert torch.allclose(compiled[key].float(), eager[key].float(), atol=1e-5), key


@pytest.mark.parametrize("shape", [(0,), (4, 0), (0, 5)])
def test_forward_on_an_empty_sample_returns_it_unchanged(backend: str, shape: tuple[int, ...]) -> None:
    t = SubgoalPotentialTransform(HALLWAYS, TabularPotential(3), gamma=0.9, observation_key="cell").use_backend(backend)
    data = TransformedEnv(FourRoomsEnv(4), t).rollout(5)  # [4, 5]
    empty = data[0, :0] if shape == (0,) else data[:, :0] if shape == (4, 0) else data[:0]
    assert empty.batch_size == shape
    before = empty.clone()
    assert t(empty) is empty
    assert (empty == before).all() and set(empty.keys(True, True)) == set(before.keys(True, True))

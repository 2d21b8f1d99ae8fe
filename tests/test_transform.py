"""SubgoalPotentialTransform: SMDP arithmetic, shaping, specs across env kinds, partial resets."""

from __future__ import annotations

from collections.abc import Iterator

import pytest
import torch
from tensordict import TensorDict
from torchrl.envs import Compose, ParallelEnv, RewardSum, SerialEnv, StepCounter, TransformedEnv
from torchrl.envs.utils import check_env_specs

from torchrl_subgoal import (
    Box,
    Cell,
    NaivePotential,
    NeuralPotential,
    State,
    SubgoalFileError,
    SubgoalPotentialTransform,
    SubgoalSeries,
    TabularPotential,
)
from torchrl_subgoal.envs import FourRoomsEnv
from torchrl_subgoal.envs.four_rooms import room_aggregation

from .line_env import LineEnv, make_four_rooms

HALLWAYS = SubgoalSeries([Cell(3, 6), Cell(7, 9)], name="hallways")


@pytest.fixture(params=["fused", "eager"])
def path(request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch) -> Iterator[str]:
    """Run a test through the fused CPU kernels and through the eager torch code."""
    if request.param == "eager":
        monkeypatch.setattr(SubgoalPotentialTransform, "_fused_constants", lambda self: None)
        monkeypatch.setattr("torchrl_subgoal.subgoals.SubgoalTables.advance",
                            lambda self, z, obs: self.advance_eager(z, obs))
    yield request.param


def step(env: TransformedEnv, td: TensorDict, action: list[int]) -> tuple[TensorDict, TensorDict]:
    td["action"] = torch.tensor(action)
    return env.step_and_maybe_reset(td)


# ----------------------------------------------------------------- arithmetic by hand


def test_smdp_arithmetic_by_hand(path: str) -> None:
    """Line 0..4, subgoals at 1 then 3, reward 1 per step and 10 at the goal.

    γ = γ_v = 0.9, α_v = 0.5, V = [0.1, 0.2, 0.3] before the episode.
    """
    v = TabularPotential(3)
    with torch.no_grad():
        v.table.copy_(torch.tensor([0.1, 0.2, 0.3]))
    t = SubgoalPotentialTransform(
        SubgoalSeries([State(1), State(3)]), v, gamma=0.9, value_lr=0.5, write_transitions=True
    )
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
        assert nxt["reward"].item() == pytest.approx(shaped, abs=1e-6)
        assert nxt["env_reward"].item() == (10.0 if z_next == 2 and r_h == 10.0 else 1.0)
    # after the goal the env was reset: the accumulators start again
    assert int(td["subgoal_index"]) == 0 and int(td["subgoal_steps"]) == 0


def test_accumulators_reset_on_emission(path: str) -> None:
    t = SubgoalPotentialTransform(SubgoalSeries([State(3)]), TabularPotential(2), gamma=0.5, write_transitions=True)
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
    t = SubgoalPotentialTransform(SubgoalSeries([State(2)]), TabularPotential(2), gamma=0.9, write_transitions=True)
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


@pytest.mark.parametrize("zero_terminal", [True, False])
def test_shaped_reward_is_r_plus_gamma_v_next_minus_v(path: str, zero_terminal: bool) -> None:
    n = 8
    patterns = [HALLWAYS, SubgoalSeries([Cell(6, 2), Cell(10, 6)]), SubgoalSeries([Cell(1, 2)])]
    v = TabularPotential(3, batch_shape=(n,))
    with torch.no_grad():
        v.table.copy_(torch.randn(n, 3))
    t = SubgoalPotentialTransform(
        patterns, v, gamma=0.95, observation_key="cell", pattern_index=torch.arange(n) % 3,
        zero_terminal_potential=zero_terminal,
    )
    env = TransformedEnv(FourRoomsEnv(n, max_steps=40), t)
    torch.manual_seed(0)
    data = env.rollout(120, break_when_any_done=False)
    table = v.table.detach()
    z, z_next = data["subgoal_index"], data["next", "subgoal_index"]
    rows = torch.arange(n)[:, None, None].expand_as(z)
    phi, phi_next = table[rows, z], table[rows, z_next]
    if zero_terminal:
        phi_next = phi_next.masked_fill(data["next", "terminated"], 0.0)
    expected = data["next", "env_reward"] + 0.95 * phi_next - phi
    assert torch.allclose(data["next", "reward"], expected, atol=1e-6)
    assert (z_next > 0).any() and (data["next", "done"]).any()  # subgoals achieved, episodes ended
    # the stored transitions are consistent with the state
    assert torch.equal(data["next", "smdp", "next", "subgoal_index"], z_next)


def test_naive_potential_pulse(path: str) -> None:
    t = SubgoalPotentialTransform(SubgoalSeries([State(1)]), NaivePotential(10.0), gamma=0.9)
    env = TransformedEnv(LineEnv(1, length=4, step_reward=0.0, goal_reward=0.0), t)
    td = env.reset()
    shaped = []
    for _ in range(3):
        data, td = step(env, td, [1])
        shaped.append(data["next", "reward"].item())
    assert shaped == pytest.approx([9.0, -10.0, 0.0])  # γη on achieving, then −η, then nothing


def test_fused_and_eager_paths_agree(monkeypatch: pytest.MonkeyPatch) -> None:
    def run(eager: bool) -> tuple[TensorDict, torch.Tensor]:
        with monkeypatch.context() as m:
            if eager:
                m.setattr(SubgoalPotentialTransform, "_fused_constants", lambda self: None)
            n = 16
            v = TabularPotential(3, batch_shape=(n,))
            with torch.no_grad():
                v.table.copy_(torch.randn(n, 3, generator=torch.Generator().manual_seed(3)))
            start = v.table.detach().clone()
            t = SubgoalPotentialTransform(
                [HALLWAYS, SubgoalSeries([Cell(6, 2), Cell(10, 6)])], v, gamma=0.99,
                observation_key="cell", pattern_index=torch.arange(n) % 2, value_lr=0.3,
                write_transitions=True,
            )
            env = TransformedEnv(FourRoomsEnv(n, max_steps=60), t)
            torch.manual_seed(1)
            data = env.rollout(300, break_when_any_done=False)
            assert not torch.allclose(v.table.detach(), start)  # the potential was trained
            return data, v.table.detach().clone()

    fused, v_fused = run(False)
    eager, v_eager = run(True)
    assert torch.allclose(v_fused, v_eager, atol=1e-5)
    for key in [("next", "reward"), ("next", "subgoal_index"), ("next", "subgoal_return"),
                ("next", "subgoal_steps"), ("next", "smdp", "mask"), ("next", "smdp", "next", "reward")]:
        assert torch.allclose(fused[key].float(), eager[key].float(), atol=1e-5), key


# ----------------------------------------------------------------- env kinds and specs


def transform_for(batch: tuple[int, ...], **kwargs) -> SubgoalPotentialTransform:
    v = TabularPotential(3, batch_shape=batch)
    return SubgoalPotentialTransform(HALLWAYS, v, gamma=0.99, observation_key="cell", value_lr=0.25, **kwargs)


def test_single_unbatched_env() -> None:
    env = TransformedEnv(FourRoomsEnv(), transform_for(()))
    check_env_specs(env)
    data = env.rollout(50)
    assert data["next", "subgoal_index"].shape == (50, 1)


@pytest.mark.parametrize("write", [True, False])
def test_batched_env_specs(write: bool) -> None:
    env = TransformedEnv(FourRoomsEnv(5), transform_for((5,), write_transitions=write))
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


def test_partial_resets_keep_other_envs_state(path: str) -> None:
    t = SubgoalPotentialTransform(SubgoalSeries([State(1), State(2)]), TabularPotential(3, (3,)), gamma=0.9)
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
    t = SubgoalPotentialTransform(series, TabularPotential(3), gamma=0.99, value_lr=0.1)
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
    t = SubgoalPotentialTransform(HALLWAYS, NeuralPotential(net), gamma=0.99, observation_key="cell", value_lr=0.01)
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
    t = SubgoalPotentialTransform(agg, TabularPotential(4, (2,)), gamma=0.99, value_lr=0.25)
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


# ----------------------------------------------------------------- bad input


def test_unknown_observation_key() -> None:
    t = SubgoalPotentialTransform(HALLWAYS, TabularPotential(3), gamma=0.9, observation_key="pos")
    with pytest.raises(KeyError, match="observation_key 'pos' is not an observation"):
        _ = TransformedEnv(FourRoomsEnv(2), t).observation_spec


def test_observation_too_small_for_the_predicate() -> None:
    series = SubgoalSeries([Cell(3, 6, (1, 2))], name="wide", source="wide.yaml")
    env = TransformedEnv(FourRoomsEnv(2), SubgoalPotentialTransform(series, TabularPotential(2), gamma=0.9,
                                                                    observation_key="cell"))
    with pytest.raises(SubgoalFileError, match=r"wide\.yaml: pattern 'wide'.*has 2 entries"):
        env.reset()


def test_potential_batch_mismatch() -> None:
    env = TransformedEnv(FourRoomsEnv(3), transform_for((4,)))
    with pytest.raises(ValueError, match=r"batch_shape \(4,\) but the env batch is \(3,\)"):
        env.reset()


def test_wrong_number_of_patterns() -> None:
    t = SubgoalPotentialTransform([HALLWAYS, HALLWAYS], TabularPotential(3), gamma=0.9, observation_key="cell")
    with pytest.raises(ValueError, match="2 subgoal series for a batch of 3 envs"):
        TransformedEnv(FourRoomsEnv(3), t).reset()


@pytest.mark.parametrize("kwargs", [{"gamma": 1.5}, {"gamma": 0.9, "value_lr": -1.0}, {"gamma": 0.9, "value_gamma": 2.0}])
def test_bad_hyper_parameters(kwargs: dict) -> None:
    with pytest.raises(ValueError):
        SubgoalPotentialTransform(HALLWAYS, TabularPotential(3), **kwargs)

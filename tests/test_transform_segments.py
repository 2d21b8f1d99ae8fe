"""The within-segment term of an interpolating potential (``TabularPotential(interpolate=True)``)."""

from __future__ import annotations

import pytest
import torch
from tensordict.nn import TensorDictModule
from torchrl.envs import Compose, StepCounter, TransformedEnv
from torchrl.objectives.value import GAE

from tests.line_env import LineEnv
from torchrl_subgoal import (
    Box,
    Cell,
    Circle,
    State,
    StateAggregation,
    SubgoalPotentialTransform,
    SubgoalSeries,
    TabularPotential,
)
from torchrl_subgoal.subgoals.tables import SubgoalTables
from torchrl_subgoal.transform.segments import closeness, segment_term


def tables_of(*predicates, rows: int = 1, size: int = 2) -> SubgoalTables:
    return SubgoalTables([SubgoalSeries(list(predicates))], torch.zeros(rows, dtype=torch.long), size)


def test_closeness_is_one_inside_and_falls_with_the_distance_in_region_sizes() -> None:
    tables = tables_of(Box((0.0, 0.0), (1.0, 2.0), (0, 1)), Circle((10.0, 0.0), 2.0), Cell(3, 3), rows=3)
    obs = torch.tensor([[0.5, 1.0], [3.0, 0.0], [10.0, 6.0]])
    near = closeness(tables, obs)
    # the box: inside; 2 half-widths to the right; 6 - 2 = 4 over a half-width of 2 in y, 9 in x
    assert near[0, 0] == 1.0
    assert near[1, 0] == pytest.approx(1 / 3)
    assert near[2, 0] == pytest.approx(1 / (1 + (81 + 4) ** 0.5))
    # the circle: (|o - c| - r) / r
    assert near[1, 1] == pytest.approx(1 / (1 + 5 / 2))
    assert near[2, 1] == pytest.approx(1 / (1 + 4 / 2))
    # the cell, of size 0: in the observation's units
    assert near[1, 2] == pytest.approx(1 / (1 + 3))
    assert near[0, 2] == pytest.approx(1 / (1 + (2.5**2 + 2**2) ** 0.5))


def test_padding_and_conditions_add_no_term() -> None:
    short, long = SubgoalSeries([Box((0.0,), (1.0,), (0,))]), SubgoalSeries([Box((0.0,), (1.0,), (0,))] * 2)
    tables = SubgoalTables([short, long], torch.tensor([0, 1]), 1)
    near = closeness(tables, torch.tensor([[5.0], [5.0]]))
    assert near[0, 1] == 0.0 and near[1, 1] > 0.0


def test_the_term_is_the_step_up_to_the_next_subgoal_times_closeness_and_zero_past_the_last() -> None:
    tables = tables_of(Box((0.0,), (1.0,), (0,)), Box((4.0,), (1.0,), (0,)), rows=3, size=1)
    values = torch.tensor([[0.0, 1.0, 3.0]] * 3)
    term = segment_term(tables, values, torch.tensor([[0], [1], [2]]), torch.tensor([[3.0], [3.0], [3.0]]))
    assert term.squeeze(-1).tolist() == pytest.approx([1.0 / 3, 2.0, 0.0])
    # a next subgoal valued below the current state pulls nowhere
    down = segment_term(tables, torch.tensor([[0.0, -1.0, 0.0]] * 3), torch.tensor([[0], [1], [2]]),
                        torch.tensor([[3.0]] * 3))  # fmt: skip
    assert down.squeeze(-1).tolist() == [0.0, 1.0, 0.0]


def line_transform(frozen: bool = True, **kwargs) -> SubgoalPotentialTransform:
    v = TabularPotential(2, init=[0.0, 1.0], interpolate=True)
    if frozen:
        v.table.requires_grad_(False)
    series = SubgoalSeries([Box((2.0,), (0.5,), (0,))])
    return SubgoalPotentialTransform(series, v, gamma=0.9, start_potential="value", **kwargs)


def right(td):
    td["action"] = torch.ones(td.batch_size, dtype=torch.long)
    return td


def test_an_interpolating_potential_shapes_by_hand() -> None:
    """Cells 0..4, the subgoal the cell 2 (half-width 0.5), V = [0, 1]: Φ(0) = 1/(1+3), Φ(1) = 1/(1+1),
    Φ(2) = Φ(3) = 1, and 0 at the goal."""
    env = TransformedEnv(LineEnv(1, length=4, step_reward=1.0, goal_reward=10.0), line_transform())
    data = env.rollout(4, policy=right)
    shaped = data["next", "reward"].reshape(-1).tolist()
    assert shaped == pytest.approx([1 + 0.9 * 0.5 - 0.25, 1 + 0.9 * 1 - 0.5, 1 + 0.9 - 1, 10 - 1])
    # the shaping telescopes: Σ γ^t F_t = γ^T Φ(s_T) − Φ(s_0), with Φ(s_T) = 0 at the goal
    env_reward = data["next", "env_reward"].reshape(-1)
    shaping = torch.tensor(shaped) - env_reward
    assert float((shaping * 0.9 ** torch.arange(4)).sum()) == pytest.approx(-0.25)


def test_an_actor_critic_shaped_gets_the_advantages_of_its_critic_offset_by_the_potential() -> None:
    """GAE over the shaped rewards with a critic ``V`` is GAE over the env's rewards with the critic ``V + Φ``, at
    every step, time-outs and the goal included: for A2C and PPO, potential-based shaping offsets the critic (where
    it starts and what it can represent) and changes nothing else (docs/does_it_help.md)."""
    env = TransformedEnv(
        LineEnv(4, length=4, step_reward=-1.0, goal_reward=10.0), Compose(StepCounter(6), line_transform())
    )
    torch.manual_seed(0)
    data = env.rollout(40, policy=lambda td: td.set("action", torch.randint(0, 2, td.batch_size)),
                       break_when_any_done=False)  # fmt: skip
    assert data["next", "terminated"].any() and data["next", "truncated"].any()
    own = torch.randn(5, 2)  # the critic's V(x, z)

    def potential(x: torch.Tensor, z: torch.Tensor) -> torch.Tensor:  # V = [0, 1]; the subgoal: cell 2, half-width 0.5
        d = (1.5 - x.float()).maximum(x.float() - 2.5).clamp(min=0.0) / 0.5
        return torch.where(z == 0, 1 / (1 + d), 1.0)

    def critic(offset: bool) -> TensorDictModule:
        def value(x: torch.Tensor, z: torch.Tensor) -> torch.Tensor:
            z = z.squeeze(-1)
            return (own[x, z] + (potential(x, z) if offset else 0.0)).unsqueeze(-1)

        return TensorDictModule(value, in_keys=["observation", "subgoal_index"], out_keys=["state_value"])

    shaped = GAE(gamma=0.9, lmbda=0.8, value_network=critic(False))(data.clone())["advantage"]
    unshaped = data.clone()
    unshaped["next", "reward"] = data["next", "env_reward"]
    offset = GAE(gamma=0.9, lmbda=0.8, value_network=critic(True))(unshaped)["advantage"]
    assert torch.allclose(shaped, offset, atol=1e-5)
    assert not torch.allclose(shaped, GAE(gamma=0.9, lmbda=0.8, value_network=critic(False))(unshaped)["advantage"])


def test_stored_steps_shape_as_the_env_did() -> None:
    env = TransformedEnv(LineEnv(2, length=4), line_transform())
    data = env.rollout(6, policy=lambda td: td.set("action", torch.randint(0, 2, td.batch_size)),
                       break_when_any_done=False)  # fmt: skip
    online = data["next", "reward"].clone()
    raw = data.exclude(("next", "reward")).clone()
    raw["next", "reward"] = data["next", "env_reward"]
    stored = env.transform.forward(raw.exclude(("next", "env_reward")))
    assert torch.allclose(stored["next", "reward"], online)


@pytest.mark.parametrize("monotone", [False, True])
@pytest.mark.parametrize("shared", [False, True])
def test_the_compiled_step_shapes_and_learns_as_the_torch_step(monotone: bool, shared: bool) -> None:
    """Learning online, one table per env or one shared, the compiled step and the torch step give the same
    shaped rewards and tables (the fused loops against the compiled step: tests/fused/test_engine.py)."""
    series = SubgoalSeries([Box((2.0,), (0.5,), (0,)), Circle((4.0,), 1.0)])
    outcomes = []
    for backend in ("compiled", "torch"):
        v = TabularPotential(3, () if shared else (3,), init=[0.0, 0.5, 0.2], monotone=monotone, interpolate=True)
        t = SubgoalPotentialTransform(series, v, gamma=0.9, value_update=0.5).use_backend(backend)
        env = TransformedEnv(LineEnv(3, length=6, goal_reward=5.0), t)
        torch.manual_seed(0)
        data = env.rollout(30, policy=lambda td: td.set("action", torch.randint(0, 2, td.batch_size)),
                           break_when_any_done=False)  # fmt: skip
        assert type(t._online.backend).__name__ == f"{backend.title()}Shaping"
        outcomes.append((data["next", "reward"], v.table.detach().clone()))
    (reward_c, table_c), (reward_t, table_t) = outcomes
    assert not torch.equal(table_c, torch.tensor([0.0, 0.5, 0.2]).expand_as(table_c))  # it learned
    torch.testing.assert_close(reward_c, reward_t, rtol=1e-5, atol=1e-5)
    torch.testing.assert_close(table_c, table_t, rtol=1e-5, atol=1e-5)


def test_states_add_no_term_and_an_aggregation_is_refused() -> None:
    """A discrete state has no distance: the interpolating table shapes a series of states exactly as the plain
    one (Taxi's subgoals), and a state beside a region adds nothing while the region still pulls."""
    tables = tables_of(State(2), Box((4.0,), (1.0,), (0,)), rows=2, size=1)
    assert closeness(tables, torch.tensor([[1.0], [3.0]]))[:, 0].tolist() == [0.0, 0.0]
    assert closeness(tables, torch.tensor([[3.0]] * 2))[:, 1].tolist() == [1.0, 1.0]

    def shaped(interpolate: bool) -> torch.Tensor:
        series = SubgoalSeries([State(1), State(3)])
        t = SubgoalPotentialTransform(series, TabularPotential(3, init=[0.0, 1.0, 2.0], interpolate=interpolate),
                                      gamma=0.9)  # fmt: skip
        env = TransformedEnv(LineEnv(2, length=4), t)
        rewards = env.rollout(6, policy=right, break_when_any_done=False)["next", "reward"]
        assert type(t._online.backend).__name__ == "CompiledShaping"  # no term to add: the compiled step shapes
        return rewards

    assert torch.equal(shaped(True), shaped(False))
    aggregation = StateAggregation(torch.tensor([0, 0, 1]), num_states=2)
    with pytest.raises(ValueError, match="not an aggregation"):
        SubgoalPotentialTransform(aggregation, TabularPotential(2, interpolate=True), gamma=0.9)

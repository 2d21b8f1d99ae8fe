"""The fused engine gives exactly the TorchRL loop's results."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import pytest
import torch
from torchrl.envs import TransformedEnv

from torchrl_subgoal import Cell, SubgoalSeries
from torchrl_subgoal._kernels.random import learner_keys
from torchrl_subgoal.envs import FourRoomsEnv
from torchrl_subgoal.envs.four_rooms import room_aggregation
from torchrl_subgoal.fused import (
    AC_PRESETS,
    SARSA_PRESETS,
    FourierActorCritic,
    SoftmaxSarsa,
    run_episodes,
)
from torchrl_subgoal.methods import HRS_D, paper_methods, shaping_transform

from ..line_env import LineEnv

PATTERNS = [SubgoalSeries([Cell(4, 9), Cell(11, 9)]), SubgoalSeries([Cell(1, 11), Cell(11, 1), Cell(10, 6)])]


def setup(
    method: str,
    n: int,
    abstract_states: int,
    max_steps: int,
    step_cost: bool = False,
    start: str = "nonpositive",
    zero_terminal: bool = True,
    learners: list[int] | None = None,
) -> tuple[object, SoftmaxSarsa]:
    """Learners ``0..n-1`` (or the given ones of those): learner ``b`` follows pattern ``b % 2``
    and has the ``b``-th seed derived from 7, whatever batch it runs in."""
    cfg = SARSA_PRESETS["released"]
    learners = list(range(n)) if learners is None else learners
    m = len(learners)
    env = FourRoomsEnv(
        m, max_steps=max_steps, goal_reward=0.0 if step_cost else 1.0, step_reward=-1.0 if step_cost else 0.0
    )
    shaping = shaping_transform(
        {**paper_methods("SARSA"), HRS_D.name: HRS_D}[method],
        env.batch_size,
        gamma=cfg.gamma,
        value_lr=cfg.value_lr,
        patterns=PATTERNS,
        pattern_index=torch.tensor(learners) % 2,
        aggregation=room_aggregation(),
        eta=1.0,
        observation_key="cell",
        start_potential=start,  # type: ignore[arg-type]
        zero_terminal_potential=zero_terminal,
    )
    learning_env = TransformedEnv(env, shaping) if shaping is not None else env
    seeds = learner_keys(7, n)[learners]
    return learning_env, SoftmaxSarsa(m, 104, 4, cfg, seed=seeds, abstract_states=abstract_states)


def _tables(env: object, agent: SoftmaxSarsa) -> tuple[torch.Tensor, torch.Tensor | None]:
    potential = env.transform.potential if hasattr(env, "transform") else None
    return agent.q.clone(), (potential.table.detach().clone() if hasattr(potential, "table") else None)


@pytest.mark.parametrize(
    ("method", "abstract_states", "step_cost", "start", "zero_terminal"),
    [
        ("SARSA", 1, False, "nonpositive", True),
        ("HRS", 1, False, "nonpositive", True),
        ("HRS", 4, False, "value", False),
        ("NRS", 1, False, "nonpositive", True),
        ("SARSA-RS", 1, False, "zero", True),
        ("HRS", 1, True, "zero", True),
        ("SARSA-RS", 1, True, "value", False),
        ("HRS-D", 1, False, "nonpositive", True),  # the within-segment term: the default potential
        ("HRS-D", 4, True, "value", False),
    ],
)
def test_fused_equals_torchrl(
    method: str, abstract_states: int, step_cost: bool, start: str, zero_terminal: bool
) -> None:
    results = {}
    for engine in ("torchrl", "fused"):
        env, agent = setup(
            method,
            n=12,
            abstract_states=abstract_states,
            max_steps=150,
            step_cost=step_cost,
            start=start,
            zero_terminal=zero_terminal,
        )
        records = run_episodes(env, agent, 25, engine=engine)
        results[engine] = (records, *_tables(env, agent))
    (a, qa, va), (b, qb, vb) = results["torchrl"], results["fused"]
    assert torch.equal(a.steps, b.steps) and torch.equal(a.returns, b.returns)
    assert torch.equal(a.success, b.success) and a.env_steps == b.env_steps
    # the TorchRL loop keeps stepping learners that have their episodes, the fused one stops them:
    # the tables agree for the learner that finished last (see test_learner_is_independent_of_its_batch)
    last = int(a.steps.sum(1).argmax())
    assert torch.equal(qa[last], qb[last])
    if va is not None:
        assert torch.equal(va[last], vb[last]) and va.abs().sum() > 0
    assert (a.steps == 150).any() and a.success.any()  # both truncations and goals happened
    if step_cost:
        assert torch.equal(a.returns, -(a.steps - a.success.long()).float())  # −1 per step, 0 at the goal


@pytest.mark.parametrize(("method", "abstract_states"), [("HRS", 4), ("NRS", 1), ("SARSA-RS", 1)])
def test_learner_is_independent_of_its_batch(method: str, abstract_states: int) -> None:
    """A learner's records and final tables depend on its seed only: the same in a batch of 12,
    in batches of 5 and 7, and alone (also with the TorchRL loop, which then stops with it)."""

    def run(learners: list[int], engine: str = "fused") -> tuple[torch.Tensor, ...]:
        env, agent = setup(
            method,
            n=12,
            abstract_states=abstract_states,
            max_steps=150,
            start="value",
            zero_terminal=False,
            learners=learners,
        )
        records = run_episodes(env, agent, 25, engine=engine)  # type: ignore[arg-type]
        q, v = _tables(env, agent)
        return records.steps, records.returns, q, (v if v is not None else torch.zeros(len(learners)))

    whole = run(list(range(12)))
    parts = [run([2, 9, 4, 0, 11]), run([1, 3, 5, 6, 7, 8, 10])]
    order = [2, 9, 4, 0, 11, 1, 3, 5, 6, 7, 8, 10]
    for whole_part, *split in zip(whole, *parts, strict=True):
        assert torch.equal(whole_part[order], torch.cat(split))
    alone = run([9], engine="torchrl")
    for whole_part, alone_part in zip(whole, alone, strict=True):
        assert torch.equal(whole_part[9:10], alone_part)
    assert torch.unique(whole[2].flatten(1), dim=0).shape[0] > 3  # the learners did differ


def test_fused_equals_torchrl_with_a_region_aggregation() -> None:
    """SARSA-RS over a ``StateAggregation.from_regions`` (two halves of the state index) shapes in
    the fused engine exactly as in the TorchRL loop (it once ran unshaped there)."""
    from torchrl_subgoal import Box, StateAggregation

    cfg = SARSA_PRESETS["released"]
    results = {}
    for engine in ("torchrl", "fused"):
        env = FourRoomsEnv(8, max_steps=150)
        halves = StateAggregation.from_regions([Box((25.5,), (26.0,), (0,)), Box((77.5,), (26.0,), (0,))], 1)
        shaping = shaping_transform(
            paper_methods("SARSA")["SARSA-RS"],
            env.batch_size,
            gamma=cfg.gamma,
            value_lr=cfg.value_lr,
            aggregation=halves,
            observation_key="cell",
        )
        learning_env = TransformedEnv(env, shaping)
        agent = SoftmaxSarsa(8, 104, 4, cfg, seed=learner_keys(7, 8))
        records = run_episodes(learning_env, agent, 25, engine=engine)  # type: ignore[arg-type]
        results[engine] = (records, *_tables(learning_env, agent))
    (a, qa, va), (b, qb, vb) = results["torchrl"], results["fused"]
    assert torch.equal(a.steps, b.steps) and torch.equal(a.returns, b.returns)
    last = int(a.steps.sum(1).argmax())
    assert va is not None and vb is not None
    assert torch.equal(qa[last], qb[last]) and torch.equal(va[last], vb[last])
    assert vb.abs().sum() > 0  # the potential was trained: the fused run was shaped


def test_fused_rejects_other_setups() -> None:
    from torchrl.envs import StepCounter

    env = TransformedEnv(FourRoomsEnv(2), StepCounter())
    agent = SoftmaxSarsa(2, 104, 4, SARSA_PRESETS["released"])
    with pytest.raises(TypeError, match="one SubgoalPotentialTransform"):
        run_episodes(env, agent, 1, engine="fused")
    with pytest.raises(ValueError, match="engine must be"):
        run_episodes(FourRoomsEnv(2), agent, 1, engine="jax")  # type: ignore[arg-type]
    with pytest.raises(TypeError, match="LineEnv with SoftmaxSarsa do not: use engine='torchrl'"):  # no kernel_state()
        run_episodes(LineEnv(2), agent, 1, engine="fused")
    with pytest.raises(
        TypeError,
        match=r"^LineState and SarsaKernelState do not implement the fused engine's "
        r"env_scratch, env_observe, env_step, env_reset, env_shaping_observation ",
    ):
        run_episodes(LineWithRecord(2), agent, 1, engine="fused")
    actor_critic = FourierActorCritic(2, torch.zeros(4), torch.ones(4), 3, AC_PRESETS["released"], seed=0)
    with pytest.raises(
        TypeError,
        match=r"the fused loop does not compile for GridKernelState with "
        r"ActorCriticKernelState",
    ):  # both registered, but not for each other
        run_episodes(FourRoomsEnv(2), actor_critic, 1, engine="fused")


class LineState(NamedTuple):
    position: np.ndarray


class LineWithRecord(LineEnv):
    """A record whose type implements none of the fused engine's steps."""

    def kernel_state(self, observation_key: str = "observation") -> LineState:
        return LineState(self.pos.numpy())


def pinball_setup(method: str, n: int, max_steps: int, preset: str = "released") -> tuple[object, object]:
    from torchrl_subgoal import Box, Circle, StateAggregation
    from torchrl_subgoal.envs import PinBallEnv
    from torchrl_subgoal.fused import AC_PRESETS, FourierActorCritic

    cfg = AC_PRESETS[preset]
    env = PinBallEnv(n, seed=3, max_steps=max_steps, step_penalty=-1.0, thrust_penalty=-5.0)
    patterns = [
        SubgoalSeries([Circle((0.2, 0.85), 0.04), Circle((0.25, 0.8), 0.04)]),
        SubgoalSeries([Circle((0.22, 0.9), 0.05)]),
    ]
    thirds = StateAggregation.from_regions([Box((c,), (1 / 6,), (0,)) for c in (1 / 6, 1 / 2, 5 / 6)], 4)
    shaping = shaping_transform(
        {**paper_methods("AC"), HRS_D.name: HRS_D}[method],
        env.batch_size,
        gamma=cfg.gamma,
        value_lr=cfg.value_lr,
        patterns=patterns,
        pattern_index=torch.arange(n) % 2,
        aggregation=thirds,
        eta=100.0,
        aggregation_key="observation",
    )
    spec = env.observation_spec["observation"]
    agent = FourierActorCritic(n, spec.low[0], spec.high[0], 5, cfg, seed=np.arange(n) + 5)
    return (TransformedEnv(env, shaping) if shaping is not None else env), agent


@pytest.mark.parametrize(
    ("method", "preset"),
    [
        ("AC", "released"),
        ("HRS", "released"),
        ("NRS", "released"),
        ("SARSA-RS", "released"),
        ("AC", "released-td"),
        ("HRS", "released-td"),
        ("HRS-D", "released"),
    ],
)
def test_pinball_fused_equals_torchrl(method: str, preset: str) -> None:
    """The Q-based actor-critic (released) and the TD-error one (released-td), with the classic penalties."""
    results = {}
    for engine in ("torchrl", "fused"):
        env, agent = pinball_setup(method, n=6, max_steps=120, preset=preset)
        records = run_episodes(env, agent, 4, engine=engine)
        results[engine] = (records, agent)
    (a, agent_a), (b, agent_b) = results["torchrl"], results["fused"]
    assert torch.equal(a.steps, b.steps) and torch.equal(a.returns, b.returns)
    assert torch.equal(a.success, b.success) and a.env_steps == b.env_steps
    last = int(a.steps.sum(1).argmax())  # the learner that finished last was never skipped
    assert (agent_a.w[last] == agent_b.w[last]).all() and (agent_a.theta[last] == agent_b.theta[last]).all()
    assert (a.steps == 120).any()
    if method != "AC":
        z = env.transform.potential  # shaping happened
        assert method == "NRS" or z.table.abs().sum() > 0

"""The fused engine: :func:`~torchrl_subgoal.agents.run_episodes` without per-step TorchRL calls.

Batched learning is limited by its slowest learner: every step of the batch
waits for it. In four-rooms, the slowest of 1,000 NRS learners needs about
360,000 sequential steps while the mean learner needs 60,000, and a
``step_and_maybe_reset`` call costs a fixed ~0.3-0.8 ms of TensorDict
bookkeeping whatever the batch size. This engine takes the *same objects* —
the env, its :class:`~torchrl_subgoal.SubgoalPotentialTransform` and the
learner — and runs them in one compiled loop that calls the same kernels in
the same order with the same random numbers, so its records, Q tables and
potentials are identical to the TorchRL loop's (``tests/agents/test_fused.py``)
while a step costs tens of microseconds.

Supported: :class:`~torchrl_subgoal.envs.FourRoomsEnv`, optionally in a
``TransformedEnv`` whose only transform is a
:class:`~torchrl_subgoal.SubgoalPotentialTransform` with a tabular or naive
potential (subgoal series or lookup aggregation), and
:class:`~torchrl_subgoal.agents.SoftmaxSarsa`. Anything else raises a
``TypeError`` that says so; use the TorchRL engine for it.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import torch
from torchrl.envs import EnvBase, TransformedEnv

from torchrl_subgoal import _kernels
from torchrl_subgoal.agents.loop import EpisodeRecords
from torchrl_subgoal.agents.sarsa import SoftmaxSarsa
from torchrl_subgoal.envs.four_rooms import FourRoomsEnv
from torchrl_subgoal.potentials import NaivePotential, TabularPotential
from torchrl_subgoal.subgoals import StateAggregation, SubgoalTables
from torchrl_subgoal.transform import SubgoalPotentialTransform

__all__ = ["run_episodes_fused"]


def _unwrap(env: EnvBase) -> tuple[FourRoomsEnv, SubgoalPotentialTransform | None]:
    if isinstance(env, FourRoomsEnv):
        return env, None
    if isinstance(env, TransformedEnv) and isinstance(env.base_env, FourRoomsEnv):
        transform = env.transform
        if isinstance(transform, SubgoalPotentialTransform):
            return env.base_env, transform
    raise TypeError(
        "the fused engine runs FourRoomsEnv, alone or with one SubgoalPotentialTransform; "
        f"got {env}. Use engine='torchrl' for other envs and transforms."
    )


def run_episodes_fused(
    env: EnvBase,
    agent: SoftmaxSarsa,
    episodes: int,
    *,
    progress: Callable[[int], None] | None = None,
    block: int = 2048,
) -> EpisodeRecords:
    """Same as ``run_episodes(env, agent, episodes)`` (see the module doc), compiled.

    Args:
        env: ``FourRoomsEnv`` or ``TransformedEnv(FourRoomsEnv, SubgoalPotentialTransform)``.
        agent: the SARSA learners; their Q tables are trained in place.
        episodes: episodes per learner.
        progress: called with learner-episodes finished, once per block of steps.
        block: steps per compiled call (random numbers are drawn per block).
    """
    base, shaping = _unwrap(env)
    if not isinstance(agent, SoftmaxSarsa):
        raise TypeError(f"the fused engine trains SoftmaxSarsa, got {type(agent).__name__}")
    if base.device.type != "cpu":
        raise TypeError("the fused engine runs on the CPU")
    td = agent.act(env.reset())  # the same start as the TorchRL loop, tables compiled
    n = max(1, base.batch_size.numel())
    action = td.get("action").reshape(-1).numpy().copy()

    if shaping is None:
        kind, observe_cell = _kernels.NO_SHAPING, False
        tables: dict[str, np.ndarray] = {}
        lookup, initial_z = np.zeros(1, np.int64), 0
        z = np.zeros((n, 1), np.int64)
        achieved = np.zeros((n, 1), np.bool_)
        r_h = np.zeros((n, 1), np.float32)
        k = np.zeros((n, 1), np.int64)
        table, shared, eta = np.zeros((0, 1), np.float32), False, 0.0
        gamma_shaping = value_gamma = value_lr = 0.0
        zero_terminal = False
    else:
        abstraction = shaping._abstraction
        observe_cell = shaping.observation_key == "cell"
        if shaping.observation_key not in ("cell", "observation"):
            raise TypeError(f"the fused engine reads 'cell' or 'observation', not {shaping.observation_key!r}")
        if isinstance(abstraction, SubgoalTables):
            kind, tables = _kernels.SUBGOAL_SHAPING, abstraction._np
            lookup, initial_z = np.zeros(1, np.int64), 0
        elif isinstance(abstraction, StateAggregation) and isinstance(abstraction.mapping, torch.Tensor):
            if observe_cell:
                raise TypeError("a lookup aggregation reads the state number ('observation')")
            kind, tables = _kernels.LOOKUP_SHAPING, {}
            lookup = abstraction.mapping.numpy()
            initial_z = int(lookup[base.start_state])
        else:
            raise TypeError("the fused engine needs a subgoal series or a lookup aggregation")
        potential = shaping.potential
        if isinstance(potential, TabularPotential):
            table = potential.table.detach().numpy().reshape(-1, potential.num_states)
            shared, eta = table.shape[0] == 1 and not potential.batch_shape, 0.0
        elif isinstance(potential, NaivePotential):
            table, shared, eta = np.zeros((0, 1), np.float32), False, potential.eta
        else:
            raise TypeError(f"the fused engine shapes with tabular or naive potentials, not {type(potential).__name__}")
        z = td.get("subgoal_index").reshape(n, 1).numpy().copy()
        r_h = td.get("subgoal_return").reshape(n, 1).numpy().copy()
        k = td.get("subgoal_steps").reshape(n, 1).numpy().copy()
        achieved = np.zeros((n, 1), np.bool_)
        gamma_shaping, value_gamma = shaping.gamma, shaping.value_gamma
        value_lr = shaping._value_lr if shaping.learning else 0.0
        zero_terminal = shaping.zero_terminal_potential
    empty3 = np.zeros((n, 1, 1), np.float32)
    lo = tables.get("lo", empty3)
    regions = (lo, tables.get("hi", empty3), tables.get("centre", empty3), tables.get("weight", empty3),
               tables.get("radius2", np.zeros((n, 1), np.float32)),
               tables.get("succ", np.zeros((n, 1, 1), np.bool_)))

    steps = torch.zeros(n, episodes, dtype=torch.long)
    returns = torch.zeros(n, episodes)
    success = torch.zeros(n, episodes, dtype=torch.bool)
    t_rec, ret, done_episodes = np.zeros(n, np.int64), np.zeros(n), np.zeros(n, np.int64)
    cfg = agent.config
    env_steps = 0
    while done_episodes.min() < episodes:
        uniforms = agent.rng.random((block, 2 * n))
        taken, filed = _kernels.sarsa_grid_run(
            base._state.numpy(), base._t.numpy(), base._transitions_np, base._cells_np,
            base.start_state, base.goal_state, base.max_steps,
            kind, observe_cell, *regions, lookup, initial_z,
            z, achieved, r_h, k, table, shared, eta, gamma_shaping, value_gamma, value_lr, zero_terminal,
            agent._q, agent.abstract_states, action, cfg.lr, cfg.gamma, 1.0 / cfg.temperature, uniforms,
            t_rec, ret, done_episodes, steps.numpy(), returns.numpy(), success.numpy(),
        )
        env_steps += taken
        if progress is not None and filed:
            progress(filed)
    return EpisodeRecords(steps, returns, success, env_steps)

"""The fused engine: :func:`~torchrl_subgoal.agents.run_episodes` without per-step TorchRL calls.

Batched learning is limited by its slowest learner: every step of the batch
waits for it. In four-rooms, the slowest of 1,000 NRS learners needs about
360,000 sequential steps while the mean learner needs 60,000, and a
``step_and_maybe_reset`` call costs a fixed ~0.3-0.8 ms of TensorDict
bookkeeping whatever the batch size. This engine takes the *same objects* —
the env, its :class:`~torchrl_subgoal.SubgoalPotentialTransform` and the
learner — and runs them in one compiled loop that calls, per learner, the
same kernels in the same order with the same random numbers (each learner
draws from its own stream), so its records are identical to the TorchRL
loop's (``tests/agents/test_fused.py``) while a learner-step costs tens of
nanoseconds (four-rooms) or a few microseconds (PinBall).

Supported: :class:`~torchrl_subgoal.envs.FourRoomsEnv` with
:class:`~torchrl_subgoal.agents.SoftmaxSarsa`, and
:class:`~torchrl_subgoal.envs.PinBallEnv` with
:class:`~torchrl_subgoal.agents.FourierActorCritic`, each alone or in a
``TransformedEnv`` whose only transform is a
:class:`~torchrl_subgoal.SubgoalPotentialTransform` with a tabular or naive
potential (a subgoal series, or a lookup / region aggregation). Anything else
raises a ``TypeError`` that says so; use the TorchRL engine for it.

Learners are independent (their own random streams and tables), so a learner
that has all its episodes leaves the loop and costs nothing more: the TorchRL
loop keeps stepping it until the slowest learner is done, which in
four-rooms' NRS tail and at PinBall's 10,000-step episodes dominates the cost.
Recorded episodes are identical in both engines; a learner's final tables
(Q, θ and w, its potential) are the ones at its last recorded episode, which
equal the TorchRL loop's for the learner that finished last (and for every
learner when it runs alone). Hence a potential shared by all learners is
refused here.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, TypeVar

import numba
import numpy as np
import torch
from tensordict import TensorDictBase
from torchrl.envs import EnvBase, TransformedEnv

from torchrl_subgoal import _kernels
from torchrl_subgoal.agents.actor_critic import FourierActorCritic
from torchrl_subgoal.agents.records import EpisodeRecords
from torchrl_subgoal.agents.sarsa import SoftmaxSarsa
from torchrl_subgoal.envs.four_rooms import FourRoomsEnv
from torchrl_subgoal.envs.pinball import PinBallEnv, step_ball
from torchrl_subgoal.potentials import NaivePotential, TabularPotential
from torchrl_subgoal.subgoals import StateAggregation, SubgoalTables
from torchrl_subgoal.transform import SubgoalPotentialTransform

__all__ = ["run_episodes_fused", "run_four_rooms_fused", "run_pinball_fused"]

B = TypeVar("B", bound=EnvBase)


def _unwrap(env: EnvBase, base_type: type[B]) -> tuple[B, SubgoalPotentialTransform | None]:
    """The ``base_type`` env and its shaping transform (``None`` if bare); a clear error for anything else."""
    if isinstance(env, base_type):
        return env, None
    if (
        isinstance(env, TransformedEnv)
        and isinstance(env.base_env, base_type)
        and isinstance(env.transform, SubgoalPotentialTransform)
    ):
        return env.base_env, env.transform
    raise TypeError(
        f"the fused engine runs {base_type.__name__}, alone or with one SubgoalPotentialTransform; "
        f"got {env}. Use engine='torchrl' for other envs and transforms."
    )


def _run_blocks(
    n: int,
    episodes: int,
    run_block: Callable[[tuple[np.ndarray, ...]], tuple[int, int]],
    progress: Callable[[int], None] | None,
) -> EpisodeRecords:
    """Call ``run_block(records)`` (one compiled block of steps) until every learner has
    ``episodes`` episodes; ``records`` are the arrays the kernels file episodes into."""
    steps = torch.zeros(n, episodes, dtype=torch.long)
    returns = torch.zeros(n, episodes)
    success = torch.zeros(n, episodes, dtype=torch.bool)
    done_episodes = np.zeros(n, np.int64)
    records = (np.zeros(n, np.int64), np.zeros(n), done_episodes, steps.numpy(), returns.numpy(), success.numpy())
    env_steps = 0
    while done_episodes.min() < episodes:
        taken, filed = run_block(records)
        env_steps += taken
        if progress is not None and filed:
            progress(filed)
    return EpisodeRecords(steps, returns, success, env_steps)


def _shaping_state(shaping: SubgoalPotentialTransform | None, td: TensorDictBase, n: int) -> dict[str, Any]:
    """The transform's tables, its per-learner state after reset and its potential, as arrays."""
    empty3 = np.zeros((n, 1, 1), np.float32)
    state: dict[str, Any] = {
        "kind": _kernels.NO_SHAPING,
        "regions": (np.zeros(n, np.int64), empty3, empty3, empty3, empty3, np.zeros((n, 1), np.float32),
                    np.zeros((n, 1, 1), np.bool_)),
        "lookup": np.zeros(1, np.int64),
        "z": np.zeros((n, 1), np.int64), "achieved": np.zeros((n, 1), np.bool_),
        "r_h": np.zeros((n, 1), np.float32), "k": np.zeros((n, 1), np.int64),
        "table": np.zeros((0, 1), np.float32), "shared": False, "eta": 0.0,
        "gamma": 0.0, "value_gamma": 0.0, "value_lr": 0.0, "zero_terminal": False, "start_mode": _kernels.START_VALUE,
        "z_start": np.zeros((n, 1), np.int64),
    }
    if shaping is None:
        return state
    abstraction = shaping.abstraction
    if isinstance(abstraction, SubgoalTables):
        t = abstraction._np
        state["kind"] = _kernels.SUBGOAL_SHAPING
        state["regions"] = (t["pattern"], t["lo"], t["hi"], t["centre"], t["weight"], t["radius2"], t["succ"])
    elif isinstance(abstraction, StateAggregation) and isinstance(abstraction.mapping, torch.Tensor):
        state["kind"] = _kernels.LOOKUP_SHAPING
        state["lookup"] = abstraction.mapping.numpy()
    elif not (isinstance(abstraction, StateAggregation) and abstraction.regions is not None):
        raise TypeError("the fused engine needs a subgoal series, a lookup or a region aggregation")
    potential = shaping.potential
    if isinstance(potential, TabularPotential):
        state["table"] = potential.table.detach().numpy().reshape(-1, potential.num_states)
        state["shared"] = state["table"].shape[0] == 1 and not potential.batch_shape
    elif isinstance(potential, NaivePotential):
        state["eta"] = potential.eta
    else:
        raise TypeError(f"the fused engine shapes with tabular or naive potentials, not {type(potential).__name__}")
    for key, name in (("z", "subgoal_index"), ("r_h", "subgoal_return"), ("k", "subgoal_steps")):
        state[key] = td.get(name).reshape(n, 1).numpy().copy()
    state["z_start"] = state["z"].copy()  # both envs start every episode in the same place
    state["gamma"], state["value_gamma"] = shaping.gamma, shaping.value_gamma
    state["value_lr"] = shaping._value_lr if shaping.learning else 0.0
    state["zero_terminal"] = shaping.zero_terminal_potential
    state["start_mode"] = shaping._start_mode
    return state


def run_episodes_fused(
    env: EnvBase,
    agent: SoftmaxSarsa | FourierActorCritic,
    episodes: int,
    *,
    progress: Callable[[int], None] | None = None,
) -> EpisodeRecords:
    """Same as ``run_episodes(env, agent, episodes)`` (see the module doc), compiled.

    Examples:
        >>> from torchrl_subgoal.agents import SARSA_PRESETS, SoftmaxSarsa
        >>> from torchrl_subgoal.envs import FourRoomsEnv
        >>> env = FourRoomsEnv(num_envs=8)
        >>> agent = SoftmaxSarsa(8, env.num_states, 4, SARSA_PRESETS["released"], seed=0)
        >>> run_episodes_fused(env, agent, 3).steps.shape
        torch.Size([8, 3])
    """
    base = env.base_env if isinstance(env, TransformedEnv) else env
    if base.device.type != "cpu":
        raise TypeError("the fused engine runs on the CPU")
    if isinstance(base, PinBallEnv) and isinstance(agent, FourierActorCritic):
        return run_pinball_fused(env, agent, episodes, progress=progress)
    if isinstance(base, FourRoomsEnv) and isinstance(agent, SoftmaxSarsa):
        return run_four_rooms_fused(env, agent, episodes, progress=progress)
    raise TypeError(
        "the fused engine runs FourRoomsEnv with SoftmaxSarsa or PinBallEnv with FourierActorCritic, "
        f"got {type(base).__name__} with {type(agent).__name__}; use engine='torchrl'"
    )


def run_four_rooms_fused(
    env: EnvBase,
    agent: SoftmaxSarsa,
    episodes: int,
    *,
    progress: Callable[[int], None] | None = None,
    block: int = 2048,
) -> EpisodeRecords:
    """The fused engine for four-rooms with SARSA (see :func:`run_episodes_fused`).

    Examples:
        >>> from torchrl_subgoal.agents import SARSA_PRESETS, SoftmaxSarsa
        >>> from torchrl_subgoal.envs import FourRoomsEnv
        >>> env = FourRoomsEnv(num_envs=8)
        >>> agent = SoftmaxSarsa(8, env.num_states, 4, SARSA_PRESETS["released"], seed=0)
        >>> records = run_four_rooms_fused(env, agent, 3)
        >>> records.steps.shape, bool((records.steps > 0).all())
        (torch.Size([8, 3]), True)
    """
    base, shaping = _unwrap(env, FourRoomsEnv)
    td = agent.act(env.reset())  # the same start as the TorchRL loop, tables compiled
    n = max(1, base.batch_size.numel())
    action = td.get("action").reshape(-1).numpy().copy()
    state = _shaping_state(shaping, td, n)
    observe_cell = shaping is not None and shaping.observation_key == "cell"
    if shaping is not None and shaping.observation_key not in ("cell", "observation"):
        raise TypeError(f"the fused engine reads 'cell' or 'observation', not {shaping.observation_key!r}")
    if state["kind"] == _kernels.LOOKUP_SHAPING and observe_cell:
        raise TypeError("a lookup aggregation reads the state number ('observation')")
    initial_z = int(state["lookup"][base.start_state]) if state["kind"] == _kernels.LOOKUP_SHAPING else 0
    _check_own_tables(state)
    cfg = agent.config
    grid, q = base.kernel_state(), agent.q.numpy()

    def run_block(records: tuple[np.ndarray, ...]) -> tuple[int, int]:
        return _kernels.sarsa_grid_run(
            *grid,
            base.start_state, base.goal_state, base.max_steps, base.goal_reward, base.step_reward,
            state["kind"], observe_cell, *state["regions"], state["lookup"], initial_z,
            state["z"], state["achieved"], state["r_h"], state["k"], state["table"],
            state["eta"], state["gamma"], state["value_gamma"], state["value_lr"], state["zero_terminal"],
            state["start_mode"], state["z_start"], q, agent.abstract_states, action, cfg.lr, cfg.gamma,
            1.0 / cfg.temperature, agent.streams, block, *records,
        )

    return _run_blocks(n, episodes, run_block, progress)


def _check_own_tables(state: dict[str, Any]) -> None:
    """The fused engine stops learners that have their episodes: each must own its potential table."""
    if state["shared"]:
        raise TypeError("the fused engine stops learners that have their episodes, so each needs its own "
                        "potential table (a TabularPotential with the env's batch shape); use engine='torchrl'")


# --------------------------------------------------------------------------- PinBall


@numba.njit(cache=True, nogil=True)
def _pinball_ac_run(
    # the env: state arrays updated in place, geometry, dynamics settings, the balls' random streams
    position, velocity, env_steps, start_x, start_y, edges, boxes, first_edge, ball_radius,
    target_x, target_y, target_radius, velocity_limit, max_steps, random_prob, goal_reward,
    step_penalty, thrust_penalty, env_streams,
    # the shaping transform
    shaping, pattern, lo, hi, centre, weight, radius2, succ, region_lo, region_hi, region_centre, region_weight,
    region_radius2, z, achieved, r_h, k, table, eta, gamma_shaping, value_gamma, value_lr, zero_terminal,
    start_mode, z_start,
    # the actor-critic learners and their random streams
    w, theta, phi, probs, action, low, inv_range, order, half, agent_streams, actor_lr, critic_lr, gamma, normalize,
    q_critic, max_steps_run,
    # records
    t_rec, ret, episode, steps_out, returns_out, success_out,
):
    """PinBall + shaping + actor-critic, per learner the TorchRL loop's kernels in its order (see module doc).

    Learners are independent (own streams, own tables), so each runs its
    steps of the block in one go (its tables stay in the core's cache) and
    one that has all its episodes stops. At most ``max_steps_run`` steps per
    learner; returns ``(steps of the longest-running learner, episodes filed)``:
    the steps the TorchRL loop's batch would take for the same block.
    """
    n_actions = 5
    obs = np.empty(4, np.float32)
    obs_next = np.empty(4, np.float64)
    obs_root = np.empty(4, np.float64)
    candidates = np.empty(edges.shape[0], np.int64)
    owners = np.empty(edges.shape[0], np.int64)
    scratch, phi_next = _kernels._feature_scratch(order, half, 4, theta.shape[2])
    max_episodes = steps_out.shape[1]
    active, n_active = _kernels._active_learners(episode, max_episodes)
    filed_total = 0
    taken = 0
    for i in range(n_active):
        b = active[i]
        steps = max_steps_run
        for step in range(max_steps_run):
            executed = _kernels._random_action(action[b], env_streams, b, random_prob, n_actions)
            px, py, vx, vy, terminated = step_ball(
                position[b, 0], position[b, 1], velocity[b, 0], velocity[b, 1], executed, edges, boxes, first_edge,
                ball_radius, target_x, target_y, target_radius, velocity_limit, candidates, owners)
            env_steps[b] += 1
            done = terminated or env_steps[b] >= max_steps
            r = goal_reward if terminated else 0.0
            if step_penalty != 0.0 or thrust_penalty != 0.0:
                r += thrust_penalty if executed != n_actions - 1 else step_penalty
            reward = np.float32(r)
            obs[0], obs[1], obs[2], obs[3] = px, py, vx, vy
            zb = z[b, 0]
            znb = zb
            if shaping == _kernels.SUBGOAL_SHAPING:
                znb = _kernels._advance_one(zb, obs, pattern[b], lo, hi, centre, weight, radius2, succ)
            elif shaping == _kernels.LOOKUP_SHAPING:
                znb = _kernels._first_region_one(zb, obs, region_lo, region_hi, region_centre, region_weight,
                                                 region_radius2)
            shaped, rh_new, k_new = _kernels._transform_learner(
                b, shaping, zb, znb, achieved, r_h, k, reward, done, terminated, table, eta, gamma_shaping,
                value_gamma, value_lr, zero_terminal, start_mode, z_start)
            _kernels._carry_learner(b, done, shaping, 0, zb, znb, z, achieved, r_h, k, rh_new, k_new)
            for d in range(4):
                obs_next[d] = obs[d]
            if done:  # the env and the transform reset this ball
                px, py, vx, vy = start_x, start_y, 0.0, 0.0
                env_steps[b] = 0
            position[b, 0], position[b, 1] = px, py
            velocity[b, 0], velocity[b, 1] = vx, vy
            obs_root[0] = np.float32(px)
            obs_root[1] = np.float32(py)
            obs_root[2] = np.float32(vx)
            obs_root[3] = np.float32(vy)
            if shaping == _kernels.LOOKUP_SHAPING and done:  # region aggregation: z of the reset state
                z[b, 0] = _kernels._first_region_one(z[b, 0], obs_root, region_lo, region_hi, region_centre,
                                                     region_weight, region_radius2)
            if q_critic:
                action[b] = _kernels._qac_learner(b, w, theta, phi, probs, action[b], shaped, obs_next, terminated,
                                                  done, obs_root, low, inv_range, order, half, agent_streams,
                                                  actor_lr, critic_lr, gamma, normalize, scratch, phi_next)
            else:
                action[b] = _kernels._ac_learner(b, w, theta, phi, probs, action[b], shaped, obs_next, terminated,
                                                 done, obs_root, low, inv_range, order, half, agent_streams,
                                                 actor_lr, critic_lr, gamma, normalize, scratch, phi_next)
            filed, finished = _kernels._record_and_stop(b, done, terminated, reward, t_rec, ret, episode, steps_out,
                                                        returns_out, success_out)
            filed_total += filed
            if finished:
                steps = step + 1
                break
        taken = max(taken, steps)
    return taken, filed_total


def run_pinball_fused(
    env: EnvBase,
    agent: FourierActorCritic,
    episodes: int,
    *,
    progress: Callable[[int], None] | None = None,
    block: int = 1024,
) -> EpisodeRecords:
    """The fused engine for :class:`~torchrl_subgoal.envs.PinBallEnv` with a
    :class:`~torchrl_subgoal.agents.FourierActorCritic` (see :func:`run_episodes_fused`).

    Examples:
        >>> from torchrl_subgoal.agents import AC_PRESETS
        >>> env = PinBallEnv(4, seed=0, max_steps=50)
        >>> spec = env.observation_spec["observation"]
        >>> agent = FourierActorCritic(4, spec.low[0], spec.high[0], 5, AC_PRESETS["released"], seed=0)
        >>> records = run_pinball_fused(env, agent, 2)
        >>> records.steps.shape, bool((records.steps <= 50).all())
        (torch.Size([4, 2]), True)
    """
    base, shaping = _unwrap(env, PinBallEnv)
    if base.physics.backend != "numba":
        raise TypeError("the fused engine needs PinBall's numba physics backend")
    td = agent.act(env.reset())
    n = base.batch_size.numel()
    action = td.get("action").reshape(-1).numpy().copy()
    region: dict[str, np.ndarray] = {k: np.zeros((1, 4), np.float32) for k in ("lo", "hi", "centre", "weight")}
    region["radius2"] = np.zeros(1, np.float32)
    state = _shaping_state(shaping, td, n)
    kind = state["kind"]
    if shaping is not None and isinstance(shaping.abstraction, StateAggregation):
        if shaping.abstraction.regions is None:
            raise TypeError("the fused PinBall engine needs a region aggregation (StateAggregation.from_regions)")
        region = shaping.abstraction.regions
        kind = _kernels.LOOKUP_SHAPING
    _check_own_tables(state)
    g = base.physics.geometry
    tx, ty, tr = g.target
    cfg = agent.config
    balls = base.kernel_state()

    def run_block(records: tuple[np.ndarray, ...]) -> tuple[int, int]:
        return _pinball_ac_run(
            *balls, base.start[0], base.start[1],
            g.edges, g.boxes, g.first_edge, g.ball_radius, tx, ty, tr, base.physics.velocity_limit,
            base.max_steps, base.random_action_prob, base.goal_reward, base.step_penalty, base.thrust_penalty,
            base.streams, kind, *state["regions"], region["lo"], region["hi"], region["centre"], region["weight"],
            region["radius2"], state["z"], state["achieved"], state["r_h"], state["k"], state["table"],
            state["eta"], state["gamma"], state["value_gamma"], state["value_lr"],
            state["zero_terminal"], state["start_mode"], state["z_start"], agent.w, agent.theta, agent.phi,
            agent.probs, action, agent.low, agent.inv_range, cfg.order, agent.half, agent.streams, cfg.actor_lr,
            cfg.critic_lr, cfg.gamma, cfg.normalize_lr, cfg.critic == "action", block, *records,
        )

    return _run_blocks(n, episodes, run_block, progress)

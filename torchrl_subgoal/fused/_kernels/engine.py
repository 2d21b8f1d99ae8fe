"""The fused engine's loop: env, shaping transform and learner stepped in one compiled call."""

from __future__ import annotations

import numba
import numpy as np

from torchrl_subgoal._kernels.regions import _in_region
from torchrl_subgoal._kernels.segments import segment_closeness, segment_value
from torchrl_subgoal._kernels.shaping import (
    NO_SHAPING,
    REGION_SHAPING,
    shaping_carry,
    shaping_start,
    shaping_step,
)
from torchrl_subgoal._kernels.steps import (
    env_observe,
    env_reset,
    env_scratch,
    env_shaping_observation,
    env_step,
    learner_scratch,
    learner_step,
)
from torchrl_subgoal.fused._kernels.records import _active_learners, _record_learner


@numba.njit(cache=True, nogil=True)
def fused_run(env, shaping, learner, action, max_steps_run, records):
    """Run steps of env + shaping + learner until every learner has its episodes (the fused engine's loop).

    ``env``, ``shaping`` and ``learner`` are the records the env, the shaping
    transform and the learner give (``kernel_state()``), updated in place; the
    env's and the learner's steps are their record types' implementations of
    the generic functions above. ``action[b]`` is learner ``b``'s next action;
    episodes are filed in ``records``
    (:class:`~torchrl_subgoal.fused.records.EpisodeArrays`).

    Per learner, the same kernels in the same order with the same random
    numbers as one iteration of :func:`torchrl_subgoal.fused.run_episodes`
    with a ``TransformedEnv(env, SubgoalPotentialTransform)``: env step,
    transform step, reset, learner step, records. Learners are independent
    (own streams, own tables), so each runs its steps of the block in one go
    (its tables stay in the core's cache) and one that has its episodes stops.
    At most ``max_steps_run`` steps per learner; returns ``(steps of the
    longest-running learner, episodes filed)``: the steps the TorchRL loop's
    batch would take for the same block.
    """
    env_buffers = env_scratch(env)
    learner_buffers = learner_scratch(learner)
    kind, regions, lookup, potential, learners, measured = shaping  # unpacked once (see the note above shaping_start)
    z, achieved, r_h, k, z_start = learners
    pattern, lo, hi, centre, weight, radius2, succ, offset = regions
    interpolate = measured.shape[0] > 0  # Φ(s, z): the within-segment term (_kernels.segments)
    near = np.zeros(lo.shape[1], np.float32)
    active, n_active = _active_learners(records.episode, records.steps.shape[1])
    t, ret, episode, steps_out, returns, success = records  # unpacked once (see the note above shaping_start)
    filed_total = 0
    taken = 0
    for i in range(n_active):
        b = active[i]
        steps = max_steps_run
        for step in range(max_steps_run):
            o, zb = env_observe(env, b, env_buffers), z[b, 0]
            if interpolate:  # the closeness at the step's start, before the env moves
                seen = env_shaping_observation(env, o, env_buffers)
                segment_closeness(pattern, lo, hi, centre, weight, radius2, succ, measured, b, zb, seen, near)
            o_next, reward, terminated, done = env_step(env, b, action[b], env_buffers)
            znb, shaped, rh_new, k_new = zb, reward, 0.0, 0
            if kind != NO_SHAPING:  # the transform's step
                seen = env_shaping_observation(env, o_next, env_buffers)
                if kind == REGION_SHAPING:  # region_search, written out (see its doc)
                    p = pattern[b] if pattern.shape[0] > 0 else 0
                    for j in range(lo.shape[1]):
                        if succ[p, zb, j] and _in_region(
                            seen, lo[p, j], hi[p, j], centre[p, j], weight[p, j], radius2[p, j]
                        ):
                            znb = j + offset
                            break
                else:
                    znb = lookup[np.int64(seen[0])]
                shaped, rh_new, k_new = shaping_step(
                    potential, b, zb, znb, achieved[b, 0], r_h[b, 0], k[b, 0], z_start[b, 0], reward, done, terminated
                )
                if interpolate:  # as the transform's compiled step adds it (add_segment_terms)
                    before = segment_value(potential.table, potential.ancestors, offset, b, b, zb, near)
                    after = np.float32(0.0)
                    if not (potential.zero_terminal and terminated):
                        segment_closeness(pattern, lo, hi, centre, weight, radius2, succ, measured, b, znb, seen, near)
                        after = segment_value(potential.table, potential.ancestors, offset, b, b, znb, near)
                    shaped = np.float32(shaped + (potential.gamma * after - before))
            o_root, z_reset = o_next, 0
            if done:  # the env and the transform reset this learner
                o_root = env_reset(env, b, env_buffers)
                z_reset = shaping_start(kind, regions, lookup, b, env_shaping_observation(env, o_root, env_buffers))
            if kind != NO_SHAPING or done:
                shaping_carry(z, achieved, r_h, k, b, done, z_reset, zb, znb, rh_new, k_new)
            action[b] = learner_step(
                learner, b, o, zb, action[b], shaped, o_next, znb, terminated, done, o_root, z[b, 0], learner_buffers
            )
            filed = (
                1 if _record_learner(b, done, terminated, reward, t, ret, episode, steps_out, returns, success) else 0
            )
            finished = episode[b] >= steps_out.shape[1]
            filed_total += filed
            if finished:
                steps = step + 1
                break
        taken = max(taken, steps)
    return taken, filed_total


#: :func:`fused_run` without numba's on-disk cache, for record types from outside this package: a cache
#: index names the record types it holds, and every process that loads it must import their modules.
fused_run_uncached = numba.njit(nogil=True)(fused_run.py_func)

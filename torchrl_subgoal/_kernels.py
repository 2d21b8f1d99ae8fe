"""Fused CPU kernels (numba) for the per-step work of the shaping transform.

Each kernel does, in one pass over the learner batch, what the eager torch
code in :mod:`torchrl_subgoal.subgoals` and :mod:`torchrl_subgoal.transform`
does with a few dozen small tensor operations; at the batch sizes used here
(10^2-10^4 learners) the cost of those is dominated by per-operation overhead,
which is why the transform would otherwise cost more than the environment.
The eager code stays the reference (and the path for other devices and neural
potentials); ``tests/test_kernels.py`` checks the two agree.

Arrays are numpy views of torch tensors (no copies); batch dimensions are
flattened, per-learner scalars have a trailing singleton.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numba
import numba.core.types
import numba.extending
import numpy as np

# --------------------------------------------------------------------------- random streams
#
# Every learner draws from its own counter-based stream, Philox4x32-10 (Salmon et al., "Parallel
# random numbers: as easy as 1, 2, 3", SC 2011), keyed by the learner's 64-bit seed: a draw
# depends on that seed and on how many draws the learner made before, never on the batch it
# runs in. A stream is a row ``[key, draws, spare, purpose]`` of a ``uint64`` array: ``purpose``
# (the third counter word) separates the streams of one seed (the agent's, the env's); each
# Philox block gives two 53-bit uniforms, the second kept in ``spare`` for the next draw.

_PHILOX_M0, _PHILOX_M1 = np.uint64(0xD2511F53), np.uint64(0xCD9E8D57)
_PHILOX_W0, _PHILOX_W1 = np.uint64(0x9E3779B9), np.uint64(0xBB67AE85)
_LOW32, _SHIFT32, _SHIFT11 = np.uint64(0xFFFFFFFF), np.uint64(32), np.uint64(11)
AGENT_STREAM, ENV_STREAM = 0, 1


@numba.njit(cache=True, nogil=True, inline="always")
def philox4x32(c0, c1, c2, c3, k0, k1):
    """Philox4x32-10 of the counter ``(c0..c3)`` under the key ``(k0, k1)`` (32-bit words in ``uint64``)."""
    for r in range(10):
        p0 = _PHILOX_M0 * c0
        p1 = _PHILOX_M1 * c2
        c0, c1, c2, c3 = (p1 >> _SHIFT32) ^ c1 ^ k0, p1 & _LOW32, (p0 >> _SHIFT32) ^ c3 ^ k1, p0 & _LOW32
        if r < 9:
            k0 = (k0 + _PHILOX_W0) & _LOW32
            k1 = (k1 + _PHILOX_W1) & _LOW32
    return c0, c1, c2, c3


@numba.njit(cache=True, nogil=True, inline="always")
def uniform(streams, b):
    """The next uniform in ``[0, 1)`` of learner ``b``'s stream (advances it)."""
    row = streams[b]
    draws = row[1]
    row[1] = draws + np.uint64(1)
    if draws & np.uint64(1):
        bits = row[2]
    else:
        block = draws >> np.uint64(1)
        key = row[0]
        c0, c1, c2, c3 = philox4x32(block & _LOW32, block >> _SHIFT32, row[3], np.uint64(0), key & _LOW32,
                                    key >> _SHIFT32)
        bits = (c0 << _SHIFT32) | c1
        row[2] = (c2 << _SHIFT32) | c3
    return np.float64(bits >> _SHIFT11) * (1.0 / 9007199254740992.0)


@numba.njit(cache=True, nogil=True)
def draw_uniforms(streams, count, out):
    """``out[b, i]``: the next ``count`` uniforms of every learner's stream."""
    for b in range(streams.shape[0]):
        for i in range(count):
            out[b, i] = uniform(streams, b)


def learner_keys(seed: int | Sequence[int] | np.ndarray | np.random.Generator, n: int) -> np.ndarray:
    """The 64-bit key of each of ``n`` learners' streams.

    ``seed`` is one key per learner (a sequence of ``n`` non-negative integers,
    e.g. from :func:`~torchrl_subgoal.experiments.sweep.learner_seeds`), or one
    integer from which learner ``b``'s key is derived with
    ``numpy.random.SeedSequence(seed, spawn_key=(b,))`` (so learner ``b`` of a
    batch of ten and of a batch of a thousand is the same learner), or a numpy
    generator that draws the keys.

    Examples:
        >>> learner_keys(0, 3)[:2].tolist() == learner_keys(0, 2).tolist()
        True
        >>> learner_keys([5, 6], 2).tolist()
        [5, 6]
    """
    if isinstance(seed, np.random.Generator):
        return seed.integers(0, 2**63, size=n, dtype=np.int64).astype(np.uint64)
    if isinstance(seed, (int, np.integer)):
        if seed < 0:
            raise ValueError(f"seed must be >= 0, got {seed}")
        return np.array([np.random.SeedSequence(int(seed), spawn_key=(b,)).generate_state(1, np.uint64)[0]
                         for b in range(n)], dtype=np.uint64)
    keys = np.asarray(seed)
    if keys.shape != (n,) or keys.dtype.kind not in "iu" or (keys < 0).any():
        raise ValueError(f"seed: give one non-negative integer per learner ({n}), got {keys.shape[0] if keys.ndim else 1}")
    return keys.astype(np.uint64)


def new_streams(keys: np.ndarray, purpose: int) -> np.ndarray:
    """Fresh streams ``[n, 4]`` (no draw made yet) for the keys, one per learner."""
    streams = np.zeros((keys.shape[0], 4), np.uint64)
    streams[:, 0] = keys
    streams[:, 3] = purpose
    return streams


@numba.njit(cache=True, nogil=True, inline="always")
def _in_region(o, lo, hi, centre, weight, radius2):
    """Whether the observation ``o`` lies in one region: ``lo ≤ o ≤ hi`` and
    ``Σ w (o − c)² ≤ r²`` over the entries with ``w ≠ 0``, all in float64.

    The comparisons are written so that NaN is never inside (as in torch), ±inf
    compares as a number, and an entry the region does not read (open bounds,
    zero weight) never matters, whatever it holds but NaN. ``SubgoalTables``'s
    torch path computes the same, in the same order, so the two agree exactly.
    """
    for d in range(lo.shape[0]):
        if not (o[d] >= lo[d] and o[d] <= hi[d]):
            return False
    if radius2 < np.inf:
        s = 0.0
        for d in range(lo.shape[0]):
            w = np.float64(weight[d])
            if w != 0.0:
                diff = np.float64(o[d]) - np.float64(centre[d])
                s += w * diff * diff
        return s <= radius2
    return True


@numba.njit(cache=True, nogil=True, inline="always")
def region_search(pattern, lo, hi, centre, weight, radius2, succ, offset, b, zb, o):
    """The abstract state of learner ``b`` after observing ``o`` in ``zb`` (the one region search),
    from the arrays of a :class:`~torchrl_subgoal.subgoals.RegionTables` (``pattern, …, offset = regions``).

    Learner ``b`` reads pattern ``pattern[b]`` (pattern 0 when ``pattern`` is
    empty); the first region ``j`` that ``succ[p, zb]`` allows and that contains
    ``o`` gives ``j + offset``; when none does, ``zb`` is kept. A subgoal series
    has ``offset`` 1 (``z`` counts the subgoals achieved), a region
    aggregation ``offset`` 0 and every region allowed. A loop unpacks the
    record once, before it (see the note above :func:`shaping_start`).
    :func:`fused_run` writes this search out in its loop body instead:
    calling it, inlined, with the seven arrays cost a shaped four-rooms
    learner-step ~40 ns (numba counts a reference per array argument).
    """
    p = pattern[b] if pattern.shape[0] > 0 else 0
    for j in range(lo.shape[1]):
        if succ[p, zb, j] and _in_region(o, lo[p, j], hi[p, j], centre[p, j], weight[p, j], radius2[p, j]):
            return j + offset
    return zb


@numba.njit(cache=True, nogil=True)
def advance_regions(regions, z, obs, z_out):
    """``z_out[b]``: abstract state after observing ``obs[b]`` in ``z[b]`` (:func:`region_search` per learner;
    ``regions``: a :class:`~torchrl_subgoal.subgoals.RegionTables`).

    The region tables are per pattern (``[P, J, D]``), which keeps them in
    cache whatever the number of learners. See :func:`_in_region` for how an
    observation is compared (NaN is never inside).
    """
    pattern, lo, hi, centre, weight, radius2, succ, offset = regions
    for b in range(z.shape[0]):
        z_out[b, 0] = region_search(pattern, lo, hi, centre, weight, radius2, succ, offset, b, z[b, 0], obs[b])


START_VALUE, START_ZERO, START_NONPOSITIVE = 0, 1, 2  # SubgoalPotentialTransform's start_potential
NO_SHAPING, REGION_SHAPING, LOOKUP_SHAPING = 0, 1, 2  # what a fused loop shapes with (ShapingKernelState.kind)


@numba.njit(cache=True, nogil=True, inline="always")
def _smdp_accumulate(zb, znb, rh, kb, reward, done, value_gamma):
    """One step of the SMDP return: ``(emit, r_h + γ_v^k r, γ_v^k, k + 1)``."""
    emit = znb != zb or done
    r = rh
    discount = 1.0
    if reward != 0.0 or emit:  # γ_v^k is needed only then
        discount = value_gamma**kb
        r += reward * discount
    return emit, r, discount, kb + 1


@numba.njit(cache=True, nogil=True, inline="always")
def _td_error(table, row, zb, znb, terminated, r, discount, value_gamma):
    """``δ = r_h + γ_v^k γ_v V(z') − V(z)`` (``V(z') = 0`` at a terminal state)."""
    v_next = 0.0 if terminated else table[row, znb]
    return r + discount * value_gamma * v_next - table[row, zb]


@numba.njit(cache=True, nogil=True, inline="always")
def _shaped_reward(table, row, zb, znb, achieved_prev, terminated, z_start, reward, eta, gamma, zero_terminal,
                   start_mode):
    """``r + γ Φ(z') − Φ(z)`` with the potential as it is now (see :func:`shape_step`)."""
    if table.shape[0] == 0:
        phi = eta if achieved_prev else 0.0
        phi_next = eta if znb != zb else 0.0
    else:
        phi = table[row, zb]
        phi_next = table[row, znb]
        if start_mode != START_VALUE:  # shift Φ so that the start's potential is 0 or ≤ 0
            v0 = table[row, z_start]
            c = v0 if start_mode == START_ZERO else max(v0, 0.0)
            phi -= c
            phi_next -= c
    if zero_terminal and terminated:
        phi_next = 0.0
    return reward + gamma * phi_next - phi


@numba.njit(cache=True, nogil=True, inline="always")
def _shape_learner(potential, row, zb, znb, achieved_prev, r_h, k, reward, done, terminated, z_start):
    """The shaping step of one learner whose potential is ``potential.table[row]`` (its own row):
    ``(shaped reward, r_h + γ_v^k r, k + 1, emit)``.

    Accumulates the SMDP return, applies the online TD update of the
    potential when the abstract state changes or the episode ends (``value_lr
    > 0``), then shapes the reward with the potential as it is now (see
    :func:`_shaped_reward`). ``potential`` is a
    :class:`~torchrl_subgoal.transform.PotentialKernelState`. The one
    implementation of the step: the fused loops (:func:`shaping_step`) and
    the transform's compiled path (:func:`shape_step`) call it.
    """
    emit, r, discount, kb = _smdp_accumulate(zb, znb, r_h, k, reward, done, potential.value_gamma)
    table = potential.table
    if emit and potential.value_lr > 0.0 and table.shape[0] > 0:
        delta = _td_error(table, row, zb, znb, terminated, r, discount, potential.value_gamma)
        if delta != 0.0:
            table[row, zb] += potential.value_lr * delta
    shaped = _shaped_reward(table, row, zb, znb, achieved_prev, terminated, z_start, reward, potential.eta,
                            potential.gamma, potential.zero_terminal, potential.start_mode)
    return shaped, r, kb, emit


@numba.njit(cache=True, nogil=True)
def shape_step(
    potential, shared, z, z_next, achieved_prev, r_h, k, reward, done, terminated, z_start,
    rh_out, k_out, reward_out, rh_acc_out, k_acc_out, emit_out,
):
    """Accumulate ``r_h, k``, update a tabular potential online, and shape the reward, for every row.

    ``potential`` is a :class:`~torchrl_subgoal.transform.PotentialKernelState`
    (its ``table`` is ``[B or 1, Z]``, empty for the naive potential
    ``Φ = eta · achieved``; ``value_lr = 0`` disables the update;
    ``start_mode`` shifts a table's potential by ``V(z_0)`` (``START_ZERO``)
    or ``max(V(z_0), 0)`` (``START_NONPOSITIVE``), with ``z_start[b]`` the
    abstract state row ``b``'s episode started in). ``rh_acc_out``,
    ``k_acc_out`` and ``emit_out`` (the SMDP transition's ``r_h``, ``k`` and
    mask) are filled when not empty.

    With a table per row this is :func:`_shape_learner` row by row, as in the
    fused loops. With one ``shared`` table the update is one SGD step of
    :class:`~torchrl_subgoal.SubgoalValueLoss` (reduction ``"sum"``) over the
    batch: every TD error is computed with the table as it was, then all are
    applied, then every reward is shaped; row by row would let a row's update
    change the next row's TD error.
    """
    n = z.shape[0]
    fill = emit_out.shape[0] > 0
    if shared:
        _shape_shared(potential, z, z_next, achieved_prev, r_h, k, reward, done, terminated, z_start, rh_out, k_out,
                      reward_out, rh_acc_out, k_acc_out, emit_out)
        return
    for b in range(n):
        shaped, r, kb, emit = _shape_learner(potential, b, z[b, 0], z_next[b, 0], achieved_prev[b, 0], r_h[b, 0],
                                             k[b, 0], reward[b, 0], done[b, 0], terminated[b, 0], z_start[b, 0])
        reward_out[b, 0] = shaped
        rh_out[b, 0] = 0.0 if emit else r
        k_out[b, 0] = 0 if emit else kb
        if fill:
            rh_acc_out[b, 0] = r
            k_acc_out[b, 0] = kb
            emit_out[b, 0] = emit


@numba.njit(cache=True, nogil=True, inline="always")
def _shape_shared(
    potential, z, z_next, achieved_prev, r_h, k, reward, done, terminated, z_start,
    rh_out, k_out, reward_out, rh_acc_out, k_acc_out, emit_out,
):
    """:func:`shape_step` with one table for every row: :func:`_shape_learner`'s three parts
    (accumulate and TD error; update; shape) each over the whole batch."""
    n = z.shape[0]
    table = potential.table
    learn = potential.value_lr > 0.0 and table.shape[0] > 0
    delta = np.zeros(n)
    for b in range(n):
        emit, r, discount, kb = _smdp_accumulate(z[b, 0], z_next[b, 0], r_h[b, 0], k[b, 0], reward[b, 0],
                                                 done[b, 0], potential.value_gamma)
        if emit and learn:
            delta[b] = _td_error(table, 0, z[b, 0], z_next[b, 0], terminated[b, 0], r, discount,
                                 potential.value_gamma)
        rh_out[b, 0] = 0.0 if emit else r
        k_out[b, 0] = 0 if emit else kb
        if emit_out.shape[0] > 0:
            rh_acc_out[b, 0] = r
            k_acc_out[b, 0] = kb
            emit_out[b, 0] = emit
    if learn:
        for b in range(n):
            if delta[b] != 0.0:
                table[0, z[b, 0]] += potential.value_lr * delta[b]
    for b in range(n):
        reward_out[b, 0] = _shaped_reward(table, 0, z[b, 0], z_next[b, 0], achieved_prev[b, 0], terminated[b, 0],
                                          z_start[b, 0], reward[b, 0], potential.eta, potential.gamma,
                                          potential.zero_terminal, potential.start_mode)


# --------------------------------------------------------------------------- shaping in a fused loop
#
# A fused loop unpacks a ShapingKernelState (torchrl_subgoal.transform) once, before its loop:
# ``kind, regions, lookup, potential, learners = shaping``, then ``z, achieved, r_h, k, z_start = learners``
# and ``pattern, …, offset = regions``. Per step, when ``kind != NO_SHAPING``, it advances the learner's
# abstract state (region_search when ``kind == REGION_SHAPING``, written out in fused_run, ``lookup`` when LOOKUP_SHAPING) and
# calls shaping_step, then shaping_carry with shaping_start's abstract state where the env reset,
# whatever the env and the learner. Each helper takes only the arrays or values it reads: numba counts
# references to every array of a tuple passed to an inlined function or read from it, and that per step
# cost a shaped four-rooms learner-step ~230 ns (the whole record to three helpers), then ~40 ns (the
# region record unpacked per step), against ~220 ns for the whole step without it.
# fused_run unpacks the EpisodeArrays once too: filing each step through the whole record cost ~35 ns
# of an unshaped four-rooms step (132 -> 98 ns, benchmarks/reproduction_speed.py --engine).


@numba.njit(cache=True, nogil=True, inline="always")
def shaping_start(kind, regions, lookup, b, o):
    """Learner ``b``'s abstract state at a reset to the observation ``o`` (a 1-D array): 0 for a
    subgoal series or no shaping, the region or lookup (``lookup[o[0]]``) of the reset state for an
    aggregation (``regions``: a :class:`~torchrl_subgoal.subgoals.RegionTables`; called only at resets)."""
    if kind == LOOKUP_SHAPING:
        return lookup[np.int64(o[0])]
    if kind == REGION_SHAPING and regions.offset == 0:  # a region aggregation
        pattern, lo, hi, centre, weight, radius2, succ, offset = regions
        return region_search(pattern, lo, hi, centre, weight, radius2, succ, offset, b, 0, o)
    return 0


@numba.njit(cache=True, nogil=True, inline="always")
def shaping_step(potential, b, zb, znb, achieved, r_h, k, z_start, reward, done, terminated):
    """The shaping transform's step for learner ``b`` in abstract state ``zb`` → ``znb`` (``achieved``,
    ``r_h``, ``k``, ``z_start``: its abstract-state values, read from an ``AbstractStates`` by the loop):
    ``(reward as float32, r_h', k')``, :func:`_shape_learner` with the learner's own table row."""
    shaped, r, kb, emit = _shape_learner(potential, b, zb, znb, achieved, r_h, k, reward, done, terminated, z_start)
    return np.float32(shaped), (0.0 if emit else r), (0 if emit else kb)


@numba.njit(cache=True, nogil=True, inline="always")
def shaping_carry(z, achieved, r_h, k, b, reset, z_reset, zb, znb, rh_new, k_new):
    """Learner ``b``'s abstract state for the next step (``z, achieved, r_h, k``: the arrays of an
    ``AbstractStates``): this step's outputs, or ``z_reset`` (:func:`shaping_start`) where ``reset``."""
    if reset:
        z[b, 0] = z_reset
        achieved[b, 0] = False
        r_h[b, 0] = 0.0
        k[b, 0] = 0
    else:
        achieved[b, 0] = znb != zb
        z[b, 0] = znb
        r_h[b, 0] = rh_new
        k[b, 0] = k_new


@numba.njit(cache=True, nogil=True, inline="always")
def _exp_shifted(values, top, scale, out):
    """``out[i] = exp((values[i] - top) · scale)`` (``values`` may be ``out``); returns their sum: the
    unnormalised softmax of both learners' policies (SARSA: ``scale = 1/τ``; actor-critic: 1, exact)."""
    total = 0.0
    for i in range(values.shape[0]):
        out[i] = np.exp((values[i] - top) * scale)
        total += out[i]
    return total


@numba.njit(cache=True, nogil=True, inline="always")
def _inverse_cdf(weights, threshold):
    """The first index whose running sum of ``weights`` exceeds ``threshold`` (the last index if none of the
    others does): both learners' action draw, ``threshold = u · Σ weights`` for a uniform ``u``."""
    n = weights.shape[0]
    acc = 0.0
    for i in range(n - 1):
        acc += weights[i]
        if acc > threshold:
            return i
    return n - 1


@numba.njit(cache=True, nogil=True, inline="always")
def _softmax_choice(q_row, inv_temperature, u, scratch):
    """Index drawn from softmax(q_row / τ) by inverse CDF with the uniform ``u``."""
    top = q_row[0]
    for i in range(1, q_row.shape[0]):
        top = max(top, q_row[i])
    total = _exp_shifted(q_row, top, inv_temperature, scratch)
    return _inverse_cdf(scratch, u * total)


@numba.njit(cache=True, nogil=True)
def softmax_sample(q, state, inv_temperature, streams, action_out):
    """``action_out[b] ~ softmax(q[b, state[b]] / τ)``, drawn from learner ``b``'s stream."""
    scratch = np.empty(q.shape[2])
    for b in range(q.shape[0]):
        action_out[b] = _softmax_choice(q[b, state[b]], inv_temperature, uniform(streams, b), scratch)


@numba.njit(cache=True, nogil=True, inline="always")
def _sarsa_learner(q_b, s, a, reward, s_next, terminated, done, s_root, streams, b, lr, gamma, inv_temperature,
                   scratch):
    """:func:`sarsa_step` for learner ``b`` (its table ``q_b``); returns its next action."""
    a2 = _softmax_choice(q_b[s_next], inv_temperature, uniform(streams, b), scratch)
    target = reward
    if not terminated:
        target += gamma * q_b[s_next, a2]
    q_b[s, a] += lr * (target - q_b[s, a])
    if done:
        a2 = _softmax_choice(q_b[s_root], inv_temperature, uniform(streams, b), scratch)
    return a2


@numba.njit(cache=True, nogil=True)
def sarsa_step(
    q, s, a, reward, s_next, terminated, done, s_root, streams, lr, gamma, inv_temperature, action_out
):
    """One SARSA(0) step per learner: draw ``a' ~ π(·|s')``, update ``Q(s, a)``, then
    the next action — ``a'``, or a fresh draw at the reset state where the episode ended.

    Learner ``b`` draws from its stream ``streams[b]``: one uniform for ``a'``,
    and one more for the reset draw when its episode ended.
    """
    scratch = np.empty(q.shape[2])
    for b in range(q.shape[0]):
        action_out[b] = _sarsa_learner(q[b], s[b], a[b], reward[b], s_next[b], terminated[b], done[b], s_root[b],
                                       streams, b, lr, gamma, inv_temperature, scratch)


@numba.njit(cache=True, nogil=True, inline="always")
def grid_step_one(grid, b, a):
    """Learner ``b``'s move ``a`` in a grid env (a :class:`~torchrl_subgoal.envs.four_rooms.GridKernelState`,
    updated in place): ``(next state, reward as float32, terminated, done)``."""
    s = grid.transitions[grid.state[b], a]
    grid.state[b] = s
    grid.t[b] += 1
    terminated = s == grid.goal
    done = terminated or grid.t[b] >= grid.max_steps
    return s, np.float32(grid.goal_reward if terminated else grid.step_reward), terminated, done


@numba.njit(cache=True, nogil=True, inline="always")
def grid_reset_one(grid, b):
    """Put learner ``b`` of a grid env back at the start."""
    grid.state[b] = grid.start
    grid.t[b] = 0


@numba.njit(cache=True, nogil=True)
def grid_step(grid, action, reward, terminated, truncated, cell_out):
    """Deterministic grid moves for a batch (:func:`grid_step_one` per learner): next state, step
    count, reward (``goal_reward`` on reaching the goal, else ``step_reward``), flags and cells."""
    for b in range(grid.state.shape[0]):
        s, r, term, done = grid_step_one(grid, b, action[b])
        terminated[b] = term
        truncated[b] = done and not term
        reward[b] = r
        cell_out[b, 0] = grid.cells[s, 0]
        cell_out[b, 1] = grid.cells[s, 1]


@numba.njit(cache=True, nogil=True)
def record_episodes(
    done, terminated, reward, t, ret, episode, steps_out, returns_out, success_out
):
    """Advance per-learner step and return counters; file finished episodes.

    Returns how many episodes were filed (those past ``steps_out.shape[1]`` are not).
    """
    filed = 0
    for b in range(done.shape[0]):
        if _record_learner(b, done[b], terminated[b], reward[b], t, ret, episode, steps_out, returns_out,
                           success_out):
            filed += 1
    return filed


@numba.njit(cache=True, nogil=True)
def grid_reset(grid, reset, cell_out):
    """Put the learners flagged in ``reset`` back at the start; write every learner's cell."""
    for b in range(grid.state.shape[0]):
        if reset[b]:
            grid_reset_one(grid, b)
        cell_out[b, 0] = grid.cells[grid.state[b], 0]
        cell_out[b, 1] = grid.cells[grid.state[b], 1]


@numba.njit(cache=True, nogil=True, inline="always")
def _active_learners(episode, max_episodes):
    """Indices of the learners that still lack episodes, and how many there are."""
    active = np.empty(episode.shape[0], np.int64)
    count = 0
    for b in range(episode.shape[0]):
        if episode[b] < max_episodes:
            active[count] = b
            count += 1
    return active, count


@numba.njit(cache=True, nogil=True, inline="always")
def _record_learner(b, done, terminated, reward, t, ret, episode, steps_out, returns_out, success_out):
    """:func:`record_episodes` for learner ``b``; whether it filed an episode."""
    t[b] += 1
    ret[b] += reward
    if not done:
        return False
    e = episode[b]
    filed = e < steps_out.shape[1]
    if filed:
        steps_out[b, e] = t[b]
        returns_out[b, e] = ret[b]
        success_out[b, e] = terminated
    episode[b] = e + 1
    t[b] = 0
    ret[b] = 0.0
    return filed


@numba.njit(cache=True, nogil=True, inline="always")
def _sarsa_row(sarsa, s, z):
    """The table row of state ``s`` in abstract state ``z``: ``s · Z + z`` (``s`` when ``Z = 1``)."""
    return s * sarsa.abstract_states + (z if sarsa.abstract_states > 1 else 0)


@numba.njit(cache=True, nogil=True, inline="always")
def sarsa_learner_step(sarsa, b, s, z, a, reward, s_next, z_next, terminated, done, s_root, z_root, scratch):
    """:func:`_sarsa_learner` for learner ``b`` of a :class:`~torchrl_subgoal.agents.sarsa.SarsaKernelState`,
    from states and abstract states; returns its next action."""
    return _sarsa_learner(sarsa.q[b], _sarsa_row(sarsa, s, z), a, reward, _sarsa_row(sarsa, s_next, z_next),
                          terminated, done, _sarsa_row(sarsa, s_root, z_root), sarsa.streams, b, sarsa.lr,
                          sarsa.gamma, sarsa.inv_temperature, scratch)


# --------------------------------------------------------------------------- the fused engine: one loop
#
# fused_run steps any env with any learner. It names neither: it calls the generic functions below, and
# an env's or a learner's record type (the NamedTuple its ``kernel_state()`` returns) joins the engine by
# implementing them, next to its own kernels, with ``@implements(generic, RecordType)`` (also
# importable from torchrl_subgoal.agents.fused, with the generic functions):
#
# - an env: env_scratch, env_observe, env_step, env_reset and env_shaping_observation
#   (envs/four_rooms.py for GridKernelState, envs/pinball.py for BallKernelState);
# - a learner: learner_scratch and learner_step (agents/sarsa.py, agents/actor_critic.py).
#
# Numba picks the implementation when it compiles the loop for the records' types (``overload``, on the
# record's class) and inlines it, so a call costs what the written-out step would. An implementation
# should not pass its whole record to further inlined helpers per step when the record holds many arrays:
# numba counts a reference per array each time (see the note above shaping_start). Numba's on-disk cache
# of fused_run is keyed on this file only: after editing an implementation elsewhere, delete this
# directory's ``__pycache__/_kernels.fused_run-*.nb[ic]``.


def implements(generic: Callable[..., Any], record: type) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    """Register ``impl`` as the compiled ``generic`` (one of the functions below) for records of type
    ``record``: the loop calls ``impl`` where ``generic``'s first argument is such a record.

    ``impl`` takes ``generic``'s arguments and is compiled with numba (inlined into :func:`fused_run`).

    Args:
        generic: the function implemented, e.g. :func:`env_step`.
        record: the ``NamedTuple`` class the implementation is for (dispatch is on the exact class).

    Examples:
        >>> from typing import NamedTuple
        >>> class Counter(NamedTuple):
        ...     count: np.ndarray
        >>> @implements(env_observe, Counter)
        ... def _observe(env, b, scratch):
        ...     return env.count[b]
        >>> @numba.njit
        ... def observe(env):
        ...     return env_observe(env, 1, ())
        >>> int(observe(Counter(np.array([3, 5]))))
        5
    """

    def register(impl: Callable[..., Any]) -> Callable[..., Any]:
        _IMPLEMENTED.setdefault(generic.__name__, set()).add(record)

        def typer(first: Any, *args: Any) -> Callable[..., Any] | None:
            if isinstance(first, numba.core.types.BaseNamedTuple) and first.instance_class is record:
                return impl
            return None

        numba.extending.overload(generic, inline="always", strict=False)(typer)
        return impl

    return register


_IMPLEMENTED: dict[str, set[type]] = {}  # generic function → the record types that implement it


def missing_steps(env: Any, learner: Any) -> list[str]:
    """The generic functions that ``env``'s or ``learner``'s record type does not implement (``[]``: they can
    run in :func:`fused_run`).

    Examples:
        >>> missing_steps((), ())[:2]
        ['env_scratch', 'env_observe']
    """
    wanted = [(name, env) for name in ENV_STEPS] + [(name, learner) for name in LEARNER_STEPS]
    return [name for name, record in wanted if type(record) not in _IMPLEMENTED.get(name, ())]


def _no_implementation(what: str, record: Any) -> TypeError:
    return TypeError(f"{what} runs only compiled, in fused_run, for the record types registered with "
                     f"torchrl_subgoal.agents.fused.implements; called from Python with {type(record).__name__}")


def env_scratch(env: Any) -> Any:
    """Scratch the env's steps share, allocated once per call of :func:`fused_run` (any numba value;
    ``()`` for none)."""
    raise _no_implementation("env_scratch", env)


def env_observe(env: Any, b: int, scratch: Any) -> Any:
    """Learner ``b``'s observation as its learner reads it (a state number, an array, …), before its step."""
    raise _no_implementation("env_observe", env)


def env_step(env: Any, b: int, a: int, scratch: Any) -> Any:
    """Learner ``b``'s env step with action ``a`` (``env`` updated in place):
    ``(observation, reward as float32, terminated, done)``, the observation as :func:`env_observe` gives it."""
    raise _no_implementation("env_step", env)


def env_reset(env: Any, b: int, scratch: Any) -> Any:
    """Put learner ``b`` back at the start of an episode; returns its observation there."""
    raise _no_implementation("env_reset", env)


def env_shaping_observation(env: Any, o: Any, scratch: Any) -> Any:
    """What the shaping transform reads of the observation ``o``: a 1-D array that a region aggregation or a
    subgoal series tests (its first entry is the index of a lookup aggregation)."""
    raise _no_implementation("env_shaping_observation", env)


def learner_scratch(learner: Any) -> Any:
    """Scratch of the learner's step, allocated once per call of :func:`fused_run`."""
    raise _no_implementation("learner_scratch", learner)


def learner_step(learner: Any, b: int, o: Any, z: int, a: int, reward: float, o_next: Any, z_next: int,
                 terminated: bool, done: bool, o_root: Any, z_root: int, scratch: Any) -> int:
    """Learner ``b``'s update for the transition ``(o, z) --a, reward--> (o_next, z_next)``; returns its next
    action, drawn at ``(o_root, z_root)`` (the reset state where ``done``, else ``(o_next, z_next)``).
    ``z`` are abstract states (0 unshaped) for a learner whose table has a row per state and abstract state."""
    raise _no_implementation("learner_step", learner)


ENV_STEPS = ("env_scratch", "env_observe", "env_step", "env_reset", "env_shaping_observation")
LEARNER_STEPS = ("learner_scratch", "learner_step")


@numba.njit(cache=True, nogil=True)
def fused_run(env, shaping, learner, action, max_steps_run, records):
    """Run steps of env + shaping + learner until every learner has its episodes (the fused engine's loop).

    ``env``, ``shaping`` and ``learner`` are the records the env, the shaping
    transform and the learner give (``kernel_state()``), updated in place; the
    env's and the learner's steps are their record types' implementations of
    the generic functions above. ``action[b]`` is learner ``b``'s next action;
    episodes are filed in ``records``
    (:class:`~torchrl_subgoal.agents.records.EpisodeArrays`).

    Per learner, the same kernels in the same order with the same random
    numbers as one iteration of :func:`torchrl_subgoal.agents.run_episodes`
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
    kind, regions, lookup, potential, learners = shaping  # unpacked once (see the note above shaping_start)
    z, achieved, r_h, k, z_start = learners
    pattern, lo, hi, centre, weight, radius2, succ, offset = regions
    active, n_active = _active_learners(records.episode, records.steps.shape[1])
    t, ret, episode, steps_out, returns, success = records  # unpacked once (see the note above shaping_start)
    filed_total = 0
    taken = 0
    for i in range(n_active):
        b = active[i]
        steps = max_steps_run
        for step in range(max_steps_run):
            o, zb = env_observe(env, b, env_buffers), z[b, 0]
            o_next, reward, terminated, done = env_step(env, b, action[b], env_buffers)
            znb, shaped, rh_new, k_new = zb, reward, 0.0, 0
            if kind != NO_SHAPING:  # the transform's step
                seen = env_shaping_observation(env, o_next, env_buffers)
                if kind == REGION_SHAPING:  # region_search, written out (see its doc)
                    p = pattern[b] if pattern.shape[0] > 0 else 0
                    for j in range(lo.shape[1]):
                        if succ[p, zb, j] and _in_region(seen, lo[p, j], hi[p, j], centre[p, j], weight[p, j],
                                                         radius2[p, j]):
                            znb = j + offset
                            break
                else:
                    znb = lookup[np.int64(seen[0])]
                shaped, rh_new, k_new = shaping_step(potential, b, zb, znb, achieved[b, 0], r_h[b, 0], k[b, 0],
                                                     z_start[b, 0], reward, done, terminated)
            o_root, z_reset = o_next, 0
            if done:  # the env and the transform reset this learner
                o_root = env_reset(env, b, env_buffers)
                z_reset = shaping_start(kind, regions, lookup, b, env_shaping_observation(env, o_root, env_buffers))
            if kind != NO_SHAPING or done:
                shaping_carry(z, achieved, r_h, k, b, done, z_reset, zb, znb, rh_new, k_new)
            action[b] = learner_step(learner, b, o, zb, action[b], shaped, o_next, znb, terminated, done, o_root,
                                     z[b, 0], learner_buffers)
            filed = 1 if _record_learner(b, done, terminated, reward, t, ret, episode, steps_out, returns,
                                         success) else 0
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


# --------------------------------------------------------------------------- linear actor-critics
#
# ``fastmath`` lets LLVM vectorise these loops (about 30% of a PinBall learner-step). The
# per-learner steps (:func:`_ac_learner`, :func:`_qac_learner`) are compiled once, not
# inlined, and called by both the batch kernels (the TorchRL loop) and the fused engine, so
# the two run the same machine code and agree bit for bit (``tests/agents/test_fused.py``).
# Numba's on-disk cache of a compiled caller is keyed on its own file only: after editing
# this file, delete the ``__pycache__/*.nb[ic]`` of ``agents/fused.py`` (or touch it).


@numba.njit(cache=True, nogil=True, inline="always", fastmath=True)
def _dot(x, y):
    """``Σ x[f] y[f]`` over ``x``'s length, as four interleaved partial sums."""
    n = x.shape[0]
    s0 = s1 = s2 = s3 = 0.0
    f = 0
    while f + 4 <= n:
        s0 += x[f] * y[f]
        s1 += x[f + 1] * y[f + 1]
        s2 += x[f + 2] * y[f + 2]
        s3 += x[f + 3] * y[f + 3]
        f += 4
    while f < n:
        s0 += x[f] * y[f]
        f += 1
    return (s0 + s1) + (s2 + s3)


@numba.njit(cache=True, nogil=True, inline="always", fastmath=True)
def _basis_exponentials(trig, k, first_dim, end_dim, out):
    """``out[:, i] = exp(iπ c_i · s̃)`` over dimensions ``[first_dim, end_dim)``, with ``c_i``
    the base-``k`` digits of ``i`` (last dimension least significant), as rows (re, im).

    Built from the last dimension up, each product ``(exponentials of the later dimensions)
    × trig[d, c]``, in place: the products of :func:`fourier_features`' definition in the
    same order, without recomputing a dimension's cosines for every entry.
    """
    out[0, 0], out[1, 0] = 1.0, 0.0
    size = 1
    for d in range(end_dim - 1, first_dim - 1, -1):
        for c in range(k - 1, -1, -1):  # c = 0 last: it overwrites the entries it reads
            cr, ci = trig[d, c, 0], trig[d, c, 1]
            for j in range(size):
                re, im = out[0, j], out[1, j]
                out[0, c * size + j], out[1, c * size + j] = re * cr - im * ci, re * ci + im * cr
        size *= k


@numba.njit(cache=True, nogil=True, inline="always", fastmath=True)
def fourier_features(obs, low, inv_range, order, half, scratch, out):
    """``out[f] = cos(π c_f · s̃)`` for every coefficient vector ``c_f ∈ {0..order}^D`` in
    lexicographic order, ``s̃ = clip((obs - low) / range, 0, 1)``.

    Computed as ``Re(A_a B_b)`` with ``f = a·M + b``: ``A`` are the complex
    exponentials of the first ``half`` dimensions, ``B`` of the others (one
    complex product per feature instead of a cosine); each is a product of the
    per-dimension ``exp(iπ c s̃_d)``, the powers of ``exp(iπ s̃_d)`` (one cosine
    and one sine per dimension; equal to ``cos(π c s̃_d)`` and ``sin(π c s̃_d)``
    within a few units in the last place).
    ``scratch`` is :func:`_feature_scratch`'s.
    """
    first, second, trig = scratch
    k = order + 1
    for d in range(obs.shape[0]):  # exp(iπ c s̃_d) = exp(iπ s̃_d)^c: two trigonometric calls per dimension
        x = min(max((obs[d] - low[d]) * inv_range[d], 0.0), 1.0)
        cr, ci = np.cos(np.pi * x), np.sin(np.pi * x)
        trig[d, 0, 0], trig[d, 0, 1] = 1.0, 0.0
        for c in range(1, k):
            re, im = trig[d, c - 1, 0], trig[d, c - 1, 1]
            trig[d, c, 0], trig[d, c, 1] = re * cr - im * ci, re * ci + im * cr
    _basis_exponentials(trig, k, 0, half, first)
    _basis_exponentials(trig, k, half, obs.shape[0], second)
    n_second = second.shape[1]
    second_re, second_im = second[0], second[1]  # rows: the loop below reads contiguous entries
    for a in range(first.shape[1]):
        first_re, first_im = first[0, a], first[1, a]
        out_a = out[a * n_second:(a + 1) * n_second]
        for b in range(n_second):
            out_a[b] = first_re * second_re[b] - first_im * second_im[b]


@numba.njit(cache=True, nogil=True, inline="always", fastmath=True)
def _policy(theta_b, phi, probs):
    """``probs`` ← softmax(θ φ)."""
    n_actions = theta_b.shape[0]
    top = -np.inf
    for a in range(n_actions):
        s = _dot(theta_b[a], phi)
        probs[a] = s
        top = max(top, s)
    total = _exp_shifted(probs, top, 1.0, probs)
    for a in range(n_actions):
        probs[a] /= total


@numba.njit(cache=True, nogil=True, inline="always", fastmath=True)
def _policy_sample(theta_b, phi, u, logits):
    """Draw from softmax(θ φ) with the uniform ``u``; ``logits`` is filled with π."""
    _policy(theta_b, phi, logits)
    return _inverse_cdf(logits, u)


@numba.njit(cache=True, nogil=True, fastmath=True)
def ac_act(theta, phi, probs, obs, low, inv_range, order, half, streams, action_out):
    """Features of ``obs`` into ``phi``, the policy into ``probs`` and a first action per learner
    (drawn from its stream; an empty ``streams`` draws nothing and leaves ``action_out`` alone)."""
    scratch, _ = _feature_scratch(order, half, obs.shape[1], 0)
    for b in range(obs.shape[0]):
        fourier_features(obs[b], low, inv_range, order, half, scratch, phi[b])
        if streams.shape[0] > 0:
            action_out[b] = _policy_sample(theta[b], phi[b], uniform(streams, b), probs[b])
        else:
            _policy(theta[b], phi[b], probs[b])


@numba.njit(cache=True, nogil=True, inline="always", fastmath=True)
def _feature_scratch(order, half, dim, n_features):
    """Scratch arrays of :func:`fourier_features` (the two halves' exponentials and the per-dimension
    ones) and a feature vector."""
    scratch = (np.empty((2, (order + 1) ** half)), np.empty((2, (order + 1) ** (dim - half))),
               np.empty((dim, order + 1, 2)))
    return scratch, np.empty(n_features)


@numba.njit(cache=True, nogil=True, inline="always", fastmath=True)
def _policy_gradient_step(theta_b, phi_b, probs_b, a_taken, lr, scale, signal):
    """``θ += lr · scale · signal · (1[a] − π(·|s)) ⊗ φ(s)``: the actor step of both actor-critics."""
    for a in range(theta_b.shape[0]):
        g = ((1.0 if a == a_taken else 0.0) - probs_b[a]) * lr * scale * signal
        for f in range(theta_b.shape[1]):
            theta_b[a, f] += g * phi_b[f]


@numba.njit(cache=True, nogil=True, fastmath=True)
def _ac_learner(b, w, theta, phi, probs, a_taken, reward, obs_next, terminated, done, obs_root, low, inv_range,
                order, half, streams, actor_lr, critic_lr, gamma, normalize, scratch, phi_next):
    """:func:`ac_step` for learner ``b``; returns its next action."""
    n_features = theta.shape[2]
    fourier_features(obs_next, low, inv_range, order, half, scratch, phi_next)
    value = _dot(w[b], phi[b])
    value_next = _dot(w[b], phi_next)
    norm2 = _dot(phi[b], phi[b])
    delta = reward - value
    if not terminated:
        delta += gamma * value_next
    scale = 1.0 / np.sqrt(norm2) if normalize else 1.0
    _policy_gradient_step(theta[b], phi[b], probs[b], a_taken, actor_lr, scale, delta)
    c = critic_lr * scale * delta
    for f in range(n_features):
        w[b, f] += c * phi[b, f]
    if done:
        fourier_features(obs_root, low, inv_range, order, half, scratch, phi_next)
    for f in range(n_features):
        phi[b, f] = phi_next[f]
    return _policy_sample(theta[b], phi[b], uniform(streams, b), probs[b])


@numba.njit(cache=True, nogil=True, fastmath=True)
def ac_step(
    w, theta, phi, probs, action, reward, obs_next, terminated, done, obs_root,
    low, inv_range, order, half, streams, actor_lr, critic_lr, gamma, normalize, action_out,
):
    """One-step actor-critic for every learner.

    ``δ = r + γ V(s') (1 − terminated) − V(s)``, ``V = w·φ``; ``w += α_c δ φ(s)``;
    ``θ += α_a δ (1[a] − π(·|s)) ⊗ φ(s)``; with ``normalize`` both rates are
    divided by ``‖φ(s)‖``. ``phi`` and ``probs`` hold each learner's ``φ(s)``
    and ``π(·|s)`` (computed when its action was drawn; ``θ`` has not changed
    since) and are replaced by those of the next state (``s'``, or the reset
    state where the episode ended), from which the next action is drawn with
    one uniform of the learner's stream.
    """
    scratch, phi_next = _feature_scratch(order, half, obs_next.shape[1], theta.shape[2])
    for b in range(w.shape[0]):
        action_out[b] = _ac_learner(b, w, theta, phi, probs, action[b], reward[b], obs_next[b], terminated[b],
                                    done[b], obs_root[b], low, inv_range, order, half, streams, actor_lr, critic_lr,
                                    gamma, normalize, scratch, phi_next)


@numba.njit(cache=True, nogil=True, fastmath=True)
def _qac_learner(b, w, theta, phi, probs, a_taken, reward, obs_next, terminated, done, obs_root, low, inv_range,
                 order, half, streams, actor_lr, critic_lr, gamma, normalize, scratch, phi_next):
    """:func:`qac_step` for learner ``b``; returns its next action."""
    n_features = theta.shape[2]
    fourier_features(obs_next, low, inv_range, order, half, scratch, phi_next)
    a_next = _policy_sample(theta[b], phi_next, uniform(streams, b), probs[b])
    q = _dot(w[b, a_taken * n_features:(a_taken + 1) * n_features], phi[b])
    q_next = _dot(w[b, a_next * n_features:(a_next + 1) * n_features], phi_next)
    norm2 = _dot(phi[b], phi[b])
    scale = 1.0 / np.sqrt(norm2) if normalize else 1.0
    _policy(theta[b], phi[b], probs[b])
    _policy_gradient_step(theta[b], phi[b], probs[b], a_taken, actor_lr, scale, q)
    delta = reward - q
    if not terminated:
        delta += gamma * q_next
    c = critic_lr * scale * delta
    first = np.uint64(a_taken * n_features)  # an unsigned index: no negative-index test, so the loop vectorises
    for f in range(n_features):
        w[b, first + np.uint64(f)] += c * phi[b, f]
    if done:
        fourier_features(obs_root, low, inv_range, order, half, scratch, phi_next)
        a_next = _policy_sample(theta[b], phi_next, uniform(streams, b), probs[b])
    for f in range(n_features):
        phi[b, f] = phi_next[f]
    return a_next


@numba.njit(cache=True, nogil=True, fastmath=True)
def qac_step(
    w, theta, phi, probs, action, reward, obs_next, terminated, done, obs_root,
    low, inv_range, order, half, streams, actor_lr, critic_lr, gamma, normalize, action_out,
):
    """One step of the Q-based actor-critic (the authors' released PinBall agent) for every learner.

    ``w`` is ``[B, A·F]``: a linear critic ``Q(s, a) = w_a·φ(s)`` per action.
    First ``a' ~ π(·|s')`` is drawn from the learner's stream (the policy
    before this step's update). Then, with ``q = Q(s, a)`` before the critic's
    update: ``θ += α_a q (1[a] − π(·|s)) ⊗ φ(s)`` (``π`` with the current
    ``θ``) and ``w_a += α_c δ φ(s)``, ``δ = r + γ Q(s', a') (1 − terminated) − q``;
    with ``normalize`` both rates are divided by ``‖φ(s)‖``. Where the episode
    ended the next action is drawn at the reset state with one more uniform.
    ``phi`` holds each learner's ``φ(s)`` and becomes that of the next state;
    ``probs`` is scratch.
    """
    scratch, phi_next = _feature_scratch(order, half, obs_next.shape[1], theta.shape[2])
    for b in range(w.shape[0]):
        action_out[b] = _qac_learner(b, w, theta, phi, probs, action[b], reward[b], obs_next[b], terminated[b],
                                     done[b], obs_root[b], low, inv_range, order, half, streams, actor_lr, critic_lr,
                                     gamma, normalize, scratch, phi_next)


@numba.njit(cache=True, nogil=True, inline="always")
def ac_learner_step(learner, b, a, reward, obs_next, terminated, done, obs_root, scratch, phi_next):
    """Learner ``b``'s step of an :class:`~torchrl_subgoal.agents.actor_critic.ActorCriticKernelState`
    (:func:`_qac_learner` or :func:`_ac_learner`, by its critic); returns its next action."""
    L = learner
    if L.q_critic:
        return _qac_learner(b, L.w, L.theta, L.phi, L.probs, a, reward, obs_next, terminated, done, obs_root, L.low,
                            L.inv_range, L.order, L.half, L.streams, L.actor_lr, L.critic_lr, L.gamma, L.normalize,
                            scratch, phi_next)
    return _ac_learner(b, L.w, L.theta, L.phi, L.probs, a, reward, obs_next, terminated, done, obs_root, L.low,
                       L.inv_range, L.order, L.half, L.streams, L.actor_lr, L.critic_lr, L.gamma, L.normalize,
                       scratch, phi_next)


@numba.njit(cache=True, nogil=True)
def random_actions(action, streams, probability, n_actions, out):
    """``out[b]``: ``action[b]``, or with ``probability`` a uniform one of ``n_actions``, drawn
    from ball ``b``'s stream (one uniform decides, a second picks the action when it is replaced)."""
    for b in range(action.shape[0]):
        out[b] = _random_action(action[b], streams, b, probability, n_actions)


@numba.njit(cache=True, nogil=True, inline="always")
def _random_action(a, streams, b, probability, n_actions):
    """The executed action of ball ``b`` (see :func:`random_actions`)."""
    if probability > 0.0 and uniform(streams, b) < probability:
        return min(int(uniform(streams, b) * n_actions), n_actions - 1)
    return a


@numba.njit(cache=True, nogil=True)
def advance_and_shape(
    regions, potential, shared, z, obs, achieved, r_h, k, reward, done, terminated, z_start,
    z_out, rh_out, k_out, reward_out, rh_acc_out, k_acc_out, emit_out,
):
    """:func:`advance_regions` then :func:`shape_step`: one transform step in one call.

    Returns ``False``, having written and updated nothing, when a ``reward`` is NaN or
    infinite or an ``obs`` entry is NaN (the caller then names the culprit); ``True`` otherwise.
    """
    if not finite_inputs(reward, obs):
        return False
    advance_regions(regions, z, obs, z_out)
    shape_step(potential, shared, z, z_out, achieved, r_h, k, reward, done, terminated, z_start, rh_out, k_out,
               reward_out, rh_acc_out, k_acc_out, emit_out)
    return True


@numba.njit(cache=True, nogil=True)
def finite_inputs(reward, obs):
    """Whether every ``reward[b, 0]`` is finite and no ``obs[b, j]`` is NaN (``±inf`` compares as a number)."""
    for b in range(reward.shape[0]):
        if not np.isfinite(reward[b, 0]):
            return False
    for b in range(obs.shape[0]):
        for j in range(obs.shape[1]):
            v = obs[b, j]
            if v != v:
                return False
    return True

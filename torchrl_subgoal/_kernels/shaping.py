"""The shaping transform's step, compiled: the SMDP return, the online update of a tabular potential and
the shaped reward (the torch functions of :mod:`torchrl_subgoal.transform.shaping` are the reference)."""

from __future__ import annotations

import numba
import numpy as np

from torchrl_subgoal._kernels.regions import advance_regions, region_search

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
def _learns_from(bootstrap_truncated, zb, znb, terminated):
    """Whether a closed transition trains ``V``: always, except a time-out inside ``z`` when
    ``bootstrap_truncated`` is off (it says how long the episode was allowed, not what ``z`` is worth)."""
    return bootstrap_truncated or terminated or znb != zb


@numba.njit(cache=True, nogil=True, inline="always")
def _expectile_weight(expectile, delta):
    """The expectile loss's weight of a TD error: ``2τ`` above the value, ``2(1 − τ)`` below; exactly 1
    for the mean (``τ = 0.5``), so that the mean's update is unchanged bit for bit."""
    if expectile == 0.5:
        return 1.0
    return 2.0 * expectile if delta > 0.0 else 2.0 * (1.0 - expectile)


@numba.njit(cache=True, nogil=True, inline="always")
def _trains(potential, zb, znb, terminated, emit):
    """Whether a step closes a transition that trains ``V(z)``: one closed, an update, a table, and not a
    time-out inside ``z`` left out."""
    return (
        emit
        and potential.value_lr > 0.0
        and potential.table.shape[0] > 0
        and _learns_from(potential.bootstrap_truncated, zb, znb, terminated)
    )


@numba.njit(cache=True, nogil=True, inline="always")
def _td_step(potential, row, zb, znb, terminated, emit, r, discount):
    """The TD error a closed transition trains ``V(z)`` of ``table[row]`` by (0 when it trains nothing:
    no transition closed, no update, a naive potential, or a time-out inside ``z`` not bootstrapped). An
    ``achievement_reward`` is added to the target where the transition reached the next subgoal, discounted
    as a reward of its last step."""
    if _trains(potential, zb, znb, terminated, emit):
        if potential.achievement_reward != 0.0 and znb != zb:
            r += potential.achievement_reward * discount
        return _td_error(potential.table, row, zb, znb, terminated, r, discount, potential.value_gamma)
    return 0.0


@numba.njit(cache=True, nogil=True, inline="always")
def _td_increment(potential, delta, row, z):
    """The online TD update's step of ``V(z)`` of ``table[row]``, ``α w δ`` (``w``: the expectile's weight):
    ``α = α_v``, or with a ``prior_weight`` ``k`` the larger of ``α_v`` and ``1 / (k + n)``, ``n`` the entry's
    count of updates, this one included (:func:`_count`). The one place the kernels say how a potential
    changes (:meth:`torchrl_subgoal.ValueUpdate.step` is its torch reference)."""
    lr = potential.value_lr
    if potential.prior_weight > 0.0:
        lr = max(lr, 1.0 / (potential.prior_weight + potential.updates[row, z]))
    return lr * _expectile_weight(potential.expectile, delta) * delta


@numba.njit(cache=True, nogil=True, inline="always")
def _count(potential, row, zb, znb, terminated, emit):
    """With a ``prior_weight``, count a transition that trains ``V(z)`` of ``table[row]`` (also one whose TD
    error is 0: the step size depends on the transitions seen, not on what they changed)."""
    if potential.prior_weight > 0.0 and _trains(potential, zb, znb, terminated, emit):
        potential.updates[row, zb] += 1.0


@numba.njit(cache=True, nogil=True, inline="always")
def _table_value(table, ancestors, row, b, z):
    """``V(z)`` as the shaping reads it from ``table[row]``: the entry, or with a monotone table
    (``ancestors`` not empty) the largest entry of ``z`` and of the states before it in row ``b``'s
    series (``ancestors[b, z, a]``; :func:`torchrl_subgoal.transform.shaping.ancestral_max`)."""
    if ancestors.shape[0] == 0:
        return table[row, z]
    best = -np.inf
    for a in range(ancestors.shape[2]):
        if ancestors[b, z, a] and table[row, a] > best:
            best = table[row, a]
    return best


@numba.njit(cache=True, nogil=True, inline="always")
def _shaped_reward(
    table, ancestors, row, b, zb, znb, achieved_prev, terminated, z_start, reward, eta, gamma, zero_terminal, start_mode
):
    """``r + γ Φ(z') − Φ(z)`` with the potential as it is now (see :func:`shape_step`); ``row`` is the
    table's row, ``b`` the batch row (whose series ``ancestors`` describes)."""
    if table.shape[0] == 0:
        phi = eta if achieved_prev else 0.0
        phi_next = eta if znb != zb else 0.0
    else:
        phi = _table_value(table, ancestors, row, b, zb)
        phi_next = _table_value(table, ancestors, row, b, znb)
        if start_mode != START_VALUE:  # shift Φ so that the start's potential is 0 or ≤ 0
            v0 = _table_value(table, ancestors, row, b, z_start)
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
    :class:`~torchrl_subgoal.transform.setup.PotentialKernelState`. The one
    implementation of the step: the fused loops (:func:`shaping_step`) and
    the transform's compiled path (:func:`shape_step`) call it.
    """
    emit, r, discount, kb = _smdp_accumulate(zb, znb, r_h, k, reward, done, potential.value_gamma)
    table = potential.table
    delta = _td_step(potential, row, zb, znb, terminated, emit, r, discount)
    _count(potential, row, zb, znb, terminated, emit)
    if delta != 0.0:
        table[row, zb] += _td_increment(potential, delta, row, zb)
    shaped = _shaped_reward(
        table,
        potential.ancestors,
        row,
        row,
        zb,
        znb,
        achieved_prev,
        terminated,
        z_start,
        reward,
        potential.eta,
        potential.gamma,
        potential.zero_terminal,
        potential.start_mode,
    )
    return shaped, r, kb, emit


@numba.njit(cache=True, nogil=True)
def shape_step(
    potential,
    group,
    z,
    z_next,
    achieved_prev,
    r_h,
    k,
    reward,
    done,
    terminated,
    z_start,
    rh_out,
    k_out,
    reward_out,
    rh_acc_out,
    k_acc_out,
    emit_out,
):
    """Accumulate ``r_h, k``, update a tabular potential online, and shape the reward, for every row.

    ``potential`` is a :class:`~torchrl_subgoal.transform.setup.PotentialKernelState`
    (its ``table`` is ``[B or 1, Z]``, empty for the naive potential
    ``Φ = eta · achieved``; ``value_lr = 0`` disables the update;
    ``start_mode`` shifts a table's potential by ``V(z_0)`` (``START_ZERO``)
    or ``max(V(z_0), 0)`` (``START_NONPOSITIVE``), with ``z_start[b]`` the
    abstract state row ``b``'s episode started in). ``rh_acc_out``,
    ``k_acc_out`` and ``emit_out`` (the SMDP transition's ``r_h``, ``k`` and
    mask) are filled when not empty.

    With a table per row (``group = 0``) this is :func:`_shape_learner` row by
    row, as in the fused loops. With ``group > 0`` rows share tables: rows
    ``b`` read and train ``table[b // group]`` (one table for every row:
    ``group ≥`` the rows), and each table's update is one SGD step of
    :class:`~torchrl_subgoal.SubgoalValueLoss` (reduction ``"sum"``) over its
    rows: every TD error is computed with the tables as they were, then all
    are applied, then every reward is shaped; row by row would let a row's
    update change the next row's TD error.
    """
    n = z.shape[0]
    fill = emit_out.shape[0] > 0
    if group > 0:
        _shape_shared(
            potential,
            group,
            z,
            z_next,
            achieved_prev,
            r_h,
            k,
            reward,
            done,
            terminated,
            z_start,
            rh_out,
            k_out,
            reward_out,
            rh_acc_out,
            k_acc_out,
            emit_out,
        )
        return
    for b in range(n):
        shaped, r, kb, emit = _shape_learner(
            potential,
            b,
            z[b, 0],
            z_next[b, 0],
            achieved_prev[b, 0],
            r_h[b, 0],
            k[b, 0],
            reward[b, 0],
            done[b, 0],
            terminated[b, 0],
            z_start[b, 0],
        )
        reward_out[b, 0] = shaped
        rh_out[b, 0] = 0.0 if emit else r
        k_out[b, 0] = 0 if emit else kb
        if fill:
            rh_acc_out[b, 0] = r
            k_acc_out[b, 0] = kb
            emit_out[b, 0] = emit


@numba.njit(cache=True, nogil=True, inline="always")
def _shape_shared(
    potential,
    group,
    z,
    z_next,
    achieved_prev,
    r_h,
    k,
    reward,
    done,
    terminated,
    z_start,
    rh_out,
    k_out,
    reward_out,
    rh_acc_out,
    k_acc_out,
    emit_out,
):
    """:func:`shape_step` with rows sharing tables (row ``b`` reads ``table[b // group]``):
    :func:`_shape_learner`'s three parts (accumulate and TD error; update; shape) each over the whole batch."""
    n = z.shape[0]
    table = potential.table
    delta = np.zeros(n)
    for b in range(n):
        emit, r, discount, kb = _smdp_accumulate(
            z[b, 0], z_next[b, 0], r_h[b, 0], k[b, 0], reward[b, 0], done[b, 0], potential.value_gamma
        )
        delta[b] = _td_step(potential, b // group, z[b, 0], z_next[b, 0], terminated[b, 0], emit, r, discount)
        _count(potential, b // group, z[b, 0], z_next[b, 0], terminated[b, 0], emit)
        rh_out[b, 0] = 0.0 if emit else r
        k_out[b, 0] = 0 if emit else kb
        if emit_out.shape[0] > 0:
            rh_acc_out[b, 0] = r
            k_acc_out[b, 0] = kb
            emit_out[b, 0] = emit
    for b in range(n):  # every TD error and count with the tables as they were, then every update
        if delta[b] != 0.0:
            table[b // group, z[b, 0]] += _td_increment(potential, delta[b], b // group, z[b, 0])
    for b in range(n):
        reward_out[b, 0] = _shaped_reward(
            table,
            potential.ancestors,
            b // group,
            b,
            z[b, 0],
            z_next[b, 0],
            achieved_prev[b, 0],
            terminated[b, 0],
            z_start[b, 0],
            reward[b, 0],
            potential.eta,
            potential.gamma,
            potential.zero_terminal,
            potential.start_mode,
        )


# --------------------------------------------------------------------------- shaping in a fused loop
#
# A fused loop unpacks a ShapingKernelState (torchrl_subgoal.fused.shaping_record) once, before its loop:
# ``kind, regions, lookup, potential, learners, measured = shaping``, then ``z, achieved, r_h, k, z_start = learners``
# and ``pattern, …, offset = regions``. Per step, when ``kind != NO_SHAPING``, it advances the learner's
# abstract state (region_search when ``kind == REGION_SHAPING``, written out in fused_run, ``lookup`` when
# LOOKUP_SHAPING) and
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


@numba.njit(cache=True, nogil=True)
def advance_and_shape(
    regions,
    potential,
    group,
    z,
    obs,
    achieved,
    r_h,
    k,
    reward,
    done,
    terminated,
    z_start,
    z_out,
    rh_out,
    k_out,
    reward_out,
    rh_acc_out,
    k_acc_out,
    emit_out,
):
    """:func:`advance_regions` then :func:`shape_step`: one transform step in one call.

    Returns ``False``, having written and updated nothing, when a ``reward`` is NaN or
    infinite or an ``obs`` entry is NaN (the caller then names the culprit); ``True`` otherwise.
    """
    if not finite_inputs(reward, obs):
        return False
    advance_regions(regions, z, obs, z_out)
    shape_step(
        potential,
        group,
        z,
        z_out,
        achieved,
        r_h,
        k,
        reward,
        done,
        terminated,
        z_start,
        rh_out,
        k_out,
        reward_out,
        rh_acc_out,
        k_acc_out,
        emit_out,
    )
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

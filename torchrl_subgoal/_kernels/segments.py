"""The within-segment term of an interpolating potential, compiled (:mod:`torchrl_subgoal.transform.segments` is
the torch reference: the same closeness, in float64, and the same term, in float32)."""

from __future__ import annotations

import numba
import numpy as np

from torchrl_subgoal._kernels.shaping import _table_value


@numba.njit(cache=True, nogil=True, inline="always")
def _closeness(o, lo, hi, centre, weight, radius2):
    """``1 / (1 + d)`` of the observation ``o`` to one region: ``d`` the box excess in half-widths and the
    circle excess in radii (entries the region does not bound or weigh are never read)."""
    d2 = 0.0
    for d in range(lo.shape[0]):
        low, high = lo[d], hi[d]
        if np.isfinite(low) and np.isfinite(high):
            half = np.float32((high - low) / np.float32(2.0))
            if not half > 0.0:
                half = np.float32(1.0)
            x = np.float64(o[d])
            excess = max(np.float64(low) - x, x - np.float64(high), 0.0)
            d2 += (excess / np.float64(half)) ** 2
    if radius2 < np.inf:
        s = 0.0
        for d in range(lo.shape[0]):
            w = np.float64(weight[d])
            if w > 0.0:
                diff = np.float64(o[d]) - np.float64(centre[d])
                s += w * diff * diff
        radius = np.float64(np.sqrt(np.float32(radius2)))
        scale = radius if radius > 0.0 else 1.0
        d2 += (max(np.sqrt(s) - radius, 0.0) / scale) ** 2
    return np.float32(1.0 / (1.0 + np.sqrt(d2)))


@numba.njit(cache=True, nogil=True, inline="always")
def segment_closeness(pattern, lo, hi, centre, weight, radius2, succ, measured, b, z, o, near):
    """``near[j]``: the closeness of learner ``b``'s observation ``o`` to each measured region ``j`` that counts
    from ``z`` (0 for the others); the region arrays are a :class:`~torchrl_subgoal.subgoals.RegionTables`'
    (per pattern), ``measured`` is ``[B, J]`` (never true for padding, a condition or a state)."""
    p = pattern[b] if pattern.shape[0] > 0 else 0
    for j in range(lo.shape[1]):
        near[j] = 0.0
        if succ[p, z, j] and measured[b, j]:
            near[j] = _closeness(o, lo[p, j], hi[p, j], centre[p, j], weight[p, j], radius2[p, j])


@numba.njit(cache=True, nogil=True, inline="always")
def segment_value(table, ancestors, offset, row, b, z, near):
    """The term at ``z`` from the closeness ``near`` (:func:`segment_closeness`) and ``table[row]`` as the shaping
    reads it: ``max_j (V(z_j) − V(z))⁺ · near[j]``, in float32."""
    here = np.float32(_table_value(table, ancestors, row, b, z))
    last = table.shape[1] - 1
    term = np.float32(0.0)
    for j in range(near.shape[0]):
        if near[j] > 0.0:
            step_up = np.float32(_table_value(table, ancestors, row, b, min(j + offset, last))) - here
            value = np.float32(step_up * near[j])
            if value > term:
                term = value
    return term


@numba.njit(cache=True, nogil=True)
def add_segment_terms(regions, measured, potential, group, z, z_next, obs_before, obs, terminated, reward_out):
    """Add ``γ t(s', z') − t(s, z)`` to each row's shaped reward (``t``: the within-segment term, read from the
    potential's table as it is after the step's update; ``t(s', z') = 0`` at a terminal state when ``Φ`` is 0
    there). ``measured``: ``[B, J]``, the regions a distance is measured to."""
    pattern, lo, hi, centre, weight, radius2, succ, offset = regions
    table, ancestors = potential.table, potential.ancestors
    near = np.zeros(lo.shape[1], np.float32)
    for b in range(z.shape[0]):
        row = b // group if group > 0 else b
        segment_closeness(pattern, lo, hi, centre, weight, radius2, succ, measured, b, z[b, 0], obs_before[b], near)
        before = segment_value(table, ancestors, offset, row, b, z[b, 0], near)
        after = np.float32(0.0)
        if not (potential.zero_terminal and terminated[b, 0]):
            segment_closeness(pattern, lo, hi, centre, weight, radius2, succ, measured, b, z_next[b, 0], obs[b], near)
            after = segment_value(table, ancestors, offset, row, b, z_next[b, 0], near)
        reward_out[b, 0] += potential.gamma * after - before

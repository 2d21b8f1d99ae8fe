"""The region search: which subgoal region (or aggregation region) an observation lies in."""

from __future__ import annotations

import numba
import numpy as np


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


@numba.njit(cache=True, nogil=True)
def advance_with_conditions(regions, condition, hits, z, obs, z_out):
    """:func:`advance_regions` for subgoal series with conditions: subgoal ``j`` of pattern ``p`` is the
    condition ``c = condition[p, j]`` when ``c ≥ 0`` (achieved by learner ``b`` where ``hits[b, c]``),
    else its region (``obs`` may have no entries when no subgoal is a region)."""
    pattern, lo, hi, centre, weight, radius2, succ, offset = regions
    for b in range(z.shape[0]):
        p = pattern[b] if pattern.shape[0] > 0 else 0
        zb = z[b, 0]
        z_out[b, 0] = zb
        for j in range(lo.shape[1]):
            if not succ[p, zb, j]:
                continue
            c = condition[p, j]
            if (
                hits[b, c]
                if c >= 0
                else _in_region(obs[b], lo[p, j], hi[p, j], centre[p, j], weight[p, j], radius2[p, j])
            ):
                z_out[b, 0] = j + offset
                break

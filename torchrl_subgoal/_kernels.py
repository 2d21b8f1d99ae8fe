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

import numba
import numpy as np


@numba.njit(cache=True, nogil=True)
def advance_regions(z, obs, lo, hi, centre, weight, radius2, succ, z_out):
    """``z_out[b]``: abstract state after observing ``obs[b]`` in ``z[b]`` (see SubgoalTables)."""
    n, n_nodes, dim = lo.shape
    for b in range(n):
        zb = z[b, 0]
        z_out[b, 0] = zb
        for j in range(n_nodes):
            if not succ[b, zb, j]:
                continue
            inside = True
            for d in range(dim):
                o = obs[b, d]
                if o < lo[b, j, d] or o > hi[b, j, d]:
                    inside = False
                    break
            if inside and radius2[b, j] < np.inf:
                s = 0.0
                for d in range(dim):
                    diff = obs[b, d] - centre[b, j, d]
                    s += weight[b, j, d] * diff * diff
                inside = s <= radius2[b, j]
            if inside:
                z_out[b, 0] = j + 1
                break


@numba.njit(cache=True, nogil=True)
def shape_step(
    z, z_next, achieved_prev, r_h, k, reward, done, terminated,
    table, shared, eta, gamma, value_gamma, lr, zero_terminal,
    rh_out, k_out, reward_out, rh_acc_out, k_acc_out, emit_out,
):
    """Accumulate ``r_h, k``, update a tabular potential online, and shape the reward.

    ``table`` is ``[B or 1, Z]`` (``shared`` = one table for all envs); an
    empty table means the naive potential ``Φ = eta · achieved``. ``lr = 0``
    disables the update. ``rh_acc_out``, ``k_acc_out`` and ``emit_out`` (the
    SMDP transition's ``r_h``, ``k`` and mask) are filled when not empty.
    The update equals one SGD step of
    :class:`~torchrl_subgoal.SubgoalValueLoss` (reduction ``"sum"``): every
    TD error is computed with the table as it was, then all are applied.
    """
    n = z.shape[0]
    naive = table.shape[0] == 0
    delta = np.zeros(n)
    for b in range(n):
        kb = k[b, 0]
        r = r_h[b, 0] + reward[b, 0] * value_gamma**kb
        kb += 1
        emit = z_next[b, 0] != z[b, 0] or done[b, 0]
        if emit and lr > 0.0 and not naive:
            row = 0 if shared else b
            v_next = 0.0 if terminated[b, 0] else table[row, z_next[b, 0]]
            delta[b] = r + value_gamma**kb * v_next - table[row, z[b, 0]]
        rh_out[b, 0] = 0.0 if emit else r
        k_out[b, 0] = 0 if emit else kb
        if emit_out.shape[0] > 0:
            rh_acc_out[b, 0] = r
            k_acc_out[b, 0] = kb
            emit_out[b, 0] = emit
    if lr > 0.0 and not naive:
        for b in range(n):
            if delta[b] != 0.0:
                table[0 if shared else b, z[b, 0]] += lr * delta[b]
    for b in range(n):
        if naive:
            phi = eta if achieved_prev[b, 0] else 0.0
            phi_next = eta if z_next[b, 0] != z[b, 0] else 0.0
        else:
            row = 0 if shared else b
            phi = table[row, z[b, 0]]
            phi_next = table[row, z_next[b, 0]]
        if zero_terminal and terminated[b, 0]:
            phi_next = 0.0
        reward_out[b, 0] = reward[b, 0] + gamma * phi_next - phi

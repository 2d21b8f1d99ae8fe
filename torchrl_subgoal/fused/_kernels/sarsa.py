"""Softmax SARSA(0), one table per learner."""

from __future__ import annotations

import numba
import numpy as np

from torchrl_subgoal._kernels.random import _exp_shifted, _inverse_cdf, uniform


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
def _sarsa_learner(
    q_b, s, a, reward, s_next, terminated, done, s_root, streams, b, lr, gamma, inv_temperature, scratch
):
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
def sarsa_step(q, s, a, reward, s_next, terminated, done, s_root, streams, lr, gamma, inv_temperature, action_out):
    """One SARSA(0) step per learner: draw ``a' ~ π(·|s')``, update ``Q(s, a)``, then
    the next action — ``a'``, or a fresh draw at the reset state where the episode ended.

    Learner ``b`` draws from its stream ``streams[b]``: one uniform for ``a'``,
    and one more for the reset draw when its episode ended.
    """
    scratch = np.empty(q.shape[2])
    for b in range(q.shape[0]):
        action_out[b] = _sarsa_learner(
            q[b],
            s[b],
            a[b],
            reward[b],
            s_next[b],
            terminated[b],
            done[b],
            s_root[b],
            streams,
            b,
            lr,
            gamma,
            inv_temperature,
            scratch,
        )


@numba.njit(cache=True, nogil=True, inline="always")
def _sarsa_row(sarsa, s, z):
    """The table row of state ``s`` in abstract state ``z``: ``s · Z + z`` (``s`` when ``Z = 1``)."""
    return s * sarsa.abstract_states + (z if sarsa.abstract_states > 1 else 0)


@numba.njit(cache=True, nogil=True, inline="always")
def sarsa_learner_step(sarsa, b, s, z, a, reward, s_next, z_next, terminated, done, s_root, z_root, scratch):
    """:func:`_sarsa_learner` for learner ``b`` of a :class:`~torchrl_subgoal.fused.sarsa.SarsaKernelState`,
    from states and abstract states; returns its next action."""
    return _sarsa_learner(
        sarsa.q[b],
        _sarsa_row(sarsa, s, z),
        a,
        reward,
        _sarsa_row(sarsa, s_next, z_next),
        terminated,
        done,
        _sarsa_row(sarsa, s_root, z_root),
        sarsa.streams,
        b,
        sarsa.lr,
        sarsa.gamma,
        sarsa.inv_temperature,
        scratch,
    )

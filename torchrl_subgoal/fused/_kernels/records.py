"""Per-learner episode counters and the filing of finished episodes."""

from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True, nogil=True)
def record_episodes(done, terminated, reward, t, ret, episode, steps_out, returns_out, success_out):
    """Advance per-learner step and return counters; file finished episodes.

    Returns how many episodes were filed (those past ``steps_out.shape[1]`` are not).
    """
    filed = 0
    for b in range(done.shape[0]):
        if _record_learner(b, done[b], terminated[b], reward[b], t, ret, episode, steps_out, returns_out, success_out):
            filed += 1
    return filed


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

"""Every learner's own random stream (Philox4x32-10), and the draws the learners and envs make from it."""

from __future__ import annotations

from collections.abc import Sequence

import numba
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
        c0, c1, c2, c3 = philox4x32(
            block & _LOW32, block >> _SHIFT32, row[3], np.uint64(0), key & _LOW32, key >> _SHIFT32
        )
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
        return np.array(
            [np.random.SeedSequence(int(seed), spawn_key=(b,)).generate_state(1, np.uint64)[0] for b in range(n)],
            dtype=np.uint64,
        )
    keys = np.asarray(seed)
    if keys.shape != (n,) or keys.dtype.kind not in "iu" or (keys < 0).any():
        raise ValueError(
            f"seed: give one non-negative integer per learner ({n}), got {keys.shape[0] if keys.ndim else 1}"
        )
    return keys.astype(np.uint64)


def new_streams(keys: np.ndarray, purpose: int) -> np.ndarray:
    """Fresh streams ``[n, 4]`` (no draw made yet) for the keys, one per learner."""
    streams = np.zeros((keys.shape[0], 4), np.uint64)
    streams[:, 0] = keys
    streams[:, 3] = purpose
    return streams


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

"""The kernels' random streams: Philox4x32-10, one stream per learner."""

from __future__ import annotations

import numba
import numpy as np
import pytest

from torchrl_subgoal._kernels.random import (
    AGENT_STREAM,
    ENV_STREAM,
    draw_uniforms,
    learner_keys,
    new_streams,
    philox4x32,
)

# Random123's known-answer vectors for Philox4x32-10 (Salmon et al. 2011): counter, key, output
KNOWN_ANSWERS = [
    ((0, 0, 0, 0), (0, 0), (0x6627E8D5, 0xE169C58D, 0xBC57AC4C, 0x9B00DBD8)),
    ((0xFFFFFFFF,) * 4, (0xFFFFFFFF,) * 2, (0x408F276D, 0x41C83B0E, 0xA20BC7C6, 0x6D5451FD)),
    (
        (0x243F6A88, 0x85A308D3, 0x13198A2E, 0x03707344),
        (0xA4093822, 0x299F31D0),
        (0xD16CFE09, 0x94FDCCEB, 0x5001E420, 0x24126EA1),
    ),
]


@numba.njit
def _philox(
    c0: np.uint64, c1: np.uint64, c2: np.uint64, c3: np.uint64, k0: np.uint64, k1: np.uint64
) -> tuple[int, int, int, int]:
    return philox4x32(c0, c1, c2, c3, k0, k1)  # type: ignore[no-any-return]


@pytest.mark.parametrize(("counter", "key", "expected"), KNOWN_ANSWERS)
def test_philox_known_answers(counter: tuple[int, ...], key: tuple[int, ...], expected: tuple[int, ...]) -> None:
    assert tuple(int(x) for x in _philox(*map(np.uint64, counter), *map(np.uint64, key))) == expected


def test_a_stream_depends_on_its_key_only() -> None:
    keys = learner_keys(3, 5)
    assert keys.dtype == np.uint64 and len(set(keys.tolist())) == 5
    assert learner_keys(3, 2).tolist() == keys[:2].tolist()  # learner b of any batch size
    together = np.empty((5, 7))
    draw_uniforms(new_streams(keys, AGENT_STREAM), 7, together)
    alone = np.empty((1, 7))
    draw_uniforms(new_streams(keys[3:4], AGENT_STREAM), 7, alone)
    assert np.array_equal(together[3], alone[0])
    streams = new_streams(keys, AGENT_STREAM)  # three draws, then four: the same seven
    first, rest = np.empty((5, 3)), np.empty((5, 4))
    draw_uniforms(streams, 3, first)
    draw_uniforms(streams, 4, rest)
    assert np.array_equal(np.concatenate([first, rest], 1), together)
    env = np.empty((5, 7))  # another purpose, another stream of the same key
    draw_uniforms(new_streams(keys, ENV_STREAM), 7, env)
    assert not np.isin(env, together).any()


def test_uniforms_look_uniform() -> None:
    from scipy import stats

    u = np.empty((4, 50_000))
    draw_uniforms(new_streams(learner_keys(0, 4), AGENT_STREAM), 50_000, u)
    assert u.min() >= 0.0 and u.max() < 1.0
    for row in u:
        assert stats.kstest(row, "uniform").pvalue > 1e-4
    assert abs(np.corrcoef(u)[np.triu_indices(4, 1)]).max() < 0.03  # learners' streams uncorrelated
    assert abs(np.corrcoef(u[0, :-1], u[0, 1:])[0, 1]) < 0.03  # nor successive draws


def test_seeds_are_checked() -> None:
    with pytest.raises(ValueError, match="one non-negative integer per learner"):
        learner_keys([1, 2], 3)
    with pytest.raises(ValueError, match="seed must be >= 0"):
        learner_keys(-1, 3)
    assert learner_keys(np.random.default_rng(0), 3).shape == (3,)

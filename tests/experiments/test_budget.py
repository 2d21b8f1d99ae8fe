"""The check every recipe's plan passes before anything runs: memory and time that cannot fit are refused,
naming the flag and the most that fits; what fits passes, up to the byte."""

from __future__ import annotations

import os

import pytest

from torchrl_subgoal.experiments.budget import (
    LEARNER_BYTES,
    MAX_SECONDS,
    RECORD_BYTES,
    STEPS_PER_SECOND,
    Budget,
    check_budget,
    check_learnings,
    memory_bytes,
)
from torchrl_subgoal.experiments.cli import ConfigError
from torchrl_subgoal.experiments.sweep import MethodSpec

GIB = 2**30
YEAR_STEPS = STEPS_PER_SECOND * MAX_SECONDS


def specs(learnings: int, patterns: int = 10) -> list[MethodSpec]:
    """HRS over ``patterns`` patterns and the unshaped learner, ``learnings`` per pattern."""
    return [
        MethodSpec("HRS", [f"p{i}" for i in range(patterns)], learnings),
        MethodSpec("SARSA", ["none"], learnings * patterns),
    ]


def refusal(**kwargs: object) -> str:
    defaults: dict[str, object] = {
        "specs": specs(10),
        "columns": 1000,
        "chunk_size": 100,
        "budget": Budget(1000, ("episodes", 1000)),
        "learnings": 10,
        "workers": 2,
        "backend": "local",
        "memory": 16 * GIB,
    }
    arguments = {**defaults, **kwargs}
    with pytest.raises(ConfigError) as caught:
        check_budget(
            arguments.pop("specs"),  # type: ignore[arg-type]
            arguments.pop("columns"),  # type: ignore[arg-type]
            arguments.pop("chunk_size"),  # type: ignore[arg-type]
            arguments.pop("budget"),  # type: ignore[arg-type]
            **arguments,  # type: ignore[arg-type]
        )
    return str(caught.value)


def test_a_paper_scale_plan_fits() -> None:
    """Four-rooms at the paper's scale (10 patterns x 100 learnings x 1,000 episodes) on 2 GiB."""
    check_budget(
        specs(100), 1000, 100, Budget(1000, ("episodes", 1000)), learnings=100, workers=2, backend="local", memory=GIB
    )


def test_one_learner_longer_than_a_year_even_at_the_generous_rate() -> None:
    frames = 10**30
    message = refusal(budget=Budget(frames, ("total_frames", frames), unit="update"), columns=frames // 256)
    assert message == (
        f"--total-frames {frames}: one learner takes at least 1e+30 steps, over 3.17e+13 years even at 1e+09 steps "
        "a second, 200 times the fastest engine here; at most 3.15e+16 fit in a year"
    )
    check_budget(  # exactly a year's steps: allowed
        specs(1, 1), 1, 1, Budget(YEAR_STEPS, ("total_frames", YEAR_STEPS)), learnings=1, workers=0,
        backend="ray", memory=GIB,
    )  # fmt: skip


def test_one_learners_records_beyond_the_memory() -> None:
    episodes = 10**15
    message = refusal(budget=Budget(episodes, ("episodes", episodes)), columns=episodes)
    most = (16 * GIB) // RECORD_BYTES
    assert message == (
        f"--episodes {episodes}: one learner records 1e+15 episodes of 17 bytes, at least 15.1 PiB, more than this "
        f"machine's 16 GiB of memory; at most {most:,} fit"
    )


def test_a_learners_working_set_beyond_the_memory_names_what_it_holds() -> None:
    budget = Budget(1000, ("total_frames", 1000), learner_bytes=32 * GIB, held="a batch of 10**9 frames")
    assert refusal(budget=budget) == (
        "one learner holds at least 32 GiB while it trains (a batch of 10**9 frames), more than this machine's "
        "16 GiB of memory"
    )


def test_the_chunks_running_at_once_must_fit() -> None:
    per_learner = 1000 * RECORD_BYTES + 10**6
    budget = Budget(1000, ("total_frames", 1000), learner_bytes=10**6, chunk_flag="seed_batch")
    message = refusal(specs=specs(10**4), chunk_size=10**4, budget=budget, learnings=10**4)
    assert message.startswith("--seed-batch 10000: 2 chunks at once (--workers 2) of 10,000 learners hold at least ")
    assert message.endswith(f"at most {(16 * GIB) // (2 * per_learner):,} learners a chunk fit")
    one = refusal(specs=specs(10**5), chunk_size=10**5, budget=budget, learnings=10**5, workers=0)
    assert one.startswith("--seed-batch 100000: a chunk of 100,000 learners hold at least")
    fixed = Budget(1000, ("epochs", 1000), learner_bytes=9 * GIB, chunk_flag=None)  # one learner a chunk
    assert refusal(chunk_size=1, budget=fixed).endswith("at most 1 chunks at once fit")
    # chunks on a cluster run on other machines: only what the driver holds is checked
    check_budget(specs(10**4), 1000, 10**4, budget, learnings=10**4, workers=2, backend="ray", memory=16 * GIB)


def test_every_learners_records_must_fit_in_the_driver() -> None:
    learners = 20 * 10**9
    total = learners * (1000 * RECORD_BYTES + LEARNER_BYTES)
    message = refusal(specs=specs(10**9), learnings=10**9, chunk_size=1)
    assert message == (
        f"--learnings 1000000000: 20,000,000,000 learners record at least {total / 2**40:.3g} TiB (1,000 episodes of "
        "17 bytes and "
        f"64 bytes each), more than this machine's 16 GiB of memory, which the sweep and its report need; at most "
        f"{10**9 * 16 * GIB // total:,} learnings per pattern fit"
    )
    many = refusal(specs=specs(1), learnings=1, chunk_size=1, columns=10**8)  # 1.6 GiB a learner, 20 learners
    assert many.endswith("not even --learnings 1 fits: lower --episodes")
    fits = (16 * GIB) // (1000 * RECORD_BYTES + LEARNER_BYTES)  # learners that fit, to the byte
    exact = [MethodSpec("HRS", ["p"], fits)]
    check_budget(
        exact, 1000, 1, Budget(1000, ("episodes", 1000)), learnings=fits, workers=2, backend="ray", memory=16 * GIB
    )
    over = [MethodSpec("HRS", ["p"], fits + 1)]
    assert refusal(specs=over, learnings=fits + 1, chunk_size=1, backend="ray").startswith("--learnings")


def test_all_learners_on_the_local_workers_longer_than_a_year() -> None:
    steps = 10**15
    budget = Budget(steps, ("total_frames", steps))
    message = refusal(specs=specs(10), budget=budget, columns=10, chunk_size=1)
    assert message == (
        "--learnings 10: 200 learners of at least 1e+15 steps take over a year on 2 worker(s) even "
        f"at 1e+09 steps a second, 200 times the fastest engine here; at most {10 * 2 * YEAR_STEPS // (200 * steps)} "
        "learnings per pattern fit (or run on a cluster: --backend ray)"
    )
    check_budget(specs(10), 10, 1, budget, learnings=10, workers=2, backend="ray", memory=16 * GIB)  # size unknown


def test_the_machines_memory() -> None:
    memory = memory_bytes()
    assert memory is not None and 0 < memory <= os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")


def test_learnings_that_cannot_fit_even_one_learner_each_are_refused_before_the_plan() -> None:
    least = LEARNER_BYTES + RECORD_BYTES
    check_learnings((16 * GIB) // least, memory=16 * GIB)  # to the byte
    with pytest.raises(ConfigError) as caught:
        check_learnings((16 * GIB) // least + 1, memory=16 * GIB)
    assert str(caught.value) == (
        f"--learnings {(16 * GIB) // least + 1}: the plan holds at least {(16 * GIB) // least + 1:,} learners of "
        f"81 bytes (its place in the plan and one record), 16 GiB, more than this machine's 16 GiB of memory; at "
        f"most {(16 * GIB) // least:,} learnings fit, and fewer with more patterns, methods or episodes"
    )

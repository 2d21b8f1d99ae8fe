"""What a sweep needs at least, checked before anything runs: a plan that cannot fit is refused.

Every recipe's plan goes through :func:`check_budget` (from
:func:`~torchrl_subgoal.experiments.recipe.recipe_main`) before the results
directory is touched, and its ``--learnings`` through :func:`check_learnings`
before the plan is made (a plan may draw a pattern per learning). It refuses only what *clearly* cannot fit, from lower
bounds:

* **memory** (this machine's, :func:`memory_bytes`): every learner's records
  (:data:`RECORD_BYTES` per learner and report column, which the sweep's driver
  and the report hold at once) and its place in the plan (:data:`LEARNER_BYTES`);
  one learner's records and working set (its collected batch, its replay buffer),
  and those of the chunks that run at once on this machine;
* **time**: a learner's steps run one after another, so one learner's
  :attr:`Budget.steps` at :data:`STEPS_PER_SECOND` (200 times the fastest engine
  measured here, 5 M learner-steps per second) must take less than
  :data:`MAX_SECONDS` (a year), and all learners on the local workers likewise.

Each refusal is one :class:`~torchrl_subgoal.experiments.cli.ConfigError` naming
the flag to lower and the largest value that fits.
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from torchrl_subgoal.experiments.cli import ConfigError
from torchrl_subgoal.experiments.sweep import MethodSpec

__all__ = [
    "LEARNER_BYTES",
    "MAX_SECONDS",
    "RECORD_BYTES",
    "STEPS_PER_SECOND",
    "Budget",
    "check_budget",
    "check_learnings",
    "memory_bytes",
]

#: One learner's record of one report column: steps (int64), return (float64), success (bool).
RECORD_BYTES = 17
#: One learner in the plan: its ``(pattern, learning)`` pair (a 56-byte tuple) and its slot in the chunk.
LEARNER_BYTES = 64
#: Learner-steps per second of one process, far above any engine's (the fused four-rooms loop: 5 M).
STEPS_PER_SECOND = 10**9
#: The longest run a plan may need at that rate: a year.
MAX_SECONDS = 365 * 24 * 3600


@dataclass(frozen=True)
class Budget:
    """What one learner of a plan costs at least, for :func:`check_budget`.

    Args:
        steps: the env steps (frames) one learner takes at least (an episode takes at least one).
        length: the flag that sets a learner's length, its steps and its report columns, with its value
            (``("episodes", 1000)``, ``("total_frames", 500_000)``).
        learner_bytes: the memory one learner holds while it trains, besides its records (its collected
            batch, its replay buffer).
        held: what ``learner_bytes`` is, for the message.
        chunk_flag: the flag that sets the learners per chunk (``None``: one learner per chunk, fixed).
        unit: what one report column of a learner is (``"episode"``, ``"update"``, ``"epoch"``).

    Examples:
        >>> Budget(steps=1000, length=("episodes", 1000)).chunk_flag
        'chunk_size'
    """

    steps: int
    length: tuple[str, int]
    learner_bytes: int = 0
    held: str = ""
    chunk_flag: str | None = "chunk_size"
    unit: str = "episode"


def memory_bytes() -> int | None:
    """This machine's memory in bytes (its physical memory, or its container's limit when lower);
    ``None`` where the system does not say.

    Examples:
        >>> memory_bytes() > 0
        True
    """
    try:
        total = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (AttributeError, ValueError, OSError):
        return None
    for limit in ("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory/memory.limit_in_bytes"):
        try:
            text = Path(limit).read_text().strip()
        except OSError:
            continue
        if text.isdigit():
            total = min(total, int(text))
    return total if total > 0 else None


def _size(n: float) -> str:
    """Bytes as people read them: ``'23.5 GiB'``."""
    for unit in ("bytes", "KiB", "MiB", "GiB", "TiB", "PiB"):
        if n < 1024 or unit == "PiB":
            return f"{n:.0f} {unit}" if unit == "bytes" else f"{n:.3g} {unit}"
        n /= 1024
    raise AssertionError("unreachable")


def _count(n: float) -> str:
    """A count, exact while short: ``'1,000'``, ``'4e+13'``."""
    return f"{int(n):,}" if n < 1e12 else f"{n:.3g}"


def _flag(name: str) -> str:
    return "--" + name.replace("_", "-")


def check_learnings(learnings: int, memory: int | None = None) -> None:
    """Refuse, before a plan is even made, a ``--learnings`` whose learners cannot fit in memory: every
    learning is at least one learner, which the plan and the results hold (:data:`LEARNER_BYTES` and at
    least one record of :data:`RECORD_BYTES`). :func:`check_budget` checks the plan made.

    Raises:
        ConfigError: naming ``--learnings`` and the most that fits.

    Examples:
        >>> check_learnings(100, memory=2**30)  # fits
        >>> check_learnings(10**12, memory=2**34)
        Traceback (most recent call last):
        ...
        torchrl_subgoal.experiments.cli.ConfigError: --learnings 1000000000000: the plan holds at least ...
    """
    memory = memory_bytes() if memory is None else memory
    least = LEARNER_BYTES + RECORD_BYTES
    if memory is not None and learnings * least > memory:
        raise ConfigError(
            f"--learnings {learnings}: the plan holds at least {_count(learnings)} learners of {least} bytes (its "
            f"place in the plan and one record), {_size(learnings * least)}, more than this machine's "
            f"{_size(memory)} of memory; at most {_count(memory // least)} learnings fit, and fewer with more "
            "patterns, methods or episodes"
        )


def check_budget(
    specs: Sequence[MethodSpec],
    columns: int,
    chunk_size: int,
    budget: Budget,
    *,
    learnings: int,
    workers: int,
    backend: str,
    memory: int | None = None,
) -> None:
    """Refuse a plan whose memory or time cannot fit (see the module doc), before anything runs.

    Args:
        specs: the plan's methods and their learners.
        columns: the report columns each learner records (episodes, updates, epochs).
        chunk_size: learners per chunk.
        budget: what one learner costs.
        learnings: the ``--learnings`` the learner counts grow with (for the message).
        workers: local worker processes (chunks at once); ``backend``: ``"local"`` or ``"ray"``
            (chunks on other machines: their memory is not checked here).
        memory: the memory to fit in (default: :func:`memory_bytes`).

    Raises:
        ConfigError: naming the flag to lower and the most that fits.

    Examples:
        >>> specs = [MethodSpec("HRS", ["p"], 10**12)]
        >>> check_budget(specs, 100, 10, Budget(100, ("episodes", 100)), learnings=10**12, workers=2,
        ...              backend="local", memory=2**34)
        Traceback (most recent call last):
        ...
        torchrl_subgoal.experiments.cli.ConfigError: --learnings 1000000000000: 1e+12 learners record ...
    """
    memory = memory_bytes() if memory is None else memory
    length_flag, length = budget.length
    learners = sum(len(spec.patterns) * spec.learnings_per_pattern for spec in specs)
    year_steps = STEPS_PER_SECOND * MAX_SECONDS
    rate = f"{STEPS_PER_SECOND:.0e} steps a second, 200 times the fastest engine here"
    if budget.steps > year_steps:
        fits = math.floor(length * year_steps / budget.steps)
        raise ConfigError(
            f"{_flag(length_flag)} {length}: one learner takes at least {_count(budget.steps)} steps, over "
            f"{budget.steps / year_steps:.3g} years even at {rate}; at most {_count(fits)} fit in a year"
        )
    per_learner = columns * RECORD_BYTES + budget.learner_bytes
    if memory is not None and per_learner > memory:
        if budget.learner_bytes > memory:
            raise ConfigError(
                f"one learner holds at least {_size(budget.learner_bytes)} while it trains ({budget.held}), more "
                f"than this machine's {_size(memory)} of memory"
            )
        fits = math.floor(length * (memory - budget.learner_bytes) / (columns * RECORD_BYTES))
        raise ConfigError(
            f"{_flag(length_flag)} {length}: one learner records {_count(columns)} {budget.unit}s of "
            f"{RECORD_BYTES} bytes, at least {_size(columns * RECORD_BYTES)}, more than this machine's "
            f"{_size(memory)} of memory; at most {_count(fits)} fit"
        )
    per_method = [len(spec.patterns) * spec.learnings_per_pattern for spec in specs]
    chunks = sum(math.ceil(n / chunk_size) for n in per_method)
    at_once = min(workers, chunks) if backend == "local" and workers > 0 else 1
    in_chunk = min(chunk_size, max(per_method, default=0))  # a chunk holds one method's learners
    held = at_once * in_chunk * per_learner
    if memory is not None and backend == "local" and held > memory:
        fits = memory // (at_once * per_learner)
        runs = f"{at_once} chunks at once (--workers {workers}) of " if at_once > 1 else "a chunk of "
        if fits >= 1 and budget.chunk_flag is not None:
            what, most = f"{_flag(budget.chunk_flag)} {chunk_size}", f"at most {_count(fits)} learners a chunk fit"
        else:
            what, most = f"--workers {workers}", f"at most {memory // per_learner} chunks at once fit"
        raise ConfigError(
            f"{what}: {runs}{_count(in_chunk)} learners hold at least {_size(held)} "
            f"({_size(per_learner)} a learner), more than this machine's {_size(memory)} of memory; {most}"
        )
    total = learners * (columns * RECORD_BYTES + LEARNER_BYTES)
    if memory is not None and total > memory:
        fits = math.floor(learnings * memory / total)
        most = (
            f"at most {_count(fits)} learnings per pattern fit"
            if fits >= 1
            else f"not even --learnings 1 fits: lower {_flag(length_flag)}"
        )
        raise ConfigError(
            f"--learnings {learnings}: {_count(learners)} learners record at least {_size(total)} "
            f"({_count(columns)} {budget.unit}s of {RECORD_BYTES} bytes and {LEARNER_BYTES} bytes each), more than "
            f"this machine's {_size(memory)} of memory, which the sweep and its report need; {most}"
        )
    if backend == "local" and learners * budget.steps > year_steps * max(workers, 1):
        fits = math.floor(learnings * year_steps * max(workers, 1) / (learners * budget.steps))
        raise ConfigError(
            f"--learnings {learnings}: {_count(learners)} learners of at least {_count(budget.steps)} steps take over "
            f"a year on {max(workers, 1)} worker(s) even at {rate}; at most {_count(fits)} learnings per pattern fit "
            "(or run on a cluster: --backend ray)"
        )

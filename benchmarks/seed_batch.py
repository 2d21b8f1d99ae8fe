"""A2C and PPO learners one at a time against the same learners as one batch (``train_<algo>_batch``,
``recipes/train.py --seed-batch``).

A cell is ``--learners`` learners of one block at the domain's defaults for it (its input
features, envs per learner and frames per batch), ``--frames`` frames each,
unshaped ("plain") or with HRS (the domain's first shipped pattern, each
learner's table trained online). "one at a time" runs them in turn with
``train_<algo>`` (what a worker process of the recipe does for one learner);
"batch" runs them together with ``train_<algo>_batch``. Measured: learner frames
(over all learners) per second of CPU time of this process, one torch thread.
The two sides of a cell run in turn within each of ``--repeats`` rounds; a
side's rate is its best round and "batch / one at a time" the median of the
rounds' paired ratios (the machine may be shared).

Each learner's final mean episode length is printed too, averaged over the
learners, so that a batch that learns differently would show.

    python benchmarks/seed_batch.py                     # A2C and PPO, 10 learners, 20,480 frames each, 2 rounds
    python benchmarks/seed_batch.py --quick             # 5 learners, 8,192 frames, 1 round
    python benchmarks/seed_batch.py --blocks ppo --domains pinball --learners 20
"""

from __future__ import annotations

import argparse
import dataclasses
import statistics
import time
from collections.abc import Callable

import torch

from torchrl_subgoal import TabularPotential, load_patterns
from torchrl_subgoal import domains as registry
from torchrl_subgoal.training import (
    LearnerDomain,
    LearningCurve,
    Shaping,
    train_a2c,
    train_a2c_batch,
    train_ppo,
    train_ppo_batch,
)

DOMAINS = ("four_rooms", "four_rooms_step", "pinball")
BLOCKS: dict[str, tuple[Callable[..., LearningCurve], Callable[..., list[LearningCurve]]]] = {
    "a2c": (train_a2c, train_a2c_batch),
    "ppo": (train_ppo, train_ppo_batch),
}


def shapings(domain: LearnerDomain, name: str, learners: int, shaped: bool) -> list[Shaping | None]:
    """Each learner's HRS shaping over the domain's first pattern (``None``: plain)."""
    if not shaped:
        return [None] * learners
    series = next(iter(load_patterns(domain.participants, domain=name).values()))
    options = {"observation_key": domain.subgoal_key}
    return [Shaping(series, TabularPotential(series.num_abstract_states), options) for _ in range(learners)]


def run(
    block: str, name: str, learners: int, frames: int, shaped: bool, batch: bool
) -> tuple[float, list[LearningCurve]]:
    """CPU seconds and the curves of one side of a cell."""
    domain = registry.part(name, LearnerDomain)
    config = dataclasses.replace(domain.defaults[block], total_frames=frames)
    parts = shapings(domain, name, learners, shaped)
    alone, together = BLOCKS[block]
    start = time.process_time()
    if batch:
        curves = together(
            domain.make_env, config, list(range(learners)), shapings=parts, observation_key=domain.observation_key
        )
    else:
        curves = [
            alone(domain.make_env, config, shaping=parts[k], seed=k, observation_key=domain.observation_key)
            for k in range(learners)
        ]
    return time.process_time() - start, curves


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--blocks", default="a2c,ppo", help="comma-separated building blocks (a2c, ppo)")
    parser.add_argument("--domains", default=",".join(DOMAINS), help="comma-separated domains")
    parser.add_argument("--learners", type=int, default=10, help="learners per cell")
    parser.add_argument("--frames", type=int, default=20_480, help="frames per learner")
    parser.add_argument("--repeats", type=int, default=2, help="rounds")
    parser.add_argument("--quick", action="store_true", help="5 learners, 8,192 frames, 1 round")
    args = parser.parse_args()
    if args.quick:
        args.learners, args.frames, args.repeats = 5, 8_192, 1
    blocks = [b for b in args.blocks.split(",") if b]
    names = [d for d in args.domains.split(",") if d]
    for block in blocks:
        if block not in BLOCKS:
            parser.error(f"--blocks: {block!r} is not one of {', '.join(BLOCKS)}")
    for name in names:
        if name not in DOMAINS:
            parser.error(f"--domains: {name!r} is not one of {', '.join(DOMAINS)}")
    torch.set_num_threads(1)
    cells = [(block, name, shaped) for block in blocks for name in names for shaped in (False, True)]
    rates: dict[tuple[str, str, bool, bool], list[float]] = {}
    lengths: dict[tuple[str, str, bool, bool], float] = {}
    for _ in range(args.repeats):
        for cell in cells:
            for batch in (False, True):
                seconds, curves = run(*cell[:2], args.learners, args.frames, cell[2], batch)
                frames = sum(c.frames[-1] for c in curves)
                rates.setdefault((*cell, batch), []).append(frames / seconds)
                lengths[(*cell, batch)] = statistics.mean(c.episode_length[-1] for c in curves)
    print(
        f"{args.learners} learners x {args.frames:,} frames per cell, one torch thread, "
        f"best of {args.repeats} round(s): learner frames per CPU second\n"
    )
    print(
        "| block | domain | shaping | one at a time | batch | batch / one at a time "
        "| final length: one at a time, batch |"
    )
    print("|---|---|---|---|---|---|---|")
    for block, name, shaped in cells:
        alone, together = rates[(block, name, shaped, False)], rates[(block, name, shaped, True)]
        ratio = statistics.median(b / a for a, b in zip(alone, together, strict=True))
        ends = f"{lengths[(block, name, shaped, False)]:.0f}, {lengths[(block, name, shaped, True)]:.0f}"
        print(
            f"| {block.upper()} | {name} | {'HRS' if shaped else 'plain'} | {max(alone):,.0f} | "
            f"{max(together):,.0f} | {ratio:.1f} | {ends} |"
        )


if __name__ == "__main__":
    main()

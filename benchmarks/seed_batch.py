"""Learners one at a time against the same learners as one batch (``train_<algo>(..., seeds=[...])``,
``recipes/train.py --seed-batch``), for every building block.

A cell is ``--learners`` learners of one block at the domain's defaults for it (its input
features, envs per learner, frames per batch, update ratio), ``--frames`` frames each,
unshaped ("plain") or with HRS (each learner's pattern of the domain's subgoal file, its
table trained online). DQN and DDPG take their first gradient step after their first
batch (``learning_starts`` = one batch), so that every batch is timed with its updates.
On PointMaze every learner has its own task (start and goal, its route's pattern): "one
at a time" gives each learner its own env; "batch" joins them into one env batch.
"one at a time" runs the learners in turn, one ``train_<algo>`` call each (what a
worker process of the recipe does for one learner); "batch" runs them together in one
call. Measured: learner frames (over all learners) per second of CPU time of this
process, one torch thread, the learners' set-up included. The two sides of a cell run in
turn within each of ``--repeats`` rounds; a side's rate is its best round and "batch / one
at a time" the median of the rounds' paired ratios (the machine may be shared).

Each learner's final mean episode length is printed too, averaged over the learners, so
that a batch that learns differently would show (at a few thousand frames most learners
have not learned yet: this is a check of plumbing, not of learning; the learning is
compared in docs/does_it_help.md).

    python benchmarks/seed_batch.py                     # A2C and PPO, 10 learners, 20,480 frames each, 2 rounds
    python benchmarks/seed_batch.py --quick             # 5 learners, 8,192 frames, 1 round
    python benchmarks/seed_batch.py --blocks dqn --domains mountain_car --frames 8192
    python benchmarks/seed_batch.py --blocks ddpg --domains point_maze_umaze --frames 5000
"""

from __future__ import annotations

import argparse
import dataclasses
import statistics
import time
from collections.abc import Callable
from typing import Any

import torch
from torchrl.envs import EnvBase

from torchrl_subgoal import TabularPotential, load_patterns
from torchrl_subgoal import domains as registry
from torchrl_subgoal.training import LEARNERS, LearnerDomain, LearningCurve, Shaping

#: The domains each block runs on (its actions): a cell is a (block, domain) pair of these.
DOMAINS = {
    "a2c": ("four_rooms", "four_rooms_step", "pinball"),
    "ppo": ("four_rooms", "four_rooms_step", "pinball"),
    "dqn": ("four_rooms", "mountain_car"),
    "ddpg": ("point_maze_umaze",),
}


def learners(name: str, count: int, shaped: bool) -> list[tuple[Callable[[int], EnvBase], Shaping | None]]:
    """Each learner's env factory and HRS shaping (``None``: plain), as the recipe gives them: learner ``k``
    follows pattern ``k mod P`` of the domain's file, in that pattern's task where the domain has one each."""
    domain = registry.part(name, LearnerDomain)
    patterns = list(load_patterns(domain.participants, domain=name).items())
    out = []
    for k in range(count):
        route, series = patterns[k % len(patterns)]
        shaping = None
        if shaped:
            shaping = Shaping(
                series, TabularPotential(series.num_abstract_states), {"observation_key": domain.subgoal_key}
            )
        out.append((domain.env_for(route, k), shaping))
    return out


def run(block: str, name: str, count: int, frames: int, shaped: bool, batch: bool) -> tuple[float, list[LearningCurve]]:
    """CPU seconds and the curves of one side of a cell."""
    domain = registry.part(name, LearnerDomain)
    config: Any = dataclasses.replace(domain.defaults[block], total_frames=frames)
    if block in ("dqn", "ddpg"):
        config = dataclasses.replace(config, learning_starts=config.frames_per_batch)
    parts = learners(name, count, shaped)
    train = LEARNERS[block].train
    kwargs: dict[str, Any] = {"observation_key": domain.observation_key}
    start = time.process_time()
    if batch:
        curves = train(
            [make for make, _ in parts], config, seeds=range(count), shaping=[s for _, s in parts], **kwargs
        ).curves
    else:
        curves = [train(make, config, seeds=[k], shaping=s, **kwargs).curve for k, (make, s) in enumerate(parts)]
    return time.process_time() - start, curves


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--blocks", default="a2c,ppo", help=f"comma-separated building blocks ({', '.join(DOMAINS)})")
    parser.add_argument("--domains", default="", help="comma-separated domains (default: every one a block runs on)")
    parser.add_argument("--learners", type=int, default=10, help="learners per cell")
    parser.add_argument("--frames", type=int, default=20_480, help="frames per learner")
    parser.add_argument("--repeats", type=int, default=2, help="rounds")
    parser.add_argument("--shaping", default="plain,hrs", help="plain, hrs or both")
    parser.add_argument("--quick", action="store_true", help="5 learners, 8,192 frames, 1 round")
    args = parser.parse_args()
    if args.quick:
        args.learners, args.frames, args.repeats = 5, 8_192, 1
    blocks = [b for b in args.blocks.split(",") if b]
    names = [d for d in args.domains.split(",") if d]
    for block in blocks:
        if block not in DOMAINS:
            parser.error(f"--blocks: {block!r} is not one of {', '.join(DOMAINS)}")
    known = sorted({d for ds in DOMAINS.values() for d in ds})
    for name in names:
        if name not in known:
            parser.error(f"--domains: {name!r} is not one of {', '.join(known)}")
    variants = [v == "hrs" for v in args.shaping.split(",") if v]
    torch.set_num_threads(1)
    cells = [
        (block, name, shaped)
        for block in blocks
        for name in DOMAINS[block]
        if not names or name in names
        for shaped in variants
    ]
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

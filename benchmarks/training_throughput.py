"""Learner frames per second per core of each TorchRL building block, with and without the shaping transform.

Each building block of ``torchrl_subgoal.training`` (A2C, PPO, DQN, DDPG) runs
on the domains it fits: four-rooms and PinBall (discrete actions: A2C, PPO,
DQN) and PointMaze UMaze (continuous actions: PPO, DDPG). A cell is a short
learning at the block's default settings (the domain's input features and
reward scale; one collector in this process, no worker process, one torch
thread), from the same seed, without shaping ("plain") and with HRS: the
transform over the domain's first shipped subgoal pattern, a tabular potential
trained online in the transform (the learners' default). DQN and DDPG take their first
gradient steps after the first batch (``learning_starts`` = one batch), so
that every measured batch includes the learner's updates.

Measured: learner frames per second of CPU time of this process (``time.process_time``)
over a learning's batches after the first: collection through the transforms,
the learner's update and the potential's, everything a training loop does per
frame, on one core. ``--learners K`` runs each cell as ``K`` learners in one batch
(``train_<algo>(..., seeds=range(K))``, each with its own table): the rate counts
every learner's frames. The cells run in turn, ``--repeats`` rounds (the machine
may be shared: a round runs every cell under the same load); a cell's rate is
its best round, and "HRS / plain" is the median over rounds of the paired
ratios (each round's HRS rate over the same round's plain rate). Shaping
changes the rewards, so over the measured batches the two learnings may end
episodes (and reset envs) at different rates; the learnings are short so that
their policies stay close to the initial ones.

``--against DIR`` runs every cell in a fresh interpreter, once with the package of
this checkout and once with that of another (e.g. the commit before a change:
``git worktree add /tmp/before <commit>``), the two in turn within every round, and
adds each side's rates and "this / against", the median over rounds of the paired
ratios of the rates.

    python benchmarks/training_throughput.py               # 3 rounds of 4 batches
    python benchmarks/training_throughput.py --quick       # 1 round of 3 batches
    python benchmarks/training_throughput.py --blocks ppo,ddpg --repeats 5
    python benchmarks/training_throughput.py --blocks ddpg --repeats 5 --against /tmp/before
    python benchmarks/training_throughput.py --learners 10   # every cell as a batch of 10 learners
"""

from __future__ import annotations

import argparse
import functools
import inspect
import json
import os
import statistics
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import torch
from tensordict.utils import NestedKey
from torchrl.envs import EnvBase

from torchrl_subgoal import SubgoalSeries, TabularPotential, load_patterns
from torchrl_subgoal import domains as registry
from torchrl_subgoal.envs.point_maze import make_point_maze, point_maze_task
from torchrl_subgoal.training import (
    A2CConfig,
    DDPGTrainConfig,
    DQNConfig,
    LearnerDomain,
    PPOConfig,
    Shaping,
    train_a2c,
    train_ddpg,
    train_dqn,
    train_ppo,
)

BLOCKS = ("a2c", "ppo", "dqn", "ddpg")


@dataclass(frozen=True)
class Domain:
    """What a cell needs of a domain: env factory, keys, a subgoal series, the features and reward scale."""

    name: str
    make_env: Callable[[int], EnvBase]
    observation_key: NestedKey
    subgoal_key: NestedKey
    series: SubgoalSeries
    features: str
    reward_scale: float
    episode_cap: float


def domains() -> dict[str, Domain]:
    """Four-rooms and PinBall (their A2C set-ups), PointMaze UMaze (seed 0's task)."""
    out = {}
    for name in ("four_rooms", "pinball"):
        d = registry.part(name, LearnerDomain)
        series = next(iter(load_patterns(d.participants).values()))
        cap = float(getattr(d.make_env(1), "max_steps", 1000))
        out[name] = Domain(
            name, d.make_env, d.observation_key, d.subgoal_key, series, d.a2c.features, d.a2c.reward_scale, cap
        )
    out["point_maze"] = Domain(
        "point_maze",
        functools.partial(make_point_maze, "umaze", seed=0),
        "observation",
        "observation",
        point_maze_task("umaze", 0).pattern(),
        "mlp",
        1.0,
        300.0,
    )
    return out


#: (block, domain) cells: the discrete-action learners on four-rooms and PinBall, the continuous ones on PointMaze.
CELLS = [
    ("a2c", "four_rooms"),
    ("a2c", "pinball"),
    ("ppo", "four_rooms"),
    ("ppo", "pinball"),
    ("ppo", "point_maze"),
    ("dqn", "four_rooms"),
    ("dqn", "pinball"),
    ("ddpg", "point_maze"),
]


def run_cell(block: str, domain: Domain, shaped: bool, batches: int, learners: int = 1) -> tuple[float, int]:
    """One short learning of ``learners`` learners; (learner frames per CPU second over the batches after the
    first, frames per batch)."""
    config: Any
    scale = domain.reward_scale
    if block == "a2c":
        base = registry.part(domain.name, LearnerDomain).a2c
        config = A2CConfig(**{**base.__dict__, "total_frames": batches * base.frames_per_batch})
        train: Callable[..., Any] = train_a2c
    elif block == "ppo":
        fpb = PPOConfig.frames_per_batch
        config = PPOConfig(features=domain.features, total_frames=batches * fpb, reward_scale=scale)  # type: ignore[arg-type]
        train = train_ppo
    elif block == "dqn":
        fpb = DQNConfig.frames_per_batch
        config = DQNConfig(
            features=domain.features,  # type: ignore[arg-type]
            total_frames=batches * fpb,
            learning_starts=fpb,
            reward_scale=scale,
        )
        train = train_dqn
    else:
        fpb = DDPGTrainConfig.frames_per_batch
        config = DDPGTrainConfig(total_frames=batches * fpb, learning_starts=fpb, reward_scale=scale)
        train = train_ddpg
    shaping = None
    if shaped:
        shaping = Shaping(
            domain.series, TabularPotential(domain.series.num_abstract_states), {"observation_key": domain.subgoal_key}
        )
    stamps: list[float] = []
    # a checkout from before the blocks were batched (``--against``) takes one seed
    seeds: dict[str, Any] = {"seed": 0} if "seed" in inspect.signature(train).parameters else {"seeds": range(learners)}
    train(
        domain.make_env,
        config,
        shaping=shaping,
        observation_key=domain.observation_key,
        episode_cap=domain.episode_cap,
        progress=lambda _: stamps.append(time.process_time()),
        **seeds,
    )
    stamps = stamps[learners - 1 :: learners]  # each batch calls progress once per learner
    frames = learners * config.frames_per_batch * (len(stamps) - 1)
    return frames / (stamps[-1] - stamps[0]), config.frames_per_batch


def _child(cell: str, pythonpath: str | None) -> tuple[float, int]:
    """:func:`run_cell` of ``cell`` (``block,domain,plain|hrs,batches``) in a fresh interpreter, with
    ``pythonpath`` first on the path if given."""
    env = dict(os.environ)
    if pythonpath is not None:
        env["PYTHONPATH"] = os.pathsep.join([pythonpath, *filter(None, [env.get("PYTHONPATH")])])
    command = [sys.executable, __file__, "--cell", cell]
    out = subprocess.run(command, env=env, capture_output=True, text=True, check=False)
    if out.returncode != 0:
        raise SystemExit(f"error: {' '.join(command)} failed:\n{out.stderr[-2000:]}")
    figures = json.loads(out.stdout.strip().splitlines()[-1])
    return float(figures["rate"]), int(figures["frames_per_batch"])


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    parser.add_argument("--repeats", type=int, default=3, help="rounds over every cell")
    parser.add_argument("--batches", type=int, default=4, help="batches per learning (the first is not timed)")
    parser.add_argument("--blocks", default=",".join(BLOCKS), help="comma-separated among " + ", ".join(BLOCKS))
    parser.add_argument("--learners", type=int, default=1, help="learners per cell, trained as one batch")
    parser.add_argument("--quick", action="store_true", help="1 round of 3 batches")
    parser.add_argument("--against", metavar="DIR", help="also run the package of the checkout DIR, in turn")
    parser.add_argument("--cell", help=argparse.SUPPRESS)  # one cell, JSON out (internal)
    args = parser.parse_args(argv)
    if args.cell:
        torch.set_num_threads(1)
        block, name, shaped, n, k = args.cell.split(",")
        rate, fpb = run_cell(block, domains()[name], shaped == "hrs", int(n), int(k))
        print(json.dumps({"rate": rate, "frames_per_batch": fpb}))
        return
    if args.against is not None and not (Path(args.against) / "torchrl_subgoal").is_dir():
        parser.error(f"--against: {args.against} holds no torchrl_subgoal package")
    repeats, batches = (1, 3) if args.quick else (args.repeats, args.batches)
    if repeats < 1 or batches < 2:
        parser.error("--repeats must be >= 1 and --batches >= 2")
    blocks = [b.strip() for b in args.blocks.split(",") if b.strip()]
    unknown = sorted(set(blocks) - set(BLOCKS))
    if unknown:
        parser.error(f"--blocks: unknown {unknown}; known: {', '.join(BLOCKS)}")
    torch.set_num_threads(1)
    known = domains()
    cells = [(b, d) for b, d in CELLS if b in blocks]
    sides: dict[str, str | None] = {"": None} if args.against is None else {"against": args.against, "this": None}
    rates: dict[tuple[str, str, bool, str], list[float]] = {}
    batch_frames: dict[tuple[str, str], int] = {}
    load = os.getloadavg()
    start = time.perf_counter()
    for _ in range(repeats):  # interleaved: every cell, both variants and both sides in each round
        for block, name in cells:
            for shaped in (False, True):
                for side, path in sides.items():
                    if args.against is None:
                        rate, fpb = run_cell(block, known[name], shaped, batches, args.learners)
                    else:
                        cell = f"{block},{name},{'hrs' if shaped else 'plain'},{batches},{args.learners}"
                        rate, fpb = _child(cell, path)
                    rates.setdefault((block, name, shaped, side), []).append(rate)
                    batch_frames[block, name] = fpb
    wall = time.perf_counter() - start
    print(
        f"Learner frames per CPU second (one core), {args.learners} learner(s) per cell, "
        f"best of {repeats} round(s) of {batches} batches "
        f"(the first untimed); load average {load[0]:.1f} / {os.getloadavg()[0]:.1f} (before / after), "
        f"wall time {wall:.0f} s.\n"
    )
    if args.against is not None:
        print(f"against: {args.against}\n")
        print(
            "| learner | domain | frames per batch | plain (against) | plain (this) | this / against | "
            "HRS (against) | HRS (this) | this / against |"
        )
        print("|---|---|---|---|---|---|---|---|---|")
        for block, name in cells:
            row = f"| {block.upper()} | {name} | {batch_frames[block, name]} |"
            for shaped in (False, True):
                old, new = rates[block, name, shaped, "against"], rates[block, name, shaped, "this"]
                ratio = statistics.median(n / o for n, o in zip(new, old, strict=True))
                row += f" {max(old):,.0f} | {max(new):,.0f} | {ratio:.2f} |"
            print(row)
        return
    print("| learner | domain | frames per batch | plain | HRS | HRS / plain (median of rounds) |")
    print("|---|---|---|---|---|---|")
    for block, name in cells:
        plain, hrs = rates[block, name, False, ""], rates[block, name, True, ""]
        ratio = statistics.median(h / p for h, p in zip(hrs, plain, strict=True))
        print(
            f"| {block.upper()} | {name} | {batch_frames[block, name]} | {max(plain):,.0f} | {max(hrs):,.0f} | "
            f"{ratio:.2f} |"
        )


if __name__ == "__main__":
    main()

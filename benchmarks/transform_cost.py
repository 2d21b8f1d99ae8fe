"""What the shaping transform costs: Python calls per collector batch, and its share of an A2C iteration.

Part 1 counts the Python function calls (cProfile's count: calls into C count one each) a TorchRL
``Collector`` makes per batch of 16 four-rooms envs x 16 steps under a random policy, for:

* ``empty``: ``TransformedEnv(FourRoomsEnv(16), Compose())``, the floor every set-up is compared with;
* ``RewardSum + StepCounter``: TorchRL's two stateful transforms together, the yardstick;
* ``shaping, built-in predicates``: ``SubgoalPotentialTransform`` with the two hallways as ``Cell``
  predicates over ``"cell"`` and one shared ``TabularPotential`` (the A2C recipe's set-up);
* ``shaping, callable predicates``: the same subgoals written as plain functions of the TensorDict;
* ``shaping, the default potential``: the built-in predicates with ``TabularPotential.for_subgoals``
  (the progress prior, the monotone lift and the within-segment term).

It prints each set-up's calls per batch added over ``empty``. A count depends only on the work done,
not on the machine's load, so two versions of the library compare exactly: run the script with each on
``PYTHONPATH`` (``PYTHONPATH=/path/to/other/checkout python benchmarks/transform_cost.py --part 1``).

Part 2 times A2C iterations at the A2C recipe's four-rooms settings (collect 256 frames, GAE, one A2C
step, and for the shaped set-up one step of the potential on the batch's SMDP transitions), with and
without the HRS transform, in turns (``benchmarks/a2c_collection.py``'s paired rounds), and prints the
shaping's share of the shaped iteration's wall and CPU time (median over the rounds).

    python benchmarks/transform_cost.py             # both parts
    python benchmarks/transform_cost.py --part 1    # the call counts alone (a few seconds)
"""

from __future__ import annotations

import argparse
import cProfile
import pstats
import sys
from collections.abc import Callable
from pathlib import Path

import torch
from tensordict import TensorDictBase
from torchrl.collectors import Collector
from torchrl.envs import Compose, RewardSum, StepCounter, Transform, TransformedEnv

from torchrl_subgoal import Cell, SubgoalPotentialTransform, SubgoalSeries, TabularPotential
from torchrl_subgoal.envs import FourRoomsEnv

ENVS, STEPS = 16, 16
WEST_HALLWAY, SOUTH_HALLWAY = torch.tensor([3, 6]), torch.tensor([7, 9])


def in_west_hallway(td: TensorDictBase) -> torch.Tensor:
    """The first hallway, as a function of the step's TensorDict."""
    return (td.get("cell") == WEST_HALLWAY).all(-1)


def in_south_hallway(td: TensorDictBase) -> torch.Tensor:
    """The second hallway, as a function of the step's TensorDict."""
    return (td.get("cell") == SOUTH_HALLWAY).all(-1)


def shaping(callable_predicates: bool, default: bool = False) -> SubgoalPotentialTransform:
    """The hallways as built-in ``Cell`` predicates or as plain functions; one shared table (a plain one, or
    the library's default potential)."""
    subgoals = [in_west_hallway, in_south_hallway] if callable_predicates else [Cell(3, 6), Cell(7, 9)]
    series = SubgoalSeries(subgoals)
    potential = TabularPotential.for_subgoals(series) if default else TabularPotential(3)
    return SubgoalPotentialTransform(series, potential, gamma=0.99, observation_key="cell")


def setups() -> dict[str, Callable[[], Transform]]:
    return {
        "empty": Compose,
        "RewardSum + StepCounter": lambda: Compose(RewardSum(), StepCounter()),
        "shaping, built-in predicates": lambda: shaping(False),
        "shaping, callable predicates": lambda: shaping(True),
        "shaping, the default potential": lambda: shaping(False, default=True),
    }


def calls_per_batch(transform: Transform, batches: int) -> float:
    """Python calls per collected batch (after three warm-up batches), one collector in this process."""
    torch.manual_seed(0)
    collector = Collector(
        TransformedEnv(FourRoomsEnv(ENVS), transform), None, frames_per_batch=ENVS * STEPS, total_frames=-1
    )
    try:
        iterator = iter(collector)
        for _ in range(3):  # kernels compiled, tables built, caches filled
            next(iterator)
        profile = cProfile.Profile()
        profile.enable()
        for _ in range(batches):
            next(iterator)
        profile.disable()
    finally:
        collector.shutdown()
    return pstats.Stats(profile).total_calls / batches  # type: ignore[attr-defined]


def part_1(batches: int) -> None:
    counts = {name: calls_per_batch(make(), batches) for name, make in setups().items()}
    print(
        f"Part 1: Python calls per collector batch ({ENVS} four-rooms envs x {STEPS} steps, random policy, "
        f"mean of {batches} batches)"
    )
    empty = counts.pop("empty")
    print(f"  {'empty TransformedEnv':32s} {empty:8.0f}")
    pair = counts["RewardSum + StepCounter"]
    for name, count in counts.items():
        added = count - empty
        print(f"  {name:32s} {count:8.0f}   added {added:7.0f}   {added / (pair - empty):5.2f} x the pair's")


def part_2(repeats: int, batches: int) -> None:
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from a2c_collection import a2c_iterations, four_rooms_a2c, hrs_shaping, paired_costs

    domain = four_rooms_a2c()
    config = domain.a2c
    torch.manual_seed(0)
    pretrain, networks = a2c_iterations(None, domain, config, 120, online=False)
    pretrain()  # the same briefly trained policy in both set-ups (then kept: lr 0)
    runs = {
        "plain A2C": a2c_iterations(None, domain, config, batches, False, networks, lr=0.0)[0],
        "HRS": a2c_iterations(hrs_shaping(domain), domain, config, batches, False, networks, lr=0.0)[0],
    }
    costs, _ = paired_costs(runs, repeats, "plain A2C")
    print(
        f"Part 2: the shaping's share of an A2C iteration ({config.frames_per_batch} frames, {config.num_envs} "
        f"four-rooms envs, the recipe's settings; potential trained per batch), median of {repeats} rounds"
    )
    for clock in ("wall", "cpu"):
        cost = costs["HRS"][clock][0]
        print(f"  {clock:5s} {100 * cost / (1 + cost):5.1f}% of the shaped iteration")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    parser.add_argument("--part", choices=["1", "2", "both"], default="both")
    parser.add_argument("--batches", type=int, default=10, help="batches counted (part 1) or per round (part 2)")
    parser.add_argument("--repeats", type=int, default=11, help="paired rounds of part 2")
    args = parser.parse_args()
    torch.set_num_threads(1)
    if args.part != "2":
        part_1(args.batches)
    if args.part != "1":
        part_2(args.repeats, args.batches)


if __name__ == "__main__":
    main()

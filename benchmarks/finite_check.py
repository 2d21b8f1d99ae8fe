"""What the transform's NaN/inf check costs: env-steps per second with and without it.

Steps ``TransformedEnv(FourRoomsEnv(N), SubgoalPotentialTransform(...))`` (the ten
participants' patterns, tabular potential trained online) with random actions through
``step_and_maybe_reset``, alternating runs with the check and with it replaced by a
no-op (the machine is shared: compare the ratio, measured in one run), then times the
check alone on a ``[N, 1]`` reward and a ``[N, 4]`` float observation.

    python benchmarks/finite_check.py            # N = 1000
"""

from __future__ import annotations

import argparse
import statistics
import time
from importlib.resources import files

import torch
from torchrl.envs import TransformedEnv

import torchrl_subgoal.transform.compiled as transform_module
from torchrl_subgoal import SubgoalPotentialTransform, TabularPotential, load_patterns
from torchrl_subgoal.envs import FourRoomsEnv


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    parser.add_argument("--envs", type=int, default=1000)
    parser.add_argument("--steps", type=int, default=300)
    parser.add_argument("--repeats", type=int, default=7)
    args = parser.parse_args()
    torch.set_num_threads(1)
    n = args.envs
    patterns = list(
        load_patterns(
            str(files("torchrl_subgoal") / "domains" / "four_rooms" / "four_rooms_participants.yaml")
        ).values()
    )
    shaping = SubgoalPotentialTransform(
        [patterns[i % len(patterns)] for i in range(n)],
        TabularPotential(3, (n,)),
        gamma=0.99,
        observation_key="cell",
        value_update=0.1,
    )
    env = TransformedEnv(FourRoomsEnv(n), shaping)
    td = env.reset()
    check = transform_module.check_finite

    def rate() -> float:
        nonlocal td
        start = time.perf_counter()
        for _ in range(args.steps):
            td["action"] = torch.randint(0, 4, (n,))
            _, td = env.step_and_maybe_reset(td)
        return args.steps / (time.perf_counter() - start)

    rates: dict[str, list[float]] = {"with": [], "without": []}
    for _ in range(args.repeats):
        for name in rates:
            transform_module.check_finite = check if name == "with" else (lambda *a: None)
            rates[name].append(rate())
    transform_module.check_finite = check
    with_, without = statistics.median(rates["with"]), statistics.median(rates["without"])
    print(f"{n} envs: {with_:.0f} steps/s with the check, {without:.0f} without, ratio {with_ / without:.3f}")
    reward, obs = torch.zeros(n, 1), torch.rand(n, 4)
    start = time.perf_counter()
    for _ in range(10_000):
        check(reward, obs, "reward", "observation")
    print(f"the check alone: {(time.perf_counter() - start) / 10_000 * 1e6:.1f} µs per step")


if __name__ == "__main__":
    main()

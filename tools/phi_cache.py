"""The shaping transform's Φ cache with pick and place's neural potential: what its check costs beside
one evaluation of ``V``, and the CPU time per env step of a collecting worker.

Prints, for ``V`` the recipe's way (``NeuralPotential`` of a 25 → 3 × 256 → 1 MLP), on one torch thread:

* the microseconds of the cache's once-per-step check that ``V``'s parameters have not changed, and of
  ``V``'s forward at batch 3, 6 and 9 (the cache pays off while its check costs less than the
  evaluations it saves);
* the CPU microseconds per env step of a ``Collector`` over ``--envs`` Fetch envs in this process (one
  ``paper`` collector worker's share: 3), HRS shaping, the recipe's exploring policy, envs stepped with
  ``fetch.LeanStep``; the least of ``--repeats`` timings of ``--steps`` steps.

CPU time (``process_time``) is what other processes disturb least on a shared machine. To compare two
versions of the library, run this script with each on ``PYTHONPATH``, alternately::

    python tools/phi_cache.py
    PYTHONPATH=/path/to/other/checkout python tools/phi_cache.py
"""

from __future__ import annotations

import argparse
import os
import time
from collections.abc import Callable
from functools import partial

import torch
from tensordict import TensorDict
from torchrl.collectors import Collector

from torchrl_subgoal import NeuralPotential
from torchrl_subgoal.envs import fetch
from torchrl_subgoal.training import Shaping, shaped_env
from torchrl_subgoal.training.ddpg_parts import DDPGAgent, DDPGConfig, mlp
from torchrl_subgoal.transform.cache import ValueCache as _ValueCache

try:
    from torchrl_subgoal.training import close_collector
except ImportError:  # a version of the library before close_collector: a Collector needs no more

    def close_collector(collector: Collector) -> None:
        collector.shutdown()


def micros(call: Callable[[], object], n: int) -> float:
    """CPU µs per call of ``call`` (after 100 warm-up calls)."""
    for _ in range(100):
        call()
    start = time.process_time()
    for _ in range(n):
        call()
    return 1e6 * (time.process_time() - start) / n


def collector_cpu(envs: int, steps: int, repeats: int) -> list[float]:
    """CPU µs per env step of a HRS-shaped ``Collector`` over ``envs`` Fetch envs, ``repeats`` timings."""
    series = fetch.human_patterns()["participants"]
    shaping = Shaping([series], NeuralPotential(mlp(fetch.OBSERVATION_SIZE, 1, (256, 256, 256))))
    env = shaped_env(
        partial(fetch.make_fetch_envs, 0, lean=True), envs, shaping=shaping, gamma=0.98, episode_stats=False
    )
    agent = DDPGAgent(fetch.OBSERVATION_SIZE, env.action_spec_unbatched, DDPGConfig(buffer_size=1000))
    collector = Collector(
        env, agent.policy, frames_per_batch=50 * envs, total_frames=-1, auto_register_policy_transforms=False
    )
    batches = iter(collector)
    next(batches)
    costs = []
    for _ in range(repeats):
        start, done = time.process_time(), 0
        while done < steps:
            done += next(batches).numel()
        costs.append(1e6 * (time.process_time() - start) / done)
    close_collector(collector)
    return costs


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    parser.add_argument("--envs", type=int, default=3, help="envs of the collector (default 3)")
    parser.add_argument("--steps", type=int, default=3000, help="env steps per timing")
    parser.add_argument("--repeats", type=int, default=3, help="timings of the collector (the least is kept)")
    args = parser.parse_args()
    if min(args.envs, args.steps, args.repeats) < 1:
        parser.error("--envs, --steps and --repeats must be >= 1")
    torch.set_num_threads(1)
    potential = NeuralPotential(mlp(fetch.OBSERVATION_SIZE, 1, (256, 256, 256)))
    cache = _ValueCache()
    print(f"load average before: {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores")
    with torch.no_grad():
        for batch in (3, 6, 9):
            inputs = TensorDict(
                {key: torch.randn(batch, fetch.OBSERVATION_SIZE) for key in potential.in_keys}, batch_size=[batch]
            )
            forward = partial(lambda td: potential(td.clone(False)), inputs)
            print(f"V forward, batch {batch}: {micros(forward, 2000):6.0f} µs")
        print(f"the cache's check of V's parameters: {micros(lambda: cache.check(potential), 2000):6.0f} µs")
    costs = collector_cpu(args.envs, args.steps, args.repeats)
    print(
        f"Collector over {args.envs} envs, HRS, LeanStep: {min(costs):.0f} CPU µs per env step (least of "
        f"{args.repeats}; all: {', '.join(f'{c:.0f}' for c in costs)})"
    )
    print(f"load average after: {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()

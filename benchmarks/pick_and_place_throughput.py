"""Pick and place throughput: collector env-steps/s, DDPG gradient steps/s, projected learning time.

Measures, in one run (the machine is shared: compare the ratios, not the absolute rates):

* the raw gymnasium ``FetchPickAndPlace-v4`` env stepped in this process under
  random actions (the reference rate);
* a TorchRL ``Collector`` over ``TransformedEnv(ParallelEnv(n), HRS shaping)`` with
  the exploring DDPG policy, as the recipe collects (shaping and the neural potential
  in this process), for ``n`` = 1 and 2 MuJoCo worker processes of one env each, and
  2 workers of 5 envs each (``--envs 10 --env-processes 2`` in the recipe: the
  policy, the shaping and the inter-process hand-over are paid once per batch);
* DDPG gradient steps per second (critic + actor + Polyak-free, batch 256, 3 × 256
  hidden units, ``torch.set_num_threads(1)`` unless ``--threads``);
* from these, the projected wall time of one paper-scale learning (200 epochs of
  2,500 env steps, 40 gradient steps per 50 env steps, 10 test episodes per epoch) on
  one core: every part runs one after another in one process.

Every figure is the best of ``--repeats`` timings. The load average is printed
before and after: it says how busy the shared cores were.

Usage::

    python benchmarks/pick_and_place_throughput.py            # ~2 minutes on an idle machine
    python benchmarks/pick_and_place_throughput.py --quick    # fewer steps
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
from torchrl.envs import ParallelEnv, SerialEnv, TransformedEnv

from torchrl_subgoal import NeuralPotential, SubgoalPotentialTransform
from torchrl_subgoal.agents.ddpg import DDPGAgent, DDPGConfig, mlp
from torchrl_subgoal.envs import fetch

PAPER_STEPS = 500_000
UPDATES_PER_STEP = 40 / 50
TEST_STEPS_PER_STEP = 10 * 50 / 2_500


def best(run: Callable[[], float], repeats: int) -> float:
    """The best of ``repeats`` rates returned by ``run``."""
    return max(run() for _ in range(repeats))


def raw_rate(steps: int) -> float:
    gymnasium = fetch.require_fetch()
    env = gymnasium.make(fetch.BASE_ENV_ID)
    env.reset(seed=0)
    env.action_space.seed(0)
    actions = [env.action_space.sample() for _ in range(64)]
    start = time.perf_counter()
    for i in range(steps):
        _, _, terminated, truncated, _ = env.step(actions[i % 64])
        if terminated or truncated:
            env.reset()
    rate = steps / (time.perf_counter() - start)
    env.close()
    return rate


def collector_rate(workers: int, per_worker: int, steps: int, repeats: int) -> float:
    make = partial(fetch.make_fetch_env, 0)
    base = ParallelEnv(workers, make if per_worker == 1 else partial(SerialEnv, per_worker, make))
    series = fetch.human_patterns()["participants"]
    potential = NeuralPotential(mlp(fetch.OBSERVATION_SIZE, 1, (256, 256, 256)))
    env = TransformedEnv(base, SubgoalPotentialTransform(series, potential, gamma=0.98, write_transitions=True))
    agent = DDPGAgent(fetch.OBSERVATION_SIZE, base.action_spec_unbatched, DDPGConfig(buffer_size=1000))
    collector = Collector(env, agent.policy, frames_per_batch=50 * workers * per_worker, total_frames=-1,
                          auto_register_policy_transforms=False)
    batches = iter(collector)
    next(batches)  # warm-up: workers started, first reset done

    def run() -> float:
        start = time.perf_counter()
        done = 0
        while done < steps:
            done += next(batches).numel()
        return done / (time.perf_counter() - start)

    rate = best(run, repeats)
    collector.shutdown()
    return rate


def update_rate(updates: int, repeats: int) -> float:
    spec = fetch.make_fetch_env(0).action_spec_unbatched
    agent = DDPGAgent(fetch.OBSERVATION_SIZE, spec, DDPGConfig(buffer_size=20_000))
    n = 10_000
    agent.extend(TensorDict({
        "observation": torch.randn(n, fetch.OBSERVATION_SIZE), "action": spec.rand((n,)),
        "next": {"observation": torch.randn(n, fetch.OBSERVATION_SIZE), "reward": -torch.ones(n, 1),
                 "done": torch.zeros(n, 1, dtype=torch.bool), "terminated": torch.zeros(n, 1, dtype=torch.bool)},
    }, [n]))
    for _ in range(10):
        agent.update()

    def run() -> float:
        start = time.perf_counter()
        for i in range(updates):
            agent.update()
            if i % 40 == 39:
                agent.soft_update()
        return updates / (time.perf_counter() - start)

    return best(run, repeats)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    parser.add_argument("--quick", action="store_true", help="fewer steps per timing")
    parser.add_argument("--repeats", type=int, default=3, help="timings per figure (best is kept)")
    parser.add_argument("--threads", type=int, default=1, help="torch threads for the gradient steps")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    steps = 1_000 if args.quick else 3_000
    print(f"load average before: {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores")
    raw = best(lambda: raw_rate(steps), args.repeats)
    print(f"raw gymnasium env, 1 process:        {raw:8.0f} env-steps/s  (1.00x)")
    rates = {}
    for workers, per_worker in ((1, 1), (2, 1), (2, 5)):
        rate = rates[workers, per_worker] = collector_rate(workers, per_worker, steps, args.repeats)
        print(f"Collector, HRS shaping, {workers} worker(s) x {per_worker} env(s): {rate:8.0f} env-steps/s  "
              f"({rate / raw:.2f}x raw)")
    updates = update_rate(200 if args.quick else 600, args.repeats)
    print(f"DDPG gradient steps, batch 256, {args.threads} thread(s): {updates:6.1f} steps/s "
          f"({1e3 / updates:.1f} ms each)")
    env_seconds = PAPER_STEPS * (1 + TEST_STEPS_PER_STEP) / rates[1, 1]
    update_seconds = PAPER_STEPS * UPDATES_PER_STEP / updates
    total = env_seconds + update_seconds
    print(f"projected paper-scale learning (5e5 steps, 4e5 gradient steps) on one core: {total / 60:.0f} min "
          f"= {env_seconds / 60:.0f} min collecting and testing (1-worker collector rate) + "
          f"{update_seconds / 60:.0f} min of gradient steps; goal <= 45 min")
    print(f"load average after: {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()

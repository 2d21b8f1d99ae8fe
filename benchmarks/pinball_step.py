"""Throughput of the batched PinBall env, in ball-steps per second, beside pynball-rl.

Measures, on the simple map with one torch thread:

* the raw physics kernel (:class:`PinBallPhysics.step`) of each backend
  (numba, torch eager, and torch.compile at the largest batch);
* the full TorchRL loop ``env.step_and_maybe_reset`` (numba and torch
  backends), which adds TorchRL's fixed per-call cost;
* the single-ball rate of the ``pynball-rl`` package (``pip install
  pynball-rl``) on its copy of the same map.

Every figure is the best of several timed repeats (the machine is shared and
noisy); balls start spread over the map with random velocities (kernel) or
after a warm-up from the start (env loop), under uniformly random actions.

Usage::

    python benchmarks/pinball_step.py           # full run (compiles torch: ~2 min more)
    python benchmarks/pinball_step.py --quick   # short run, no torch.compile
"""

from __future__ import annotations

import argparse
import random
import time
from collections.abc import Callable

import torch

from torchrl_subgoal.envs.pinball import PinBallEnv, PinBallPhysics

BATCHES = (1, 100, 1000)


def best_rate(run: Callable[[int], None], balls: int, min_time: float, repeats: int) -> float:
    """Best ball-steps/s over ``repeats`` timings of ``run(steps)``, each at least ``min_time``."""
    steps = 1
    while True:  # grow the step count until one timing lasts long enough
        start = time.perf_counter()
        run(steps)
        elapsed = time.perf_counter() - start
        if elapsed >= min_time:
            break
        steps *= 2 if elapsed < min_time / 4 else 1 + int(min_time / max(elapsed, 1e-9))
    best = steps / elapsed
    for _ in range(repeats - 1):
        start = time.perf_counter()
        run(steps)
        best = max(best, steps / (time.perf_counter() - start))
    return best * balls


def action_pool(balls: int, size: int = 64) -> list[torch.Tensor]:
    generator = torch.Generator().manual_seed(0)
    return [torch.randint(5, (balls,), generator=generator) for _ in range(size)]


def kernel_rate(backend: str, balls: int, min_time: float, repeats: int) -> tuple[float, float]:
    """Ball-steps/s of the physics kernel, and the seconds the first call took (compilation)."""
    physics = PinBallPhysics("simple", backend=backend)  # type: ignore[arg-type]
    env = PinBallEnv(1, "simple")
    generator = torch.Generator().manual_seed(0)
    position = env.sample_free_positions(balls, generator).double()
    velocity = torch.rand(balls, 2, generator=generator, dtype=torch.float64) * 2.0 - 1.0
    actions = action_pool(balls)
    start = time.perf_counter()
    physics.step(position, velocity, actions[0])
    first_call = time.perf_counter() - start

    def run(steps: int) -> None:
        for i in range(steps):
            physics.step(position, velocity, actions[i % len(actions)])

    return best_rate(run, balls, min_time, repeats), first_call


def env_rate(backend: str, balls: int, min_time: float, repeats: int, warmup: int) -> float:
    """Ball-steps/s of ``env.step_and_maybe_reset`` with the actions set in the loop."""
    env = PinBallEnv(balls, "simple", seed=0, backend=backend)  # type: ignore[arg-type]
    actions = action_pool(balls)
    td = env.reset()
    for i in range(warmup):
        td["action"] = actions[i % len(actions)]
        _, td = env.step_and_maybe_reset(td)

    def run(steps: int) -> None:
        nonlocal td
        for i in range(steps):
            td["action"] = actions[i % len(actions)]
            _, td = env.step_and_maybe_reset(td)

    return best_rate(run, balls, min_time, repeats)


def pynball_rate(min_time: float, repeats: int) -> float | None:
    """Single-ball steps/s of pynball-rl on its copy of the simple map (None if not installed)."""
    try:
        import importlib.resources
        from pathlib import Path

        from pynball_rl.pynball_env import PynBall
    except ImportError:
        return None
    config = importlib.resources.files("pynball_rl.configs") / "easy_config.toml"
    game = PynBall(Path(str(config)))
    game.reset()
    rng = random.Random(0)
    actions = [rng.randrange(5) for _ in range(4096)]

    def run(steps: int) -> None:
        for i in range(steps):
            _, _, terminal, _ = game.step(actions[i % len(actions)])
            if terminal:
                game.reset()

    return best_rate(run, 1, min_time, repeats)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="short timings, no torch.compile")
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    min_time, repeats = (0.1, 3) if args.quick else (0.4, 5)
    warmup = 20 if args.quick else 100

    try:
        import numba  # noqa: F401

        backends = ["numba", "torch"]
    except ImportError:
        print("numba is not installed: only the torch backends are measured")
        backends = ["torch"]

    print(f"PinBall simple map, ball-steps/s (best of {repeats}), torch threads = 1")
    reference = pynball_rate(min_time, repeats)
    if reference is None:
        print("pynball-rl        not installed (pip install pynball-rl)")
    else:
        print(f"pynball-rl        N=1: {reference:>12,.0f}")

    rows: dict[str, dict[int, float]] = {}
    for backend in backends:
        rows[f"kernel {backend}"] = {n: kernel_rate(backend, n, min_time, repeats)[0] for n in BATCHES}
    if not args.quick:
        rate, compile_time = kernel_rate("compile", BATCHES[-1], min_time, repeats)
        rows["kernel compile"] = {BATCHES[-1]: rate}
        print(f"(torch.compile: first call {compile_time:.0f} s, measured at N={BATCHES[-1]} only)")
    for backend in backends:
        rows[f"env loop {backend}"] = {n: env_rate(backend, n, min_time, repeats, warmup) for n in BATCHES}

    header = "".join(f"{f'N={n}':>14}" for n in BATCHES)
    print(f"{'':18}{header}")
    for name, rates in rows.items():
        cells = "".join(f"{rates[n]:>14,.0f}" if n in rates else f"{'-':>14}" for n in BATCHES)
        print(f"{name:18}{cells}")
    if reference is not None:
        n = BATCHES[-1]
        print(f"ratio to pynball-rl at N={n:,}:")
        for name, rates in rows.items():
            print(f"  {name:16}{rates[n] / reference:>10,.0f}x")


if __name__ == "__main__":
    main()

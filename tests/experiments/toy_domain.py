"""A tiny synthetic domain for the experiment-engine tests.

``run_chunk`` fabricates deterministic learning curves from the chunk seed, so a
sweep's results depend only on (seed, chunk layout), never on the backend or on
the order chunks run in. Environment variables steer it from outside the process
(spawn workers and a Ray instance the sweep starts inherit them; a running cluster's workers get those
of the `ray start` of their node):

* ``TOY_SLEEP``: seconds each chunk sleeps (default 0);
* ``TOY_LOG``: a file each chunk appends ``<TOY_TAG> <chunk name> <pid> <Ray node or ->`` to when it starts;
* ``TOY_FAIL``: a chunk name (``HRS/00001``) that raises instead of finishing;
* ``TOY_GATE`` and ``TOY_FREE``: a file path and comma-separated chunk names; every
  chunk not named waits until the file exists (at most 10 minutes), so a test can
  interrupt a sweep at a known point without depending on timing.

Run as a module it runs a sweep (``sweep DIR [--backend ray]``; a failed chunk is one line on stderr and
exit code 1, as in the recipes) or writes a synthetic paper-scale results directory (``paper-scale DIR``:
5 methods x 1000 learners x 1000 episodes).
"""

from __future__ import annotations

import argparse
import os
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from torchrl_subgoal.experiments import Chunk, ChunkFailedError, EpisodeTable, MethodSpec, Sweep
from torchrl_subgoal.experiments.recipe import fail

DOMAIN = "toy"
PATTERNS = {
    "p1": [{"cell": [4, 9]}, {"cell": [11, 9]}],
    "p2": [{"cell": [6, 2]}, {"cell": [10, 6]}],
}
# time constant of each method's fake learning curve: smaller learns faster; STUCK never learns
SCALES = {"HRS": 4.0, "RRS": 6.0, "SARSA": 9.0, "NRS": 12.0, "SARSA-RS": 7.0, "STUCK": np.inf}


def toy_methods(learnings: int = 3, names: Sequence[str] = ("HRS", "SARSA")) -> list[MethodSpec]:
    """Methods with subgoals get both patterns; the others one pseudo-pattern."""
    return [
        MethodSpec(name, list(PATTERNS), learnings)
        if name in ("HRS", "RRS", "NRS")
        else MethodSpec(name, ["none"], 2 * learnings)
        for name in names
    ]


def toy_config(n_episodes: int = 30, window: int = 1) -> dict[str, Any]:
    return {
        "n_episodes": n_episodes,
        "patterns": PATTERNS,
        "report": {
            "metric": "steps",
            "lower_is_better": True,
            "thresholds": [500, 100],
            "window": window,
            "asymptotic_window": [n_episodes - 5, n_episodes],
        },
    }


def run_chunk(chunk: Chunk, config: Mapping[str, Any], progress: Any) -> EpisodeTable:
    """Fake learners: steps decay like 1000 exp(-episode / scale) plus noise."""
    if os.environ.get("TOY_LOG"):
        with open(os.environ["TOY_LOG"], "a") as log:
            log.write(f"{os.environ.get('TOY_TAG', '')} {chunk.name} {os.getpid()} {_ray_node()}\n")
    if os.environ.get("TOY_FAIL") == chunk.name:
        raise RuntimeError(f"toy failure in {chunk.name}")
    gate = os.environ.get("TOY_GATE")
    if gate and chunk.name not in os.environ.get("TOY_FREE", "").split(","):
        deadline = time.monotonic() + 600
        while not os.path.exists(gate) and time.monotonic() < deadline:
            time.sleep(0.05)
    n, e = chunk.n_learners, int(config["n_episodes"])
    rng = np.random.default_rng(chunk.seed)
    episode = np.arange(e)
    scale = SCALES.get(chunk.method, 10.0) * rng.uniform(0.5, 1.5, size=(n, 1))
    noise = rng.lognormal(0.0, 0.3, size=(n, e))
    steps = np.minimum(1000, np.round(20 + 980 * np.exp(-episode / scale) * noise)).astype(np.int64)
    success = steps < 1000
    returns = success * 0.99**steps
    sleep = float(os.environ.get("TOY_SLEEP", "0"))
    for _ in range(n):
        time.sleep(sleep / n)
        progress(e)
    return EpisodeTable(steps, returns, success)


def _ray_node() -> str:
    """The Ray node this process is a worker of, or ``-``."""
    import sys

    ray = sys.modules.get("ray")
    if ray is None or not ray.is_initialized():
        return "-"
    return str(ray.get_runtime_context().get_node_id())


def paper_scale(results_dir: Path) -> None:
    """5 methods x 1000 learners x 1000 episodes = 5M rows."""
    names = ("HRS", "RRS", "SARSA", "NRS", "SARSA-RS")
    methods = [
        MethodSpec(n, [f"p{i}" for i in range(10)], 100)
        if n in ("HRS", "RRS", "NRS")
        else MethodSpec(n, ["none"], 1000)
        for n in names
    ]
    config = toy_config(1000)
    config["report"]["thresholds"] = [500, 300, 100, 50]
    config["report"]["asymptotic_window"] = [990, 1000]
    Sweep("four_rooms", results_dir, methods, run_chunk, config, seed=0, chunk_size=100, n_episodes=1000).run(
        workers=0, progress=False
    )


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("command", choices=["sweep", "paper-scale"])
    parser.add_argument("results_dir", type=Path)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--learnings", type=int, default=3)
    parser.add_argument("--chunk-size", type=int, default=1)
    parser.add_argument("--episodes", type=int, default=30)
    parser.add_argument("--backend", choices=["local", "ray"], default="local")
    args = parser.parse_args(argv)
    if args.command == "paper-scale":
        paper_scale(args.results_dir)
        return 0
    sweep = Sweep(
        DOMAIN,
        args.results_dir,
        toy_methods(args.learnings),
        run_chunk,
        toy_config(args.episodes),
        seed=7,
        chunk_size=args.chunk_size,
        n_episodes=args.episodes,
    )
    try:
        sweep.run(backend=args.backend, workers=args.workers, progress=False)
    except ChunkFailedError as exc:
        return fail(exc)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

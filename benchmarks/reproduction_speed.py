"""Wall time, CPU time and tail of the paper reproductions (four-rooms, PinBall), end to end.

For each reproduction this runs the recipe's command as a user would (its
default methods and chunking, ``--workers 2``, a fresh results directory,
report included) and prints:

* wall time of the command and of its sweep (until the last chunk is stored),
* CPU time of the process and its workers, and the average cores busy (CPU / wall),
* learner-steps (the sum of every recorded episode's steps) per second of sweep wall time,
* the share of the sweep's wall time spent after 99% of the learner-episodes were done.

``--engine`` measures instead the fused engine alone, in one process: CPU time per
recorded learner-step of one batch (four-rooms: 100 unshaped SARSA learners, 300
episodes; PinBall: 50 actor-critic learners, 3 episodes capped at 2,000 steps).
``--engine --shaped`` shapes the four-rooms learners as most of the paper's methods
do: a three-subgoal series (states 25, 51, 77), each learner with its own
potential table learnt online (``value_lr`` 0.25, γ 0.99).

``--against DIR`` also runs the reproductions with the package of another
checkout (e.g. the commit before a change: ``git worktree add /tmp/before <commit>``),
alternating the two in every repeat so that both see the same machine load,
and prints the ratios. The numba caches are warmed first (a tiny run) on each side.

Usage::

    python benchmarks/reproduction_speed.py                 # paper scale: four-rooms then PinBall
    python benchmarks/reproduction_speed.py --quick         # 1/10 of the learnings, 1/4 of PinBall's episodes
    python benchmarks/reproduction_speed.py --domains four_rooms --against /tmp/before --repeats 2
    python benchmarks/reproduction_speed.py --engine --against /tmp/before --repeats 3
    python benchmarks/reproduction_speed.py --engine --shaped --domains four_rooms --against /tmp/before
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import io
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from statistics import median
from typing import Any

#: the recipe's arguments at the paper's scale and at --quick scale
SCALES: dict[str, dict[str, list[str]]] = {
    "four_rooms": {"paper": ["--learnings", "100"], "quick": ["--learnings", "10"]},
    "pinball": {"paper": ["--learnings", "10"], "quick": ["--learnings", "2", "--episodes", "50"]},
}
WARM_UP: dict[str, list[str]] = {  # compiles (or loads) every numba kernel the run needs
    "four_rooms": ["--learnings", "1", "--episodes", "2"],
    "pinball": ["--learnings", "1", "--episodes", "1", "--max-steps", "50"],
}
FIGURES = ("wall_s", "sweep_wall_s", "cpu_s", "cores_busy", "learner_steps_per_s", "tail_share")
ENGINE_FIGURES = ("cpu_ns_per_learner_step", "learner_steps")


def measure_engine(domain: str, batch_size: int | None = None, shaped: bool = False) -> dict[str, float]:
    """CPU time per recorded learner-step of the fused engine on one batch (after a compiling run) of
    ``batch_size`` learners (default 100 for four-rooms, 50 for PinBall); ``shaped``: four-rooms with
    a three-subgoal series and a potential table per learner (see the module doc)."""
    import torch
    from torchrl.envs import TransformedEnv

    from torchrl_subgoal import State, SubgoalPotentialTransform, SubgoalSeries, TabularPotential
    from torchrl_subgoal.envs import FourRoomsEnv, PinBallEnv
    from torchrl_subgoal.fused import (
        AC_PRESETS,
        SARSA_PRESETS,
        FourierActorCritic,
        SoftmaxSarsa,
        run_episodes,
    )

    torch.set_num_threads(1)

    def batch(n: int) -> tuple[Any, Any, int]:
        if domain == "four_rooms":
            grid = FourRoomsEnv(n)
            agent = SoftmaxSarsa(n, grid.num_states, 4, SARSA_PRESETS["released"], seed=1)
            if not shaped:
                return grid, agent, 300
            series = SubgoalSeries([State(25), State(51), State(77)])
            shaping = SubgoalPotentialTransform(series, TabularPotential(4, (n,)), gamma=0.99, value_update=0.25)
            return TransformedEnv(grid, shaping), agent, 300
        table = PinBallEnv(n, seed=1, max_steps=2000)
        spec = table.observation_spec["observation"]
        return table, FourierActorCritic(n, spec.low[0], spec.high[0], 5, AC_PRESETS["released"], seed=1), 3

    run_episodes(*batch(2)[:2], 1, engine="fused")  # compiles or loads the kernels
    env, agent, episodes = batch(batch_size or (100 if domain == "four_rooms" else 50))
    cpu = time.process_time()
    records = run_episodes(env, agent, episodes, engine="fused")
    cpu = time.process_time() - cpu
    steps = int(records.steps.sum())
    return {"cpu_ns_per_learner_step": 1e9 * cpu / steps, "learner_steps": steps}


def _cpu_seconds() -> float:
    """User + system time of this process and of its reaped children (the sweep's workers)."""
    own, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


def _recipe(domain: str) -> Any:
    """The recipe module of the checkout whose package is imported (``<repo>/recipes/<domain>.py``),
    imported by name so that the sweep's spawned workers (which get this ``sys.path``) find it."""
    import torchrl_subgoal

    recipes = Path(torchrl_subgoal.__file__).resolve().parents[1] / "recipes"
    if not (recipes / f"{domain}.py").is_file():
        raise SystemExit(f"error: no recipe {domain}.py in {recipes}")
    sys.path.insert(0, str(recipes))
    return importlib.import_module(domain)


def measure(domain: str, args: list[str]) -> dict[str, float]:
    """Run one reproduction in this process (workers are its children) and return its figures."""
    from torchrl_subgoal.experiments import load_results, sweep

    timeline: list[tuple[float, int]] = []  # (seconds since start, learner-episodes done)
    start = time.perf_counter()

    class RecordingBar(sweep.ProgressBar):
        def add(self, name: str, k: int) -> None:
            super().add(name, k)
            timeline.append((time.perf_counter() - start, int(self.bar.n)))

        def done(self, chunk: Any, n_episodes: int) -> None:
            super().done(chunk, n_episodes)
            timeline.append((time.perf_counter() - start, int(self.bar.n)))

    sweep.ProgressBar = RecordingBar  # type: ignore[misc]
    recipe = _recipe(domain)
    with tempfile.TemporaryDirectory() as tmp:
        results = os.path.join(tmp, "results")
        cpu = _cpu_seconds()
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
            code = recipe.main([*args, "--workers", "2", "--results", results])
        wall, cpu = time.perf_counter() - start, _cpu_seconds() - cpu
        if code != 0:
            raise SystemExit(f"error: {domain} {' '.join(args)} exited with {code}")
        learner_steps = int(load_results(results).to_frame()["steps"].sum())
    total = timeline[-1][1]
    sweep_wall = timeline[-1][0]
    t99 = next(t for t, done in timeline if done >= 0.99 * total)
    return {
        "wall_s": wall,
        "sweep_wall_s": sweep_wall,
        "cpu_s": cpu,
        "cores_busy": cpu / wall,
        "learner_steps_per_s": learner_steps / sweep_wall,
        "tail_share": (sweep_wall - t99) / sweep_wall,
        "learner_steps": learner_steps,
    }


def _child(domain: str, args: list[str], pythonpath: str | None) -> dict[str, float]:
    """:func:`measure` in a fresh interpreter (with ``pythonpath`` first on the path, if given)."""
    env = dict(os.environ)
    if pythonpath is not None:
        env["PYTHONPATH"] = os.pathsep.join([pythonpath, *filter(None, [env.get("PYTHONPATH")])])
    command = [sys.executable, __file__, "--measure", domain, "--", *args]
    out = subprocess.run(command, env=env, capture_output=True, text=True, check=False)
    if out.returncode != 0:
        raise SystemExit(f"error: {' '.join(command)} failed:\n{out.stderr[-2000:]}")
    figures: dict[str, float] = json.loads(out.stdout.strip().splitlines()[-1])
    return figures


def _row(label: str, figures: dict[str, float]) -> str:
    return (
        f"| {label} | {figures['wall_s']:.1f} | {figures['sweep_wall_s']:.1f} | {figures['cpu_s']:.1f} | "
        f"{figures['cores_busy']:.2f} | {figures['learner_steps_per_s'] / 1e6:.2f} M | "
        f"{100 * figures['tail_share']:.1f}% |"
    )


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    parser.add_argument("--quick", action="store_true", help="a tenth of the learnings (PinBall: 50 episodes)")
    parser.add_argument("--domains", default="four_rooms,pinball", help="comma-separated: four_rooms, pinball")
    parser.add_argument("--repeats", type=int, default=1, help="runs per side; the table shows the medians")
    parser.add_argument("--against", metavar="DIR", help="also run the package of this checkout, alternating")
    parser.add_argument("--engine", action="store_true", help="the fused engine's CPU time per learner-step only")
    parser.add_argument(
        "--batch",
        type=int,
        metavar="N",
        help="--engine: learners per batch (default: 100 for "
        "four-rooms, 50 for PinBall; the recipes' chunks are 100 and 10)",
    )
    parser.add_argument(
        "--shaped",
        action="store_true",
        help="--engine: four-rooms shaped by a three-subgoal "
        "series, a potential table per learner (as most of the paper's methods)",
    )
    parser.add_argument("--measure", metavar="DOMAIN", help=argparse.SUPPRESS)  # one run, JSON out (internal)
    parser.add_argument("recipe_args", nargs="*", help=argparse.SUPPRESS)
    opts = parser.parse_args(argv)
    if opts.measure:
        if opts.recipe_args[:1] == ["engine"]:
            batch_size, shape = opts.recipe_args[1:3]
            figures = measure_engine(opts.measure, int(batch_size) or None, shape == "shaped")
        else:
            figures = measure(opts.measure, opts.recipe_args)
        print(json.dumps(figures))
        return
    domains = [d.strip() for d in opts.domains.split(",") if d.strip()]
    unknown = [d for d in domains if d not in SCALES]
    if unknown or opts.repeats < 1:
        raise SystemExit(f"error: --domains: choose from {list(SCALES)}; --repeats: >= 1 (got {unknown})")
    if opts.against is not None and not (Path(opts.against) / "torchrl_subgoal").is_dir():
        raise SystemExit(f"error: --against: {opts.against} holds no torchrl_subgoal package")
    sides: dict[str, str | None] = {"this checkout": None}
    if opts.against is not None:
        sides = {"against": opts.against, "this checkout": None}
    if opts.shaped and (not opts.engine or domains != ["four_rooms"]):
        raise SystemExit("error: --shaped measures the engine on four-rooms only: add --engine --domains four_rooms")
    if opts.engine:
        _engine_table(domains, sides, opts.repeats, opts.batch, opts.shaped)
        return
    scale = "quick" if opts.quick else "paper"
    print(f"{scale} scale, 2 workers, median of {opts.repeats} run(s) per side; {os.cpu_count()} CPUs\n")
    print("| reproduction | wall s | sweep wall s | CPU s | cores busy | learner-steps/s | wall after 99% |")
    print("|---|---|---|---|---|---|---|")
    for domain in domains:
        for path in sides.values():
            _child(domain, WARM_UP[domain], path)
        medians = _alternate(domain, SCALES[domain][scale], sides, opts.repeats, FIGURES)
        for label in sides:
            print(_row(f"{domain} ({label})", medians[label]), flush=True)
        if opts.against is not None:
            new, old = medians["this checkout"], medians["against"]
            print(
                f"| {domain}: this / against | {new['wall_s'] / old['wall_s']:.2f}x | "
                f"{new['sweep_wall_s'] / old['sweep_wall_s']:.2f}x | {new['cpu_s'] / old['cpu_s']:.2f}x | | "
                f"{new['learner_steps_per_s'] / old['learner_steps_per_s']:.2f}x | |",
                flush=True,
            )


def _alternate(
    domain: str, args: list[str], sides: dict[str, str | None], repeats: int, figures: tuple[str, ...]
) -> dict[str, dict[str, float]]:
    """Median figures per side over ``repeats`` runs, the sides alternating within every repeat."""
    runs: dict[str, list[dict[str, float]]] = {label: [] for label in sides}
    for _ in range(repeats):
        for label, path in sides.items():
            runs[label].append(_child(domain, args, path))
    return {label: {k: median(r[k] for r in rs) for k in figures} for label, rs in runs.items()}


def _engine_table(
    domains: list[str], sides: dict[str, str | None], repeats: int, batch: int | None, shaped: bool
) -> None:
    size = f", batches of {batch} learners" if batch else ""
    kind = "shaped (three-subgoal series, a potential table per learner)" if shaped else "unshaped"
    print(
        f"fused engine, {kind}, one process, median of {repeats} run(s) per side{size}; "
        f"load average {os.getloadavg()[0]:.2f}\n"
    )
    print("| engine | CPU ns per learner-step | learner-steps |")
    print("|---|---|---|")
    for domain in domains:
        args = ["engine", str(batch or 0), "shaped" if shaped else "unshaped"]
        medians = _alternate(domain, args, sides, repeats, ENGINE_FIGURES)
        for label in sides:
            m = medians[label]
            print(f"| {domain} ({label}) | {m['cpu_ns_per_learner_step']:.0f} | {m['learner_steps']:.0f} |", flush=True)
        if len(sides) == 2:
            ratio = medians["this checkout"]["cpu_ns_per_learner_step"] / medians["against"]["cpu_ns_per_learner_step"]
            print(f"| {domain}: this / against | {ratio:.2f}x | |", flush=True)
    print(f"\nload average at the end {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()

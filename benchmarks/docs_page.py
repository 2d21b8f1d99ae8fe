"""Run the benchmarks at a quick scale and write the documentation's benchmarks page.

Each benchmark script under ``benchmarks/`` (and two end-to-end reproductions at a
small scale) runs in its own process, one after another, under ``nice``; the page
records the machine (CPU model, cores, memory, library versions), the load average
before and after each run, and every script's printed output with its command and
wall time. The output is verbatim except for what would tie the page to one run rather
than to the figures: log lines with a time stamp are dropped and the temporary results
directory reads ``RESULTS``. A script that fails is reported on the page with its exit
status and the end of its error output, never left out.

    python benchmarks/docs_page.py docs/benchmarks.md       # `make bench-docs`
    python benchmarks/docs_page.py out.md --only four_rooms_step
"""

from __future__ import annotations

import argparse
import os
import platform
import re
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from importlib import metadata
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
_ANSI = re.compile(r"\x1b\[[0-9;]*m")
#: a log line that starts with a date and a time (TorchRL's ``[torchrl][INFO]`` lines)
_STAMPED = re.compile(r"^\d{4}-\d{2}-\d{2}[ T]\d{2}:\d{2}:\d{2}\S*\s.*$\n?", re.MULTILINE)


def clean(text: str, tmp: Path | None = None) -> str:
    r"""``text`` without terminal colour codes, without time-stamped log lines, and with the
    temporary directory ``tmp`` written ``RESULTS``.

    Examples:
        >>> log = "\x1b[32mok\x1b[0m\n2026-01-02 03:04:05,678 [torchrl][INFO] storage\nResults: `/tmp/x/a`"
        >>> clean(log, Path("/tmp/x"))
        'ok\nResults: `RESULTS/a`'
    """
    text = _STAMPED.sub("", _ANSI.sub("", text))
    return text.replace(str(tmp), "RESULTS") if tmp is not None else text


@dataclass(frozen=True)
class Run:
    """One command on the page.

    Attributes:
        name: short identifier (``--only``).
        title: the section heading.
        what: what it measures, one sentence.
        args: the command after ``python``, relative to the repository root;
            ``{tmp}`` is replaced by a fresh temporary directory.
    """

    name: str
    title: str
    what: str
    args: tuple[str, ...]


RUNS = (
    Run(
        "four_rooms_step",
        "Four-rooms env and the shaping transform",
        "env-steps per second of `FourRoomsEnv(1000)` bare, wrapped, with the shaping transform, and the "
        "TorchRL loop against the fused engine for SARSA + HRS.",
        ("benchmarks/four_rooms_step.py", "--quick"),
    ),
    Run(
        "pinball_step",
        "PinBall physics and env",
        "ball-steps per second of the batched PinBall physics (numba, torch) and of the TorchRL env loop, "
        "beside the single-ball `pynball-rl` package.",
        ("benchmarks/pinball_step.py", "--quick"),
    ),
    Run(
        "a2c_collection",
        "Collector throughput and the transform's cost in A2C",
        "frames per second of TorchRL `Collector`s over the batched four-rooms env (in process and over a "
        "`ParallelEnv`), and the time of one A2C iteration with and without the shaping transform.",
        ("benchmarks/a2c_collection.py", "--quick"),
    ),
    Run(
        "seed_batch",
        "Learners as a batch",
        "learner-frames per CPU-second of A2C and PPO learners run one at a time against the same learners "
        "stepped as one batch (`--seed-batch`), unshaped and with HRS.",
        ("benchmarks/seed_batch.py", "--quick"),
    ),
    Run(
        "arithmetic_bound",
        "How far a batch of DQN or DDPG learners can go on this CPU",
        "FLOPs per learner frame of DQN (MountainCar) and DDPG (PointMaze UMaze), the rate one core multiplies "
        "ten stacked copies of their MLPs, and the learner frames per CPU second a batch cannot exceed.",
        ("benchmarks/arithmetic_bound.py", "--frames", "2000", "--repeats", "20"),
    ),
    Run(
        "transform_cost",
        "What the shaping transform costs a collector and an A2C iteration",
        "Python calls per collector batch (16 four-rooms envs x 16 steps) the shaping transform adds over an "
        "empty `TransformedEnv`, beside TorchRL's `RewardSum` + `StepCounter`, and its share of an A2C "
        "iteration at the A2C recipe's four-rooms settings.",
        ("benchmarks/transform_cost.py", "--repeats", "5"),
    ),
    Run(
        "finite_check",
        "The NaN/inf check of the transform",
        "env-steps per second with and without the transform's finite-reward check.",
        ("benchmarks/finite_check.py", "--steps", "200", "--repeats", "3"),
    ),
    Run(
        "pick_and_place_throughput",
        "Pick-and-place collection and DDPG steps",
        "MuJoCo Fetch env-steps per second raw and through shaped collectors (the recipe's stack, whose envs "
        "step with `fetch.LeanStep`, beside the same with gymnasium's step), CPU time per env step beside the "
        "raw env's, DDPG gradient steps per CPU second (beside a hand-written torch step), the FLOP floor, and "
        "the projected time of one paper-scale learning.",
        ("benchmarks/pick_and_place_throughput.py", "--quick", "--repeats", "1"),
    ),
    Run(
        "training_throughput",
        "Learner frames per second of the training building blocks",
        "frames per CPU second of A2C, PPO, DQN and DDPG learnings (four-rooms, PinBall, PointMaze UMaze) "
        "without shaping and with HRS, and the median HRS / plain ratio.",
        ("benchmarks/training_throughput.py", "--quick"),
    ),
    Run(
        "studio_try_it",
        "The studio's Try it",
        "wall time of the studio's *Try it* (HRS and the unshaped learner on the fused engine) at its default "
        "and largest settings, for four-rooms and PinBall.",
        ("benchmarks/studio_try_it.py",),
    ),
    Run(
        "four_rooms_demo",
        "End to end: the four-rooms reproduction at `make demo` scale",
        "wall time of `make demo`'s run (5 methods x 10 patterns x 10 learnings x 1,000 episodes, fused engine) "
        "including the report, in one worker process (`make demo` uses 2).",
        ("recipes/four_rooms.py", "--workers", "1", "--results", "{tmp}/four_rooms"),
    ),
    Run(
        "pinball_small",
        "End to end: a small PinBall reproduction",
        "wall time of `recipes/pinball.py` at 1 learning per pattern (10 learners per method, 200 episodes), "
        "in one worker process.",
        ("recipes/pinball.py", "--learnings", "1", "--workers", "1", "--results", "{tmp}/pinball"),
    ),
    Run(
        "reproduction_speed",
        "End to end: the four-rooms reproduction at the paper's scale",
        "wall time, CPU time, cores busy, learner-steps per second and the share of wall time after 99% of the "
        "learner-episodes of `recipes/four_rooms.py --learnings 100` (5 methods x 1,000 learnings x 1,000 "
        "episodes, 2 workers, report included).",
        ("benchmarks/reproduction_speed.py", "--domains", "four_rooms"),
    ),
)


def _cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def _memory_gib() -> str:
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemTotal"):
                return f"{int(line.split()[1]) / 2**20:.0f} GiB"
    except OSError:
        pass
    return "unknown"


def _load() -> str:
    try:
        return " / ".join(f"{x:.1f}" for x in os.getloadavg())
    except OSError:
        return "unknown"


def _version(package: str) -> str:
    try:
        return metadata.version(package)
    except metadata.PackageNotFoundError:
        return "not installed"


def machine() -> list[str]:
    """The machine table of the page."""
    rows = [
        ("CPU", _cpu_model()),
        ("cores (logical, as the OS reports)", str(os.cpu_count())),
        ("memory", _memory_gib()),
        ("OS", f"{platform.system()} {platform.release()}"),
        ("Python", platform.python_version()),
        *((name, _version(name)) for name in ("torch", "torchrl", "tensordict", "numba", "mujoco")),
    ]
    return ["| | |", "|---|---|", *(f"| {k} | {v} |" for k, v in rows)]


def run(item: Run, tmp: Path, timeout: float) -> list[str]:
    """Run one command; its section of the page."""
    args = [a.replace("{tmp}", str(tmp)) for a in item.args]
    command = ["nice", "-n", "5", sys.executable, *args]
    shown = "python " + " ".join(item.args).replace("{tmp}", "RESULTS")
    print(f"[bench-docs] {shown}", file=sys.stderr, flush=True)
    load_before = _load()
    start = time.perf_counter()
    try:
        done = subprocess.run(
            command,
            cwd=ROOT,
            capture_output=True,
            text=True,
            timeout=timeout,
            env={**os.environ, "PYTHONUNBUFFERED": "1"},
        )
        status, out, err = done.returncode, done.stdout, done.stderr
    except subprocess.TimeoutExpired as exc:
        status = None
        out = exc.stdout.decode() if isinstance(exc.stdout, bytes) else (exc.stdout or "")
        err = f"timed out after {timeout:.0f} s"
    wall = time.perf_counter() - start
    lines = [
        f"## {item.title}",
        "",
        item.what,
        "",
        f"`{shown}`: wall time {wall:.0f} s, load average (1/5/15 min) {load_before} before, {_load()} after.",
        "",
    ]
    if status != 0:
        tail = "\n".join(clean(err, tmp).strip().splitlines()[-15:])
        lines += [
            f"**Failed** ({'timeout' if status is None else f'exit status {status}'}):",
            "",
            "```text",
            tail,
            "```",
            "",
        ]
    if out.strip():
        lines += ["```text", clean(out, tmp).rstrip(), "```", ""]
    return lines


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    parser.add_argument("output", type=Path, help="the Markdown page to write (docs/benchmarks.md)")
    parser.add_argument("--only", default="", help="comma-separated run names (default: all)")
    parser.add_argument("--timeout", type=float, default=1800.0, help="seconds per run before it is stopped")
    args = parser.parse_args(argv)
    wanted = [w for w in args.only.split(",") if w]
    unknown = sorted(set(wanted) - {r.name for r in RUNS})
    if unknown:
        parser.error(f"--only: unknown run(s) {unknown}; known: {[r.name for r in RUNS]}")
    runs = [r for r in RUNS if not wanted or r.name in wanted]
    cores = os.cpu_count() or 1
    head = [
        "# Benchmarks",
        "",
        "Generated by `make bench-docs` (`python benchmarks/docs_page.py docs/benchmarks.md`): every "
        "benchmark under `benchmarks/` at its quick scale and two end-to-end reproductions at a small "
        "scale, one after another, each in its own process under `nice -n 5`. The output below is each "
        "script's (log lines with a time stamp left out). One section can be measured again on its own "
        "(`python benchmarks/docs_page.py OUT --only NAME`, the names in `benchmarks/docs_page.py`).",
        "",
        '!!! note "Reading the figures"',
        f"    Each run's load average is printed with it: with {cores} logical cores, a load above {cores} "
        "means the run waited for a core, and its absolute rates are then low. Compare the ratios *within* "
        "one benchmark, whose set-ups are timed in one run. The reproduction pages give the figures "
        "measured for their own claims.",
        "",
        "## Machine",
        "",
        *machine(),
        "",
    ]
    body: list[str] = []
    with tempfile.TemporaryDirectory(prefix="bench-docs-") as tmp:
        for item in runs:
            body += run(item, Path(tmp), args.timeout)
    page = "\n".join([*head, *body]).rstrip() + "\n"
    out = args.output
    out.parent.mkdir(parents=True, exist_ok=True)
    partial = out.with_suffix(out.suffix + ".partial")
    partial.write_text(page)
    partial.replace(out)  # atomically: a failed run never leaves half a page
    print(f"[bench-docs] wrote {out}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())

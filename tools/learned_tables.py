"""The potential tables the learners of a ``recipes/train.py`` run learned: at the end, over time, as a file.

The learner recipes log each shaped learner's table after every batch (``potential_z0``,
``potential_z1``, … under ``RESULTS/logs/<method>_<pattern>_<learning>/scalars``). This prints

* every learner's final table, marking (``*``) a table that values a subgoal below the one
  before it (the shaping then charges the agent for reaching that subgoal), and the subgoals its
  episodes reached (``subgoals_reached``: the mean over its recent finished episodes, at its
  highest in the run and at the end; a learned value stays at its initial one while every
  episode that enters its ``z`` times out there, since time-outs do not train it by default);
* with ``--at F1,F2,…``: the mean (s.d.) of each ``V(z)`` over the learners at those frames, and
  how many tables are still all zero (no learner return has reached them yet): when, in a run,
  the potential starts to say something;
* with ``--json OUT``: one table per pattern (the first learner's, over the results directories
  in the order given; with ``--in-order``, the first that does not decrease along ``z``), the
  file ``recipes/train.py --frozen-potential`` shapes with from the first step.

    python tools/learned_tables.py results/a2c_pinball --at 10000,30000,60000,120000
    python tools/learned_tables.py results/a2c_pinball --json results/a2c_pinball_tables.json
"""

from __future__ import annotations

import argparse
import csv
import itertools
import json
import sys
from pathlib import Path

import numpy as np

Series = tuple[np.ndarray, np.ndarray]  # frames, values


def learner_tables(results: Path, method: str) -> dict[tuple[str, int], list[Series]]:
    """Each learner of ``method`` in ``results``, by ``(pattern, learning)``: its logged ``V(z)`` series, by ``z``.

    Raises:
        SystemExit: ``results`` holds no run's configuration, or no learner of ``method`` logged a table.
    """
    config_path = results / "config.json"
    try:
        config = json.loads(config_path.read_text())
    except (OSError, json.JSONDecodeError) as exc:
        raise SystemExit(f"{config_path}: not a recipe's results directory ({exc})") from None
    tables: dict[tuple[str, int], list[Series]] = {}
    for spec in config.get("methods", []):
        if spec["name"] != method:
            continue
        for pattern in spec["patterns"]:
            for learning in range(spec["learnings_per_pattern"]):
                scalars = results / "logs" / f"{method}_{pattern}_{learning}" / "scalars"
                files = sorted(scalars.glob("potential_z*.csv"), key=lambda p: int(p.stem.removeprefix("potential_z")))
                series = [_read(f) for f in files]
                if series and all(len(frames) for frames, _ in series):
                    tables[(pattern, learning)] = series
    if not tables:
        raise SystemExit(f"{results}: no {method} learner logged a table (potential_z*.csv under logs/)")
    return tables


def subgoals_reached(results: Path, method: str, pattern: str, learning: int) -> str:
    """``"most, last"`` of a learner's logged ``subgoals_reached`` (``"—"`` where it logged none)."""
    path = results / "logs" / f"{method}_{pattern}_{learning}" / "scalars" / "subgoals_reached.csv"
    if not path.exists():
        return "—"
    _, values = _read(path)
    return f"{values.max():.2f}, {values[-1]:.2f}" if len(values) else "—"


def _read(path: Path) -> Series:
    with path.open() as f:
        rows = [(float(step), float(value)) for step, value in csv.reader(f)]
    return np.array([r[0] for r in rows]), np.array([r[1] for r in rows])


def at(series: Series, frames: float) -> float:
    """The value logged last at or before ``frames`` (the initial 0 before the first log)."""
    steps, values = series
    i = int(np.searchsorted(steps, frames, side="right")) - 1
    return float(values[i]) if i >= 0 else 0.0


def in_order(table: list[float]) -> bool:
    """Whether ``table`` does not decrease along ``z``."""
    return all(b >= a for a, b in itertools.pairwise(table))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    parser.add_argument("results", nargs="+", type=Path, help="results directories of recipes/train.py")
    parser.add_argument("--method", default="HRS", help="the shaped method whose tables to read (default HRS)")
    parser.add_argument("--at", default="", help="comma-separated frames: mean tables over the learners there")
    parser.add_argument("--json", type=Path, help="write one final table per pattern here")
    parser.add_argument("--in-order", action="store_true", help="with --json: only tables that do not decrease")
    opts = parser.parse_args(argv)
    try:
        checkpoints = [float(f) for f in opts.at.split(",") if f.strip()]
    except ValueError:
        parser.error(f"--at: expected comma-separated frame counts, got {opts.at!r}")
    chosen: dict[str, list[float]] = {}
    wanted: set[str] = set()
    for results in opts.results:
        tables = learner_tables(results, opts.method)
        wanted.update(pattern for pattern, _ in tables)
        finals = {key: [float(values[-1]) for _, values in series] for key, series in tables.items()}
        disorder = [key for key, table in finals.items() if not in_order(table)]
        print(f"\n{results}: {opts.method}, {len(finals)} learners, {len(disorder)} tables out of order (*)\n")
        width = max(len(t) for t in finals.values())
        print("| learner | " + " | ".join(f"V(z{z})" for z in range(width)) + " | subgoals reached: most, last |")
        print("|---|" + "---|" * (width + 1))
        for (pattern, learning), table in finals.items():
            mark = " *" if (pattern, learning) in disorder else ""
            reached = subgoals_reached(results, opts.method, pattern, learning)
            print(f"| {pattern} {learning}{mark} | " + " | ".join(f"{v:.3g}" for v in table) + f" | {reached} |")
            if opts.json and pattern not in chosen and (in_order(table) or not opts.in_order):
                chosen[pattern] = table
        if checkpoints:
            print("\n| frames | " + " | ".join(f"V(z{z}), mean (s.d.)" for z in range(width)) + " | tables all 0 |")
            print("|---|" + "---|" * (width + 1))
            same = [s for s in tables.values() if len(s) == width]
            for frames in checkpoints:
                values = np.array([[at(one, frames) for one in series] for series in same])
                cells = " | ".join(f"{m:.3f} ({s:.3f})" for m, s in zip(values.mean(0), values.std(0), strict=True))
                print(f"| {frames:,.0f} | {cells} | {int((np.abs(values).max(1) == 0).sum())} of {len(same)} |")
    if opts.json:
        missing = sorted(wanted - set(chosen))
        if missing:
            raise SystemExit(f"--json: no {'in-order ' if opts.in_order else ''}table for pattern(s) {missing}")
        opts.json.write_text(json.dumps(chosen, indent=1) + "\n")
        print(f"\n{len(chosen)} tables written to {opts.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

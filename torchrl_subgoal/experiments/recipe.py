"""What the paper-reproduction recipes share: patterns, learners per method, chunk decoding, run + report.

A recipe (``recipes/four_rooms.py``, ``recipes/pinball.py``) supplies its
domain's pieces — the human patterns, candidate subgoals for RRS, an env and an
agent per chunk — and these helpers do the rest the same way for every domain.
"""

from __future__ import annotations

import sys
from collections.abc import Mapping, Sequence
from typing import Any, Literal

import torch

from torchrl_subgoal.experiments.cli import ConfigError
from torchrl_subgoal.experiments.store import Chunk, UnknownMethodError
from torchrl_subgoal.experiments.sweep import MethodSpec, RunChunk, Sweep, select_methods
from torchrl_subgoal.methods import Method, random_patterns
from torchrl_subgoal.subgoals import Predicate, SubgoalSeries

__all__ = ["chunk_patterns", "method_specs", "pattern_config", "pattern_sets", "sweep_and_report"]

PatternSets = dict[str, dict[str, SubgoalSeries]]


def pattern_sets(
    human: Mapping[str, SubgoalSeries], candidates: Sequence[Predicate], num_random: int, seed: int
) -> PatternSets:
    """The patterns by kind: ``human`` (as given), ``random`` (RRS, seeded, as long as the longest human one)."""
    num_subgoals = max(len(p) for p in human.values())
    rand = random_patterns(candidates, num_random, num_subgoals, seed=seed)
    return {"human": dict(human), "random": {p.name: p for p in rand}, "none": {}}


def pattern_config(patterns: PatternSets) -> dict[str, Any]:
    """Every pattern a sweep may use, as stored in its configuration (read back by :func:`chunk_patterns`)."""
    return {n: s.to_dict() for kind in ("human", "random") for n, s in patterns[kind].items()}


def method_specs(
    methods: Mapping[str, Method], names: Sequence[str], patterns: PatternSets, learnings: int
) -> list[MethodSpec]:
    """Learners of the methods ``names`` (a recipe's ``--methods``): every pattern
    ``learnings`` times; methods without patterns get as many learnings in all, of
    one pseudo-pattern ``"none"``. An unknown name is a :class:`ConfigError`."""
    specs = []
    for name, method in methods.items():
        kind = method.subgoals
        per_pattern = learnings if kind != "none" else learnings * len(patterns["human"])
        specs.append(MethodSpec(name, list(patterns[kind]) or ["none"], per_pattern))
    try:
        return select_methods(specs, names)
    except UnknownMethodError as exc:
        raise ConfigError(f"--methods: {exc}") from None


def chunk_patterns(chunk: Chunk, config: Mapping[str, Any]) -> tuple[list[SubgoalSeries], torch.Tensor]:
    """The chunk's subgoal series (from the sweep's configuration) and each learner's index into them."""
    names = sorted({pattern for pattern, _ in chunk.learners})
    series = [SubgoalSeries.from_dict(config["patterns"][n], name=n) for n in names if n != "none"]
    return series, torch.tensor([names.index(p) for p, _ in chunk.learners])


def sweep_and_report(
    domain: str,
    results: str,
    specs: Sequence[MethodSpec],
    run_chunk: RunChunk,
    config: Mapping[str, Any],
    *,
    seed: int,
    chunk_size: int,
    episodes: int,
    overwrite: bool,
    backend: Literal["local", "ray"],
    workers: int,
) -> int:
    """Run (or resume) the sweep, write the report, print its Markdown; the recipe's exit code."""
    from torchrl_subgoal.experiments.report import write_report

    sweep = Sweep(domain, results, specs, run_chunk, config, seed=seed, chunk_size=chunk_size,
                  n_episodes=episodes, overwrite=overwrite)
    sweep.run(backend=backend, workers=workers)
    report = write_report(results)
    print(report.markdown)
    print(f"results, report.md, summary.json and plots in {results}", file=sys.stderr)
    return 0

"""What the recipes share: one settings base, one ``main``, patterns, learners per method, chunk decoding,
run + report.

A recipe (:mod:`torchrl_subgoal.recipes`: ``torchrl-subgoal reproduce four-rooms``, ``... pinball``,
``... pick-and-place``, ``torchrl-subgoal train``; ``recipes/a2c.py`` and ``recipes/qlearning.py`` in
the repository) is a :class:`RecipeConfig` subclass (a paper
reproduction: a :class:`ReproductionConfig`), a ``plan`` that turns its settings
into a :class:`Plan` (the domain's pieces: the human patterns, candidate subgoals
for RRS, a ``run_chunk`` making an env and an agent per chunk) and
``main = recipe_main(Config, plan)``; these helpers do the rest the same way for
every domain, and record in the results' ``config.json`` the command, its settings
(what ``--config`` reads back) and the package's version and commit.
"""

from __future__ import annotations

import dataclasses
import logging
import os
import shlex
import sys
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, ClassVar, Literal, TypeVar

import torch
from torchrl.envs import EnvBase, TransformedEnv

from torchrl_subgoal.experiments.backend import BackendUnavailableError, ChunkFailedError, RunChunk
from torchrl_subgoal.experiments.budget import Budget, check_budget, check_learnings
from torchrl_subgoal.experiments.cli import ConfigError, check, parse_config, setting, settings_data
from torchrl_subgoal.experiments.results import Chunk, ResultsError, UnknownMethodError
from torchrl_subgoal.experiments.store import code_version
from torchrl_subgoal.experiments.sweep import MethodSpec, Sweep, select_methods
from torchrl_subgoal.methods import Method, random_patterns
from torchrl_subgoal.potentials import NaivePotential
from torchrl_subgoal.subgoals import Predicate, SubgoalFileError, SubgoalSeries, pattern_from_data
from torchrl_subgoal.transform import SubgoalPotentialTransform

__all__ = [
    "RECIPE_ERRORS",
    "Plan",
    "RecipeConfig",
    "ReproductionConfig",
    "check_device",
    "check_methods",
    "check_patterns",
    "check_unused",
    "chunk_patterns",
    "config_main",
    "fail",
    "method_specs",
    "needs_random_patterns",
    "pattern_config",
    "pattern_sets",
    "pattern_sources",
    "potential_entries",
    "potential_options",
    "quiet_torchrl",
    "recipe_main",
    "sweep_and_report",
    "sweep_entries",
    "warm_up_chunks",
]

PatternSets = dict[str, dict[str, SubgoalSeries]]
C = TypeVar("C", bound="RecipeConfig")
T = TypeVar("T")

#: What a recipe reports as one line on stderr instead of a traceback (see :func:`fail`).
RECIPE_ERRORS = (ConfigError, SubgoalFileError, ResultsError, ChunkFailedError, BackendUnavailableError)


def quiet_torchrl() -> None:
    """Keep TorchRL's INFO lines (``Initialized LazyTensorStorage ...``) out of a recipe's progress bar:
    its logger at WARNING, here and in the worker processes this one starts (``RL_LOGGING_LEVEL``,
    which a user's own setting overrides).

    Examples:
        >>> quiet_torchrl()
        >>> logging.getLogger("torchrl").level >= logging.WARNING or "RL_LOGGING_LEVEL" in os.environ
        True
    """
    level = os.environ.setdefault("RL_LOGGING_LEVEL", "WARNING")
    logging.getLogger("torchrl").setLevel(level)


def fail(exc: BaseException) -> int:
    """Print ``exc`` as one line on stderr; the exit code: 1 for a failed chunk, else 2 (a user error).

    Examples:
        >>> fail(ValueError("runs.yaml: episodes: must be >= 1"))  # prints "error: ..." on stderr
        2
        >>> fail(ChunkFailedError("chunk HRS/00000 failed"))
        1
    """
    print(f"error: {' '.join(str(exc).split())}", file=sys.stderr)
    return 1 if isinstance(exc, ChunkFailedError) else 2


def pattern_sets(
    human: Mapping[str, SubgoalSeries],
    candidates: Sequence[Predicate],
    num_random: int,
    seed: int,
    *,
    random_needed: bool = True,
) -> PatternSets:
    """The patterns by kind: ``human`` (as given), ``random`` (RRS, seeded, as long as the longest human one).

    Random patterns are drawn from ``candidates``; a human pattern longer than there are
    candidates is an error only when they are needed (``random_needed``: RRS is among the
    sweep's methods), else there are none.

    Args:
        human: the human patterns by name.
        candidates: the subgoals random patterns are drawn from.
        num_random: how many random patterns.
        seed: their seed.
        random_needed: whether the sweep runs RRS.

    Raises:
        SubgoalFileError: the longest human pattern is longer than the candidates and RRS runs.

    Examples:
        >>> from torchrl_subgoal.subgoals import Cell
        >>> human = {"alice": SubgoalSeries([Cell(4, 9), Cell(10, 9)], name="alice")}
        >>> sets = pattern_sets(human, [Cell(1, 1), Cell(2, 2), Cell(3, 3)], num_random=2, seed=0)
        >>> list(sets["human"]), list(sets["random"]), len(sets["random"]["random_1"])
        (['alice'], ['random_1', 'random_2'], 2)
        >>> pattern_sets(human, [Cell(1, 1)], num_random=2, seed=0, random_needed=False)["random"]
        {}
    """
    num_subgoals = max(len(p) for p in human.values())
    if num_subgoals > len(candidates):
        if not random_needed:
            return {"human": dict(human), "random": {}, "none": {}}
        longest = max(human.values(), key=len)
        raise SubgoalFileError(
            f"{longest.source or '<subgoals>'}: pattern {longest.name!r}: has {num_subgoals} subgoals, more "
            f"than the {len(candidates)} candidate subgoals random patterns (RRS) of that length are drawn from"
        )
    source = f"random patterns (seed {seed})"
    rand = [
        SubgoalSeries(p.predicates, name=p.name, source=source)
        for p in random_patterns(candidates, num_random, num_subgoals, seed=seed)
    ]
    return {"human": dict(human), "random": {p.name: p for p in rand}, "none": {}}


def check_methods(methods: Mapping[str, Method] | Sequence[str], names: Sequence[str]) -> list[str]:
    """``--methods`` checked: at least one, each known and named once; the names, in order.

    Args:
        methods: the recipe's methods (or their names).
        names: the names given.

    Raises:
        ConfigError: naming ``--methods`` and what to choose from.

    Examples:
        >>> check_methods(["HRS", "SARSA"], ["SARSA", "HRS"])
        ['SARSA', 'HRS']
        >>> check_methods(["HRS", "SARSA"], ["HRS", "HRS"])
        Traceback (most recent call last):
        ...
        torchrl_subgoal.experiments.cli.ConfigError: --methods: HRS is named twice; name each method once
    """
    known = list(methods)
    if not names:
        raise ConfigError(f"--methods: give at least one method; choose from {known}")
    unknown = [n for n in names if n not in known]
    if unknown:
        raise ConfigError(f"--methods: unknown method(s) {unknown}; choose from {known}")
    repeated = sorted({n for n in names if names.count(n) > 1}, key=list(names).index)
    if repeated:
        twice = " and ".join(repeated)
        raise ConfigError(
            f"--methods: {twice} {'is' if len(repeated) == 1 else 'are'} named twice; name each method once"
        )
    return list(names)


def check_unused(cfg: Any, names: Sequence[str], reason: str) -> None:
    """Refuse the settings ``names`` of ``cfg`` (a settings dataclass) set to anything but their defaults:
    under the chosen settings they do not apply (``reason`` says why), and a flag is never silently ignored.

    Raises:
        ConfigError: naming the flags given, why they do not apply, and to leave them out.

    Examples:
        >>> from dataclasses import dataclass
        >>> @dataclass
        ... class Settings:
        ...     task: str = "four_rooms"
        ...     reward: str = "step-cost"
        >>> check_unused(Settings(task="taxi"), ["reward"], "applies to --task four_rooms only")  # the default
        >>> check_unused(Settings(task="taxi", reward="goal"), ["reward"], "applies to --task four_rooms only")
        Traceback (most recent call last):
        ...
        torchrl_subgoal.experiments.cli.ConfigError: --reward goal: applies to --task four_rooms only; leave it out
    """
    defaults = {f.name: f.default for f in dataclasses.fields(cfg)}
    given = [name for name in names if getattr(cfg, name) != defaults[name]]
    if given:
        flags = ", ".join(f"--{name.replace('_', '-')} {getattr(cfg, name)}" for name in given)
        raise ConfigError(f"{flags}: {reason}; leave {'it' if len(given) == 1 else 'them'} out")


def needs_random_patterns(methods: Mapping[str, Method], names: Sequence[str]) -> bool:
    """Whether any of the methods ``names`` learns with random patterns (RRS).

    Args:
        methods: the recipe's methods by name.
        names: those the sweep runs.

    Examples:
        >>> from torchrl_subgoal.methods import paper_methods
        >>> needs_random_patterns(paper_methods("SARSA"), ["HRS", "SARSA"])
        False
        >>> needs_random_patterns(paper_methods("SARSA"), ["RRS"])
        True
    """
    return any(methods[n].subgoals == "random" for n in names if n in methods)


def check_device(device: str, flag: str = "device") -> torch.device:
    """``--device`` checked: a device torch knows and this machine has (``cuda:7`` on a machine without
    eight GPUs is an error before anything runs).

    Args:
        device: the flag's value (``cpu``, ``cuda``, ``cuda:1``, ``mps``...).
        flag: the flag's name, for the message.

    Raises:
        ConfigError: naming the flag and why.

    Examples:
        >>> check_device("cpu")
        device(type='cpu')
        >>> check_device("gpu0")
        Traceback (most recent call last):
        ...
        torchrl_subgoal.experiments.cli.ConfigError: --device: 'gpu0' is not a device; give e.g. cpu, cuda or cuda:1
    """
    try:
        parsed = torch.device(device)
    except (RuntimeError, ValueError, TypeError):
        raise ConfigError(f"--{flag}: {device!r} is not a device; give e.g. cpu, cuda or cuda:1") from None
    try:
        torch.empty(0, device=parsed)
    except (RuntimeError, AssertionError, ValueError) as exc:  # AssertionError: torch built without CUDA
        reason = " ".join(str(exc).split()) or type(exc).__name__
        raise ConfigError(f"--{flag}: {device} is not available on this machine ({reason})") from None
    return parsed


def pattern_config(patterns: PatternSets) -> dict[str, Any]:
    """Every pattern a sweep may use, as stored in its configuration (read back by :func:`chunk_patterns`).

    Examples:
        >>> from torchrl_subgoal.subgoals import Cell
        >>> sets = pattern_sets({"alice": SubgoalSeries([Cell(4, 9)], name="alice")}, [Cell(1, 1)], 1, seed=0)
        >>> sorted(pattern_config(sets))
        ['alice', 'random_1']
    """
    return {n: s.to_dict() for kind in ("human", "random") for n, s in patterns[kind].items()}


def pattern_sources(patterns: PatternSets) -> dict[str, str]:
    """Where each pattern came from (its subgoal file), so a chunk's errors can name it.

    Examples:
        >>> from torchrl_subgoal.subgoals import Cell
        >>> human = {"alice": SubgoalSeries([Cell(4, 9)], name="alice", source="alice.yaml")}
        >>> pattern_sources(pattern_sets(human, [Cell(1, 1)], 1, seed=0))
        {'alice': 'alice.yaml', 'random_1': 'random patterns (seed 0)'}
    """
    return {n: s.source for kind in ("human", "random") for n, s in patterns[kind].items() if s.source}


def check_patterns(patterns: PatternSets, env: EnvBase, observation_key: str) -> None:
    """Compile every pattern against the observation its shaping transform will read.

    The same check the transform makes at its first reset (one entry per read index,
    ``state:`` only on a scalar state or a one-hot observation, …), made before a
    sweep starts, so a subgoal that does not fit fails with nothing written.

    Raises:
        SubgoalFileError: naming the file, the pattern and the field.

    Examples:
        >>> from torchrl_subgoal.envs import FourRoomsEnv
        >>> from torchrl_subgoal.subgoals import Cell
        >>> sets = pattern_sets({"alice": SubgoalSeries([Cell(4, 9)], name="alice")}, [Cell(1, 1)], 1, seed=0)
        >>> check_patterns(sets, FourRoomsEnv(), "cell")  # fits: nothing raised
    """
    series = [s for kind in ("human", "random") for s in patterns[kind].values()]
    if not series:
        return
    for one in series:  # each compiled as the transform compiles it at a reset
        transform = SubgoalPotentialTransform(one, NaivePotential(1.0), gamma=1.0, observation_key=observation_key)
        TransformedEnv(env, transform).reset()


def method_specs(
    methods: Mapping[str, Method], names: Sequence[str], patterns: PatternSets, learnings: int
) -> list[MethodSpec]:
    """Learners of the methods ``names`` (a recipe's ``--methods``): every pattern
    ``learnings`` times; methods without patterns get as many learnings in all, of
    one pseudo-pattern ``"none"``. An unknown or repeated name is a :class:`ConfigError` (see
    :func:`check_methods`).

    Examples:
        >>> from torchrl_subgoal.methods import paper_methods
        >>> from torchrl_subgoal.subgoals import Cell
        >>> sets = pattern_sets({"alice": SubgoalSeries([Cell(4, 9)], name="alice")}, [Cell(1, 1)], 1, seed=0)
        >>> specs = method_specs(paper_methods("SARSA"), ["HRS", "SARSA"], sets, learnings=3)
        >>> [(s.name, s.patterns, s.learnings_per_pattern) for s in specs]
        [('HRS', ('alice',), 3), ('SARSA', ('none',), 3)]
    """
    names = check_methods(methods, names)
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
    """The chunk's subgoal series (from the sweep's configuration) and each learner's index into them.

    Examples:
        >>> from torchrl_subgoal.subgoals import Cell
        >>> sets = pattern_sets({"alice": SubgoalSeries([Cell(4, 9)], name="alice")}, [Cell(1, 1)], 1, seed=0)
        >>> chunk = Chunk("HRS", 0, (("alice", 0), ("alice", 1)), seed=1)
        >>> series, index = chunk_patterns(chunk, {"patterns": pattern_config(sets)})
        >>> [s.name for s in series], index.tolist()
        (['alice'], [0, 0])
    """
    names = sorted({pattern for pattern, _ in chunk.learners})
    sources = config.get("pattern_sources") or {}
    series = [pattern_from_data(config["patterns"][n], name=n, source=sources.get(n)) for n in names if n != "none"]
    return series, torch.tensor([names.index(p) for p, _ in chunk.learners])


def sweep_and_report(
    plan: Plan,
    results: str,
    *,
    seed: int,
    overwrite: bool,
    backend: Literal["local", "ray"],
    workers: int,
    provenance: Mapping[str, Any] | None = None,
) -> int:
    """Run (or resume) the sweep of ``plan`` into ``results``, write the report, print its Markdown; the
    recipe's exit code. ``provenance`` (what made the results) goes to ``config.json``, as the plan's
    ``runtime`` does (see :class:`~torchrl_subgoal.experiments.Sweep`).

    Raises:
        ConfigError: a setting the sweep cannot use, naming its flag.
        ResultsError: the results directory cannot be used (not ours, another experiment,
            busy, unwritable).
        ChunkFailedError: a chunk failed; the message says what was saved and what to do.

    Examples:
        >>> plan = Plan("four_rooms", [], print, {}, episodes=1, chunk_size=1)
        >>> sweep_and_report(plan, "results/demo", seed=-1, overwrite=False, backend="local", workers=0)
        Traceback (most recent call last):
        ...
        torchrl_subgoal.experiments.cli.ConfigError: --seed: must be >= 0, got -1
    """
    from torchrl_subgoal.experiments.report import write_report

    for flag, value, low in (
        ("seed", seed, 0),
        ("chunk_size", plan.chunk_size, 1),
        ("episodes", plan.episodes, 1),
        ("workers", workers, 0),
    ):
        if value < low:
            raise ConfigError(f"--{flag.replace('_', '-')}: must be >= {low}, got {value}")
    if not results.strip():
        raise ConfigError("--results: give a directory")
    sweep = Sweep(
        plan.domain,
        results,
        plan.specs,
        plan.run_chunk,
        plan.config,
        seed=seed,
        chunk_size=plan.chunk_size,
        n_episodes=plan.episodes,
        overwrite=overwrite,
        runtime=plan.runtime,
        provenance=provenance,
        warm_up=plan.warm_up,
    )
    try:
        sweep.run(backend=backend, workers=workers)
    except KeyboardInterrupt:
        print(
            f"interrupted: finished chunks are saved in {results}; run the same command again to resume",
            file=sys.stderr,
        )
        return 130
    print("writing the report: statistics (rliable's bootstrap intervals), figures ...", file=sys.stderr, flush=True)
    report = write_report(results)
    print(report.markdown)
    print(f"results, report.md, summary.json and plots in {results}", file=sys.stderr)
    return 0


@dataclass
class RecipeConfig:
    """Settings every recipe has: which methods, how many learnings, the seed, where results go and how
    chunks run. A recipe's ``Config`` subclasses it; redefining a field changes its default or help text.

    ``__post_init__`` checks that the fields named in ``AT_LEAST_ONE`` are >= 1 and those in
    ``AT_LEAST_ZERO`` >= 0 (a subclass names its own), raising :class:`ConfigError` for the flag.

    Examples:
        >>> from dataclasses import dataclass
        >>> @dataclass
        ... class Config(RecipeConfig):
        ...     episodes: int = setting(100, "episodes per learning")
        ...     AT_LEAST_ONE = ("learnings", "episodes")
        >>> cfg = parse_config(Config, ["--methods", "HRS, SARSA", "--episodes", "5"])
        >>> cfg.method_names, cfg.episodes, cfg.workers
        (['HRS', 'SARSA'], 5, 2)
        >>> Config(episodes=0)
        Traceback (most recent call last):
        ...
        torchrl_subgoal.experiments.cli.ConfigError: --episodes: must be >= 1, got 0
    """

    methods: str = setting("", "comma-separated methods to run")
    learnings: int = setting(10, "learnings per subgoal pattern")
    seed: int = setting(0, "sweep seed (random patterns, chunk seeds)")
    results: str = setting("results", "results directory (re-run to resume)")
    backend: Literal["local", "ray"] = setting("local", "where chunks run")
    workers: int = setting(2, "local worker processes (0: in this process)")
    overwrite: bool = setting(False, "discard results of a different experiment in --results")

    AT_LEAST_ONE: ClassVar[tuple[str, ...]] = ("learnings",)
    AT_LEAST_ZERO: ClassVar[tuple[str, ...]] = ("workers",)

    def __post_init__(self) -> None:
        for low, names in ((1, self.AT_LEAST_ONE), (0, self.AT_LEAST_ZERO)):
            for name in names:
                check(getattr(self, name) >= low, name, f"must be >= {low}, got {getattr(self, name)}")

    @property
    def method_names(self) -> list[str]:
        """``--methods`` as a list of names."""
        return [m.strip() for m in self.methods.split(",") if m.strip()]


@dataclass
class ReproductionConfig(RecipeConfig):
    """The settings of a paper reproduction on the fused engine (four-rooms, PinBall): episodes, the human
    and random patterns, NRS's η, the shaping convention, the engine and the chunk size.

    Examples:
        >>> ReproductionConfig(eta=-1.0)
        Traceback (most recent call last):
        ...
        torchrl_subgoal.experiments.cli.ConfigError: --eta: must be >= 0, got -1.0
    """

    episodes: int = setting(1000, "episodes per learning")
    subgoals: str = setting("", "subgoal file of the human patterns (HRS, NRS)")
    random_patterns: int = setting(10, "random subgoal patterns for RRS (paper: 10)")
    eta: float = setting(1.0, "NRS potential η")
    zero_terminal_potential: bool = setting(
        False, "Φ = 0 at the goal (exact policy invariance); the authors shape the goal step with γΦ(z_T)"
    )
    start_potential: str = setting(
        "value",
        "level of Φ: value (Φ = V, the authors), zero (Φ(z_0) = 0) or "
        "nonpositive (Φ(z_0) = min(V(z_0), 0), the library default)",
        choices=["value", "zero", "nonpositive"],
    )
    expectile: float = setting(
        0.5, "τ of the learned potential's TD target: 0.5 the mean (the authors), 0.9 the library default"
    )
    bootstrap_truncated: bool = setting(
        True, "train V(z) on a time-out inside z (this engine's reproductions; the library default skips it)"
    )
    progress_scale: float = setting(
        0.0,
        "the learned potentials' tables start at the subgoals' progress prior of this scale, in reward units "
        "(0: at 0, the authors; the library default: the goal's reward); SRS shapes with that prior "
        "(of scale --eta when 0)",
    )
    monotone_potential: bool = setting(
        False, "shape with the learned tables non-decreasing along the series (the library default; not the authors)"
    )
    engine: str = setting(
        "fused",
        "fused: one compiled loop; torchrl: step_and_maybe_reset (identical results)",
        choices=["fused", "torchrl"],
    )
    chunk_size: int = setting(
        100,
        "learners per batch (results do not depend on it; small chunks keep both "
        "workers busy to the end and resume finer)",
    )

    AT_LEAST_ONE: ClassVar[tuple[str, ...]] = ("episodes", "learnings", "random_patterns", "chunk_size")

    def __post_init__(self) -> None:
        super().__post_init__()
        check(self.eta >= 0, "eta", f"must be >= 0, got {self.eta}")
        check(0.0 < self.expectile < 1.0, "expectile", f"must lie strictly between 0 and 1, got {self.expectile}")
        check(self.progress_scale >= 0, "progress_scale", f"must be >= 0, got {self.progress_scale}")


def potential_entries(cfg: ReproductionConfig) -> dict[str, Any]:
    """The learned potential's conventions a reproduction records beyond the authors' (none when it runs theirs,
    so that the configuration of an authors' run is what it always was).

    Examples:
        >>> potential_entries(ReproductionConfig()), potential_entries(ReproductionConfig(progress_scale=1.0))
        ({}, {'progress_scale': 1.0})
    """
    entries: dict[str, Any] = {}
    if cfg.progress_scale:
        entries["progress_scale"] = cfg.progress_scale
    if cfg.monotone_potential:
        entries["monotone_potential"] = True
    return entries


def potential_options(config: Mapping[str, Any], method: Method) -> dict[str, Any]:
    """The keyword arguments of :func:`~torchrl_subgoal.methods.shaping_transform` that a reproduction's stored
    ``config`` gives ``method``'s potential (:func:`potential_entries`); SRS's prior has the scale η when the
    sweep set none.

    Examples:
        >>> from torchrl_subgoal.methods import SRS, paper_methods
        >>> potential_options({"eta": 10.0}, paper_methods("SARSA")["HRS"]), potential_options({"eta": 10.0}, SRS)
        ({'progress_scale': 0.0, 'monotone_potential': False}, {'progress_scale': 10.0, 'monotone_potential': False})
    """
    scale = float(config.get("progress_scale", 0.0))
    if method.shaping == "progress" and not scale:
        scale = float(config["eta"])
    return {"progress_scale": scale, "monotone_potential": bool(config.get("monotone_potential", False))}


def sweep_entries(cfg: RecipeConfig, subgoal_file: str, patterns: PatternSets) -> dict[str, Any]:
    """The entries of a sweep's configuration every reproduction records: the seed its learners' seeds
    derive from (:func:`~torchrl_subgoal.experiments.learner_seeds`), the subgoal file and the patterns.

    Examples:
        >>> from torchrl_subgoal.subgoals import Cell
        >>> sets = pattern_sets({"alice": SubgoalSeries([Cell(4, 9)], name="alice")}, [Cell(1, 1)], 1, seed=0)
        >>> sorted(sweep_entries(RecipeConfig(), "alice.yaml", sets))
        ['pattern_sources', 'patterns', 'seed', 'subgoal_file']
    """
    return {
        "seed": cfg.seed,
        "subgoal_file": subgoal_file,
        "patterns": pattern_config(patterns),
        "pattern_sources": pattern_sources(patterns),
    }


@dataclass
class Plan:
    """What a recipe's settings make: the sweep :func:`recipe_main` runs and reports.

    Args:
        domain: the name the results record (the report's map and paper columns, :mod:`torchrl_subgoal.domains`).
        specs: the learners of each method.
        run_chunk: runs one chunk of learners.
        config: the sweep's configuration (stored; what ``run_chunk`` reads).
        episodes: the report's columns per learner (episodes, updates or epochs).
        chunk_size: learners per chunk.
        results: the results directory (default: the recipe's ``--results``).
        runtime: settings that change how chunks run but not their results (the logger): handed to
            ``run_chunk`` with ``config``, not part of what identifies the experiment.
        warm_up: run before the sweep's chunks, saying so (what compiles numba kernels: :func:`warm_up_chunks`).
        budget: what one learner costs at least, checked before anything runs (:func:`check_budget`);
            default: ``episodes`` episodes (``--episodes``) of at least one step, ``--chunk-size`` learners a chunk.

    Examples:
        >>> Plan("four_rooms", [], print, {}, episodes=10, chunk_size=100).results is None
        True
    """

    domain: str
    specs: Sequence[MethodSpec]
    run_chunk: RunChunk
    config: Mapping[str, Any]
    episodes: int
    chunk_size: int
    results: str | None = None
    runtime: Mapping[str, Any] = field(default_factory=dict)
    warm_up: Callable[[], object] | None = None
    budget: Budget | None = None


def warm_up_chunks(
    run_chunk: RunChunk, specs: Sequence[MethodSpec], config: Mapping[str, Any], episodes_key: str = "episodes"
) -> Callable[[], object]:
    """What compiles a fused-engine recipe's numba kernels once, in the process that starts the sweep: one
    learner of each method for one episode, whose records are dropped. numba caches what it compiles on disk,
    so the sweep's worker processes load it instead of each compiling it at 0% of the progress bar (some 20 s
    of CPU on a first run after an install; a fraction of a second afterwards).

    Examples:
        >>> calls = []
        >>> warm = warm_up_chunks(lambda chunk, config, progress: calls.append((chunk.method, config["episodes"])),
        ...                       [MethodSpec("HRS", ["p1"], 3)], {"episodes": 1000})
        >>> _ = warm(); calls
        [('HRS', 1)]
    """

    def warm() -> None:
        for spec in specs:
            chunk = Chunk(spec.name, 0, ((spec.patterns[0], 0),), seed=0)
            run_chunk(chunk, {**config, episodes_key: 1}, lambda done: None)

    return warm


def config_main(
    config_cls: type[T],
    run: Callable[[T], int],
    argv: Sequence[str] | None = None,
    *,
    description: str | None = None,
    threads: int | None = 1,
    errors: tuple[type[BaseException], ...] = RECIPE_ERRORS,
    prog: str | None = None,
) -> int:
    """A script's ``main``: parse the flags into ``config_cls`` and ``run`` it; its exit code, or a
    one-line error on stderr (see :func:`fail`; a bad flag exits with code 2, as argparse does).
    :func:`recipe_main` is this with a sweep and its report as ``run``; a script that prints something else
    (``recipes/four_rooms_greedy.py``) uses this directly.

    Args:
        config_cls: the settings, a dataclass of :func:`~torchrl_subgoal.experiments.cli.setting` fields.
        run: the settings -> the exit code.
        argv: the command line (default: ``sys.argv[1:]``).
        description: the ``--help`` description (default: the settings' docstring's first line).
        threads: ``torch.set_num_threads`` first (batched small ops run fastest on one thread); ``None``: leave it.
        errors: what is reported as one line on stderr instead of a traceback.
        prog: the command's name in its help and errors (default: the script's file name).

    Examples:
        >>> from dataclasses import dataclass
        >>> @dataclass
        ... class Settings:
        ...     episodes: int = setting(3, "episodes")
        >>> config_main(Settings, lambda cfg: print(cfg.episodes) or 0, ["--episodes", "5"])
        5
        0
        >>> config_main(Settings, lambda cfg: check(cfg.episodes > 5, "episodes", "must be > 5") or 0, [])
        2
    """
    if threads is not None:
        torch.set_num_threads(threads)
    quiet_torchrl()
    try:
        return run(parse_config(config_cls, argv, description=description, prog=prog))
    except errors as exc:
        return fail(exc)


def recipe_main(
    config_cls: type[C],
    plan: Callable[[C], Plan],
    argv: Sequence[str] | None = None,
    *,
    description: str | None = None,
    threads: int | None = 1,
    errors: tuple[type[BaseException], ...] = RECIPE_ERRORS,
    prog: str | None = None,
) -> int:
    """A recipe's ``main``: parse the flags into ``config_cls``, make the :class:`Plan`, check that it fits
    this machine's memory and a year (:func:`~torchrl_subgoal.experiments.budget.check_budget`), run (or
    resume) the sweep, write the report and print it; the exit code (see :func:`fail`, :func:`sweep_and_report`).
    The results' ``config.json`` records the command, its settings (``--config`` reads them back) and
    the package's version and commit.

    Args:
        config_cls: the recipe's settings (a :class:`RecipeConfig`).
        plan: the recipe's settings -> its sweep.
        argv: the command line; ``description``, ``threads``, ``errors``, ``prog``: as in :func:`config_main`.

    Examples:
        >>> def plan(cfg: RecipeConfig) -> Plan:
        ...     raise ConfigError("--methods: give at least one method")
        >>> recipe_main(RecipeConfig, plan, [])  # prints "error: --methods: ..." on stderr
        2
    """

    args = list(sys.argv[1:] if argv is None else argv)
    command = shlex.join([*(prog or os.path.basename(sys.argv[0])).split(), *args])

    def run(cfg: C) -> int:
        check_learnings(cfg.learnings)  # before the plan, which may draw a pattern per learning
        sweep = plan(cfg)
        provenance = {"command": command, "settings": settings_data(cfg), **code_version()}
        check_budget(
            sweep.specs,
            sweep.episodes,
            sweep.chunk_size,
            sweep.budget or Budget(steps=sweep.episodes, length=("episodes", sweep.episodes)),
            learnings=cfg.learnings,
            workers=cfg.workers,
            backend=cfg.backend,
        )
        return sweep_and_report(
            sweep,
            sweep.results or cfg.results,
            seed=cfg.seed,
            overwrite=cfg.overwrite,
            backend=cfg.backend,
            workers=cfg.workers,
            provenance=provenance,
        )

    return config_main(config_cls, run, args, description=description, threads=threads, errors=errors, prog=prog)

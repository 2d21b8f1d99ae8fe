"""What the learner recipes share: a sweep of one TorchRL learner (A2C, PPO, DQN or DDPG) on a registered
domain, unshaped and with the paper's shaping methods, through the experiment engine.

``torchrl-subgoal train`` (:mod:`torchrl_subgoal.recipes.train`: any learner, any domain with a
:class:`~torchrl_subgoal.training.LearnerDomain`) and ``recipes/a2c.py`` (A2C on
four-rooms and PinBall with the settings of the A2C figures) are :class:`LearnerRecipeConfig`
subclasses whose ``plan`` is :func:`learner_plan`. Every field of the learner's settings
(:class:`~torchrl_subgoal.training.PPOConfig`, ...) is a flag (``--clip-epsilon``,
``--hidden 32 32``...) whose default is the domain's (``--help`` with ``--algo`` and
``--domain`` shows them). Every setting is checked
before the first chunk runs (the learner's settings, the learner against the
domain's actions, the subgoal patterns against its observation), each failure
one line naming the flag. One learner is one chunk (:func:`run_learner_chunk`):
its env factory, its shaping from the method and pattern, one
``train_<algo>`` call; one report column is one collected batch (an *update*),
whose metric is the mean episode length (frames per finished episode over the
last ``record_window`` batches), and the report gives times to threshold in
updates and in frames.
"""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from importlib.util import find_spec
from pathlib import Path
from typing import Any, ClassVar, Literal, cast

import numpy as np
import torch
from torchrl.envs import EnvBase

from torchrl_subgoal import registry
from torchrl_subgoal.experiments.budget import Budget
from torchrl_subgoal.experiments.cli import ConfigError, check, flag_of, setting
from torchrl_subgoal.experiments.recipe import (
    PatternSets,
    Plan,
    RecipeConfig,
    check_methods,
    check_patterns,
    chunk_patterns,
    method_specs,
    needs_random_patterns,
    pattern_config,
    pattern_sets,
    pattern_sources,
    quiet_torchrl,
)
from torchrl_subgoal.experiments.results import Chunk, EpisodeTable
from torchrl_subgoal.methods import Method, all_methods, shaping_parts
from torchrl_subgoal.potentials import TabularPotential
from torchrl_subgoal.registry import load_patterns
from torchrl_subgoal.training import (
    LEARNERS,
    LearnerDomain,
    Shaping,
    check_actions,
    experiment_logger,
)

__all__ = [
    "LOGGERS",
    "LearnerRecipeConfig",
    "check_seed_batch",
    "default_learner",
    "frozen_tables",
    "learner_budget",
    "learner_domain",
    "learner_methods",
    "learner_plan",
    "learner_settings",
    "run_learner_chunk",
]


#: What ``--logger`` takes: TorchRL's loggers (``none``: no log).
LOGGERS = ("csv", "tensorboard", "wandb", "none")


def learner_domain(name: str) -> LearnerDomain:
    """The :class:`~torchrl_subgoal.training.LearnerDomain` of the domain ``name``.

    Raises:
        ConfigError: naming ``--domain`` and the domains to choose from.

    Examples:
        >>> learner_domain("four_rooms").subgoal_key
        'cell'
        >>> learner_domain("cartpole")  # doctest: +ELLIPSIS
        Traceback (most recent call last):
        ...
        torchrl_subgoal.experiments.cli.ConfigError: --domain: unknown domain 'cartpole'; choose from acrobot, ...
    """
    if registry.find(name) is None:
        raise ConfigError(
            f"--domain: unknown domain {name!r}; choose from {', '.join(registry.having(LearnerDomain))} "
            "(or register your own: docs/adding_a_domain.md)"
        )
    try:
        return registry.part(name, LearnerDomain)
    except ValueError as exc:
        raise ConfigError(f"--domain: {exc}") from None


def default_learner(algo: str, domain: LearnerDomain, changes: Mapping[str, Any] | None = None) -> Any:
    """The settings of learner ``algo`` on ``domain``: the domain's defaults for it (the learner's own
    where the domain has none), with ``changes``.

    Examples:
        >>> default_learner("ppo", learner_domain("four_rooms"), {"total_frames": 512}).total_frames
        512
    """
    base = domain.defaults.get(algo) or LEARNERS[algo].config()
    try:
        return dataclasses.replace(base, **(changes or {}))
    except ValueError as exc:
        raise ConfigError(str(exc)) from None


@dataclass
class LearnerRecipeConfig(RecipeConfig):
    """The settings of a learner recipe: the domain, the methods, the shaping options, the logger, and the
    learner's own settings (``learner``: on the command line one flag per field, ``--total-frames``,
    ``--lr``, ``--clip-epsilon`` ..., whose defaults are the domain's for the learner).

    Examples:
        >>> from torchrl_subgoal.experiments.cli import parse_config
        >>> cfg = parse_config(LearnerRecipeConfig, ["--domain", "four_rooms_step", "--total-frames", "512"])
        >>> type(cfg.learner).__name__, cfg.learner.total_frames, cfg.learner.num_envs
        ('A2CConfig', 512, 16)
    """

    domain: str = setting(
        "four_rooms",
        "a registered domain with a learner set-up (a LearnerDomain part); an unknown name lists them",
    )
    methods: str = setting(
        "",
        "comma-separated methods: the learner's name for the unshaped learner (A2C, PPO, DQN, DDPG), HRS, "
        "HRS-D, NRS, RRS, SARSA-RS, SRS",
        shown_default="the unshaped learner,HRS-D,NRS",
    )
    learnings: int = setting(1, "learnings per subgoal pattern (unshaped: as many per pattern of the file)")
    subgoals: str = setting("", "subgoal file of the human patterns", shown_default="the domain's")
    random_patterns: int = setting(10, "random subgoal patterns for RRS")
    zero_terminal_potential: bool = setting(True, "Φ = 0 at the goal (exact policy invariance)")
    start_potential: str = setting(
        "nonpositive",
        "level of Φ: nonpositive (the library default; docs/shaping_defaults.md), zero or value (Φ = V)",
        choices=["value", "zero", "nonpositive"],
    )
    monotone_potential: bool = setting(
        True, "shape with the learned table made non-decreasing along the series (HRS, RRS)"
    )
    progress_scale: float = setting(
        1.0,
        "the learned tables (HRS, RRS) start at the subgoals' progress prior of this scale, the goal's worth in "
        "the env's reward units (the learner's --reward-scale applies to it as to the reward); 0 starts them at 0; "
        "SRS shapes with the prior",
    )
    frozen_potential: str = setting(
        "",
        "a JSON file {pattern: [V(z0), V(z1), ...]}: HRS and RRS shape with these tables from the first step and "
        "do not train them (tools/learned_tables.py writes one from a run's logs)",
    )
    prior_weight: float = setting(
        0.0,
        "HRS, HRS-D, RRS: the table's start counts as this many transitions, handed over to the learned values "
        "as each z gathers them (the online update's steps max(value_lr, 1/(k + n))); 0: none",
    )
    achievement_reward: float = setting(
        0.0,
        "HRS, HRS-D, RRS: added to the potential's target per subgoal achieved, in the env's reward units "
        "(the learner's --reward-scale applies to it); 0: none",
    )
    seed_batch: int = setting(
        1,
        "learners of a method trained together as one batch in one process (one env batch, stacked "
        "networks, a replay buffer and a table per learner); 1: one learner at a time",
    )
    seed: int = setting(0, "sweep seed (random patterns, learner seeds)")
    results: str = setting("", "results directory (re-run to resume)", shown_default="results/<algo>_<domain>")
    backend: Literal["local", "ray"] = setting("local", "where learners run")
    workers: int = setting(2, "learners run at once (processes; 0: in this process)")
    logger: str = setting(
        "csv",
        "each learner's log under RESULTS/logs: TorchRL's CSVLogger, TensorboardLogger (the tensorboard extra) "
        "or WandbLogger (the wandb extra; WANDB_MODE=offline logs without an account), or none",
        choices=LOGGERS,
    )
    learner: Any = dataclasses.field(default=None, metadata={"nested": True})

    #: the learner of a recipe of one (``recipes/a2c.py``); ``None``: the ``algo`` field's
    ALGO: ClassVar[str | None] = "a2c"
    #: what the learner's settings depend on: read from the command line before the rest
    EARLY: ClassVar[tuple[str, ...]] = ("domain",)
    #: this recipe's changes to the domain's defaults for the learner (shown as the defaults in ``--help``)
    LEARNER_DEFAULTS: ClassVar[Mapping[str, Any]] = {}
    AT_LEAST_ONE: ClassVar[tuple[str, ...]] = ("learnings", "random_patterns", "seed_batch")
    AT_LEAST_ZERO: ClassVar[tuple[str, ...]] = ("workers",)

    def __post_init__(self) -> None:
        super().__post_init__()
        check(
            math.isfinite(self.progress_scale) and self.progress_scale >= 0,
            "progress_scale",
            f"must be a finite number >= 0, got {self.progress_scale}",
        )
        check(
            math.isfinite(self.prior_weight) and self.prior_weight >= 0,
            "prior_weight",
            f"must be a finite number >= 0 (transitions), got {self.prior_weight}",
        )
        finite = math.isfinite(self.achievement_reward)
        check(finite, "achievement_reward", f"must be finite, got {self.achievement_reward}")
        check(
            self.progress_scale > 0 or "SRS" not in self.method_names,
            "progress_scale",
            "SRS shapes with the progress prior: give it a scale > 0",
        )

    @classmethod
    def nested_settings(cls, early: Mapping[str, Any]) -> dict[str, tuple[str, Any]]:
        """The learner's settings, as the defaults of its flags: the domain's, with :attr:`LEARNER_DEFAULTS`."""
        algo = str(early.get("algo", cls.ALGO))
        if algo not in LEARNERS:  # the --algo flag refuses it, naming the choices
            algo = str(next(f.default for f in dataclasses.fields(cls) if f.name == "algo"))
        return {"learner": (algo, default_learner(algo, learner_domain(str(early["domain"])), cls.LEARNER_DEFAULTS))}

    @classmethod
    def check_flags(cls, early: Mapping[str, Any], flags: Sequence[str]) -> None:
        """Refuse a flag of another learner's settings, naming the learners it is a setting of."""
        algo = str(early.get("algo", cls.ALGO))
        if algo not in LEARNERS:
            return
        own = {flag_of(f.name) for f in dataclasses.fields(LEARNERS[algo].config)}
        for flag in flags:
            names = {flag, "--" + flag.removeprefix("--no-")}
            owners = [
                name
                for name, learner in LEARNERS.items()
                if name != algo and names & {flag_of(f.name) for f in dataclasses.fields(learner.config)}
            ]
            if owners and not names & own:
                raise ConfigError(f"{flag}: a setting of {' and '.join(owners)}, not of {algo}")


def learner_methods(algo: str) -> dict[str, Method]:
    """The methods a sweep of learner ``algo`` compares: the paper's, the unshaped one named after the learner,
    SRS and HRS-D (the library's default potential).

    Examples:
        >>> list(learner_methods("ppo"))
        ['HRS', 'RRS', 'PPO', 'NRS', 'SARSA-RS', 'SRS', 'HRS-D']
    """
    return all_methods(baseline=LEARNERS[algo].title)


def learner_settings(cfg: LearnerRecipeConfig, algo: str, domain: LearnerDomain) -> Any:
    """The learners' settings: ``cfg.learner`` (from the flags), or the domain's defaults for ``algo`` with the
    recipe's :attr:`~LearnerRecipeConfig.LEARNER_DEFAULTS` when it has none; checked against one batch.

    Raises:
        ConfigError: the settings are another learner's, or the budget is less than one batch.

    Examples:
        >>> four_rooms = learner_domain("four_rooms")
        >>> learner_settings(LearnerRecipeConfig(), "dqn", four_rooms).total_frames
        100000
        >>> learner_settings(LearnerRecipeConfig(learner=default_learner("ppo", four_rooms)), "dqn", four_rooms)
        Traceback (most recent call last):
        ...
        torchrl_subgoal.experiments.cli.ConfigError: --algo: the learner settings are PPOConfig's, not dqn's (DQNConfig)
    """
    learner = LEARNERS[algo]
    settings: Any = (
        cfg.learner if cfg.learner is not None else default_learner(algo, domain, type(cfg).LEARNER_DEFAULTS)
    )
    fits = isinstance(settings, learner.config)
    if not fits:
        raise ConfigError(
            f"--algo: the learner settings are {type(settings).__name__}'s, not {algo}'s ({learner.config.__name__})"
        )
    check(
        settings.total_frames >= settings.frames_per_batch,
        "total_frames",
        f"{settings.total_frames} is less than one batch of {settings.frames_per_batch} frames "
        f"(--frames-per-batch); give at least {settings.frames_per_batch}",
    )
    return settings


def learner_plan(cfg: LearnerRecipeConfig, algo: str, *, final_updates: int | None = None) -> Plan:
    """The sweep of learner ``algo`` on ``cfg.domain``: one chunk per learner, the stored configuration,
    the report's thresholds (episode lengths; times in updates and frames).

    Args:
        cfg: the recipe's settings.
        algo: ``"a2c"``, ``"ppo"``, ``"dqn"`` or ``"ddpg"``.
        final_updates: the updates the asymptotic performance averages (default: the last 5%, at least 10).

    Raises:
        ConfigError: naming the flag; SubgoalFileError: naming the file, the pattern and the field.

    Examples:
        >>> from torchrl_subgoal.training import DDPGTrainConfig
        >>> cfg = LearnerRecipeConfig(domain="four_rooms", methods="DDPG", learner=DDPGTrainConfig())
        >>> learner_plan(cfg, "ddpg")
        Traceback (most recent call last):
        ...
        torchrl_subgoal.experiments.cli.ConfigError: --algo: ddpg needs continuous actions; ...
    """
    check(algo in LEARNERS, "algo", f"unknown learner {algo!r}; choose from {', '.join(LEARNERS)}")
    domain = learner_domain(cfg.domain)
    if cfg.logger in ("tensorboard", "wandb") and find_spec(cfg.logger) is None:
        raise ConfigError(
            f"--logger: {cfg.logger} needs the {cfg.logger} package: pip install 'torchrl_subgoal[{cfg.logger}]'"
        )
    methods = learner_methods(algo)
    names = check_methods(methods, cfg.method_names or [LEARNERS[algo].title, "HRS-D", "NRS"])
    if "SARSA-RS" in names and domain.aggregation() is None:
        raise ConfigError(f"--methods: SARSA-RS needs an aggregation g(s), which {cfg.domain} does not register")
    settings = learner_settings(cfg, algo, domain)
    probe = domain.make_env(1)
    try:
        check_actions(algo, probe, cfg.domain)
    except ValueError as exc:
        raise ConfigError(f"--algo: {exc}") from None
    subgoal_file = cfg.subgoals or domain.participants
    human = load_patterns(subgoal_file, domain=cfg.domain)
    if domain.pattern_env is not None:
        for name in human:
            try:
                domain.env_for(name, 0)
            except ValueError as exc:
                raise ConfigError(f"--subgoals: {subgoal_file}: {exc}") from None
    patterns = pattern_sets(
        human,
        domain.candidates(cfg.seed),
        cfg.random_patterns,
        cfg.seed,
        random_needed=needs_random_patterns(methods, names),
    )
    check_patterns(patterns, probe, str(domain.subgoal_key))
    specs = method_specs(methods, names, patterns, cfg.learnings)
    frozen = frozen_tables(cfg.frozen_potential, [methods[n] for n in names], patterns) if cfg.frozen_potential else {}
    results = cfg.results or f"results/{algo}_{cfg.domain}"
    iterations = settings.iterations
    final = final_updates if final_updates is not None else max(10, iterations // 20)
    config = {
        "domain": cfg.domain,
        "algo": algo,
        "learner": dataclasses.asdict(settings),
        "zero_terminal_potential": cfg.zero_terminal_potential,
        "start_potential": cfg.start_potential,
        "monotone_potential": cfg.monotone_potential,
        "progress_scale": cfg.progress_scale,
        **{k: getattr(cfg, k) for k in ("prior_weight", "achievement_reward") if getattr(cfg, k)},
        **({"frozen_potential": frozen} if frozen else {}),
        "subgoal_file": subgoal_file,
        "patterns": pattern_config(patterns),
        "pattern_sources": pattern_sources(patterns),
        "routes": list(human),
        "log_dir": str(Path(results) / "logs"),
        "report": {
            "metric": "steps",
            "thresholds": list(domain.thresholds),
            "unit": "update",
            "frames_per_unit": settings.frames_per_batch,
            "asymptotic_window": [max(0, iterations - final), iterations],
        },
    }
    if cfg.seed_batch > 1:
        check_seed_batch(algo, domain, settings, [methods[n] for n in names])
    return Plan(
        f"{algo}_{cfg.domain}",
        specs,
        run_learner_chunk,
        config,
        episodes=iterations,
        chunk_size=cfg.seed_batch,
        results=results,
        runtime={"logger": cfg.logger},
        budget=learner_budget(settings, probe),
    )


def learner_budget(settings: Any, probe: EnvBase) -> Budget:
    """What one learner costs at least: ``total_frames`` steps, and its collected batch (and replay buffer)
    of frames at least as large as one of ``probe``'s (all its entries, ``next`` included).

    Examples:
        >>> from torchrl_subgoal.training import DQNConfig
        >>> four_rooms = registry.part("four_rooms", LearnerDomain)
        >>> budget = learner_budget(DQNConfig(total_frames=10_000), four_rooms.make_env(1))
        >>> budget.steps, budget.length, budget.chunk_flag, budget.unit
        (10000, ('total_frames', 10000), 'seed_batch', 'update')
    """
    fake = probe.fake_tensordict()
    frame = sum(t.numel() * t.element_size() for t in fake.values(True, True)) // max(fake.numel(), 1)
    frames = max(settings.frames_per_batch, settings.num_envs)
    replayed = getattr(settings, "buffer_size", 0)
    held = f"a batch of {frames} frames (--frames-per-batch, --num-envs)" + (
        f" and {replayed} replayed ones" if replayed else ""
    )
    return Budget(
        steps=settings.total_frames,
        length=("total_frames", settings.total_frames),
        learner_bytes=(frames + replayed) * frame,
        held=f"{held}, {frame} bytes each",
        chunk_flag="seed_batch",
        unit="update",
    )


def check_seed_batch(algo: str, domain: LearnerDomain, settings: Any, methods: Sequence[Method]) -> None:
    """Refuse ``--seed-batch`` where learners cannot be batched, naming the flag and the reason.

    Examples:
        >>> from torchrl_subgoal.training import DQNConfig
        >>> check_seed_batch("dqn", registry.part("four_rooms", LearnerDomain), DQNConfig(collector_workers=1), [])
        Traceback (most recent call last):
        ...
        torchrl_subgoal.experiments.cli.ConfigError: --seed-batch: needs --collector-workers 0 (one collector for ...
    """
    check(settings.collector_workers == 0, "seed_batch", "needs --collector-workers 0 (one collector for the batch)")
    check(
        domain.pattern_env is None or settings.env_workers == 0,
        "seed_batch",
        f"{domain.name} gives each learner its own task, whose envs step in the batch's process: needs --env-workers 0",
    )
    trained = any(m.shaping in ("subgoals", "aggregation") for m in methods)
    check(
        settings.online_potential or not trained,
        "seed_batch",
        "trains each learner's table online: drop --no-online-potential",
    )


def frozen_tables(path: str, methods: Sequence[Method], patterns: PatternSets) -> dict[str, list[float]]:
    """The tables ``--frozen-potential`` gives: one per pattern of the sweep's learned-potential methods (HRS, RRS).

    Raises:
        ConfigError: naming the flag, the file and the pattern (an unreadable or malformed file, a
            pattern without a table, a table of the wrong length), or no method that learns a table.

    Examples:
        >>> import json, tempfile
        >>> from torchrl_subgoal.subgoals import Cell, SubgoalSeries
        >>> sets = {"human": {"alice": SubgoalSeries([Cell(4, 9)], name="alice")}, "random": {}}
        >>> path = tempfile.mktemp(suffix=".json")
        >>> _ = Path(path).write_text(json.dumps({"alice": [0.5, 0.8]}))
        >>> frozen_tables(path, [Method("HRS", "subgoals", "human")], sets)
        {'alice': [0.5, 0.8]}
        >>> _ = Path(path).write_text(json.dumps({"alice": [0.5]}))
        >>> frozen_tables(path, [Method("HRS", "subgoals", "human")], sets)
        Traceback (most recent call last):
        ...
        torchrl_subgoal.experiments.cli.ConfigError: --frozen-potential: ...: pattern 'alice': expected 2 ...
    """
    where = f"--frozen-potential: {path}"
    try:
        data = json.loads(Path(path).read_text())
    except OSError as exc:
        raise ConfigError(f"{where}: cannot read it ({exc.strerror or exc})") from None
    except json.JSONDecodeError as exc:
        raise ConfigError(f"{where}: not valid JSON (line {exc.lineno}: {exc.msg})") from None
    if not isinstance(data, dict):
        raise ConfigError(f"{where}: expected an object {{pattern: [V(z0), V(z1), ...]}}, got {type(data).__name__}")
    learned = [m for m in methods if m.shaping == "subgoals"]
    check(bool(learned), "frozen_potential", "no method of --methods learns a table (HRS and RRS do)")
    tables = {}
    for method in learned:
        for name, series in patterns[method.subgoals].items():
            if name not in data:
                raise ConfigError(f"{where}: no table for pattern {name!r} ({method.name}); it has {sorted(data)}")
            table, size = data[name], series.num_abstract_states
            numbers = isinstance(table, list) and all(
                isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in table
            )
            if not numbers or len(table) != size:
                raise ConfigError(
                    f"{where}: pattern {name!r}: expected {size} finite numbers (V(z) for z = 0..{size - 1}), "
                    f"got {table!r}"
                )
            tables[name] = [float(v) for v in table]
    return tables


def run_learner_chunk(chunk: Chunk, config: Mapping[str, Any], progress: Callable[[int], None]) -> EpisodeTable:
    """Train the chunk's learners (one, or ``--seed-batch`` of them) as one batch (the learner's ``train``,
    e.g. :func:`~torchrl_subgoal.training.train_a2c`); their records.

    Examples:
        >>> import tempfile
        >>> a2c = default_learner("a2c", learner_domain("four_rooms"), {"total_frames": 512})
        >>> cfg = LearnerRecipeConfig(domain="four_rooms", methods="A2C", learner=a2c, results=tempfile.mkdtemp())
        >>> plan = learner_plan(cfg, "a2c")
        >>> table = run_learner_chunk(Chunk("A2C", 0, (("none", 0),), seed=1), plan.config, lambda done: None)
        >>> table.n_learners, table.n_episodes  # one learner, one column per batch of 256 frames
        (1, 2)
    """
    torch.set_num_threads(1)
    quiet_torchrl()
    domain = registry.part(config["domain"], LearnerDomain)
    learner = LEARNERS[config["algo"]]
    method = learner_methods(config["algo"])[chunk.method]
    patterns, pattern_index = chunk_patterns(chunk, config)
    settings = learner.config(**config["learner"])
    if method.shaping == "none":  # no transform, so no z to see and no potential to re-shape with
        settings = dataclasses.replace(
            settings,
            sees_subgoal=False,
            **({"reshape_samples": False} if learner.has_setting("reshape_samples") else {}),
        )
    routes = config["routes"]
    aggregation = domain.aggregation()
    runs = []
    for i, (pattern, learning) in enumerate(chunk.learners):
        index = int(pattern_index[i])
        parts = shaping_parts(
            method,
            (),
            patterns=patterns[index : index + 1] if patterns else None,
            aggregation=aggregation,
            eta=domain.eta,
            observation_key=domain.subgoal_key,
            aggregation_key=domain.aggregation_key,
            zero_terminal_potential=config["zero_terminal_potential"],
            start_potential=config["start_potential"],
            monotone_potential=config.get("monotone_potential", False),
            # in the env's reward units: the transform shapes the reward after the learner's reward_scale
            progress_scale=config.get("progress_scale", 0.0) * settings.reward_scale,
        )
        frozen = config.get("frozen_potential", {}).get(pattern) if method.shaping == "subgoals" else None
        if parts is not None and frozen is not None:
            potential = parts[1]
            assert isinstance(potential, TabularPotential), f"{method.name} learns no table to freeze"
            potential.freeze(frozen)
        seed = chunk.seed + i
        # a pattern-less learner (unshaped, SARSA-RS) runs the task its learning number picks
        make_env = domain.env_for(pattern if pattern in routes else routes[learning % len(routes)], seed)
        # fresh: a learner run again after an interruption starts its log over, as its results do
        logger = experiment_logger(
            Path(config["log_dir"]),
            f"{chunk.method}_{pattern}_{learning}",
            cast(Any, config.get("logger", "csv")),
            fresh=True,
        )
        shaping = None
        if parts is not None:
            achievement = config.get("achievement_reward", 0.0) * settings.reward_scale
            loss = {"achievement_reward": achievement} if achievement else {}
            shaping = Shaping(*parts, loss=loss, prior_weight=config.get("prior_weight", 0.0))
        runs.append((make_env, shaping, seed, logger))
    # the chunk's learners as one batch (one learner is a batch of one); each its own task where the
    # domain gives one per learner (the plan checked that the learners can share one env batch)
    trained = learner.train(
        [make_env for make_env, *_ in runs],
        settings,
        seeds=[seed for _, _, seed, _ in runs],
        shaping=[shaping for _, shaping, _, _ in runs],
        observation_key=domain.observation_key,
        loggers=[logger for *_, logger in runs],
        progress=progress,
        success=domain.success,
    )
    curves = trained.curves
    steps = np.array([np.round(c.episode_length) for c in curves], dtype=np.int64)
    returns = np.array([c.episode_return for c in curves])
    success = np.nan_to_num(np.array([c.success for c in curves], dtype=np.float64), nan=0.0)  # no signal: 0
    return EpisodeTable(steps, returns, success)

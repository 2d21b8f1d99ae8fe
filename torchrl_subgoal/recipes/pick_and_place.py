"""Pick and place: DDPG with subgoal-based shaping on single-goal FetchPickAndPlace.

Reproduces the pick-and-place experiment of Okudo & Yamada, "Reward Shaping with
Dynamic Trajectory Aggregation" (IJCNN 2021):

* HRS      — a neural potential V(o; θ) over the participants' two box subgoals (ours),
* RRS      — the same with random boxes over the same components,
* DDPG     — no shaping,
* NRS      — naive subgoal shaping with a fixed potential η,
* SARSA-RS — a learned table over a hand-given three-state aggregation;

and, beyond the paper, the library's potentials over the same boxes:

* HRS-D    — the library's default (``TabularPotential.for_subgoals``): a table over ``z`` that starts
  at the progress prior, rises within each segment as the next box comes nearer and is learned online
  with the library's target,
* SRS      — the progress prior, fixed.

Each learning is one ``torchrl_subgoal.training.train_ddpg`` (its collector: a
``MultiSyncCollector`` of ``--collector-workers`` processes, each stepping its share of
the MuJoCo envs through the shaping transform, whose potential is this process's V in
shared memory; or, with ``--collector-workers 0``, a ``Collector`` here) on the authors'
schedule: one collected batch per cycle (every env one episode), ``updates`` DDPG
gradient steps and one soft target update after it, V one step of ``SubgoalValueLoss``
on the cycle's SMDP transitions; after every epoch of cycles (the recipe's hooks,
``Epochs``), ``test_episodes`` greedy episodes whose final-step success gives the
epoch's success rate. Every epoch is checkpointed, so a re-run resumes
mid-learning; results go through the experiment engine (one chunk per learning) and the report gives success
curves, epochs to a success rate of 0.6 and the asymptotic success beside the paper's.

    torchrl-subgoal reproduce pick-and-place                      # paper scale: 5 learnings x 200 epochs
    torchrl-subgoal reproduce pick-and-place --preset tiny --results /tmp/pp   # plumbing check, seconds
"""

from __future__ import annotations

import dataclasses
import inspect
import json
import sys
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Any, Literal

import numpy as np
import torch
from tensordict import TensorDictBase
from torchrl.envs import (
    EnvBase,
    ExplorationType,
    set_exploration_type,
)

from torchrl_subgoal import (
    NeuralPotential,
    SubgoalPotentialTransform,
    SubgoalSeries,
)
from torchrl_subgoal.envs import fetch
from torchrl_subgoal.experiments import (
    Chunk,
    EpisodeTable,
    MethodSpec,
    UnknownMethodError,
    select_methods,
)
from torchrl_subgoal.experiments.budget import Budget
from torchrl_subgoal.experiments.checkpoint import (
    LearningCheckpoint,
    restore_rng_states,
    rng_states,
)
from torchrl_subgoal.experiments.cli import ConfigError, check, setting
from torchrl_subgoal.experiments.recipe import (
    RECIPE_ERRORS,
    Plan,
    RecipeConfig,
    check_device,
    check_methods,
    chunk_patterns,
    needs_random_patterns,
    pattern_config,
    pattern_sources,
    recipe_main,
)
from torchrl_subgoal.methods import Method, all_methods, shaping_parts
from torchrl_subgoal.registry import load_patterns
from torchrl_subgoal.training import (
    DDPGHooks,
    DDPGTrainConfig,
    LearnerBatch,
    PotentialTrainer,
    Shaping,
    train_ddpg,
)
from torchrl_subgoal.training.ddpg_parts import DDPG_KEYS, DDPGAgent, DDPGConfig, mlp

METHODS = all_methods(baseline="DDPG")
#: The neural potential's target (the paper's): the mean of the SMDP returns, a time-out bootstrapped.
NEURAL_TARGET = {"expectile": 0.5, "bootstrap_truncated": True}
#: --clip-positive: which learners clip their critic's targets above at 0.
CLIP_POSITIVE = ("unshaped", "all", "none")
#: epochs, cycles per epoch, env steps per cycle, gradient steps per cycle, test episodes, DDPG settings.
#: "paper" is the authors' released run (docs/pick_and_place.md): 6 MPI workers, each collecting one
#: 50-step episode per cycle, then 40 synchronous gradient steps whose gradients sum the 6 workers'
#: 256-transition batches (= one batch of 1,536 under Adam); "paper-1worker" is one worker's share.
PRESETS: dict[str, dict[str, Any]] = {
    "paper": {
        "epochs": 200,
        "cycles": 50,
        "cycle_steps": 300,
        "updates": 40,
        "test_episodes": 10,
        "ddpg": {"batch_size": 1536},
    },
    "paper-1worker": {"epochs": 200, "cycles": 50, "cycle_steps": 50, "updates": 40, "test_episodes": 10, "ddpg": {}},
    "tiny": {
        "epochs": 2,
        "cycles": 2,
        "cycle_steps": 100,
        "updates": 2,
        "test_episodes": 1,
        "ddpg": {"hidden": (16, 16), "batch_size": 16},
    },
}


@dataclass
class Config(RecipeConfig):
    """Pick and place reproduction: DDPG with HRS, RRS, NRS and SARSA-RS (and the library's HRS-D and SRS)."""

    preset: str = setting("paper", "schedule and network sizes", choices=sorted(PRESETS))
    epochs: int = setting(0, "epochs per learning (0: the preset's; paper: 200 of 2,500 steps)")
    learnings: int = setting(5, "learnings per method (paper: 5)")
    methods: str = setting("HRS,RRS,DDPG,NRS", f"comma-separated methods among {','.join(METHODS)}")
    num_envs: int = setting(0, "MuJoCo envs collecting together (0: the preset's, one episode each per cycle)")
    collector_workers: int = setting(
        2, "MultiSyncCollector processes the envs are spread over; 0: a Collector in this process"
    )
    env_workers: int = setting(0, "ParallelEnv processes per collecting process (0: envs stepped in it)")
    subgoals: str = setting(
        fetch.PARTICIPANTS_FILE, "subgoal file of the human pattern (HRS, NRS)", shown_default="the paper's"
    )
    value_lr: float = setting(1e-3, "Adam learning rate of the neural potential V(o; θ)")
    aggregation_lr: float = setting(0.1, "SGD learning rate of SARSA-RS's table")
    progress_scale: float = setting(
        1.0,
        "HRS-D, SRS: their tables start at the subgoals' progress prior of this scale, what reaching "
        "the goal is worth in the env's reward units (HRS-D's table then learns online at the training "
        "blocks' value_lr)",
    )
    eta: float = setting(0.1, "NRS potential η (the authors' released value)")
    start_potential: str = setting(
        "zero",
        "level of HRS's and RRS's neural potential: zero (Phi(z_0) = 0, the "
        "authors' level), nonpositive (the library's default: Phi(z_0) = min(V(z_0), 0), "
        "-50 once V has learnt the failure return), value (Phi = V); "
        "docs/pick_and_place.md",
        choices=("zero", "nonpositive", "value"),
    )
    shaping: str = setting(
        "{}", "JSON of extra SubgoalPotentialTransform options, e.g. '{\"zero_terminal_potential\": false}'"
    )
    clip_return: float = setting(50.0, "critic targets clipped to [-clip_return, 0]; 0: no clipping")
    clip_positive: str = setting(
        "unshaped",
        "whose critic targets are clipped above at 0: unshaped (DDPG only), "
        "all (the authors'), none; a shaped target Q - Φ exceeds 0 wherever Q > Φ, and "
        "with Φ(z_0) = -50 every shaped target clips to 0 (docs/pick_and_place.md)",
        choices=CLIP_POSITIVE,
    )
    device: str = setting("cpu", "device of the networks and replay buffer (e.g. cuda)")
    seed: int = setting(0, "sweep seed (goals, random patterns, chunk seeds)")
    results: str = setting("results/pick_and_place", "results directory (re-run to resume)")
    backend: Literal["local", "ray"] = setting("local", "where learnings run")
    workers: int = setting(1, "learnings run at once (0: in this process)")

    AT_LEAST_ZERO = ("epochs", "num_envs", "workers", "collector_workers", "env_workers")

    def __post_init__(self) -> None:
        super().__post_init__()
        check(self.value_lr > 0 and self.aggregation_lr > 0, "value_lr", "learning rates must be > 0")
        check(self.progress_scale > 0, "progress_scale", "what reaching the goal is worth must be > 0")
        cycle_steps = PRESETS[self.preset]["cycle_steps"]
        self.num_envs = self.num_envs or cycle_steps // fetch.MAX_EPISODE_STEPS
        check(
            cycle_steps % (self.num_envs * fetch.MAX_EPISODE_STEPS) == 0,
            "num_envs",
            f"a cycle's {cycle_steps} steps must split into whole {fetch.MAX_EPISODE_STEPS}-step episodes "
            f"over {self.num_envs} envs",
        )
        processes = max(self.collector_workers, 1) * max(self.env_workers, 1)
        check(
            self.num_envs % processes == 0,
            "num_envs",
            f"{self.num_envs} envs do not split evenly over "
            f"--collector-workers {self.collector_workers} x --env-workers {self.env_workers}",
        )
        try:
            options = json.loads(self.shaping)
        except json.JSONDecodeError as exc:
            raise ConfigError(f"--shaping: not valid JSON: {exc}") from None
        check(isinstance(options, dict), "shaping", f"must be a JSON object, got {self.shaping!r}")
        check_shaping(options)


def make_shaping(
    method_name: str, series: SubgoalSeries | None, config: Mapping[str, Any], gamma: float
) -> tuple[Shaping | None, PotentialTrainer | None]:
    """The method's shaping and, for a neural potential (HRS, RRS), its trainer (the paper's target: the mean,
    a time-out bootstrapped; Adam at ``value_lr``). HRS-D's and SRS's tables are the library's, at
    ``progress_scale`` (stored when one of them runs), with the library's level and target."""
    method = METHODS[method_name]
    parts = shaping_parts(
        method,
        (),
        patterns=[series] if series is not None else None,
        aggregation=fetch.three_state_aggregation(),
        eta=config["eta"],
        progress_scale=config.get("progress_scale", 1.0),
    )
    if parts is None:
        return None, None
    subgoals, potential, options = parts
    neural = is_neural(method)
    if neural and "start_potential" in config:  # HRS, RRS: --start-potential (--shaping wins)
        options = {**options, "start_potential": config["start_potential"]}
    shaping = Shaping(subgoals, potential, {**options, **config["shaping"]}, loss=NEURAL_TARGET if neural else {})
    if not neural:  # NRS: fixed η; SRS: the fixed prior; SARSA-RS, HRS-D: their tables learn online
        return shaping, None
    shaping.potential = NeuralPotential(mlp(fetch.OBSERVATION_SIZE, 1, config["ddpg"]["hidden"]))
    return shaping, PotentialTrainer.for_shaping(shaping, gamma, config["value_lr"], "adam")


def is_neural(method: Method) -> bool:
    """Whether ``method``'s potential is the paper's network over the observation where ``z`` began (HRS,
    RRS), not a table over ``z`` (HRS-D's interpolating table, SRS's fixed one, SARSA-RS's aggregation).

    Examples:
        >>> [name for name, method in METHODS.items() if is_neural(method)]
        ['HRS', 'RRS']
    """
    return method.shaping == "subgoals" and not method.interpolate


def is_library_table(method: Method) -> bool:
    """Whether ``method`` shapes with one of the library's tables over the subgoal series, which start at the
    progress prior (HRS-D, learned online; SRS, fixed): the subgoal methods that are not neural here.

    Examples:
        >>> [name for name, method in METHODS.items() if is_library_table(method)]
        ['SRS', 'HRS-D']
    """
    return method.shaping in ("subgoals", "progress") and not is_neural(method)


def agent_config(config: Mapping[str, Any], shaped: bool) -> DDPGConfig:
    """The DDPG settings of a learner; ``shaped``: its reward carries ``F = γΦ(z') − Φ(z)``.

    A shaped critic learns ``Q − Φ``, which exceeds 0 wherever ``Q > Φ``; once the
    potential of the start state has learned the failure return (``Φ(z_0) = −50``),
    the clip at 0 cuts every shaped target to 0, successes included. So by default
    (``--clip-positive unshaped``) only unshaped learners clip above at 0; a stored
    configuration from before that setting (no ``"shaped_clip_positive"``) clips all.

    Examples:
        >>> config = {"ddpg": dataclasses.asdict(DDPGConfig()), "shaped_clip_positive": False}
        >>> agent_config(config, shaped=False).clip_positive, agent_config(config, shaped=True).clip_positive
        (True, False)
    """
    settings = {**config["ddpg"], "hidden": tuple(config["ddpg"]["hidden"])}
    if shaped:
        settings["clip_positive"] = config.get("shaped_clip_positive", settings["clip_positive"])
    return DDPGConfig(**settings)


def learner_config(config: Mapping[str, Any], method_name: str, shaped: bool, epochs: int) -> DDPGTrainConfig:
    """A learning's settings for :func:`~torchrl_subgoal.training.train_ddpg`: ``epochs`` epochs of the
    authors' schedule, one collected batch per cycle (``cycle_steps`` frames), ``updates`` gradient steps
    after it and one soft target update; the DDPG settings of :func:`agent_config`; the neural potential
    (HRS, RRS) trained per batch, SARSA-RS's table online at ``aggregation_lr``, HRS-D's online at the
    training blocks' ``value_lr``.

    Examples:
        >>> config = {"ddpg": dataclasses.asdict(DDPGConfig()), "cycles": 50, "cycle_steps": 300, "updates": 40,
        ...           "envs": 6, "collector_workers": 2, "env_processes": 0, "device": "cpu", "value_lr": 1e-3,
        ...           "aggregation_lr": 0.1}
        >>> settings = learner_config(config, "HRS", shaped=True, epochs=200)
        >>> settings.total_frames, settings.num_envs, settings.polyak_every, settings.online_potential
        (3000000, 3, 'batch', False)
    """
    ddpg = agent_config(config, shaped)
    if ddpg.actor_lr != ddpg.critic_lr:
        raise ValueError(f"actor_lr ({ddpg.actor_lr}) and critic_lr ({ddpg.critic_lr}) differ: train_ddpg takes one lr")
    workers = config["collector_workers"]
    method = METHODS[method_name]
    aggregation = method.shaping == "aggregation"
    online = aggregation or (is_library_table(method) and method.shaping == "subgoals")  # SARSA-RS, HRS-D
    # the neural potential's Adam (HRS, RRS), SARSA-RS's SGD, or the training blocks' online step (HRS-D)
    value_lr = config["aggregation_lr"] if aggregation else DDPGTrainConfig.value_lr if online else config["value_lr"]
    return DDPGTrainConfig(
        num_envs=config["envs"] // max(workers, 1),
        env_workers=config["env_processes"],
        collector_workers=workers,
        frames_per_batch=config["cycle_steps"],
        total_frames=epochs * config["cycles"] * config["cycle_steps"],
        gamma=ddpg.gamma,
        lr=ddpg.actor_lr,
        learning_starts=0,
        updates_per_batch=config["updates"],
        batch_size=ddpg.batch_size,
        buffer_size=ddpg.buffer_size,
        polyak=ddpg.polyak,
        polyak_every="batch",
        hidden=ddpg.hidden,
        noise_eps=ddpg.noise_eps,
        random_eps=ddpg.random_eps,
        action_l2=ddpg.action_l2,
        norm_clip=ddpg.norm_clip,
        clip_return=ddpg.clip_return,
        clip_positive=ddpg.clip_positive,
        value_lr=value_lr,
        online_potential=online,
        device=config["device"],
    )


def evaluate(env: EnvBase, agent: DDPGAgent, episodes: int) -> tuple[float, float]:
    """Success rate (at the episode's last step) and mean return of greedy episodes."""
    successes, returns = [], []
    with set_exploration_type(ExplorationType.DETERMINISTIC), torch.no_grad():
        for _ in range(episodes):
            rollout = env.rollout(fetch.MAX_EPISODE_STEPS, agent.greedy)
            successes.append(float(rollout["next", "is_success"][-1].item()))
            returns.append(float(rollout["next", "reward"].sum()))
    return float(np.mean(successes)), float(np.mean(returns))


class Epochs:
    """A learning's epochs on :func:`~torchrl_subgoal.training.train_ddpg`'s loop (:class:`DDPGHooks`): after
    every ``cycles`` batches, ``test_episodes`` greedy episodes and a checkpoint (networks, optimisers,
    normaliser, potential, random states and the epoch's transitions); a resumed learning restores the
    last checkpoint before its first batch. The collector is re-seeded at every epoch's start (epochs end
    on whole episodes), so a resumed learning collects as the uninterrupted one did."""

    def __init__(
        self,
        chunk: Chunk,
        config: Mapping[str, Any],
        checkpoint: LearningCheckpoint,
        test_env: EnvBase,
        progress: Callable[[int], None],
    ) -> None:
        self.chunk, self.config, self.checkpoint, self.test_env, self.progress = (
            chunk,
            config,
            checkpoint,
            test_env,
            progress,
        )
        self.saved = checkpoint.load()
        self.records: list[list[float]] = self.saved[0]["records"] if self.saved is not None else []
        self.collected: list[TensorDictBase] = []
        self.cycle = 0

    def start(self, agent: DDPGAgent, batch: LearnerBatch[DDPGTrainConfig]) -> None:
        """Restore the checkpoint (after the collector, whose set-up draws random numbers); seed the epoch."""
        if self.saved is not None:
            state, transitions = self.saved
            for part in transitions:
                agent.replay.extend(part.to(agent.device))
            agent.load_training_state(state["agent"])
            if batch.shaping is not None and state["potential"] is not None:
                batch.shaping.potential.load_state_dict(state["potential"])
            if batch.trainer is not None:
                batch.trainer.optimizer.load_state_dict(state["value_optimizer"])
            restore_rng_states(state["rng"])
            self.progress(len(self.records))
        self._seed(batch)

    def batch(self, agent: DDPGAgent, batch: LearnerBatch[DDPGTrainConfig], data: TensorDictBase) -> bool:
        """Keep the batch's transitions; at an epoch's end, test, checkpoint and seed the next epoch."""
        self.collected.append(data.select(*DDPG_KEYS).reshape(-1))
        self.cycle += 1
        if self.cycle % self.config["cycles"]:
            return False
        success, test_return = evaluate(self.test_env, agent, self.config["test_episodes"])
        self.records.append([self.config["cycles"] * self.config["cycle_steps"], test_return, success])
        state = {
            "agent": agent.training_state(),
            "records": self.records,
            "rng": rng_states(),
            "potential": batch.shaping.potential.state_dict() if batch.shaping is not None else None,
            "value_optimizer": batch.trainer.optimizer.state_dict() if batch.trainer is not None else None,
        }
        self.checkpoint.save(len(self.records), state, torch.cat(self.collected))
        self.collected = []
        self.progress(1)
        self._seed(batch)
        return len(self.records) >= self.config["epochs"]

    def _seed(self, batch: LearnerBatch[DDPGTrainConfig]) -> None:
        assert batch.collector is not None
        epoch = len(self.records)
        batch.collector.set_seed(int(np.random.SeedSequence([self.chunk.seed, epoch]).generate_state(1)[0]))


def learn(
    chunk: Chunk,
    learning: int,
    series: SubgoalSeries | None,
    config: Mapping[str, Any],
    progress: Callable[[int], None],
) -> np.ndarray:
    """One learning on :func:`~torchrl_subgoal.training.train_ddpg`; returns ``[epochs, 3]`` records (env steps,
    test return, success rate)."""
    torch.set_num_threads(1)  # a MultiSyncCollector's shutdown gives this process its workers' threads back
    torch.manual_seed(chunk.seed)  # the neural potential's weights
    np.random.seed(chunk.seed % 2**32)
    goal_seed = int(np.random.SeedSequence([config["seed"], learning]).generate_state(1)[0])
    shaping, _ = make_shaping(chunk.method, series, config, config["ddpg"]["gamma"])
    test_env = fetch.make_fetch_env(goal_seed, device=torch.device(config["device"]))
    epochs = Epochs(chunk, config, LearningCheckpoint(Path(config["checkpoints"]) / chunk.name), test_env, progress)
    left = config["epochs"] - len(epochs.records)
    if left > 0:
        train_ddpg(
            partial(fetch.make_fetch_envs, goal_seed),
            learner_config(config, chunk.method, shaping is not None, left),
            seeds=[chunk.seed],
            shaping=shaping,
            hooks=DDPGHooks(start=epochs.start, batch=epochs.batch),
        )
    test_env.close()
    return np.asarray(epochs.records, dtype=np.float64)


def run_chunk(chunk: Chunk, config: Mapping[str, Any], progress: Callable[[int], None]) -> EpisodeTable:
    """The learnings of one chunk, one after another."""
    series, index = chunk_patterns(chunk, config)
    offsets = config["learning_offsets"]  # RRS: learning k uses random pattern k and goal k
    rows = [
        learn(chunk, learning + offsets.get(pattern, 0), series[int(i)] if series else None, config, progress)
        for (pattern, learning), i in zip(chunk.learners, index, strict=True)
    ]
    records = np.stack(rows)
    return EpisodeTable(records[..., 0].astype(np.int64), records[..., 1], records[..., 2])


def build_patterns(cfg: Config) -> dict[str, dict[str, Any]]:
    """The human pattern(s) and one random pattern per learning (RRS; none when RRS does not run and the
    first pattern's components are not ones random boxes are drawn over)."""
    human = load_patterns(cfg.subgoals, domain="pick_and_place")
    first = next(iter(human))
    try:
        rand = fetch.random_patterns(human[first], cfg.learnings, seed=cfg.seed)
    except ValueError as exc:
        if needs_random_patterns(METHODS, cfg.method_names):
            raise ConfigError(f"{cfg.subgoals}: pattern {first!r}: {exc}") from None
        rand = []
    return {"human": dict(human), "random": {p.name: p for p in rand}, "none": {}}


def build_specs(cfg: Config, patterns: dict[str, dict[str, Any]]) -> list[MethodSpec]:
    """``learnings`` learnings per method: of each human pattern, of one random pattern each (RRS),
    or without patterns."""
    names = check_methods(METHODS, cfg.method_names)
    specs = [
        MethodSpec(name, list(patterns[m.subgoals]) or ["none"], 1 if m.subgoals == "random" else cfg.learnings)
        for name, m in METHODS.items()
    ]
    try:
        return select_methods(specs, names)
    except UnknownMethodError as exc:
        raise ConfigError(f"--methods: {exc}") from None


#: What ``--shaping`` may not set: the recipe sets these itself for every learner.
SHAPING_SET_BY_THE_RECIPE = ("gamma", "value_update")


def check_shaping(options: Mapping[str, Any]) -> None:
    """``--shaping`` checked against the options of :class:`~torchrl_subgoal.SubgoalPotentialTransform`:
    each must be one of its keyword options that the recipe does not set (or ``"backend"``), with a JSON value of the
    option's kind (``true``/``false`` for a flag, a string for a name, a number for a number).

    Args:
        options: the parsed ``--shaping`` object.

    Raises:
        ConfigError: naming ``--shaping``, the option and what it takes.

    Examples:
        >>> check_shaping({"zero_terminal_potential": False})
        >>> check_shaping({"foo": 1})
        Traceback (most recent call last):
        ...
        torchrl_subgoal.experiments.cli.ConfigError: --shaping: unknown option 'foo'; ...
    """
    defaults = {
        name: p.default
        for name, p in inspect.signature(SubgoalPotentialTransform).parameters.items()
        if p.kind is inspect.Parameter.KEYWORD_ONLY and name != "keys"  # entry names: not a JSON value
    }
    defaults["backend"] = "auto"  # SubgoalPotentialTransform.use_backend
    allowed = [name for name in defaults if name not in SHAPING_SET_BY_THE_RECIPE]
    for name, value in options.items():
        if name in SHAPING_SET_BY_THE_RECIPE:
            raise ConfigError(f"--shaping: {name!r} is set by the recipe for every learner; leave it out")
        if name not in defaults:
            raise ConfigError(
                f"--shaping: unknown option {name!r}; SubgoalPotentialTransform takes {', '.join(allowed)}"
            )
        default = defaults[name]
        kinds = {
            bool: ((bool,), "true or false"),
            str: ((str,), "a string"),
            float: ((int, float), "a number"),
            int: ((int,), "a whole number"),
        }
        if default is None or type(default) not in kinds:
            continue  # the transform checks it (see check_shaping_builds)
        accepted, wanted = kinds[type(default)]
        if not isinstance(value, accepted) or (isinstance(value, bool) and bool not in accepted):
            raise ConfigError(f"--shaping: {name!r} takes {wanted}, got {json.dumps(value)}")


def check_shaping_builds(specs: Sequence[MethodSpec], config: Mapping[str, Any]) -> None:
    """Build every shaped learner's transform once, as its chunk will: what ``--shaping`` sets that the
    transform refuses (a bad ``start_potential``, ...) is a :class:`ConfigError` before anything runs.

    Args:
        specs: the sweep's methods.
        config: the sweep's configuration (what ``run_chunk`` reads).
    """
    for spec in specs:
        series, _ = chunk_patterns(Chunk(spec.name, 0, ((spec.patterns[0], 0),), seed=0), config)
        try:
            shaping, _ = make_shaping(spec.name, series[0] if series else None, config, config["ddpg"]["gamma"])
            if shaping is not None:
                shaping.transform(shaping.potential, config["ddpg"]["gamma"], None)
        except (TypeError, ValueError) as exc:
            raise ConfigError(f"--shaping: {spec.name}: {' '.join(str(exc).split())}") from None


def plan(cfg: Config) -> Plan:
    """The sweep of ``cfg``: one chunk per learning, the stored configuration, the report's threshold."""
    check_methods(METHODS, cfg.method_names)
    check_device(cfg.device)
    fetch.require_fetch()
    patterns = build_patterns(cfg)
    specs = build_specs(cfg, patterns)
    preset = PRESETS[cfg.preset]
    epochs = cfg.epochs or preset["epochs"]
    ddpg = dataclasses.asdict(
        DDPGConfig(**preset["ddpg"], clip_return=cfg.clip_return or None, clip_positive=cfg.clip_positive != "none")
    )
    config = {
        **{k: preset[k] for k in ("cycles", "cycle_steps", "updates", "test_episodes")},
        # stored under their former names, so that results started before the flags' renaming resume
        "envs": cfg.num_envs,
        "env_processes": cfg.env_workers,
        **{
            k: getattr(cfg, k)
            for k in (
                "collector_workers",
                "value_lr",
                "aggregation_lr",
                "eta",
                "device",
                "seed",
                "start_potential",
            )
        },
        # stored only where a method reads it, so that results started before it existed resume
        **(
            {"progress_scale": cfg.progress_scale}
            if any(is_library_table(METHODS[n]) for n in cfg.method_names)
            else {}
        ),
        "epochs": epochs,
        "ddpg": ddpg,
        "shaped_clip_positive": cfg.clip_positive == "all",
        "shaping": json.loads(cfg.shaping),
        "checkpoints": str((Path(cfg.results) / "checkpoints").resolve()),
        "subgoal_file": cfg.subgoals,
        "patterns": pattern_config(patterns),
        "pattern_sources": pattern_sources(patterns),
        "learning_offsets": {name: k for k, name in enumerate(patterns["random"])},
        "report": {
            "metric": "success",
            "lower_is_better": False,
            "thresholds": [0.6],
            "window": 1,
            "asymptotic_window": [max(0, epochs - 10), epochs],
            "log_scale": False,
            "unit": "epoch",
        },
    }
    check_shaping_builds(specs, config)
    steps = epochs * preset["cycles"] * preset["cycle_steps"]
    budget = Budget(steps, ("epochs", epochs), chunk_flag=None, unit="epoch")
    return Plan("fetch", specs, run_chunk, config, episodes=epochs, chunk_size=1, budget=budget)


def main(argv: list[str] | None = None, prog: str | None = None) -> int:
    """``torchrl-subgoal reproduce pick-and-place``: parse the flags, run (or resume) the sweep, print the report."""
    return recipe_main(
        Config,
        plan,
        argv,
        description=__doc__.splitlines()[0] if __doc__ else None,
        errors=(*RECIPE_ERRORS, ValueError, ImportError),  # ImportError: the fetch extra missing
        prog=prog,
    )


if __name__ == "__main__":
    sys.exit(main())

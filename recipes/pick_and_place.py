"""Pick and place: DDPG with subgoal-based shaping on single-goal FetchPickAndPlace.

Reproduces the pick-and-place experiment of Okudo & Yamada, "Reward Shaping with
Dynamic Trajectory Aggregation" (IJCNN 2021):

* HRS      — a neural potential V(o; θ) over the participants' two box subgoals (ours),
* RRS      — the same with random boxes over the same components,
* DDPG     — no shaping,
* NRS      — naive subgoal shaping with a fixed potential η,
* SARSA-RS — a learned table over a hand-given three-state aggregation.

Each learning: a TorchRL ``Collector`` over ``TransformedEnv(ParallelEnv(MuJoCo
workers), shaping)`` (shaping and V stay in this process), the authors' schedule
(epochs of cycles: collect ``cycle_steps`` env steps, train V on their SMDP
transitions, ``updates`` DDPG gradient steps, one soft target update), then
``test_episodes`` greedy episodes whose final-step success gives the epoch's success
rate. Every epoch is checkpointed, so a re-run resumes mid-learning; results go
through the experiment engine (one chunk per learning) and the report gives success
curves, epochs to a success rate of 0.6 and the asymptotic success beside the paper's.

    python recipes/pick_and_place.py                          # paper scale: 5 learnings x 200 epochs
    python recipes/pick_and_place.py --preset tiny --results /tmp/pp   # plumbing check, seconds
"""

from __future__ import annotations

import dataclasses
import json
import sys
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Any, Literal

import numpy as np
import torch
from tensordict import TensorDictBase
from torchrl.collectors import Collector
from torchrl.envs import (
    EnvBase,
    ExplorationType,
    ParallelEnv,
    SerialEnv,
    TransformedEnv,
    set_exploration_type,
)

from torchrl_subgoal import (
    NeuralPotential,
    SubgoalPotentialTransform,
    SubgoalSeries,
    SubgoalValueLoss,
)
from torchrl_subgoal.agents.ddpg import DDPG_KEYS, DDPGAgent, DDPGConfig, mlp
from torchrl_subgoal.envs import fetch
from torchrl_subgoal.experiments import (
    Chunk,
    EpisodeTable,
    MethodSpec,
    UnknownMethodError,
    select_methods,
)
from torchrl_subgoal.experiments.checkpoint import (
    LearningCheckpoint,
    restore_rng_states,
    rng_states,
)
from torchrl_subgoal.experiments.cli import ConfigError, check, parse_config, setting
from torchrl_subgoal.experiments.recipe import (
    RECIPE_ERRORS,
    chunk_patterns,
    fail,
    pattern_config,
    pattern_sources,
    sweep_and_report,
)
from torchrl_subgoal.methods import paper_methods, shaping_transform

METHODS = paper_methods(baseline="DDPG")
#: epochs, cycles per epoch, env steps per cycle, gradient steps per cycle, test episodes, DDPG settings
PRESETS: dict[str, dict[str, Any]] = {
    "paper": {"epochs": 200, "cycles": 50, "cycle_steps": 50, "updates": 40, "test_episodes": 10,
              "ddpg": {}},
    "tiny": {"epochs": 2, "cycles": 2, "cycle_steps": 50, "updates": 2, "test_episodes": 1,
             "ddpg": {"hidden": (16, 16), "batch_size": 16}},
}


@dataclass
class Config:
    """Pick and place reproduction: DDPG with HRS, RRS, NRS and SARSA-RS."""

    preset: str = setting("paper", "schedule and network sizes", choices=sorted(PRESETS))
    epochs: int = setting(0, "epochs per learning (0: the preset's; paper: 200 of 2,500 steps)")
    learnings: int = setting(5, "learnings per method (paper: 5)")
    methods: str = setting("HRS,RRS,DDPG,NRS", f"comma-separated methods among {','.join(METHODS)}")
    envs: int = setting(2, "MuJoCo envs collecting together (a batch)")
    env_processes: int = setting(2, "worker processes the envs are spread over (ParallelEnv); 0: this process")
    subgoals: str = setting(fetch.PARTICIPANTS_FILE, "subgoal file of the human pattern (HRS, NRS)")
    value_lr: float = setting(1e-3, "Adam learning rate of the neural potential V(o; θ)")
    aggregation_lr: float = setting(0.1, "SGD learning rate of SARSA-RS's table")
    eta: float = setting(0.1, "NRS potential η (the authors' released value)")
    shaping: str = setting("{}", "JSON of extra SubgoalPotentialTransform options, e.g. "
                           '\'{"zero_terminal_potential": false}\'')
    clip_return: float = setting(50.0, "critic targets clipped to [-clip_return, 0]; 0: no clipping")
    device: str = setting("cpu", "device of the networks and replay buffer (e.g. cuda)")
    seed: int = setting(0, "sweep seed (goals, random patterns, chunk seeds)")
    results: str = setting("results/pick_and_place", "results directory (re-run to resume)")
    backend: Literal["local", "ray"] = setting("local", "where learnings run")
    workers: int = setting(1, "learnings run at once (0: in this process)")
    overwrite: bool = setting(False, "discard results of a different experiment in --results")

    def __post_init__(self) -> None:
        check(self.epochs >= 0, "epochs", f"must be >= 0, got {self.epochs}")
        for name in ("learnings", "envs"):
            check(getattr(self, name) >= 1, name, f"must be >= 1, got {getattr(self, name)}")
        check(self.workers >= 0, "workers", f"must be >= 0, got {self.workers}")
        check(self.env_processes >= 0 and self.envs % max(self.env_processes, 1) == 0, "env_processes",
              f"must be >= 0 and divide --envs {self.envs}, got {self.env_processes}")
        check(self.value_lr > 0 and self.aggregation_lr > 0, "value_lr", "learning rates must be > 0")
        schedule = PRESETS[self.preset]
        check(schedule["cycles"] * schedule["cycle_steps"] % (self.envs * fetch.MAX_EPISODE_STEPS) == 0,
              "envs", f"an epoch's {schedule['cycles'] * schedule['cycle_steps']} steps must split into "
              f"whole {fetch.MAX_EPISODE_STEPS}-step episodes over {self.envs} envs")
        try:
            options = json.loads(self.shaping)
        except json.JSONDecodeError as exc:
            raise ConfigError(f"--shaping: not valid JSON: {exc}") from None
        check(isinstance(options, dict), "shaping", f"must be a JSON object, got {self.shaping!r}")

    @property
    def method_names(self) -> list[str]:
        return [m.strip() for m in self.methods.split(",") if m.strip()]


PotentialTrainer = tuple[SubgoalValueLoss, torch.optim.Optimizer]


def make_shaping(method_name: str, series: SubgoalSeries | None, config: Mapping[str, Any],
                 gamma: float) -> tuple[SubgoalPotentialTransform | None, PotentialTrainer | None]:
    """The method's shaping transform and, for a neural potential, its loss and optimiser."""
    method, options = METHODS[method_name], dict(config["shaping"])
    if method.shaping == "subgoals":  # HRS, RRS: V(o; θ) trained from the SMDP transitions
        potential = NeuralPotential(mlp(fetch.OBSERVATION_SIZE, 1, config["ddpg"]["hidden"]))
        assert series is not None
        transform = SubgoalPotentialTransform(series, potential, gamma=gamma, write_transitions=True, **options)
        loss = SubgoalValueLoss(potential, gamma=gamma, reduction="mean")  # the transform's own potential
        return transform, (loss, torch.optim.Adam(potential.parameters(), lr=config["value_lr"]))
    baseline = shaping_transform(method, torch.Size([]), gamma=gamma, value_lr=config["aggregation_lr"],
                                 patterns=[series] if series is not None else None,
                                 aggregation=fetch.three_state_aggregation(), eta=config["eta"], **options)
    return baseline, None


def make_env(goal_seed: int, config: Mapping[str, Any]) -> EnvBase:
    make = partial(fetch.make_fetch_env, goal_seed)
    processes, envs = config["env_processes"], config["envs"]
    if processes == 0:
        return SerialEnv(envs, make)
    per_process = envs // processes
    return ParallelEnv(processes, make if per_process == 1 else partial(SerialEnv, per_process, make))


def evaluate(env: EnvBase, agent: DDPGAgent, episodes: int) -> tuple[float, float]:
    """Success rate (at the episode's last step) and mean return of greedy episodes."""
    successes, returns = [], []
    with set_exploration_type(ExplorationType.DETERMINISTIC), torch.no_grad():
        for _ in range(episodes):
            rollout = env.rollout(fetch.MAX_EPISODE_STEPS, agent.greedy)
            successes.append(float(rollout["next", "is_success"][-1].item()))
            returns.append(float(rollout["next", "reward"].sum()))
    return float(np.mean(successes)), float(np.mean(returns))


def learn(chunk: Chunk, learning: int, series: SubgoalSeries | None, config: Mapping[str, Any],
          progress: Callable[[int], None]) -> np.ndarray:
    """One learning; returns ``[epochs, 3]`` records (env steps, test return, success rate)."""
    torch.manual_seed(chunk.seed)
    np.random.seed(chunk.seed % 2**32)
    goal_seed = int(np.random.SeedSequence([config["seed"], learning]).generate_state(1)[0])
    ddpg = DDPGConfig(**{**config["ddpg"], "hidden": tuple(config["ddpg"]["hidden"])})
    device = torch.device(config["device"])
    shaping, trainer = make_shaping(chunk.method, series, config, ddpg.gamma)
    env = make_env(goal_seed, config)
    train_env = TransformedEnv(env, shaping) if shaping is not None else env
    test_env = fetch.make_fetch_env(goal_seed, device=device)
    agent = DDPGAgent(fetch.OBSERVATION_SIZE, test_env.action_spec_unbatched, ddpg, device)

    checkpoint = LearningCheckpoint(Path(config["checkpoints"]) / chunk.name)
    records: list[list[float]] = []
    if (saved := checkpoint.load()) is not None:  # resume: replay the stored transitions, restore state
        state, transitions = saved
        for part in transitions:
            agent.replay.extend(part.to(device))
        agent.load_training_state(state["agent"])
        if shaping is not None:
            shaping.potential.load_state_dict(state["potential"])
        if trainer is not None:
            trainer[1].load_state_dict(state["value_optimizer"])
        records = state["records"]
        progress(len(records))
    epochs = config["epochs"]
    if len(records) < epochs:
        collector = Collector(train_env, agent.policy, frames_per_batch=config["cycle_steps"], total_frames=-1,
                              policy_device=device, storing_device="cpu", env_device="cpu",
                              auto_register_policy_transforms=False)
        if saved is not None:  # after the collector, whose set-up draws random numbers
            restore_rng_states(saved[0]["rng"])
        batches = iter(collector)
        for epoch in range(len(records), epochs):
            collected = []
            for _ in range(config["cycles"]):
                data: TensorDictBase = next(batches)
                if trainer is not None:
                    train_potential(*trainer, data)
                agent.extend(data)
                collected.append(data.select(*DDPG_KEYS).reshape(-1))
                for _ in range(config["updates"]):
                    agent.update()
                agent.soft_update()
            success, test_return = evaluate(test_env, agent, config["test_episodes"])
            records.append([config["cycles"] * config["cycle_steps"], test_return, success])
            state = {"agent": agent.training_state(), "records": records, "rng": rng_states(),
                     "potential": shaping.potential.state_dict() if shaping is not None else None,
                     "value_optimizer": trainer[1].state_dict() if trainer is not None else None}
            checkpoint.save(epoch + 1, state, torch.cat(collected))
            progress(1)
        collector.shutdown()
    test_env.close()
    return np.asarray(records, dtype=np.float64)


def train_potential(loss: SubgoalValueLoss, optimizer: torch.optim.Optimizer, data: TensorDictBase) -> None:
    """One Adam step of V on the SMDP transitions emitted in ``data`` (if any)."""
    smdp = data["next", "smdp"]
    mask = smdp["mask"].squeeze(-1)
    if bool(mask.any()):
        optimizer.zero_grad(set_to_none=True)
        loss(smdp[mask])["loss_value"].backward()
        optimizer.step()


def run_chunk(chunk: Chunk, config: Mapping[str, Any], progress: Callable[[int], None]) -> EpisodeTable:
    """The learnings of one chunk, one after another."""
    series, index = chunk_patterns(chunk, config)
    offsets = config["learning_offsets"]  # RRS: learning k uses random pattern k and goal k
    rows = [learn(chunk, learning + offsets.get(pattern, 0), series[int(i)] if series else None, config, progress)
            for (pattern, learning), i in zip(chunk.learners, index, strict=True)]
    records = np.stack(rows)
    return EpisodeTable(records[..., 0].astype(np.int64), records[..., 1], records[..., 2])


def build_patterns(cfg: Config) -> dict[str, dict[str, Any]]:
    """The human pattern(s) and one random pattern per learning (RRS)."""
    human = fetch.human_patterns(cfg.subgoals)
    rand = fetch.random_patterns(next(iter(human.values())), cfg.learnings, seed=cfg.seed)
    return {"human": dict(human), "random": {p.name: p for p in rand}, "none": {}}


def build_specs(cfg: Config, patterns: dict[str, dict[str, Any]]) -> list[MethodSpec]:
    """``learnings`` learnings per method: of each human pattern, of one random pattern each (RRS),
    or without patterns."""
    specs = [MethodSpec(name, list(patterns[m.subgoals]) or ["none"],
                        1 if m.subgoals == "random" else cfg.learnings) for name, m in METHODS.items()]
    try:
        return select_methods(specs, cfg.method_names)
    except UnknownMethodError as exc:
        raise ConfigError(f"--methods: {exc}") from None


def main(argv: list[str] | None = None) -> int:
    torch.set_num_threads(1)
    try:
        cfg = parse_config(Config, argv, description=__doc__.splitlines()[0] if __doc__ else None)
        fetch.require_fetch()
        patterns = build_patterns(cfg)
        specs = build_specs(cfg, patterns)
    except (ConfigError, ValueError, ImportError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    preset = PRESETS[cfg.preset]
    epochs = cfg.epochs or preset["epochs"]
    ddpg = dataclasses.asdict(DDPGConfig(**preset["ddpg"], clip_return=cfg.clip_return or None))
    config = {
        **{k: preset[k] for k in ("cycles", "cycle_steps", "updates", "test_episodes")},
        **{k: getattr(cfg, k) for k in ("envs", "env_processes", "value_lr", "aggregation_lr", "eta",
                                        "device", "seed")},
        "epochs": epochs, "ddpg": ddpg, "shaping": json.loads(cfg.shaping),
        "checkpoints": str((Path(cfg.results) / "checkpoints").resolve()),
        "subgoal_file": cfg.subgoals, "patterns": pattern_config(patterns),
        "pattern_sources": pattern_sources(patterns),
        "learning_offsets": {name: k for k, name in enumerate(patterns["random"])},
        "report": {"metric": "success", "lower_is_better": False, "thresholds": [0.6], "window": 1,
                   "asymptotic_window": [max(0, epochs - 10), epochs], "log_scale": False, "unit": "epoch"},
    }
    try:
        return sweep_and_report("fetch", cfg.results, specs, run_chunk, config, seed=cfg.seed, chunk_size=1,
                                episodes=epochs, overwrite=cfg.overwrite, backend=cfg.backend,
                                workers=cfg.workers)
    except RECIPE_ERRORS as exc:  # results dir not usable, a failed chunk: one line, no traceback
        return fail(exc)


if __name__ == "__main__":
    sys.exit(main())

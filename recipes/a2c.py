"""A2C on TorchRL collectors with subgoal shaping: four-rooms or PinBall, against the paper's baselines.

Each learner is one A2C agent (TorchRL's ``A2CLoss`` with ``GAE``; policy and
value ``TensorDictModule`` s: a one-hot table for four-rooms, a Fourier basis
for PinBall) trained on batches from a ``Collector`` over ``--num-envs`` envs
(a ``ParallelEnv`` with ``--env-workers``; a ``MultiSyncCollector`` with
``--collector-workers``). The shaping transform sits on the outer env; its
potential is shared with the main process, where ``SubgoalValueLoss`` trains
it from each batch's SMDP transitions with its own optimiser (``--online-potential``:
the transform's per-step update instead). Methods: plain A2C, HRS, RRS, NRS and
SARSA-RS from the same subgoal files as the SARSA / actor-critic recipes.

Learners run through the experiment engine (resumable; the same report and
statistics); one report column is one A2C update (a collected batch of
``--frames-per-batch`` frames), whose metric is the mean episode length (frames per
finished episode over the last 8 batches): updates to a threshold x frames per batch
= frames.
TorchRL CSV logs (TensorBoard too if installed) go to ``RESULTS/logs``.

    python recipes/a2c.py --domain four_rooms                 # plain vs HRS vs SARSA-RS, 10 learners each
    python recipes/a2c.py --domain pinball --total-frames 2000000
"""

from __future__ import annotations

import dataclasses
import sys
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np
import torch

from torchrl_subgoal import domains, load_patterns
from torchrl_subgoal.experiments import Chunk, EpisodeTable
from torchrl_subgoal.experiments.cli import ConfigError, check, setting
from torchrl_subgoal.experiments.recipe import (
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
    recipe_main,
)
from torchrl_subgoal.methods import paper_methods, shaping_parts
from torchrl_subgoal.training import A2CConfig, A2CDomain, Shaping, experiment_logger, train_a2c

METHODS = paper_methods(baseline="A2C")


@dataclass
class Config(RecipeConfig):
    """A2C with subgoal shaping on TorchRL collectors."""

    domain: str = setting("four_rooms", "four_rooms or pinball", choices=["four_rooms", "pinball"])
    methods: str = setting("A2C,HRS,SARSA-RS", "comma-separated methods: " + ", ".join(METHODS))
    learnings: int = setting(1, "learnings per subgoal pattern (10 patterns: 10 learners per method)")
    subgoals: str = setting("", "subgoal file of the human patterns (default: the domain's participants)")
    random_patterns: int = setting(10, "random subgoal patterns for RRS")
    total_frames: int = setting(0, "frames per learner (0: the domain's default)")
    num_envs: int = setting(16, "envs per learner")
    frames_per_batch: int = setting(256, "frames per A2C update")
    env_workers: int = setting(0, "ParallelEnv workers per learner (0: the batched env in the collector)")
    collector_workers: int = setting(0, "0: Collector; k: MultiSyncCollector of k processes")
    lr: float = setting(0.0, "A2C learning rate (0: the domain's default)")
    reward_scale: float = setting(0.0, "env reward x this, before shaping and learning (0: the domain's default)")
    value_lr: float = setting(0.05, "learning rate of the potential's optimiser (Adam)")
    online_potential: bool = setting(False, "train the potential in the transform every step instead")
    normalize_advantage: bool = setting(False, "standardise GAE advantages per batch")
    zero_terminal_potential: bool = setting(True, "Φ = 0 at the goal (exact policy invariance)")
    start_potential: str = setting(
        "value",
        "level of Φ: value (Φ = V; docs/torchrl.md's figures), zero or "
        "nonpositive (the library default; docs/shaping_defaults.md)",
        choices=["value", "zero", "nonpositive"],
    )
    seed: int = setting(0, "sweep seed (random patterns, learner seeds)")
    results: str = setting("", "results directory (default results/a2c_<domain>; re-run to resume)")
    backend: Literal["local", "ray"] = setting("local", "where learners run")
    workers: int = setting(2, "learners run at once (processes; 0: in this process)")

    AT_LEAST_ONE = ("learnings", "random_patterns", "num_envs", "frames_per_batch")
    AT_LEAST_ZERO = ("total_frames", "env_workers", "collector_workers", "workers")

    def __post_init__(self) -> None:
        super().__post_init__()
        check(self.value_lr > 0, "value_lr", f"must be positive, got {self.value_lr}")
        check(self.lr >= 0, "lr", f"must be >= 0, got {self.lr}")
        check(self.reward_scale >= 0, "reward_scale", f"must be >= 0, got {self.reward_scale}")


def a2c_config(config: Mapping[str, Any]) -> A2CConfig:
    """The learners' A2C settings from the sweep's configuration."""
    return A2CConfig(**config["a2c"])


def run_chunk(chunk: Chunk, config: Mapping[str, Any], progress: Callable[[int], None]) -> EpisodeTable:
    """Train the chunk's learners one after the other (each steps its own batch of envs)."""
    torch.set_num_threads(1)
    domain = domains.part(config["domain"], A2CDomain)
    method = METHODS[chunk.method]
    patterns, pattern_index = chunk_patterns(chunk, config)
    a2c = a2c_config(config)
    rows = []
    for i, (pattern, learning) in enumerate(chunk.learners):
        index = int(pattern_index[i])
        parts = shaping_parts(
            method,
            (),
            patterns=patterns[index : index + 1] if patterns else None,
            aggregation=domain.aggregation(),
            eta=domain.eta,
            observation_key=domain.subgoal_key,
            aggregation_key=domain.aggregation_key,
            zero_terminal_potential=config["zero_terminal_potential"],
            start_potential=config["start_potential"],
        )
        shaping = Shaping(*parts) if parts is not None else None
        # fresh: a learner run again after an interruption starts its log over, as its results do
        logger = experiment_logger(Path(config["log_dir"]), f"{chunk.method}_{pattern}_{learning}", fresh=True)
        curve = train_a2c(
            domain.make_env,
            a2c,
            shaping=shaping,
            observation_key=domain.observation_key,
            seed=chunk.seed + i,
            logger=logger,
            progress=progress,
        )
        rows.append(curve)
    steps = np.array([np.round(c.episode_length) for c in rows], dtype=np.int64)
    returns = np.array([c.episode_return for c in rows])
    success = np.array([c.success for c in rows])
    return EpisodeTable(steps, returns, success)


def plan(cfg: Config) -> Plan:
    """The sweep of ``cfg``: one chunk per learner, the stored configuration, the report's thresholds."""
    domain = domains.part(cfg.domain, A2CDomain)
    check_methods(METHODS, cfg.method_names)
    try:
        a2c = dataclasses.replace(
            domain.a2c,
            num_envs=cfg.num_envs,
            frames_per_batch=cfg.frames_per_batch,
            env_workers=cfg.env_workers,
            collector_workers=cfg.collector_workers,
            value_lr=cfg.value_lr,
            online_potential=cfg.online_potential,
            normalize_advantage=cfg.normalize_advantage,
            total_frames=cfg.total_frames or domain.a2c.total_frames,
            lr=cfg.lr or domain.a2c.lr,
            reward_scale=cfg.reward_scale or domain.a2c.reward_scale,
        )
    except ValueError as exc:
        raise ConfigError(str(exc)) from None
    check(
        a2c.total_frames >= a2c.frames_per_batch,
        "total_frames",
        f"{a2c.total_frames} is less than one batch of {a2c.frames_per_batch} frames (--frames-per-batch); "
        f"give at least {a2c.frames_per_batch}",
    )
    human = load_patterns(cfg.subgoals or domain.participants, domain=cfg.domain)
    patterns = pattern_sets(
        human,
        domain.candidates(cfg.seed),
        cfg.random_patterns,
        cfg.seed,
        random_needed=needs_random_patterns(METHODS, cfg.method_names),
    )
    check_patterns(patterns, domain.make_env(1), str(domain.subgoal_key))
    specs = method_specs(METHODS, cfg.method_names, patterns, cfg.learnings)
    results = cfg.results or f"results/a2c_{cfg.domain}"
    config = {
        "domain": cfg.domain,
        "a2c": dataclasses.asdict(a2c),
        "zero_terminal_potential": cfg.zero_terminal_potential,
        "start_potential": cfg.start_potential,
        "subgoal_file": cfg.subgoals or domain.participants,
        "patterns": pattern_config(patterns),
        "pattern_sources": pattern_sources(patterns),
        "log_dir": str(Path(results) / "logs"),
        "report": {
            "metric": "steps",
            "thresholds": list(domain.thresholds),
            "unit": "update",
            "asymptotic_window": [max(0, a2c.iterations - 10), a2c.iterations],
        },
    }
    return Plan(f"a2c_{cfg.domain}", specs, run_chunk, config, episodes=a2c.iterations, chunk_size=1, results=results)


def main(argv: list[str] | None = None) -> int:
    return recipe_main(Config, plan, argv, description=__doc__.splitlines()[0] if __doc__ else None, threads=None)


if __name__ == "__main__":
    sys.exit(main())

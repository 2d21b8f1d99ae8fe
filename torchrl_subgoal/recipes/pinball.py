"""PinBall: a Fourier-basis actor-critic with subgoal-based reward shaping against the paper's baselines.

Reproduces the PinBall experiment of Okudo & Yamada, "Reward Shaping with
Dynamic Trajectory Aggregation" (IJCNN 2021), on the "simple" map:

* HRS      — shaping from the ten participants' two-circle subgoal series (ours),
* RRS      — the same with ten random two-circle series,
* AC       — no shaping,
* NRS      — naive subgoal shaping with a fixed potential η (10,000),
* SARSA-RS — a learned potential over three abstract states (thirds of the table in x).

The agent is the authors' released Q-based actor-critic (``--preset released``)
or the TD-error actor-critic of the paper's text (``--preset paper``); shaping
follows the authors' conventions unless ``--zero-terminal-potential`` /
``--start-potential`` say otherwise (docs/shaping_defaults.md).
``learnings`` learnings per pattern (ten patterns; the unshaped methods get
ten times as many of one pseudo-pattern), each method's learnings batched.
Results go to ``--results`` chunk by chunk (re-run to resume); the report
gives times to reach a 10-episode moving average of 3000/2000/1000/500 steps
beside the paper's table.

    torchrl-subgoal reproduce pinball                   # the paper's scale: 100 learnings per method
    torchrl-subgoal reproduce pinball --learnings 2     # a quick look
"""

from __future__ import annotations

import dataclasses
import sys
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from importlib.resources import files
from typing import Any

import torch
from torchrl.envs import TransformedEnv

from torchrl_subgoal import Box, Circle, StateAggregation, load_patterns
from torchrl_subgoal.envs import PinBallEnv
from torchrl_subgoal.experiments import Chunk, EpisodeTable, learner_seeds
from torchrl_subgoal.experiments.cli import ConfigError, setting
from torchrl_subgoal.experiments.recipe import (
    PatternSets,
    Plan,
    ReproductionConfig,
    check_methods,
    check_patterns,
    chunk_patterns,
    method_specs,
    needs_random_patterns,
    pattern_sets,
    potential_entries,
    potential_options,
    recipe_main,
    sweep_entries,
    warm_up_chunks,
)
from torchrl_subgoal.fused import AC_PRESETS, FourierActorCritic, run_episodes
from torchrl_subgoal.methods import all_methods, paper_methods, shaping_transform

METHODS = all_methods(baseline="AC")
OBSERVATION_KEY = "observation"  # what the subgoal predicates read: (x, y, ẋ, ẏ)
PARTICIPANTS = str(files("torchrl_subgoal") / "domains" / "pinball" / "pinball_participants.yaml")
SUBGOAL_RADIUS = 0.04  # the target's radius, as in the paper


@dataclass
class Config(ReproductionConfig):
    """PinBall reproduction: actor-critic with HRS, RRS, NRS and SARSA-RS."""

    preset: str = setting(
        "released",
        "agent and rates: released (the authors' Q-based actor-critic), paper "
        "(the text's TD-error actor-critic, rates 0.01) or released-td (TD-error, released rates)",
        choices=sorted(AC_PRESETS),
    )
    episodes: int = setting(200, "episodes per learning (paper: 200)")
    learnings: int = setting(10, "learnings per subgoal pattern (paper: 10)")
    methods: str = setting(
        ",".join(paper_methods(baseline="AC")), f"comma-separated methods to run, of {', '.join(METHODS)}"
    )
    subgoals: str = setting(
        PARTICIPANTS, "subgoal file of the human patterns (HRS, NRS)", shown_default="the paper's ten participants'"
    )
    eta: float = setting(10_000.0, "NRS potential η (paper: 10,000)")
    step_penalty: float = setting(0.0, "reward of a step without thrust (classic PinBall: -1; the paper: 0)")
    thrust_penalty: float = setting(0.0, "reward of a thrust (classic PinBall: -5; the paper: 0)")
    map: str = setting("simple", "PinBall configuration: simple, hard or a file")
    max_steps: int = setting(10_000, "episode cap (paper: 10,000)")
    engine: str = setting(
        "fused", "fused: one compiled loop; torchrl: step_and_maybe_reset (same episodes)", choices=["fused", "torchrl"]
    )
    results: str = setting("results/pinball", "results directory (re-run to resume)")
    chunk_size: int = setting(
        10,
        "learners per batch (results do not depend on it; small chunks keep both "
        "workers busy to the end and resume finer)",
    )

    AT_LEAST_ONE = ("episodes", "learnings", "random_patterns", "max_steps", "chunk_size")


def thirds_of_the_table() -> StateAggregation:
    """SARSA-RS's three abstract states: x in [0, 1/3], [1/3, 2/3], [2/3, 1]."""
    return StateAggregation.from_regions([Box((c,), (1 / 6,), (0,)) for c in (1 / 6, 1 / 2, 5 / 6)], 4)


def pinball_env(cfg: Config) -> PinBallEnv:
    """One env on ``--map`` (a bad map name or file is a :class:`ConfigError` naming the flag)."""
    try:
        return PinBallEnv(1, cfg.map)
    except (ValueError, OSError) as exc:
        raise ConfigError(f"--map: {' '.join(str(exc).split())}") from None


def build_patterns(cfg: Config) -> PatternSets:
    """The human patterns (from the file) and the seeded random ones, by kind."""
    human = load_patterns(cfg.subgoals, domain="pinball")
    env = pinball_env(cfg)
    points = env.sample_free_positions(500, torch.Generator().manual_seed(cfg.seed))
    candidates = [Circle((float(x), float(y)), SUBGOAL_RADIUS) for x, y in points.tolist()]
    return pattern_sets(
        human, candidates, cfg.random_patterns, cfg.seed, random_needed=needs_random_patterns(METHODS, cfg.method_names)
    )


def run_chunk(chunk: Chunk, config: Mapping[str, Any], progress: Callable[[int], None]) -> EpisodeTable:
    """One batch of learnings of one method: env batch = learners."""
    ac = AC_PRESETS[config["preset"]]
    method = METHODS[chunk.method]
    patterns, pattern_index = chunk_patterns(chunk, config)

    seeds = learner_seeds(config["seed"], chunk)  # each learner's own: results do not depend on the chunking
    env = PinBallEnv(
        chunk.n_learners,
        config["map"],
        max_steps=config["max_steps"],
        seed=seeds,
        step_penalty=config["step_penalty"],
        thrust_penalty=config["thrust_penalty"],
    )
    shaping = shaping_transform(
        method,
        env.batch_size,
        gamma=ac.gamma,
        value_lr=ac.value_lr,
        patterns=patterns,
        pattern_index=pattern_index,
        aggregation=thirds_of_the_table(),
        eta=config["eta"],
        zero_terminal_potential=config["zero_terminal_potential"],
        observation_key=OBSERVATION_KEY,
        start_potential=config["start_potential"],
        expectile=config.get("expectile", 0.5),
        bootstrap_truncated=config.get("bootstrap_truncated", True),
        **potential_options(config, method),
    )
    learning_env = TransformedEnv(env, shaping) if shaping is not None else env
    spec = env.observation_spec["observation"]
    agent = FourierActorCritic(chunk.n_learners, spec.low[0], spec.high[0], 5, ac, seed=seeds)
    records = run_episodes(learning_env, agent, config["episodes"], progress=progress, engine=config["engine"])
    return EpisodeTable(records.steps, records.returns, records.success)


def plan(cfg: Config) -> Plan:
    """The sweep of ``cfg``: every method's learners, the stored configuration, the report's thresholds."""
    check_methods(METHODS, cfg.method_names)
    patterns = build_patterns(cfg)
    check_patterns(patterns, pinball_env(cfg), OBSERVATION_KEY)
    specs = method_specs(METHODS, cfg.method_names, patterns, cfg.learnings)
    settings = dataclasses.asdict(cfg)
    config = {
        **{
            k: settings[k]
            for k in (
                "preset",
                "episodes",
                "eta",
                "zero_terminal_potential",
                "start_potential",
                "step_penalty",
                "thrust_penalty",
                "map",
                "max_steps",
                "engine",
                "expectile",
                "bootstrap_truncated",
            )
        },
        "actor_critic": dataclasses.asdict(AC_PRESETS[cfg.preset]),
        **potential_entries(cfg),
        **sweep_entries(cfg, cfg.subgoals, patterns),
        "report": {
            "metric": "steps",
            "thresholds": [3000, 2000, 1000, 500],
            "window": min(10, cfg.episodes),
            "asymptotic_window": [max(0, cfg.episodes - 10), cfg.episodes],
            "map": {"config": cfg.map},
        },
    }
    return Plan(
        "pinball",
        specs,
        run_chunk,
        config,
        episodes=cfg.episodes,
        chunk_size=cfg.chunk_size,
        warm_up=warm_up_chunks(run_chunk, specs, config),
    )


def main(argv: list[str] | None = None, prog: str | None = None) -> int:
    """``torchrl-subgoal reproduce pinball``: parse the flags, run (or resume) the sweep, print the report."""
    return recipe_main(Config, plan, argv, description=__doc__.splitlines()[0] if __doc__ else None, prog=prog)


if __name__ == "__main__":
    sys.exit(main())

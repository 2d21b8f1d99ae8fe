"""Four-rooms: SARSA with subgoal-based reward shaping against the paper's baselines.

Reproduces the four-rooms experiment of Okudo & Yamada, "Reward Shaping with
Dynamic Trajectory Aggregation" (IJCNN 2021):

* HRS      — shaping from the ten participants' subgoal series (ours),
* RRS      — the same with ten random subgoal series,
* SARSA    — no shaping,
* NRS      — naive subgoal shaping with a fixed potential η,
* SARSA-RS — a learned potential over the four rooms (Grzes & Kudenko).

Shaping follows the authors' released conventions (goal step shaped with
``γV(z_T)``, ``Φ = V``) unless ``--zero-terminal-potential`` /
``--start-potential`` say otherwise; ``--reward step-cost`` pays -1 per step
and 0 at the goal instead of +1 at the goal (docs/shaping_defaults.md).
Every method runs ``learnings`` independent learnings per subgoal pattern
(ten patterns; the unshaped methods get ten times as many learnings of one
pseudo-pattern), all learnings of a method as one batch: the env batch *is*
the set of learners. Results go to ``--results`` chunk by chunk (re-run the
same command to resume), then the report prints the table beside the paper's
and writes ``report.md``, ``summary.json`` and PNGs there.

    torchrl-subgoal reproduce four-rooms                      # small default, under a minute of CPU
    torchrl-subgoal reproduce four-rooms --learnings 100      # paper scale: 1,000 learnings per method
"""

from __future__ import annotations

import dataclasses
import sys
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from importlib.resources import files
from typing import Any

from torchrl.envs import TransformedEnv

from torchrl_subgoal import load_patterns
from torchrl_subgoal.envs import FourRoomsEnv
from torchrl_subgoal.envs.four_rooms import GOAL, START, free_cells, room_aggregation
from torchrl_subgoal.experiments import Chunk, EpisodeTable, learner_seeds
from torchrl_subgoal.experiments.cli import setting
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
from torchrl_subgoal.fused import SARSA_PRESETS, SoftmaxSarsa, run_episodes
from torchrl_subgoal.methods import all_methods, paper_methods, shaping_transform
from torchrl_subgoal.subgoals import Cell

METHODS = all_methods(baseline="SARSA")
PARTICIPANTS = str(files("torchrl_subgoal") / "domains" / "four_rooms" / "four_rooms_participants.yaml")
OBSERVATION_KEY = "cell"  # what the subgoal predicates read: (row, col)


@dataclass
class Config(ReproductionConfig):
    """Four-rooms reproduction: SARSA with HRS, RRS, NRS and SARSA-RS."""

    preset: str = setting(
        "released",
        "SARSA hyper-parameters: the paper's text or the released configuration",
        choices=sorted(SARSA_PRESETS),
    )
    episodes: int = setting(1000, "episodes per learning (paper: 1000)")
    learnings: int = setting(10, "learnings per subgoal pattern (paper: 100)")
    methods: str = setting(
        ",".join(paper_methods(baseline="SARSA")), f"comma-separated methods to run, of {', '.join(METHODS)}"
    )
    subgoals: str = setting(
        PARTICIPANTS, "subgoal file of the human patterns (HRS, NRS)", shown_default="the paper's ten participants'"
    )
    eta: float = setting(1.0, "NRS potential η (paper: 1)")
    agent_state: str = setting(
        "s",
        "what SARSA's table is over for subgoal methods: s (the paper) or s,z "
        "(z = subgoal index; makes Φ(z) a potential over the agent's state)",
        choices=["s", "s,z"],
    )
    reward: str = setting(
        "goal",
        "goal: +1 at the goal, 0 otherwise (the paper); step-cost: -1 per step, 0 at the goal",
        choices=["goal", "step-cost"],
    )
    results: str = setting("results/four_rooms", "results directory (re-run to resume)")


def build_patterns(cfg: Config) -> PatternSets:
    """The human patterns (from the file) and the seeded random ones, by kind."""
    human = load_patterns(cfg.subgoals, domain="four_rooms")
    candidates = [Cell(r, c) for r, c in free_cells() if (r, c) not in (START, GOAL)]
    return pattern_sets(
        human, candidates, cfg.random_patterns, cfg.seed, random_needed=needs_random_patterns(METHODS, cfg.method_names)
    )


def run_chunk(chunk: Chunk, config: Mapping[str, Any], progress: Callable[[int], None]) -> EpisodeTable:
    """One batch of learnings of one method: env batch = learners."""
    sarsa = SARSA_PRESETS[config["preset"]]
    method = METHODS[chunk.method]
    patterns, pattern_index = chunk_patterns(chunk, config)

    goal_reward, step_reward = (1.0, 0.0) if config["reward"] == "goal" else (0.0, -1.0)
    env = FourRoomsEnv(num_envs=chunk.n_learners, goal_reward=goal_reward, step_reward=step_reward)
    shaping = shaping_transform(
        method,
        env.batch_size,
        gamma=sarsa.gamma,
        value_lr=sarsa.value_lr,
        patterns=patterns,
        pattern_index=pattern_index,
        aggregation=room_aggregation(),
        eta=config["eta"],
        observation_key=OBSERVATION_KEY,
        zero_terminal_potential=config["zero_terminal_potential"],
        start_potential=config["start_potential"],
        expectile=config.get("expectile", 0.5),
        bootstrap_truncated=config.get("bootstrap_truncated", True),
        **potential_options(config, method),
    )
    learning_env = TransformedEnv(env, shaping) if shaping is not None else env
    subgoal_aware = config["agent_state"] == "s,z" and method.shaping in ("subgoals", "naive", "progress")
    abstract_states = max(len(p) for p in patterns) + 1 if subgoal_aware else 1
    agent = SoftmaxSarsa(
        chunk.n_learners,
        env.num_states,
        4,
        sarsa,
        seed=learner_seeds(config["seed"], chunk),
        abstract_states=abstract_states,
    )
    records = run_episodes(learning_env, agent, config["episodes"], progress=progress, engine=config["engine"])
    return EpisodeTable(records.steps, records.returns, records.success)


def plan(cfg: Config) -> Plan:
    """The sweep of ``cfg``: every method's learners, the stored configuration, the report's thresholds."""
    check_methods(METHODS, cfg.method_names)
    patterns = build_patterns(cfg)
    check_patterns(patterns, FourRoomsEnv(num_envs=1), OBSERVATION_KEY)
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
                "reward",
                "engine",
                "agent_state",
                "expectile",
                "bootstrap_truncated",
            )
        },
        "sarsa": dataclasses.asdict(SARSA_PRESETS[cfg.preset]),
        **potential_entries(cfg),
        **sweep_entries(cfg, cfg.subgoals, patterns),
        "report": {
            "metric": "steps",
            "thresholds": [500, 300, 100, 50],
            "asymptotic_window": [max(0, cfg.episodes - 10), cfg.episodes],
        },
    }
    return Plan(
        "four_rooms",
        specs,
        run_chunk,
        config,
        episodes=cfg.episodes,
        chunk_size=cfg.chunk_size,
        warm_up=warm_up_chunks(run_chunk, specs, config),
    )


def main(argv: list[str] | None = None, prog: str | None = None) -> int:
    """``torchrl-subgoal reproduce four-rooms``: parse the flags, run (or resume) the sweep, print the report."""
    return recipe_main(Config, plan, argv, description=__doc__.splitlines()[0] if __doc__ else None, prog=prog)


if __name__ == "__main__":
    sys.exit(main())

"""Tabular Q-learning on a TorchRL Collector with subgoal shaping, under a step cost or a goal reward.

The first learner a TorchRL user writes (an ε-greedy table, a ``Collector``, one
Q-learning update per step; :mod:`torchrl_subgoal.training.qlearning`) against:

* Q        — no shaping (the table over ``s``),
* HRS      — the learned subgoal potential, the library's defaults (``SubgoalValueLoss``:
  the 0.9-expectile target, no update on a time-out inside ``z``; ``--expectile`` and
  ``--bootstrap-truncated`` change them),
* HRS-mean — the same with the paper's mean target, time-outs bootstrapped,
* NRS      — naive subgoal shaping, ``Φ = η`` once a subgoal is achieved,
* SRS      — a fixed potential rising with each subgoal achieved (the progress prior),
* HRS-D    — the library's default potential (``TabularPotential.for_subgoals``): HRS whose potential
  also rises as the next subgoal's cell comes nearer (straight-line distance, walls ignored;
  :mod:`torchrl_subgoal.transform.segments`).

The shaped learners' tables are over ``(s, z)`` (``--agent-state s`` for ``s``). Tasks:
``four_rooms`` (the participants' subgoal series; ``--reward step-cost``: −1 per step and
0 at the goal, or ``goal``: +1 at the goal), ``sparse_rooms`` (four 9 × 9 rooms, the goal
35 steps away in the far corner by either of two routes, 500 steps per episode, so a random
walk seldom finds it; subgoals: the two doorways of one route) and ``taxi`` (gymnasium's
Taxi: −1 per step, −10 per illegal action, +20 at delivery; subgoals: passenger in the taxi,
then at the destination). Results go to ``--results`` chunk by chunk (re-run to resume); the report
gives episodes to each threshold of steps per episode, the final steps and the tests.

    python recipes/qlearning.py --domain four_rooms --reward step-cost    # 20 learners per method
    python recipes/qlearning.py --domain taxi --episodes 400
"""

from __future__ import annotations

import dataclasses
import math
import sys
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from importlib.resources import files
from typing import Any

import torch
from torchrl.envs import EnvBase, TransformedEnv

from torchrl_subgoal import Cell, SubgoalSeries, load_patterns
from torchrl_subgoal.envs import FourRoomsEnv
from torchrl_subgoal.experiments import Chunk, EpisodeTable
from torchrl_subgoal.experiments.cli import check, setting
from torchrl_subgoal.experiments.recipe import (
    Plan,
    RecipeConfig,
    check_methods,
    check_patterns,
    check_unused,
    chunk_patterns,
    method_specs,
    pattern_sets,
    recipe_main,
    sweep_entries,
)
from torchrl_subgoal.methods import HRS_D, SRS, Method, shaping_transform
from torchrl_subgoal.training import SuccessSignal
from torchrl_subgoal.training.qlearning import QLearningConfig, train_qlearning

METHODS = {
    "Q": Method("Q", "none", "none"),
    "HRS": Method("HRS", "subgoals", "human"),
    "HRS-mean": Method("HRS-mean", "subgoals", "human"),
    "NRS": Method("NRS", "naive", "human"),
    "SRS": SRS,
    "HRS-D": HRS_D,
}
#: the paper's target (HRS-mean); HRS's comes from the flags (default: the library's)
MEAN_TARGET = {"expectile": 0.5, "bootstrap_truncated": True}
PARTICIPANTS = str(files("torchrl_subgoal") / "domains" / "four_rooms" / "four_rooms_participants.yaml")
#: per task: the env's subgoal-read key, the report's thresholds and moving-average window
TASKS: dict[str, dict[str, Any]] = {
    "four_rooms": {"subgoal_key": "cell", "thresholds": [100, 50], "window": 1},
    "sparse_rooms": {"subgoal_key": "cell", "thresholds": [200, 60], "window": 1},
    "taxi": {"subgoal_key": "observation", "thresholds": [100, 50, 25], "window": 20},
}
#: sparse_rooms: four 9 x 9 rooms; start top-left, goal bottom-right, 35 steps by either route
SPARSE_ROOMS = """\
wwwwwwwwwwwwwwwwwwwww
w         w         w
w         w         w
w         w         w
w         w         w
w                   w
w         w         w
w         w         w
w         w         w
wwwwww wwwwwwww wwwww
w         w         w
w         w         w
w         w         w
w         w         w
w                   w
w         w         w
w         w         w
w         w         w
w         w         w
wwwwwwwwwwwwwwwwwwwww"""
#: sparse_rooms' subgoals: the doorways of the route through the top-right room
SPARSE_ROOMS_ROUTE = SubgoalSeries([Cell(5, 10), Cell(9, 15)], name="through_the_top_right")


@dataclass
class Config(RecipeConfig):
    """Tabular ε-greedy Q-learning with HRS-D (the library's default potential), HRS, HRS-mean and NRS against no
    shaping."""

    domain: str = setting("four_rooms", "four_rooms, sparse_rooms or taxi", choices=sorted(TASKS))
    reward: str = setting(
        "step-cost",
        "four_rooms and sparse_rooms: step-cost (-1 per step) or goal (+1 at the goal)",
        choices=["step-cost", "goal"],
    )
    methods: str = setting("Q,HRS-D,HRS,HRS-mean,NRS", f"comma-separated methods to run, of {', '.join(METHODS)}")
    learnings: int = setting(2, "learnings per subgoal pattern (four_rooms has 10 patterns, taxi 1)")
    episodes: int = setting(200, "episodes per learning")
    lr: float = setting(0.25, "Q-learning step size alpha")
    epsilon: float = setting(0.1, "probability of a random action")
    gamma: float = setting(0.99, "discount gamma (of the learner and of the shaping term)")
    value_lr: float = setting(0.1, "alpha_v of the learned potentials' online update")
    eta: float = setting(1.0, "NRS potential η")
    progress_scale: float = setting(
        1.0, "HRS's table starts at the subgoals' progress prior of this scale (0: at 0); SRS shapes with the prior"
    )
    monotone_potential: bool = setting(True, "HRS, HRS-mean: shape with the table non-decreasing along the series")
    agent_state: str = setting("s,z", "what the shaped learners' tables are over", choices=["s,z", "s"])
    expectile: float = setting(0.9, "HRS: τ of the potential's target (HRS-mean: 0.5)")
    bootstrap_truncated: bool = setting(False, "HRS: train V(z) on a time-out inside z (HRS-mean: true)")
    prior_weight: float = setting(
        0.0, "HRS, HRS-D: the table's start counts as this many transitions, handed over as V(z) learns (0: none)"
    )
    achievement_reward: float = setting(
        0.0, "HRS, HRS-D: added to the potential's target per subgoal achieved, in the env's reward units (0: none)"
    )
    zero_terminal_potential: bool = setting(True, "HRS, HRS-mean: Φ = 0 at the goal")
    start_potential: str = setting(
        "nonpositive", "HRS, HRS-mean: the level of Φ", choices=["value", "zero", "nonpositive"]
    )
    chunk_size: int = setting(100, "learners per batch (one policy seed per chunk)")
    results: str = setting(
        "", "results directory (re-run to resume)", shown_default="results/qlearning_<domain>[_<reward>]"
    )

    AT_LEAST_ONE = ("learnings", "episodes", "chunk_size")

    def __post_init__(self) -> None:
        super().__post_init__()
        for name in ("lr", "value_lr"):
            check(0.0 < getattr(self, name) <= 1.0, name, f"must lie in (0, 1], got {getattr(self, name)}")
        check(0.0 <= self.epsilon <= 1.0, "epsilon", f"must lie in [0, 1], got {self.epsilon}")
        check(0.0 <= self.gamma <= 1.0, "gamma", f"must lie in [0, 1], got {self.gamma}")
        check(self.eta >= 0.0, "eta", f"must be >= 0, got {self.eta}")
        check(self.progress_scale >= 0.0, "progress_scale", f"must be >= 0, got {self.progress_scale}")
        check(0.0 < self.expectile < 1.0, "expectile", f"must lie strictly between 0 and 1, got {self.expectile}")
        check(self.prior_weight >= 0.0, "prior_weight", f"must be >= 0 (transitions), got {self.prior_weight}")
        finite = math.isfinite(self.achievement_reward)
        check(finite, "achievement_reward", f"must be finite, got {self.achievement_reward}")
        if self.domain == "taxi":
            check_unused(
                self, ["reward"], "applies to --domain four_rooms and sparse_rooms only (taxi's rewards are its own)"
            )


def make_env(config: Mapping[str, Any], n: int) -> EnvBase:
    """The task's batch of ``n`` envs."""
    if config["task"] == "taxi":
        from torchrl_subgoal.envs.taxi import make_taxi

        return make_taxi(n)
    goal = config["reward"] == "goal"
    goal_reward, step_reward = (1.0, 0.0) if goal else (0.0, -1.0)
    if config["task"] == "sparse_rooms":
        return FourRoomsEnv(
            n,
            layout=SPARSE_ROOMS,
            start=(1, 1),
            goal=(18, 19),
            max_steps=500,
            goal_reward=goal_reward,
            step_reward=step_reward,
        )
    return FourRoomsEnv(num_envs=n, goal_reward=goal_reward, step_reward=step_reward)


def task_success(config: Mapping[str, Any]) -> SuccessSignal:
    """What a successful episode is: the goal's step, told by its reward (four-rooms: 1 with the goal reward, 0
    against -1 under the step cost; Taxi: the delivery's +20, which a return cannot tell from a time-out after
    illegal moves)."""
    if config["task"] == "taxi":
        return SuccessSignal(final_reward=20.0)
    return SuccessSignal(final_reward=1.0 if config["reward"] == "goal" else 0.0)


def run_chunk(chunk: Chunk, config: Mapping[str, Any], progress: Callable[[int], None]) -> EpisodeTable:
    """One batch of learnings of one method: one Q table per env."""
    env = make_env(config, chunk.n_learners)
    patterns, index = chunk_patterns(chunk, config)
    shaping = shaping_transform(
        METHODS[chunk.method],
        env.batch_size,
        gamma=config["gamma"],
        value_lr=config["value_lr"],
        patterns=patterns,
        pattern_index=index,
        eta=config["eta"],
        observation_key=TASKS[config["task"]]["subgoal_key"],
        zero_terminal_potential=config["zero_terminal_potential"],
        start_potential=config["start_potential"],
        progress_scale=config.get("progress_scale", 0.0),
        monotone_potential=config.get("monotone_potential", False),
        **(MEAN_TARGET if chunk.method == "HRS-mean" else config["target"]),
    )
    env = TransformedEnv(env, shaping) if shaping is not None else env
    settings = QLearningConfig(
        episodes=config["episodes"],
        lr=config["lr"],
        gamma=config["gamma"],
        epsilon=config["epsilon"],
        sees_subgoal=config["agent_state"] == "s,z",
    )
    records = train_qlearning(env, settings, seed=chunk.seed, progress=progress, success=task_success(config)).records
    return EpisodeTable(records.steps, records.returns, records.success)


def plan(cfg: Config) -> Plan:
    """The sweep of ``cfg``: every method's learners, the stored configuration, the report's thresholds."""
    check_methods(METHODS, cfg.method_names)
    task = TASKS[cfg.domain]
    if cfg.domain == "taxi":
        from torchrl_subgoal.envs.taxi import taxi_subgoals

        human, subgoal_file = {"pick_up_then_drive": taxi_subgoals()}, "torchrl_subgoal.envs.taxi:taxi_subgoals"
    elif cfg.domain == "sparse_rooms":
        human, subgoal_file = {SPARSE_ROOMS_ROUTE.name: SPARSE_ROOMS_ROUTE}, "recipes/qlearning.py:SPARSE_ROOMS_ROUTE"
    else:
        human, subgoal_file = load_patterns(PARTICIPANTS, domain="four_rooms"), PARTICIPANTS
    patterns = pattern_sets(human, [], 0, cfg.seed, random_needed=False)
    settings = dataclasses.asdict(cfg)
    config: dict[str, Any] = {
        "task": cfg.domain,  # the key results started before the flag's renaming (--task) resume with
        **{
            k: settings[k]
            for k in (
                "reward",
                "episodes",
                "lr",
                "epsilon",
                "gamma",
                "value_lr",
                "eta",
                "agent_state",
                "zero_terminal_potential",
                "start_potential",
                "progress_scale",
                "monotone_potential",
            )
        },
    }
    check_patterns(patterns, make_env(config, 1), task["subgoal_key"])
    name = cfg.domain if cfg.domain == "taxi" else f"{cfg.domain}_{cfg.reward.replace('-', '_')}"
    config.update(
        domain=cfg.domain,
        target={
            "expectile": cfg.expectile,
            "bootstrap_truncated": cfg.bootstrap_truncated,
            **{k: getattr(cfg, k) for k in ("prior_weight", "achievement_reward") if getattr(cfg, k)},
        },
        **sweep_entries(cfg, subgoal_file, patterns),
        report={
            "metric": "steps",
            "thresholds": task["thresholds"],
            "window": min(task["window"], cfg.episodes),
            "asymptotic_window": [max(0, cfg.episodes - 20), cfg.episodes],
        },
    )
    specs = method_specs(METHODS, cfg.method_names, patterns, cfg.learnings)
    return Plan(
        f"qlearning_{name}",
        specs,
        run_chunk,
        config,
        episodes=cfg.episodes,
        chunk_size=cfg.chunk_size,
        results=cfg.results or f"results/qlearning_{name}",
    )


def main(argv: list[str] | None = None) -> int:
    torch.set_num_threads(1)
    return recipe_main(Config, plan, argv, description=__doc__.splitlines()[0] if __doc__ else None)


if __name__ == "__main__":
    sys.exit(main())

"""The PinBall domain plugin: env, subgoal check, and each layer's part (A2C set-up, paper table and
report map, studio table and learner).

Everything the package knows about PinBall beyond the env itself, in one
place; :mod:`torchrl_subgoal.domains` imports this module the first time
``"pinball"`` is looked up.
"""

from __future__ import annotations

import functools
from collections.abc import Mapping
from importlib.resources import files
from typing import Any

import torch
from torchrl.envs import EnvBase

from torchrl_subgoal import domains
from torchrl_subgoal.envs import pinball
from torchrl_subgoal.experiments.paper import PaperResults, paper_table
from torchrl_subgoal.experiments.plots import ReportMap
from torchrl_subgoal.fused import AC_PRESETS, FourierActorCritic
from torchrl_subgoal.fused.loop import OnlineAgent
from torchrl_subgoal.studio.domains import Limit, StudioDomain
from torchrl_subgoal.subgoals import Box, Circle, Predicate, StateAggregation
from torchrl_subgoal.training import A2CConfig, DQNConfig, LearnerDomain, PPOConfig, SuccessSignal

__all__ = ["A2C", "DOMAIN", "PAPER", "STUDIO", "check_subgoal", "pinball_env"]


def check_subgoal(predicate: Predicate) -> str | None:
    """Why ``predicate`` is not a valid PinBall subgoal, or ``None``.

    A PinBall subgoal is a circle over the ball position (observation entries
    0 and 1) with a positive radius and its centre on the table (the unit
    square). Used by subgoal files that declare ``domain: pinball``.

    Examples:
        >>> from torchrl_subgoal import Cell
        >>> check_subgoal(Circle((0.5, 0.2), 0.04)) is None
        True
        >>> check_subgoal(Cell(3, 6))
        'pinball subgoals are circles over (x, y), not cell'
    """
    if not isinstance(predicate, Circle):
        return f"pinball subgoals are circles over (x, y), not {predicate.kind}"
    if tuple(predicate.dims()) != (0, 1):
        return f"a pinball subgoal circle covers (x, y), dims [0, 1], not {list(predicate.dims())}"
    if not predicate.radius > 0:
        return f"radius must be positive, got {predicate.radius}"
    x, y = predicate.centre
    if not (0.0 <= x <= 1.0 and 0.0 <= y <= 1.0):
        return f"centre ({x}, {y}) is off the table (the unit square)"
    return None


def pinball_env(num_envs: int) -> EnvBase:
    """``PinBallEnv(num_envs)`` on the simple map, the paper's 10,000-step cap, seeded from torch.

    Examples:
        >>> pinball_env(2).reset()["observation"].shape
        torch.Size([2, 4])
    """
    return pinball.PinBallEnv(num_envs, "simple", seed=int(torch.randint(2**31 - 1, ())))


def _draw_map(ax: Any, patterns: Mapping[str, Any], options: Mapping[str, Any]) -> None:
    circles: dict[str, list[tuple[float, float, float]]] = {}
    for name, series in patterns.items():
        circles[name] = []
        for predicate in series.predicates:
            if not isinstance(predicate, Circle):
                raise ValueError(f"pattern {name}: a {type(predicate).__name__} is not a circle")
            x, y = predicate.centre[:2]
            circles[name].append((float(x), float(y), float(predicate.radius)))
    pinball.draw_map(ax, circles=circles, **options)


@functools.lru_cache(maxsize=32)
def _load_map(config: str) -> pinball.PinBallConfig:
    return pinball.PinBallConfig.load(config)


def _geometry(config: str) -> dict[str, Any]:
    cfg = _load_map(config)
    return {
        "kind": "table",
        "ball_radius": cfg.ball_radius,
        "target": list(cfg.target),
        "start": list(cfg.start),
        "polygons": [[list(v) for v in poly] for poly in cfg.polygons],
        "default_radius": cfg.target[2],  # the target's radius, as the paper's participants' circles
    }


def _map_check(predicate: Predicate, map_name: str, config: str) -> str | None:
    if not isinstance(predicate, Circle):
        return None
    x, y = predicate.centre[:2]
    for i, polygon in enumerate(_load_map(config).polygons):
        if pinball.point_in_polygon((x, y), polygon):
            return (
                f"centre ({x:g}, {y:g}) lies inside obstacle {i + 1} of the {map_name!r} map; "
                "move it to where the ball can go"
            )
    return None


def _actor_critic(
    learners: int, seed: int, max_steps: int | None, map_: str | None
) -> tuple[EnvBase, OnlineAgent, Mapping[str, Any]]:
    """The paper's learner: the Fourier actor-critic with the released settings."""
    ac = AC_PRESETS["released"]
    env = pinball.PinBallEnv(learners, map_ or "simple", max_steps=max_steps or 10_000, seed=seed)
    spec = env.observation_spec["observation"]
    agent = FourierActorCritic(learners, spec.low[0], spec.high[0], 5, ac, seed=seed)
    return (
        env,
        agent,
        {"gamma": ac.gamma, "value_lr": ac.value_lr, "observation_key": "observation", "goal_reward": 10_000.0},
    )


def _candidates(seed: int) -> list[Predicate]:
    points = pinball.PinBallEnv(1, "simple").sample_free_positions(500, torch.Generator().manual_seed(seed))
    return [Circle((float(x), float(y)), 0.04) for x, y in points.tolist()]


def _aggregation() -> StateAggregation:
    return StateAggregation.from_regions([Box((c,), (1 / 6,), (0,)) for c in (1 / 6, 1 / 2, 5 / 6)], 4)


A2C = LearnerDomain(
    "pinball",
    pinball_env,
    "observation",
    "observation",
    "observation",
    str(files(__name__) / "pinball_participants.yaml"),
    eta=1.0,
    thresholds=(3000.0, 2000.0, 1000.0, 500.0),
    success=SuccessSignal(min_return=10_000.0),  # the target's reward (no step cost)
    # lr: the paper's 0.01 divided by the Fourier features' norm (‖φ‖ ≈ 11.3 for order 3 on PinBall's
    # states), as its actor-critic divides its steps; with 0.01 A2C learns, then collapses (docs/torchrl.md).
    defaults={
        "a2c": A2CConfig(
            features="fourier", hidden=(), fourier_order=3, lr=1e-3, reward_scale=1e-4, total_frames=2_000_000
        ),
        # the A2C set-up's features and reward scale for PPO and DQN (a starting point, not tuned)
        "ppo": PPOConfig(
            features="fourier",
            hidden=(),
            fourier_order=3,
            num_envs=16,
            frames_per_batch=2048,
            lr=1e-3,
            reward_scale=1e-4,
            total_frames=2_000_000,
        ),
        "dqn": DQNConfig(
            features="fourier",
            hidden=(),
            fourier_order=3,
            num_envs=16,
            frames_per_batch=256,
            gradient_steps=16,
            lr=1e-3,
            reward_scale=1e-4,
            learning_starts=10_240,
            exploration_frames=500_000,
            buffer_size=100_000,
            total_frames=2_000_000,
        ),
    },
    aggregation=_aggregation,
    candidates=_candidates,
)


PAPER = PaperResults(
    domain="pinball",
    metric="steps",
    window=10,
    time_to_threshold=paper_table(
        ("HRS", "RRS", "AC", "NRS"),
        {
            3000: ((21.2, 39.8), (34.6, 48.4), (51.7, 67.1), (40.0, 50.7)),
            2000: ((26.8, 40.4), (48.7, 54.2), (70.2, 77.8), (59.0, 59.0)),
            1000: ((56.7, 58.5), (89.1, 67.9), (101.0, 71.4), (93.0, 70.1)),
            500: ((115.3, 66.4), (147.3, 64.7), (163.0, 54.8), (157.0, 61.6)),
        },
    ),
    learnings=100,
)

STUDIO = StudioDomain(
    _geometry,
    maps={"simple": "simple", "hard": "hard"},
    map_check=_map_check,
    limits={"episodes": Limit(30, 1, 100), "learners": Limit(5, 1, 10), "max_steps": Limit(10_000, 100, 10_000)},
    recipe="torchrl-subgoal reproduce pinball",
    learner=_actor_critic,
    position=1,
)

DOMAIN = domains.register(
    domains.Domain(
        "pinball",
        "PinBall",
        make_env=pinball_env,
        check_subgoal=check_subgoal,
        parts=(A2C, PAPER, ReportMap(_draw_map), STUDIO),
    )
)

"""The Acrobot domain plugin: env, subgoal check, and the learners' set-up and report map.

Everything the package knows about Acrobot beyond the env itself, in one place;
:mod:`torchrl_subgoal.domains` imports this module the first time ``"acrobot"`` is
looked up. Needs ``gymnasium`` only when an env is made. The report map draws each
subgoal over ``cos θ₁`` as the arc of the circle the joint moves on that it admits.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from torchrl_subgoal import domains
from torchrl_subgoal.envs import acrobot
from torchrl_subgoal.experiments.plots import ReportMap, numbered_subgoals
from torchrl_subgoal.subgoals import Box, Predicate
from torchrl_subgoal.training import A2CConfig, DQNConfig, LearnerDomain, PPOConfig, SuccessSignal

__all__ = ["DOMAIN", "LEARNERS", "check_subgoal"]

#: The observation's bounds: cos θ₁, sin θ₁, cos θ₂, sin θ₂, θ̇₁, θ̇₂ (gymnasium's).
BOUNDS = ((-1.0, 1.0), (-1.0, 1.0), (-1.0, 1.0), (-1.0, 1.0), (-4 * math.pi, 4 * math.pi), (-9 * math.pi, 9 * math.pi))
NAMES = ("cos θ1", "sin θ1", "cos θ2", "sin θ2", "θ1 velocity", "θ2 velocity")


def check_subgoal(predicate: Predicate) -> str | None:
    """Why ``predicate`` is not a valid Acrobot subgoal, or ``None``: a box over the observation's six entries
    that overlaps their bounds.

    Examples:
        >>> check_subgoal(Box((-0.25,), (0.75,), (0,))) is None
        True
        >>> check_subgoal(Box((2.0,), (0.5,), (0,)))
        'cos θ1: the box [1.5, 2.5] lies outside [-1.0, 1.0]'
    """
    if not isinstance(predicate, Box):
        return f"Acrobot subgoals are boxes over the observation, not {predicate.kind}"
    if not set(predicate.box_dims) <= set(range(len(BOUNDS))):
        return f"an Acrobot box covers observation entries 0 to 5, not dims {list(predicate.box_dims)}"
    return predicate.outside(BOUNDS, NAMES)


def _draw_map(ax: Any, patterns: Mapping[str, Any], options: Mapping[str, Any]) -> None:
    """The circle the joint moves on, ``(sin θ₁, −cos θ₁)`` with the pivot at the origin; each subgoal that
    bounds ``cos θ₁`` alone as the arc of angles it admits."""
    import numpy as np

    angle = np.linspace(-math.pi, math.pi, 361)
    cos = np.cos(angle)
    ax.plot(np.sin(angle), -cos, color="lightgrey", lw=1)
    ax.plot([0, 0], [0, -1], color="grey", lw=3)  # the first link hanging at rest
    ax.axhline(1.0, color="tab:red", ls="--")
    ax.annotate("goal", (-1.4, 1.05), color="tab:red", va="bottom", fontsize="small")
    for index, (_name, colour, number, box) in enumerate(numbered_subgoals(patterns, Box)):
        if list(box.box_dims) != [0]:
            continue
        low, high = box.centre[0] - box.margin[0], box.centre[0] + box.margin[0]
        inside = (cos >= low) & (cos <= high)
        radius = 1.0 + 0.08 * (index + 1)
        ax.plot(
            np.where(inside, radius * np.sin(angle), np.nan),
            np.where(inside, -radius * cos, np.nan),
            color=colour,
            lw=3,
        )
        end = math.acos(max(min(high, 1.0), -1.0))  # where the arc begins, on the right
        ax.annotate(
            str(number),
            (1.15 * radius * math.sin(end), -1.15 * radius * math.cos(end)),
            color=colour,
            ha="center",
            va="center",
            fontsize="small",
        )
    ax.set_xlim(-1.5, 1.5)
    ax.set_ylim(-1.4, 1.4)
    ax.set_aspect("equal")
    ax.set_xlabel("sin θ1", fontsize="small")
    ax.set_ylabel("joint height, -cos θ1", fontsize="small")


LEARNERS = LearnerDomain(
    "acrobot",
    acrobot.make_acrobot,
    "observation",
    "observation",
    "observation",
    acrobot.SUBGOAL_FILE,
    eta=1.0,
    thresholds=(200.0, 150.0, 100.0),
    success=SuccessSignal(min_return=-499.0),  # the goal within 499 steps (-1 a step; 500 is the time limit)
    defaults={
        # TorchRL's DQN example (DQNConfig's defaults: 1,000 frames then 100 gradient steps, a 120-84 MLP) at a
        # budget of 100,000 frames; the window spans 2,000 frames, four 500-step time-outs. rl-baselines3-zoo's
        # tuned DQN (a gradient step per frame on a 256-256 MLP) costs about an hour per 10 learners on one core
        "dqn": DQNConfig(total_frames=100_000, record_window=2),
        # rl-baselines3-zoo's A2C and PPO for Acrobot-v1 (16 envs, no entropy bonus; PPO: 256 steps per env per
        # batch, 4 epochs, GAE λ 0.94) over the raw observation (the zoo also normalises it) with its 64-unit MLPs,
        # at half its budget. The recorded window spans at least 500 steps per env: until a learner reaches the goal,
        # its envs time out together every 500 steps and a shorter window would read shorter episodes
        "a2c": A2CConfig(
            num_envs=16, frames_per_batch=256, total_frames=500_000, entropy_coeff=0.0, record_window=32, features="mlp"
        ),
        "ppo": PPOConfig(
            num_envs=16, frames_per_batch=256 * 16, total_frames=500_000, epochs=4, gae_lambda=0.94, features="mlp"
        ),
    },
)

DOMAIN = domains.register(
    domains.Domain(
        "acrobot",
        "Acrobot",
        make_env=acrobot.make_acrobot,
        check_subgoal=check_subgoal,
        parts=(LEARNERS, ReportMap(_draw_map)),
    )
)

"""The MountainCar domain plugin: env, subgoal check, and each layer's part (the learners' set-up, report map,
studio form).

Everything the package knows about MountainCar beyond the env itself, in one
place; :mod:`torchrl_subgoal.domains` imports this module the first time
``"mountain_car"`` is looked up. Needs ``gymnasium`` only when an env is made.
The report map draws the subgoals as boxes over ``(position, velocity)``; the
studio edits them in a form of two components, ``position`` and ``velocity``
(the form pick-and-place uses), with "Try it" off (deep learners only).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from torchrl_subgoal import domains
from torchrl_subgoal.envs import mountain_car
from torchrl_subgoal.experiments.plots import ReportMap, numbered_subgoals
from torchrl_subgoal.studio.domains import BoxForm, StudioDomain
from torchrl_subgoal.subgoals import Box, Predicate
from torchrl_subgoal.training import A2CConfig, DQNConfig, LearnerDomain, PPOConfig, SuccessSignal

__all__ = ["DOMAIN", "FORM", "LEARNERS", "STUDIO", "check_subgoal"]

#: The observation's bounds: position, velocity.
BOUNDS = ((-1.2, 0.6), (-0.07, 0.07))


def check_subgoal(predicate: Predicate) -> str | None:
    """Why ``predicate`` is not a valid MountainCar subgoal, or ``None``: a box over position (dim 0)
    and/or velocity (dim 1) that overlaps the state space.

    Examples:
        >>> check_subgoal(Box((-1.025,), (0.175,), (0,))) is None
        True
        >>> check_subgoal(Box((2.0,), (0.1,), (0,)))
        'position: the box [1.9, 2.1] lies outside [-1.2, 0.6]'
    """
    if not isinstance(predicate, Box):
        return f"MountainCar subgoals are boxes over (position, velocity), not {predicate.kind}"
    if not set(predicate.box_dims) <= {0, 1}:
        return f"a MountainCar box covers position (0) and velocity (1), not dims {list(predicate.box_dims)}"
    return predicate.outside(BOUNDS, ("position", "velocity"))


def _draw_map(ax: Any, patterns: Mapping[str, Any], options: Mapping[str, Any]) -> None:
    from matplotlib.patches import Rectangle

    for _name, colour, number, box in numbered_subgoals(patterns, Box):
        span = [list(BOUNDS[0]), list(BOUNDS[1])]
        for dim, centre, margin in zip(box.box_dims, box.centre, box.margin, strict=True):
            span[dim] = [max(span[dim][0], centre - margin), min(span[dim][1], centre + margin)]
        (x0, x1), (y0, y1) = span
        ax.add_patch(Rectangle((x0, y0), x1 - x0, y1 - y0, fill=False, color=colour, lw=2))
        ax.annotate(str(number), ((x0 + x1) / 2, (y0 + y1) / 2), color=colour, ha="center", va="center")
    ax.axvline(0.5, color="tab:red", ls="--")
    ax.annotate("flag", (0.5, 0.0), color="tab:red", rotation=90, ha="right", va="center")
    ax.set_xlim(*BOUNDS[0])
    ax.set_ylim(*BOUNDS[1])
    ax.set_xlabel("position")
    ax.set_ylabel("velocity")


LEARNERS = LearnerDomain(
    "mountain_car",
    mountain_car.make_mountain_car,
    "observation",
    "observation",
    "observation",
    mountain_car.SUBGOAL_FILE,
    eta=1.0,
    thresholds=(180.0, 150.0, 120.0),
    success=SuccessSignal(min_return=-199.0),  # the flag within 199 steps (-1 a step; 200 is the time limit)
    defaults={
        "dqn": DQNConfig.preset("mountain_car"),  # rl-baselines3-zoo's tuned DQN
        # 50 batches of 16 steps per env = 4 whole 200-step episodes: while a learner never reaches the flag, its
        # 16 envs time out together every 200 steps, and a window of any other length counts 1 time-out too many
        # or too few (with 8 batches, 128 steps read as 128-step episodes, below every threshold)
        # A linear policy and critic over order-3 Fourier features of (position, velocity) scaled to the observation's
        # bounds: an MLP over the raw observation (velocity within ±0.07) reached the flag with no method in 500,000
        # frames (docs/does_it_help.md). The rewards are scaled by 1 - γ, so returns lie in [-1, 0]: Adam moves each
        # weight by about its learning rate per step, and a critic learning returns down to -87 got no further than -15
        # in the budget (rl-baselines3-zoo normalises these rewards). As in the zoo, A2C has no entropy bonus.
        "a2c": A2CConfig(
            num_envs=16,
            frames_per_batch=256,
            total_frames=500_000,
            record_window=50,
            features="fourier",
            hidden=(),
            reward_scale=0.01,
            entropy_coeff=0.0,
        ),
        "ppo": PPOConfig(
            num_envs=16,
            frames_per_batch=256 * 16,
            minibatch_size=256,
            total_frames=500_000,
            features="fourier",
            hidden=(),
            reward_scale=0.01,
        ),
    },
)

#: The studio's form: a box over position (entry 0), velocity (entry 1) or both.
FORM = BoxForm(
    {"position": slice(0, 1), "velocity": slice(1, 2)},
    2,
    0.05,
    ticked=("position",),
    ranges={"position": BOUNDS[0], "velocity": BOUNDS[1]},
)

STUDIO = StudioDomain(
    FORM.geometry,
    recipe="torchrl-subgoal train --algo dqn --domain mountain_car",
    to_page=FORM.to_page,
    from_page=FORM.from_page,
    try_note=(
        "Not offered for MountainCar: it is learned by deep learners only (DQN, PPO, A2C; 120,000 frames "
        "or more), not by the quick learners Try it runs. Save the file and run the command shown "
        "under File: torchrl-subgoal train --algo dqn --domain mountain_car --subgoals FILE"
    ),
    position=5,
)

DOMAIN = domains.register(
    domains.Domain(
        "mountain_car",
        "MountainCar",
        make_env=mountain_car.make_mountain_car,
        check_subgoal=check_subgoal,
        parts=(LEARNERS, ReportMap(_draw_map), STUDIO),
    )
)

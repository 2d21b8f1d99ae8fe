"""Tutorial: shape your own env.

Appends :class:`~torchrl_subgoal.SubgoalPotentialTransform` to gymnasium's
CliffWalking (through TorchRL's ``GymEnv``: an env this package knows nothing
about), writes its subgoals as a built-in predicate and two plain functions,
trains A2C with a TorchRL ``Collector``, ``GAE`` and ``A2CLoss`` without shaping,
with the default potential and with its table shaped as learned, and plots the
learning curves.

    python docs/tutorials/shape_your_env.py                 # the budget of the docs' figure
    python docs/tutorials/shape_your_env.py --tiny          # seconds: what CI runs
    python docs/tutorials/shape_your_env.py --frames 20000 --seeds 2 --out /tmp/cliff

It writes ``shape_your_env.png`` and ``shape_your_env.txt`` (the printed table)
into ``--out`` (default ``docs/tutorials/output``). ``TUTORIAL_TINY=1`` in the
environment is the same as ``--tiny``.
"""

from __future__ import annotations

import argparse
import math
import os
from collections.abc import Callable
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import gymnasium as gym
import matplotlib.pyplot as plt
import numpy as np
import torch
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from tensordict import TensorDictBase
from tensordict.nn import TensorDictModule
from torch import nn
from torchrl.collectors import Collector
from torchrl.envs import Compose, GymWrapper, RewardSum, StepCounter, TransformedEnv
from torchrl.modules import ProbabilisticActor, ValueOperator
from torchrl.objectives import A2CLoss
from torchrl.objectives.value import GAE

from torchrl_subgoal import (
    State,
    SubgoalPotentialTransform,
    SubgoalSeries,
    TabularPotential,
)

# --8<-- [start:env]
# CliffWalking: a 4 × 12 grid, the observation is the cell index row * 12 + col. Start (3, 0),
# goal (3, 11), the cliff between them on row 3; -1 per step, -100 (and back to the start)
# for stepping into the cliff. The shortest safe path takes 13 steps: return -13.
COLS, MAX_STEPS, GAMMA, VALUE_LR = 12, 5000, 0.99, 0.1


def make_env(num_envs: int) -> GymWrapper:
    """``num_envs`` copies of the gymnasium env in one vector env; TorchRL resets each when it ends."""
    envs = gym.vector.SyncVectorEnv(
        [lambda: gym.make("CliffWalking-v1")] * num_envs, autoreset_mode=gym.vector.AutoresetMode.DISABLED
    )
    return GymWrapper(envs, categorical_action_encoding=True)


# --8<-- [end:env]


# --8<-- [start:subgoals]
# Subgoals are predicates over the step's TensorDict. A built-in one (State: the discrete
# observation equals a cell index) is compiled into the fused kernel; any function returning
# a boolean mask of the batch is a subgoal too (it may read any entry of the step).
def past_halfway(td: TensorDictBase) -> torch.Tensor:
    """On the safe rows, in the right half of the grid."""
    cell = td["observation"]
    return (cell // COLS <= 2) & (cell % COLS >= COLS // 2)


def above_the_goal(td: TensorDictBase) -> torch.Tensor:
    """The cell right above the goal."""
    return td["observation"] == 2 * COLS + COLS - 1


series = SubgoalSeries(
    [State(2 * COLS), past_halfway, above_the_goal],  # leave the start upwards, then go right
    names=["up", "halfway", "above_goal"],
)
# --8<-- [end:subgoals]


# --8<-- [start:agent]
def a2c_agent() -> tuple[ProbabilisticActor, Callable[[TensorDictBase], None]]:
    """A tabular softmax policy and value (``nn.Embedding`` rows over the cell index), and the
    update of one collected batch: GAE advantages and one Adam step on TorchRL's ``A2CLoss``."""
    logits, value = nn.Embedding(48, 4), nn.Embedding(48, 1)
    for table in (logits, value):
        nn.init.zeros_(table.weight)  # uniform policy, zero values
    actor = ProbabilisticActor(
        TensorDictModule(logits, in_keys=["observation"], out_keys=["logits"]),
        in_keys=["logits"],
        distribution_class=torch.distributions.Categorical,
        return_log_prob=True,
    )
    critic = ValueOperator(value, in_keys=["observation"])
    advantage = GAE(gamma=GAMMA, lmbda=0.95, value_network=critic)
    loss = A2CLoss(actor, critic, entropy_coeff=0.01)
    optimizer = torch.optim.Adam(loss.parameters(), lr=0.05)

    def update(data: TensorDictBase) -> None:
        with torch.no_grad():
            advantage(data)  # over data["next", "reward"]: the shaped reward, when shaped
        losses = loss(data)
        optimizer.zero_grad()
        (losses["loss_objective"] + losses["loss_critic"] + losses["loss_entropy"]).backward()
        optimizer.step()

    return actor, update


# --8<-- [end:agent]


# --8<-- [start:train]
def make_env_with(transform: SubgoalPotentialTransform | None, num_envs: int, seed: int) -> TransformedEnv:
    """The env a collector steps: a step counter, the shaping transform (if any), the episode's env return."""
    reward_key = "reward" if transform is None else transform.env_reward_key  # the unshaped reward
    transforms = [
        StepCounter(max_steps=MAX_STEPS),
        *([transform] if transform else []),
        RewardSum(in_keys=[reward_key], out_keys=["episode_return"]),
    ]
    env = TransformedEnv(make_env(num_envs), Compose(*transforms))
    env.set_seed(seed)
    return env


def recent_returns(data: TensorDictBase, recent: list[float]) -> list[float]:
    """``recent`` with the env returns of the episodes that ended in ``data``, the last 32 kept."""
    done = data["next", "done"].squeeze(-1)
    return (recent + data["next", "episode_return"][done].flatten().tolist())[-32:]


#: The arms compared: no shaping; the default potential; the same table shaped as it is learned.
ARMS = ("unshaped", "default", "as learned")


def train(
    arm: str, frames: int, seed: int, num_envs: int = 16, frames_per_batch: int = 256
) -> tuple[np.ndarray, list[float], list[float]]:
    """One A2C learner of ``arm``: ``[batches, 2]`` (frames so far, mean env return of recent episodes),
    and the learned potential ``Φ(z)`` of each abstract state after a sixth of the frames and at the end
    (empty when unshaped)."""
    torch.manual_seed(seed)
    transform, potential = None, None
    if arm != "unshaped":
        # Φ(z), one table for the batch: the default starts at a progress prior, is learned online, and shapes
        # each z with the largest value among it and the z before it; "as learned" shapes with the table as it is
        potential = TabularPotential.for_subgoals(series, monotone=arm == "default")
        transform = SubgoalPotentialTransform(  # reward ← r + γΦ(z') − Φ(z); r stays under "env_reward"
            series,
            potential,
            gamma=GAMMA,
            observation_key="observation",
            value_update=VALUE_LR,  # train Φ online (the SMDP update, optimistic target), then shape
        )
    env = make_env_with(transform, num_envs, seed)
    actor, update = a2c_agent()
    collector = Collector(
        env, actor, frames_per_batch=frames_per_batch, total_frames=frames, auto_register_policy_transforms=False
    )
    curve: list[tuple[int, float]] = []
    recent: list[float] = []
    seen, early = 0, list[float]()
    for data in collector:
        update(data)
        recent = recent_returns(data, recent)
        seen += data.numel()
        curve.append((seen, float(np.mean(recent)) if recent else math.nan))
        if potential is not None and not early and seen >= frames // 6:
            early = potential.table.flatten().tolist()
    collector.shutdown()
    phi = potential.table.flatten().tolist() if potential is not None else []
    return np.asarray(curve), early, phi


# --8<-- [end:train]


def returns_axes(ax: Axes, title: str) -> None:
    """Labels of a plot of returns against frames: the optimum, a symmetric log scale."""
    ax.axhline(-13, color="grey", linestyle=":", label="optimal (-13)")
    ax.set_yscale("symlog", linthresh=10)
    ax.set(xlabel="frames", ylabel="return of recent episodes (env reward)", title=title)
    ax.legend(loc="upper left")


def save(fig: Figure, lines: list[str], stem: Path) -> None:
    """Write the figure (``stem.png``) and print the lines, also into ``stem.txt``."""
    fig.tight_layout()
    fig.savefig(stem.with_suffix(".png"), dpi=110)
    text = "\n".join(lines)
    print(text)
    stem.with_suffix(".txt").write_text(text + "\n")


def frames_to(curve: np.ndarray, level: float) -> float:
    """Frames until the recent mean return first rises above ``level`` (``nan``: never)."""
    above = np.flatnonzero(curve[:, 1] > level)
    return float(curve[above[0], 0]) if above.size else math.nan


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--frames", type=int, default=60_000, help="frames per learner")
    parser.add_argument("--seeds", type=int, default=5, help="learners per arm")
    parser.add_argument("--tiny", action="store_true", help="a budget of seconds (CI)")
    parser.add_argument("--out", type=Path, default=Path(__file__).parent / "output")
    args = parser.parse_args()
    if args.tiny or os.environ.get("TUTORIAL_TINY"):
        args.frames, args.seeds = 2048, 1
    torch.set_num_threads(1)
    args.out.mkdir(parents=True, exist_ok=True)

    # --8<-- [start:compare]
    results = {arm: [train(arm, args.frames, seed) for seed in range(args.seeds)] for arm in ARMS}
    curves = {arm: [curve for curve, _, _ in runs] for arm, runs in results.items()}
    lines = [
        f"CliffWalking-v1, A2C: {args.frames} frames x {args.seeds} learners per arm",
        "arm        frames to a return > -50 (per learner)      final return (mean of learners)",
    ]
    fig, ax = plt.subplots(figsize=(6.4, 3.6))
    for arm, runs in curves.items():
        returns = np.stack([run[:, 1] for run in runs])  # [learners, batches]; nan before any episode ended
        finished = ~np.isnan(returns).any(0)
        frames = runs[0][finished, 0]
        mean = returns[:, finished].mean(0)
        se = returns[:, finished].std(0) / np.sqrt(len(runs))
        ax.plot(frames, mean, label=arm)
        ax.fill_between(frames, mean - se, mean + se, alpha=0.25)
        to_50 = ", ".join("never" if math.isnan(f) else f"{f:.0f}" for f in (frames_to(r, -50) for r in runs))
        final = f"{mean[-1]:.1f}" if mean.size else "no episode ended"
        lines.append(f"{arm:10s} {to_50:44s} {final}")
    for arm in ARMS[1:]:
        for when, tables in (
            (f"at {args.frames // 6} frames", [early for _, early, _ in results[arm]]),
            ("at the end", [end for _, _, end in results[arm]]),
        ):
            phi = np.mean(tables, 0)
            values = ", ".join(f"Φ({z})={v:.1f}" for z, v in enumerate(phi))
            lines.append(f"learned potential, {arm}, {when} (mean): {values}")
    returns_axes(ax, "CliffWalking-v1, A2C")
    # --8<-- [end:compare]
    save(fig, lines, args.out / "shape_your_env")


if __name__ == "__main__":
    main()

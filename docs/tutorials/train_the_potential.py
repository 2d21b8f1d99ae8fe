"""Tutorial: train the potential yourself.

The same CliffWalking env, subgoals and A2C agent as ``shape_your_env.py``, but
the shaping potential is a small neural network over the cell at which the
current subgoal stage was entered, trained by you: the transform only shapes,
the SMDP transitions ``(z, r_h, k, z')`` of every collected batch go into a
TorchRL replay buffer, and ``SubgoalValueLoss`` with Adam trains the network
from samples of it.

    python docs/tutorials/train_the_potential.py            # the budget of the docs' figure
    python docs/tutorials/train_the_potential.py --tiny     # seconds: what CI runs

It writes ``train_the_potential.png`` and ``train_the_potential.txt`` into
``--out`` (default ``docs/tutorials/output``). ``TUTORIAL_TINY=1`` is the same as ``--tiny``.
"""

from __future__ import annotations

import argparse
import math
import os
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import torch
from shape_your_env import (
    COLS,
    GAMMA,
    a2c_agent,
    make_env_with,
    recent_returns,
    returns_axes,
    save,
    series,
)
from torch import nn
from torchrl.collectors import Collector
from torchrl.data import LazyTensorStorage, ReplayBuffer

from torchrl_subgoal import NeuralPotential, SubgoalPotentialTransform, SubgoalValueLoss
from torchrl_subgoal.training import extend_transitions


# --8<-- [start:potential]
class CellFeatures(nn.Module):
    """(row, col) of a CliffWalking cell index, scaled to [0, 1]."""

    def forward(self, cell: torch.Tensor) -> torch.Tensor:
        cell = cell.squeeze(-1)
        return torch.stack([(cell // COLS) / 3.0, (cell % COLS) / (COLS - 1.0)], -1)


def make_potential() -> NeuralPotential:
    """``V(o_z; θ)``: an MLP over the observation at which the abstract state ``z`` was entered."""
    return NeuralPotential(nn.Sequential(CellFeatures(), nn.Linear(2, 32), nn.Tanh(), nn.Linear(32, 1)))


# --8<-- [end:potential]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--frames", type=int, default=60_000, help="frames collected")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--tiny", action="store_true", help="a budget of seconds (CI)")
    parser.add_argument("--out", type=Path, default=Path(__file__).parent / "output")
    args = parser.parse_args()
    if args.tiny or os.environ.get("TUTORIAL_TINY"):
        args.frames = 4096
    torch.set_num_threads(1)
    torch.manual_seed(args.seed)
    args.out.mkdir(parents=True, exist_ok=True)

    # --8<-- [start:setup]
    potential = make_potential()
    # no value_update: the transform shapes with the potential as it is and never trains it
    transform = SubgoalPotentialTransform(series, potential, gamma=GAMMA, observation_key="observation")
    env = make_env_with(transform, num_envs=16, seed=args.seed)
    actor, update = a2c_agent()
    collector = Collector(
        env, actor, frames_per_batch=256, total_frames=args.frames, auto_register_policy_transforms=False
    )

    buffer = ReplayBuffer(storage=LazyTensorStorage(20_000), batch_size=64)  # SMDP transitions only
    value_loss = SubgoalValueLoss(potential, reduction="mean").make_value_estimator(
        gamma=GAMMA
    )  # TD(0) on the SMDP target
    value_optimizer = torch.optim.Adam(potential.parameters(), lr=0.05)
    # --8<-- [end:setup]

    # --8<-- [start:loop]
    lines: list[str] = []
    history: list[tuple[int, float, float]] = []  # frames, recent env return, potential loss
    recent: list[float] = []
    seen = 0
    for data in collector:
        update(data)  # the agent learns from the shaped reward
        stored = extend_transitions(buffer, data, transform)  # the batch's real SMDP transitions
        if seen == 0:
            first = buffer[:stored]
            lines.append(
                f"first batch: {data.numel()} steps, {stored} SMDP transitions; the first: stage "
                f"entered at cell {first['subgoal_anchor'][0].item():.0f}, left after "
                f"k={first['steps_to_next_obs'][0].item()} steps at cell "
                f"{first['next', 'subgoal_anchor'][0].item():.0f}, r_h={first['next', 'reward'][0].item():.2f}"
            )
        loss_value = math.nan
        if len(buffer) >= 64:
            for _ in range(8):  # a few gradient steps per batch on samples of the buffer
                value_optimizer.zero_grad()
                loss = value_loss(buffer.sample())["loss_value"]
                loss.backward()
                value_optimizer.step()
                loss_value = loss.item()
        recent = recent_returns(data, recent)
        seen += data.numel()
        history.append((seen, float(np.mean(recent)) if recent else math.nan, loss_value))
    collector.shutdown()
    # --8<-- [end:loop]

    # --8<-- [start:inspect]
    # the learned potential at the cell each stage is typically entered at
    entries = {
        "start (z=0)": 3 * COLS,
        "up (z=1)": 2 * COLS,
        "halfway (z=2)": 2 * COLS + COLS // 2,
        "above_goal (z=3)": 3 * COLS - 1,
    }
    with torch.no_grad():
        for name, cell in entries.items():
            value = potential(torch.tensor([[float(cell)]])).item()
            lines.append(f"V at {name:18s} cell {cell:2d}: {value:8.2f}")
    # --8<-- [end:inspect]
    curve = np.asarray(history)
    final = curve[-1, 1]
    lines.append(
        f"{args.frames} frames, seed {args.seed}: final return of recent episodes "
        f"{'no episode ended' if math.isnan(final) else f'{final:.1f}'}; buffer holds {len(buffer)}"
    )

    fig, (left, right) = plt.subplots(1, 2, figsize=(9, 3.4))
    left.plot(curve[:, 0], curve[:, 1])
    returns_axes(left, "A2C shaped by a neural potential")
    right.plot(curve[:, 0], curve[:, 2])
    right.set_yscale("log")
    right.set(xlabel="frames", ylabel="SubgoalValueLoss (mean)", title="the potential's TD loss")
    save(fig, lines, args.out / "train_the_potential")


if __name__ == "__main__":
    main()

"""Tutorial: CartPole from zero to a shaped PPO run and a plot.

Takes gymnasium's CartPole-v1 as a user's own env (through TorchRL's ``GymWrapper``),
writes three ordered subgoals for it as plain functions of the step (keep the pole
up for 50 steps, then 100, then 200), trains the package's PPO building block
(``torchrl_subgoal.training.train_ppo``: TorchRL's ``ClipPPOLoss``, ``GAE`` and a
``Collector``) without shaping, with the default learned subgoal potential and with
its table shaped as learned, and plots the learning curves against frames.

    python docs/tutorials/cartpole.py                 # the budget of the docs' figure
    python docs/tutorials/cartpole.py --tiny          # seconds: what CI runs
    python docs/tutorials/cartpole.py --frames 20000 --seeds 2 --out /tmp/cartpole

It writes ``cartpole.png`` and ``cartpole.txt`` (the printed table) into ``--out``
(default ``docs/tutorials/output``). ``TUTORIAL_TINY=1`` in the environment is the
same as ``--tiny``.
"""

from __future__ import annotations

import argparse
import os
from collections.abc import Callable
from pathlib import Path

import gymnasium as gym
import numpy as np
import torch
from matplotlib.figure import Figure
from tensordict import TensorDictBase
from torchrl.envs import EnvBase, GymWrapper, StepCounter, TransformedEnv

from torchrl_subgoal import SubgoalSeries, TabularPotential
from torchrl_subgoal.training import LearningCurve, PPOConfig, Shaping, train_ppo


# --8<-- [start:env]
# CartPole-v1: keep a pole upright on a cart. +1 per step; the episode ends when the pole falls
# (or the cart leaves the track), and is cut at 500 steps. The observation is
# (cart position, cart velocity, pole angle, pole angular velocity).
def make_env(num_envs: int) -> EnvBase:
    """``num_envs`` CartPoles in one gymnasium vector env (stepped in this process; TorchRL resets each
    copy when its episode ends), with a step counter: what the subgoals read."""
    envs = gym.vector.SyncVectorEnv(
        [lambda: gym.make("CartPole-v1")] * num_envs, autoreset_mode=gym.vector.AutoresetMode.DISABLED
    )
    return TransformedEnv(GymWrapper(envs), StepCounter())


# --8<-- [end:env]


# --8<-- [start:subgoals]
# What someone who knows the task would say: first keep the pole up for 50 steps, then 100, then
# 200. A subgoal is any function of the step's TensorDict that returns a boolean mask of the batch.
def balanced_for(steps: int) -> Callable[[TensorDictBase], torch.Tensor]:
    def reached(td: TensorDictBase) -> torch.Tensor:
        return td["step_count"].reshape(-1) >= steps

    reached.__name__ = f"balanced_for_{steps}"
    return reached


series = SubgoalSeries([balanced_for(50), balanced_for(100), balanced_for(200)], names=["50", "100", "200"])
# --8<-- [end:subgoals]


# --8<-- [start:train]
def settings(frames: int) -> PPOConfig:
    """PPO as TorchRL's examples set it (clip 0.2, GAE λ 0.95, two hidden layers of 64), on 8 envs."""
    return PPOConfig(num_envs=8, frames_per_batch=1024, minibatch_size=256, epochs=4, total_frames=frames)


#: The arms compared: no shaping; the default potential; the same table shaped as it is learned.
ARMS = ("unshaped", "default", "as learned")


def train(arm: str, frames: int, seed: int) -> tuple[LearningCurve, list[float]]:
    """One PPO learner of ``arm``: its curve, and the learned values V(z) at the end (empty when unshaped)."""
    shaping = None
    if arm != "unshaped":
        # the default table starts at a progress prior, is learned online as the learner collects, and shapes each
        # milestone with the largest value among it and those before it; "as learned" shapes with the table as it is
        shaping = Shaping(series, TabularPotential.for_subgoals(series, monotone=arm == "default"))
    trained = train_ppo(make_env, settings(frames), shaping=shaping, seeds=[seed], episode_cap=500.0)
    learned = trained.potential()  # the learner's table at the end (None unshaped)
    return trained.curve, learned.table.flatten().tolist() if isinstance(learned, TabularPotential) else []


# --8<-- [end:train]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--frames", type=int, default=100_000, help="frames per learner")
    parser.add_argument("--seeds", type=int, default=3, help="learners per arm")
    parser.add_argument("--tiny", action="store_true", help="a budget of seconds (CI)")
    parser.add_argument("--out", type=Path, default=Path(__file__).parent / "output")
    args = parser.parse_args()
    if args.tiny or os.environ.get("TUTORIAL_TINY"):
        args.frames, args.seeds = 2048, 1
    torch.set_num_threads(1)
    args.out.mkdir(parents=True, exist_ok=True)

    # --8<-- [start:compare]
    results = {arm: [train(arm, args.frames, seed) for seed in range(args.seeds)] for arm in ARMS}
    curves = {arm: [curve for curve, _ in runs] for arm, runs in results.items()}
    lines = [
        f"CartPole-v1, PPO: {args.frames} frames x {args.seeds} learners per arm",
        "arm        mean episode length at the end (per learner)     mean over learners",
    ]
    fig = Figure(figsize=(6.4, 3.6))
    ax = fig.subplots()
    for arm, runs in curves.items():
        lengths = np.array([run.episode_length for run in runs])  # [learners, batches]
        frames = np.array(runs[0].frames)
        line = ax.plot(frames, lengths.mean(0), label=f"{arm} (mean of {len(runs)})")[0]
        for one in lengths:
            ax.plot(frames, one, color=line.get_color(), alpha=0.25, linewidth=0.8)
        final = lengths[:, -1]
        lines.append(f"{arm:10s} {', '.join(f'{v:.0f}' for v in final):48s} {final.mean():.0f}")
    names = ["start", *(series.names or ())]
    for arm in ARMS[1:]:
        table = np.mean([v for _, v in results[arm]], 0)
        values = ", ".join(f"V({n})={v:.1f}" for n, v in zip(names, table, strict=True))
        lines.append(f"learned values, {arm} (mean): {values}")
    ax.set(xlabel="frames", ylabel="mean episode length (= return)", title="CartPole-v1, PPO")
    ax.legend(loc="upper left")
    fig.tight_layout()
    # --8<-- [end:compare]
    fig.savefig(args.out / "cartpole.png", dpi=110)
    text = "\n".join(lines)
    print(text)
    (args.out / "cartpole.txt").write_text(text + "\n")


if __name__ == "__main__":
    main()

"""How far an actor-critic's critic gets towards the returns it learns, on MountainCar.

Trains unshaped A2C or PPO learners with MountainCar's domain settings (a linear policy and critic
over Fourier features), then runs each learner's policy for one 200-step episode per env and prints
its critic's values beside the discounted returns that followed, in the learner's reward units.
Adam moves each weight by about its learning rate per step, so a linear critic has a reach: with
the env's −1 per step (``--reward-scale 1``) it stays far above the returns; with the domain's
``1 − γ`` it fits them (docs/shaping_defaults.md).

    python tools/critic_reach.py --algo ppo --reward-scale 1
    python tools/critic_reach.py --algo ppo
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from collections.abc import Sequence

import torch
from torchrl.objectives.value.functional import reward2go

from torchrl_subgoal import domains
from torchrl_subgoal.training import LearnerDomain, train_a2c, train_ppo
from torchrl_subgoal.training.stack import per_learner


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--algo", choices=("a2c", "ppo"), default="ppo")
    parser.add_argument("--reward-scale", type=float, default=None, help="default: the domain's")
    parser.add_argument("--frames", type=int, default=None, help="frames per learner (default: the domain's)")
    parser.add_argument("--learners", type=int, default=2)
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    domain = domains.part("mountain_car", LearnerDomain)
    config = domain.defaults[args.algo]
    changes = {"reward_scale": args.reward_scale, "total_frames": args.frames}
    config = dataclasses.replace(config, **{k: v for k, v in changes.items() if v is not None})
    train = train_a2c if args.algo == "a2c" else train_ppo
    trained = train(domain.make_env, config, seeds=list(range(args.learners)))
    env = domain.make_env(config.num_envs)
    print(f"{args.algo}, reward scale {config.reward_scale}, {config.total_frames} frames per learner")
    for k in range(args.learners):
        with torch.no_grad():
            data = env.rollout(200, per_learner(trained.modules["actor"], k), break_when_any_done=False)
            values = per_learner(trained.modules["critic"], k)(data.clone())["state_value"].squeeze(-1)
        reward = data["next", "reward"] * config.reward_scale  # [envs, T, 1]
        returns = reward2go(reward, data["next", "done"], config.gamma)  # TorchRL's: restarts at each episode end
        last = trained.curves[k].episode_length[-1]
        print(
            f"learner {k}: last recorded episode {last:.0f} steps; critic mean {values.mean():.2f} "
            f"[{values.min():.2f}, {values.max():.2f}], returns mean {returns.mean():.2f} "
            f"[{returns.min():.2f}, {returns.max():.2f}]"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())

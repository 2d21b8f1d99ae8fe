"""How far an actor-critic's critic gets towards the returns it learns, on MountainCar or PinBall.

Trains unshaped A2C or PPO learners with the domain's settings (MountainCar's and PinBall's: a linear
policy and critic over Fourier features), then runs each learner's policy for ``--steps`` steps per env
and prints its critic's values beside the discounted returns that followed, in the learner's reward
units, over the steps of the episodes that ended within them. Adam moves each weight by about its
learning rate per step, so a linear critic has a reach: on MountainCar with the env's −1 per step
(``--reward-scale 1``) it stays far above the returns; with the domain's ``1 − γ`` it fits them
(docs/shaping_defaults.md).

    python tools/critic_reach.py --algo ppo --reward-scale 1
    python tools/critic_reach.py --algo ppo
    python tools/critic_reach.py --algo a2c --domain pinball --frames 200000 --steps 1000
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
    parser.add_argument("--domain", choices=("mountain_car", "pinball"), default="mountain_car")
    parser.add_argument("--steps", type=int, default=200, help="steps of the evaluation rollout per env")
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    domain = domains.part(args.domain, LearnerDomain)
    config = domain.defaults[args.algo]
    changes = {"reward_scale": args.reward_scale, "total_frames": args.frames}
    config = dataclasses.replace(config, **{k: v for k, v in changes.items() if v is not None})
    train = train_a2c if args.algo == "a2c" else train_ppo
    trained = train(domain.make_env, config, seeds=list(range(args.learners)))
    env = domain.make_env(config.num_envs)
    print(f"{args.algo}, reward scale {config.reward_scale}, {config.total_frames} frames per learner")
    for k in range(args.learners):
        with torch.no_grad():
            data = env.rollout(args.steps, per_learner(trained.modules["actor"], k), break_when_any_done=False)
            values = per_learner(trained.modules["critic"], k)(data.clone())["state_value"]
        reward = data["next", "reward"] * config.reward_scale  # [envs, T, 1]
        done = data["next", "done"]
        returns = reward2go(reward, done, config.gamma)  # TorchRL's: restarts at each episode end
        ended = done.flip(1).cumsum(1).flip(1) > 0  # steps of an episode that ended within the rollout
        if not ended.any():
            print(f"learner {k}: no episode ended within {args.steps} steps; give more --steps or --frames")
            continue
        values, returns = values[ended], returns[ended]
        last = trained.curves[k].episode_length[-1]
        print(
            f"learner {k}: last recorded episode {last:.0f} steps; critic mean {values.mean():.2f} "
            f"[{values.min():.2f}, {values.max():.2f}], returns mean {returns.mean():.2f} "
            f"[{returns.min():.2f}, {returns.max():.2f}]"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())

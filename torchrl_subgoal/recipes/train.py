"""Any TorchRL learner (A2C, PPO, DQN, DDPG) with subgoal shaping on a registered domain, against the unshaped one.

Each learner is one ``torchrl_subgoal.training`` building block (``train_a2c``,
``train_ppo``, ``train_dqn`` or ``train_ddpg``: TorchRL's losses, collectors and
replay buffers) with the domain's default settings for it (its
``LearnerDomain.defaults``), trained on its own batch of envs. The shaping
transform sits on the outer env; ``SubgoalValueLoss`` trains its potential from
each batch's SMDP transitions. Methods: the unshaped learner (named after it:
A2C, PPO, DQN, DDPG), HRS (the learned potential over the domain's subgoal
file), NRS (a fixed η on reaching a subgoal), and where the domain allows them
RRS and SARSA-RS. The learner must suit the domain's actions: DQN and A2C need
discrete ones, DDPG continuous ones, PPO takes either.

Learners run through the experiment engine (resumable: run the same command
again; the same report and statistics). A report column is one collected
batch; its metric is the mean episode length, and times to threshold are given
in batches and in frames. TorchRL CSV logs go to ``RESULTS/logs``.

    python recipes/train.py --algo ppo --domain four_rooms
    python recipes/train.py --algo dqn --domain mountain_car --methods DQN,HRS --learnings 3
    python recipes/train.py --algo ddpg --domain point_maze_umaze --total-frames 50000 --sees-subgoal yes
"""

from __future__ import annotations

import sys
from dataclasses import dataclass

from torchrl_subgoal.experiments.cli import setting
from torchrl_subgoal.experiments.learners import LearnerRecipeConfig, learner_plan
from torchrl_subgoal.experiments.recipe import Plan, recipe_main
from torchrl_subgoal.training import LEARNERS


@dataclass
class Config(LearnerRecipeConfig):
    """A TorchRL learner with subgoal shaping on a registered domain."""

    algo: str = setting("ppo", "the learner", choices=list(LEARNERS))


def plan(cfg: Config) -> Plan:
    """The sweep of ``cfg``: every setting checked first, then one chunk per learner."""
    return learner_plan(cfg, cfg.algo)


def main(argv: list[str] | None = None) -> int:
    return recipe_main(Config, plan, argv, description=__doc__.splitlines()[0] if __doc__ else None, threads=None)


if __name__ == "__main__":
    sys.exit(main())

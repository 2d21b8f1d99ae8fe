"""Any TorchRL learner (A2C, PPO, DQN, DDPG) with subgoal shaping on a registered domain, against the unshaped one.

Each learner is one ``torchrl_subgoal.training`` building block (``train_a2c``,
``train_ppo``, ``train_dqn`` or ``train_ddpg``: TorchRL's losses, collectors and
replay buffers) with the domain's default settings for it (its
``LearnerDomain.defaults``), trained on its own batch of envs. Every field of the
learner's settings is a flag (``--total-frames``, ``--lr``, ``--clip-epsilon``,
``--hidden 32 32`` ...; ``--algo ppo --domain pinball --help`` lists PPO's with
PinBall's defaults). The shaping transform sits on the outer env;
``SubgoalValueLoss`` trains its potential from each batch's SMDP transitions.
Methods: the unshaped learner (named after it: A2C, PPO, DQN, DDPG), HRS-D (the
library's default potential over the domain's subgoal file: learned, and rising
towards the next subgoal within each segment), HRS (the same over the subgoals
reached alone), SRS (the progress prior, fixed), NRS (a fixed η on reaching a
subgoal), and where the domain allows them RRS and SARSA-RS; by default the
unshaped learner, HRS-D and NRS. The learner must
suit the domain's actions: DQN and A2C need discrete ones, DDPG continuous ones,
PPO takes either.

Learners run through the experiment engine (resumable: run the same command
again; the same report and statistics). A report column is one collected
batch; its metric is the mean episode length, the curves' x axis is frames, and
times to threshold are given in batches and in frames. Each learner's log goes
to ``RESULTS/logs`` (``--logger csv``, ``tensorboard``, ``wandb`` or ``none``).

    torchrl-subgoal train --algo ppo --domain four_rooms
    torchrl-subgoal train --algo dqn --domain mountain_car --methods DQN,HRS --learnings 3
    torchrl-subgoal train --algo ddpg --domain point_maze_umaze --total-frames 50000 --sees-subgoal True
    torchrl-subgoal train --config results/ppo_four_rooms/config.json --results results/again
"""

from __future__ import annotations

import sys
from dataclasses import dataclass
from typing import ClassVar

from torchrl_subgoal.experiments.cli import setting
from torchrl_subgoal.experiments.learners import LearnerRecipeConfig, learner_plan
from torchrl_subgoal.experiments.recipe import Plan, recipe_main
from torchrl_subgoal.training import LEARNERS


@dataclass
class Config(LearnerRecipeConfig):
    """A TorchRL learner with subgoal shaping on a registered domain."""

    algo: str = setting("ppo", "the learner", choices=list(LEARNERS))

    ALGO: ClassVar[str | None] = None
    EARLY: ClassVar[tuple[str, ...]] = ("algo", "domain")


def plan(cfg: Config) -> Plan:
    """The sweep of ``cfg``: every setting checked first, then one chunk per learner."""
    return learner_plan(cfg, cfg.algo)


def main(argv: list[str] | None = None, prog: str | None = None) -> int:
    """``torchrl-subgoal train``: parse the flags, run (or resume) the sweep, print the report; the exit code."""
    return recipe_main(
        Config, plan, argv, description=__doc__.splitlines()[0] if __doc__ else None, threads=None, prog=prog
    )


if __name__ == "__main__":
    sys.exit(main())

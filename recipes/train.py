"""Any TorchRL learner (A2C, PPO, DQN, DDPG) with subgoal shaping on a registered domain, against the unshaped one.

The recipe lives in the package (:mod:`torchrl_subgoal.recipes.train`), so that an installed wheel
runs it too: ``torchrl-subgoal train`` is this script.

    python recipes/train.py --algo ppo --domain four_rooms
    python recipes/train.py --algo dqn --domain mountain_car --methods DQN,HRS --learnings 3
"""

import sys

from torchrl_subgoal.recipes.train import main

if __name__ == "__main__":
    sys.exit(main())

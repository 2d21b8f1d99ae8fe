"""Four-rooms: SARSA with subgoal-based reward shaping against the paper's baselines.

The recipe lives in the package (:mod:`torchrl_subgoal.recipes.four_rooms`), so that an installed
wheel runs it too: ``torchrl-subgoal reproduce four-rooms`` is this script.

    python recipes/four_rooms.py                      # small default
    python recipes/four_rooms.py --learnings 100      # paper scale: 1,000 learnings per method
"""

import sys

from torchrl_subgoal.recipes.four_rooms import main

if __name__ == "__main__":
    sys.exit(main())

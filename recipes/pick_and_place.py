"""Pick and place: DDPG with subgoal-based shaping on single-goal FetchPickAndPlace (the ``fetch`` extra).

The recipe lives in the package (:mod:`torchrl_subgoal.recipes.pick_and_place`), so that an installed
wheel runs it too: ``torchrl-subgoal reproduce pick-and-place`` is this script.

    python recipes/pick_and_place.py                          # paper scale: 5 learnings x 200 epochs
    python recipes/pick_and_place.py --preset tiny --results /tmp/pp   # plumbing check, seconds
"""

import sys

from torchrl_subgoal.recipes.pick_and_place import main

if __name__ == "__main__":
    sys.exit(main())

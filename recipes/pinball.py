"""PinBall: a Fourier-basis actor-critic with subgoal-based reward shaping against the paper's baselines.

The recipe lives in the package (:mod:`torchrl_subgoal.recipes.pinball`), so that an installed wheel
runs it too: ``torchrl-subgoal reproduce pinball`` is this script.

    python recipes/pinball.py                   # the paper's scale: 100 learnings per method
    python recipes/pinball.py --learnings 2     # a quick look
"""

import sys

from torchrl_subgoal.recipes.pinball import main

if __name__ == "__main__":
    sys.exit(main())

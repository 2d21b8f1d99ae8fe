"""Write the report of a sweep's results directory.

    python recipes/report.py results/four_rooms [--out DIR]

Same as ``torchrl-subgoal-report``; see ``docs/experiments.md``.
"""

import sys

from torchrl_subgoal.experiments.report import main

if __name__ == "__main__":
    sys.exit(main())

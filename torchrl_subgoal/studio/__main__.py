"""``python -m torchrl_subgoal.studio``: serve the subgoal studio."""

import sys

from torchrl_subgoal.studio import main

if __name__ == "__main__":
    sys.exit(main())

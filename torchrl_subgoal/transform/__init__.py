"""The shaping transform, in small rooms.

* :mod:`.keys`: the names of the kept entries, the env keys resolved from the parent env, their specs;
* :mod:`.setup`: what shaping a batch needs (the subgoals compiled for its rows, the potential as the
  kernels read it);
* :mod:`.shaping`: the shaping math as plain torch functions, the reference of the kernels;
* :mod:`.compiled` and :mod:`.eager`: one step, with the numba kernels or in torch;
* :mod:`.transitions`: the SMDP transitions, and their rebuilding from collected data;
* :mod:`.stored`: the learners of stored rows;
* :mod:`.transform`: :class:`SubgoalPotentialTransform` itself.
"""

from torchrl_subgoal.transform.compiled import AbstractStates, ShapingKernelState
from torchrl_subgoal.transform.keys import RETURN, STEPS, EnvKeys, SubgoalKeys
from torchrl_subgoal.transform.setup import PotentialKernelState
from torchrl_subgoal.transform.shaping import StartPotential
from torchrl_subgoal.transform.transform import SubgoalPotentialTransform

__all__ = [
    "RETURN",
    "STEPS",
    "AbstractStates",
    "EnvKeys",
    "PotentialKernelState",
    "ShapingKernelState",
    "StartPotential",
    "SubgoalKeys",
    "SubgoalPotentialTransform",
]

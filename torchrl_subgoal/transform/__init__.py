"""The shaping transform, in small rooms.

* :mod:`.keys`: the names of the kept entries, the env keys resolved from the parent env, their specs;
* :mod:`.setup`: what shaping a batch needs (the subgoals compiled for its rows, the potential as the
  kernels read it);
* :mod:`.shaping`: the shaping math as plain torch functions, the reference of the kernels;
* :mod:`.backends`: how one step is shaped (the protocol), in torch (:mod:`.eager`, the reference) or
  with the numba kernels (:mod:`.compiled`);
* :mod:`.transitions`: the SMDP transitions, and their rebuilding from collected data;
* :mod:`.stored`: the learners of stored rows;
* :mod:`.transform`: :class:`SubgoalPotentialTransform` itself.
"""

from torchrl_subgoal.transform.keys import RETURN, STEPS, EnvKeys, SubgoalKeys
from torchrl_subgoal.transform.shaping import StartPotential
from torchrl_subgoal.transform.transform import SubgoalPotentialTransform

__all__ = [
    "RETURN",
    "STEPS",
    "EnvKeys",
    "StartPotential",
    "SubgoalKeys",
    "SubgoalPotentialTransform",
]

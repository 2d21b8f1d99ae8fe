"""The shaping transform as the fused engine reads it: every learner's abstract state as arrays, the
abstraction's regions or lookup, and the potential as the compiled step reads it.

The fused engine runs the transform's kernels in its own compiled loop; this record is all it takes of
the transform, built from its public :attr:`~torchrl_subgoal.SubgoalPotentialTransform.env_batch`.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import torch
from tensordict import TensorDictBase

from torchrl_subgoal._kernels.shaping import LOOKUP_SHAPING, NO_SHAPING, REGION_SHAPING, START_VALUE
from torchrl_subgoal.subgoals import RegionTables, SubgoalTables
from torchrl_subgoal.transform import SubgoalPotentialTransform
from torchrl_subgoal.transform.setup import NO_TABLE, PotentialKernelState, compiled_potential

__all__ = ["AbstractStates", "ShapingKernelState", "shaping_record"]


class AbstractStates(NamedTuple):
    """Every learner's abstract-state entries as ``[N, 1]`` arrays (a compiled loop updates them in place).

    Examples:
        >>> AbstractStates.zeros(2).z.shape
        (2, 1)
    """

    z: np.ndarray  #: int64 abstract state of every learner
    achieved: np.ndarray  #: bool: the last step changed it
    r_h: np.ndarray  #: float32 discounted return since it was entered
    k: np.ndarray  #: int64 steps since it was entered
    z_start: np.ndarray  #: int64 abstract state the episode started in

    @classmethod
    def zeros(cls, n: int) -> AbstractStates:
        """Every learner in ``z = 0`` at the start of an episode."""
        return cls(
            np.zeros((n, 1), np.int64),
            np.zeros((n, 1), np.bool_),
            np.zeros((n, 1), np.float32),
            np.zeros((n, 1), np.int64),
            np.zeros((n, 1), np.int64),
        )


#: ``ShapingKernelState.measured`` of a potential over ``z`` alone
NO_MEASURED = np.zeros((0, 0), np.bool_)


class ShapingKernelState(NamedTuple):
    """The shaping transform for a compiled loop: its abstraction, its potential and every learner's
    abstract state (``[N, 1]`` arrays, updated in place), from :func:`shaping_record`.

    A loop advances a learner with :func:`~torchrl_subgoal._kernels.regions.region_search` (or ``lookup``),
    shapes its reward with :func:`~torchrl_subgoal._kernels.shaping.shaping_step` and carries its state over
    (or resets it to :func:`~torchrl_subgoal._kernels.shaping.shaping_start`'s) with
    :func:`~torchrl_subgoal._kernels.shaping.shaping_carry`.

    Examples:
        >>> state = ShapingKernelState.unshaped(3)
        >>> state.kind == NO_SHAPING, state.learners.z.shape
        (True, (3, 1))
    """

    kind: int  #: ``NO_SHAPING``, ``REGION_SHAPING`` (subgoal series, region aggregation) or ``LOOKUP_SHAPING``
    regions: RegionTables  #: the regions (``REGION_SHAPING``)
    lookup: np.ndarray  #: ``[S]`` abstract state of every state number (``LOOKUP_SHAPING``)
    potential: PotentialKernelState
    learners: AbstractStates  #: every learner's abstract state
    #: ``[N, J]``: the regions an interpolating table measures a distance to; empty: no within-segment term
    measured: np.ndarray = NO_MEASURED

    @classmethod
    def unshaped(cls, n: int) -> ShapingKernelState:
        """No shaping, for ``n`` learners (a bare env)."""
        empty3 = np.zeros((1, 1, 1), np.float32)
        regions = RegionTables(
            np.zeros(0, np.int64),
            empty3,
            empty3,
            empty3,
            empty3,
            np.zeros((1, 1), np.float32),
            np.zeros((1, 1, 1), np.bool_),
            1,
        )
        potential = PotentialKernelState(NO_TABLE, 0.0, 0.0, 0.0, 0.0, False, START_VALUE)
        return cls(NO_SHAPING, regions, np.zeros(1, np.int64), potential, AbstractStates.zeros(n))


def shaping_record(transform: SubgoalPotentialTransform, tensordict: TensorDictBase) -> ShapingKernelState:
    """``transform`` for a compiled loop: its abstraction, its potential and each learner's abstract state as
    ``tensordict`` (a reset of the env through the transform) holds it, copied; the loop applies the online
    update when the transform learns.

    Needs the env's batch set up for the compiled step (a tabular or naive potential on the CPU, reset through
    the transform) and a subgoal series of regions (no conditions), a lookup or a region aggregation; anything
    else is a ``TypeError`` that says so.

    Examples:
        >>> from torchrl.envs import TransformedEnv
        >>> from torchrl_subgoal import State, SubgoalSeries, TabularPotential
        >>> from torchrl_subgoal.envs import FourRoomsEnv
        >>> shaping = SubgoalPotentialTransform(SubgoalSeries([State(3), State(7)]), TabularPotential(3, [2]),
        ...                                     gamma=0.9, value_update=0.1)
        >>> env = TransformedEnv(FourRoomsEnv(num_envs=2), shaping)
        >>> state = shaping_record(shaping, env.reset())
        >>> state.potential.table.shape, state.potential.value_lr, state.learners.z.shape
        ((2, 3), 0.1, (2, 1))
    """
    setup = transform.env_batch
    if setup is None:
        raise TypeError("the fused engine needs the env reset through the transform first (env.reset())")
    if not setup.compiled:
        update = transform.value_update
        why = compiled_potential(transform.potential, update.loss if update else None)
        raise TypeError(
            "a compiled loop shapes as the compiled step does, which it cannot here: "
            f"{why or f'backend={transform.backend!r}'}"
        )
    abstraction = setup.abstraction
    lookup = np.zeros(1, np.int64)
    regions = ShapingKernelState.unshaped(0).regions
    if isinstance(abstraction, SubgoalTables):
        if not abstraction.fusable:
            raise TypeError("a compiled loop advances subgoal regions, not conditions")
        kind, regions = REGION_SHAPING, abstraction.kernel_state()
    elif isinstance(abstraction.mapping, torch.Tensor):
        if setup.observation_size != 1:
            raise TypeError(
                f"a lookup aggregation reads a state number, not an observation of {setup.observation_size} "
                "entries (observation_key)"
            )
        kind, lookup = LOOKUP_SHAPING, abstraction.mapping.numpy()
    elif abstraction.regions is not None:
        kind, regions = REGION_SHAPING, abstraction.regions
    else:
        raise TypeError(
            "a compiled loop needs a subgoal series, a lookup or a region aggregation, not a function aggregation"
        )
    keys, n = transform.keys, setup.batch_shape.numel()
    written = {key if isinstance(key, str) else key[-1]: key for key in transform.out_keys}  # in the reward's group
    z, r_h, k = (
        tensordict.get(written[name]).reshape(n, 1).numpy().copy() for name in (keys.index, keys.ret, keys.steps)
    )
    potential = setup.kernel[transform.learning]  # type: ignore[index]
    measured = NO_MEASURED
    if transform._settings.interpolate:
        assert isinstance(abstraction, SubgoalTables)
        measured = abstraction.measured.numpy()
    # both envs of the fused engine start every episode in the same place
    return ShapingKernelState(
        kind, regions, lookup, potential, AbstractStates(z, np.zeros((n, 1), np.bool_), r_h, k, z.copy()), measured
    )

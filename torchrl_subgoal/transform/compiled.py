"""The compiled step of the shaping transform (a tabular or naive potential on the CPU), and the
records a compiled loop (the fused engine) reads the transform through."""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np
import torch
from tensordict import TensorDictBase
from tensordict.utils import NestedKey

from torchrl_subgoal._kernels import NUMBA
from torchrl_subgoal.subgoals import RegionTables, SubgoalTables
from torchrl_subgoal.transform.setup import NO_TABLE, BatchSetup, PotentialKernelState, Settings
from torchrl_subgoal.transform.transitions import transition

if NUMBA:  # without numba the transform never takes this path (setup.compiles)
    from torchrl_subgoal._kernels.shaping import (
        LOOKUP_SHAPING,
        NO_SHAPING,
        REGION_SHAPING,
        START_VALUE,
        advance_and_shape,
        finite_inputs,
        shape_step,
    )

__all__ = ["AbstractStates", "ShapingKernelState", "StepInputs", "check_finite", "compiled_step"]

_NO_TRANSITION = tuple(np.zeros((0, 1), dtype=d) for d in (np.float32, np.int64, np.bool_))
_NO_ENTRIES = np.zeros((0, 0), np.float32)  # finite_inputs without an observation to check


class StepInputs(NamedTuple):
    """One step's entries of ``"next"`` that the shaping reads.

    Examples:
        >>> one = torch.ones(2, 1)
        >>> StepInputs(None, one, one, one.bool(), one.bool(), None).reward.shape
        torch.Size([2, 1])
    """

    obs: torch.Tensor | None  #: the observation the region predicates read (``None``: not read)
    reward: torch.Tensor  #: the reward to shape
    env_reward: torch.Tensor  #: the env's reward, which ``r_h`` accumulates (``reward`` itself but after a shaping)
    done: torch.Tensor
    terminated: torch.Tensor
    td: TensorDictBase | None  #: the step's ``"next"`` entries, for the conditions


def check_finite(reward: torch.Tensor, obs: torch.Tensor | None, reward_key: NestedKey, obs_key: NestedKey) -> None:
    """Refuse a NaN or infinite reward and a NaN observation, naming the entry.

    One reduction per tensor when all is well (a NaN or inf anywhere makes the sum
    non-finite); the search for the culprit runs only then.

    Examples:
        >>> check_finite(torch.tensor([[1.0], [float("nan")]]), None, "reward", "observation")
        Traceback (most recent call last):
        ...
        ValueError: SubgoalPotentialTransform: 'reward' is NaN or infinite at index (1, 0) (value nan): ...
    """
    for tensor, key, bad in ((reward, reward_key, "NaN or infinite"), (obs, obs_key, "NaN")):
        if tensor is None or not tensor.is_floating_point():
            continue
        if math.isfinite(float(tensor.sum())):  # an overflow to inf only costs the search below
            continue
        wrong = ~torch.isfinite(tensor) if tensor is reward else torch.isnan(tensor)
        if bool(wrong.any()):
            first = tuple(int(i) for i in wrong.nonzero()[0])
            raise ValueError(
                f"SubgoalPotentialTransform: {key!r} is {bad} at index {first} (value "
                f"{tensor[first].item()}): it would make the potential NaN for good; fix the env, or "
                "replace such values before this transform"
            )


def _column(t: torch.Tensor, n: int, name: str) -> np.ndarray:
    """A ``[*B, 1]`` CPU tensor as an ``[n, 1]`` numpy view; a clear ``ValueError`` if it does not hold one
    entry per row (the kernels index it unchecked). ``[n, 1]`` tensors do not come here (see below)."""
    if t.numel() != n:
        raise ValueError(f"{name!r} has shape {tuple(t.shape)}, expected one entry per row of a batch of {n}")
    return t.numpy().reshape(n, 1)


def compiled_step(
    setup: BatchSetup, settings: Settings, current: dict[str, torch.Tensor], step: StepInputs, learn: bool
) -> dict[str, Any]:
    """One step of aggregation and shaping from the abstract-state entries ``current``, compiled.

    Returns the next entries (names as in :class:`~torchrl_subgoal.SubgoalKeys`, ``"reward"`` the
    shaped reward, ``"transition"`` the step's SMDP transition when the settings write it).

    Examples:
        >>> from torchrl_subgoal import State, SubgoalPotentialTransform, SubgoalSeries, TabularPotential
        >>> t = SubgoalPotentialTransform(SubgoalSeries([State(1)]), TabularPotential(2), gamma=0.9)
        >>> batch = t._batch(torch.Size([2]), torch.zeros(2, 1, dtype=torch.long), 1, torch.zeros(2, 1), online=True)
        >>> z, zero = torch.zeros(2, 1, dtype=torch.long), torch.zeros(2, 1)
        >>> out = compiled_step(batch, t._settings, {"subgoal_index": z, "subgoal_return": zero, "subgoal_steps": z},
        ...                     StepInputs(torch.tensor([[1], [0]]), zero, zero, z.bool(), z.bool(), None), learn=False)
        >>> out["subgoal_index"].tolist(), out["subgoal_steps"].tolist()
        ([[1], [0]], [[0], [1]])
    """
    keys = settings.keys
    n = setup.rows
    col = (n, 1)
    # every entry read and written as an [n, 1] numpy view: a batch of one dimension gives those at once (this
    # runs every step: views taken in line), other shapes are reshaped by _column, which checks them
    z, r_h, k = current[keys.index], current[keys.ret], current[keys.steps]
    reward, env_reward = step.reward, step.env_reward
    z_col, rh_col, k_col, env_col, done_col = z.numpy(), r_h.numpy(), k.numpy(), env_reward.numpy(), step.done.numpy()
    if not z_col.shape == rh_col.shape == k_col.shape == env_col.shape == done_col.shape == col:
        z_col, rh_col, k_col, env_col, done_col = (
            _column(t, n, name)
            for t, name in (
                (z, keys.index),
                (r_h, keys.ret),
                (k, keys.steps),
                (env_reward, "reward"),
                (step.done, "done"),
            )
        )
    ends = done_col
    if step.terminated is not step.done and (ends := step.terminated.numpy()).shape != col:
        ends = _column(step.terminated, n, "terminated")
    start = _column(current[keys.start], n, keys.start) if keys.start in current else setup.z_start
    achieved = _column(current[keys.achieved], n, keys.achieved) if keys.achieved in current else z_col
    z_next, rh_out, k_out, shaped = (
        torch.empty_like(z),
        torch.empty_like(r_h),
        torch.empty_like(k),
        torch.empty_like(reward),
    )
    outputs: tuple[np.ndarray, ...] = (z_next.numpy(), rh_out.numpy(), k_out.numpy(), shaped.numpy())
    if z_next.ndim != 2:
        outputs = tuple(a.reshape(col) for a in outputs)
    extra: tuple[np.ndarray, ...] = _NO_TRANSITION
    if settings.transitions:  # the kernel also fills the transition's r_h, k and mask
        r_acc, k_acc, closed = torch.empty_like(r_h), torch.empty_like(k), torch.empty_like(step.done)
        extra = (r_acc.numpy().reshape(col), k_acc.numpy().reshape(col), closed.numpy().reshape(col))
    inputs = (achieved, rh_col, k_col, env_col, done_col, ends, start)
    potential = setup.kernel[learn]  # type: ignore[index]
    if setup.regions is not None:
        if not advance_and_shape(
            setup.regions, potential, setup.group, z_col, _rows(step.obs, n, setup), *inputs, *outputs, *extra
        ):
            check_finite(reward, step.obs, "reward", settings.observation_key)  # raises, naming the entry
            raise ValueError(
                f"SubgoalPotentialTransform: the reward is not finite or {settings.observation_key!r} holds a NaN"
            )
    else:  # conditions or a lookup: advanced first (conditions called in Python), then shaped
        if not finite_inputs(env_col, _NO_ENTRIES):
            check_finite(env_reward, None, "reward", settings.observation_key)
        abstraction = setup.abstraction
        if isinstance(abstraction, SubgoalTables):
            abstraction.advance_into(z_col, step.obs, step.td, outputs[0])
        else:
            z_next = abstraction.advance(z, step.obs, step.td)
            outputs = (z_next.numpy().reshape(col), *outputs[1:])
        zn_col = outputs[0]
        shape_step(potential, setup.group, z_col, zn_col, *inputs, *outputs[1:], *extra)
    if reward is not env_reward:  # after another shaping transform: shape its reward, accumulate the env's
        shaped += reward - env_reward
    out: dict[str, Any] = {keys.index: z_next, keys.ret: rh_out, keys.steps: k_out, "reward": shaped}
    if keys.achieved in settings.kept:
        out[keys.achieved] = z_next != z
    for carried in (keys.learner, keys.start):
        if carried in current:
            out[carried] = current[carried]
    if settings.transitions:
        out["transition"] = transition(
            setup.batch_shape,
            {key: current[key] for key in settings.inputs},
            {key: out[key] for key in settings.inputs},
            r_acc,
            k_acc,
            closed,
            step.done,
            step.terminated,
            z_next != z,
        )
    return out


def _rows(obs: torch.Tensor | None, n: int, setup: BatchSetup) -> np.ndarray:
    """The observation as the ``[n, D]`` rows the region search reads."""
    assert obs is not None
    regions = setup.regions
    assert regions is not None
    d = regions.lo.shape[2]
    a = obs.numpy()
    if a.size != n * d:
        raise ValueError(
            f"the observation of shape {tuple(obs.shape)} does not fit the subgoal tables compiled for "
            f"{n} rows x {d} entries (batch shape {tuple(setup.batch_shape)})"
        )
    return a.reshape(n, d)


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


class ShapingKernelState(NamedTuple):
    """The shaping transform for a compiled loop: its abstraction, its potential and every learner's
    abstract state (``[N, 1]`` arrays, updated in place), from :meth:`SubgoalPotentialTransform.kernel_state`.

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


def kernel_state(
    setup: BatchSetup, state: tuple[torch.Tensor, torch.Tensor, torch.Tensor], learn: bool, observation_size: int
) -> ShapingKernelState:
    """The record of a compiled loop for the env batch ``setup`` (set up for the compiled step), with every
    learner's ``state = (z, r_h, k)`` copied; ``learn``: the loop applies the online update.

    Examples:
        >>> from torchrl.envs import TransformedEnv
        >>> from torchrl_subgoal import State, SubgoalPotentialTransform, SubgoalSeries, TabularPotential
        >>> from torchrl_subgoal.envs import FourRoomsEnv
        >>> t = SubgoalPotentialTransform(SubgoalSeries([State(3)]), TabularPotential(2, (2,)), gamma=0.9)
        >>> td = TransformedEnv(FourRoomsEnv(2), t).reset()
        >>> state = (td["subgoal_index"], td["subgoal_return"], td["subgoal_steps"])
        >>> kernel_state(t._online, state, learn=False, observation_size=1).learners.z.shape
        (2, 1)
    """
    abstraction = setup.abstraction
    lookup = np.zeros(1, np.int64)
    regions = ShapingKernelState.unshaped(0).regions
    if isinstance(abstraction, SubgoalTables):
        if not abstraction.fusable:
            raise TypeError("a compiled loop advances subgoal regions, not conditions")
        kind, regions = REGION_SHAPING, abstraction.kernel_state()
    elif isinstance(abstraction.mapping, torch.Tensor):
        if observation_size != 1:
            raise TypeError(
                f"a lookup aggregation reads a state number, not an observation of {observation_size} "
                "entries (observation_key)"
            )
        kind, lookup = LOOKUP_SHAPING, abstraction.mapping.numpy()
    elif abstraction.regions is not None:
        kind, regions = REGION_SHAPING, abstraction.regions
    else:
        raise TypeError(
            "a compiled loop needs a subgoal series, a lookup or a region aggregation, not a function aggregation"
        )
    n = setup.batch_shape.numel()
    z, r_h, k = (t.reshape(n, 1).numpy().copy() for t in state)
    potential = setup.kernel[learn]  # type: ignore[index]
    # both envs of the fused engine start every episode in the same place
    return ShapingKernelState(
        kind, regions, lookup, potential, AbstractStates(z, np.zeros((n, 1), np.bool_), r_h, k, z.copy())
    )

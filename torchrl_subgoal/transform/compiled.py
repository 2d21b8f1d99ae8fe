"""The compiled step of the shaping transform (a tabular or naive potential on the CPU)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import torch
from tensordict.utils import NestedKey

from torchrl_subgoal._kernels import NUMBA
from torchrl_subgoal.subgoals import SubgoalTables
from torchrl_subgoal.transform.keys import StepInputs
from torchrl_subgoal.transform.setup import BatchSetup, Settings
from torchrl_subgoal.transform.transitions import transition

if NUMBA:  # without numba the transform never takes this path (setup.compiles)
    from torchrl_subgoal._kernels.segments import add_segment_terms
    from torchrl_subgoal._kernels.shaping import (
        advance_and_shape,
        finite_inputs,
        shape_step,
    )

__all__ = ["StepInputs", "check_finite", "compiled_step"]

_NO_TRANSITION = tuple(np.zeros((0, 1), dtype=d) for d in (np.float32, np.int64, np.bool_))
_NO_ENTRIES = np.zeros((0, 0), np.float32)  # finite_inputs without an observation to check


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
    if settings.interpolate:  # Φ(s, z): the within-segment term on each side of the step
        tables = setup.abstraction
        assert isinstance(tables, SubgoalTables) and step.obs_before is not None
        before, after = _rows(step.obs_before, n, setup), _rows(step.obs, n, setup)
        measured = tables.measured.numpy()
        add_segment_terms(tables.kernel_state(), measured, potential, setup.group, z_col, outputs[0], before, after,
                          ends, outputs[3])  # fmt: skip
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
    if regions is None and isinstance(setup.abstraction, SubgoalTables):  # regions beside conditions
        regions = setup.abstraction.kernel_state()
    assert regions is not None
    d = regions.lo.shape[2]
    a = obs.numpy()
    if a.size != n * d:
        raise ValueError(
            f"the observation of shape {tuple(obs.shape)} does not fit the subgoal tables compiled for "
            f"{n} rows x {d} entries (batch shape {tuple(setup.batch_shape)})"
        )
    return a.reshape(n, d)

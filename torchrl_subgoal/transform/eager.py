"""The torch step of the shaping transform: any potential, any device, conditions; the reference the
compiled step agrees with."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import torch
from tensordict import TensorDict, TensorDictBase
from tensordict.nn import TensorDictModuleBase

from torchrl_subgoal.potentials import NaivePotential, TabularPotential, check_value
from torchrl_subgoal.subgoals.tables import SubgoalTables
from torchrl_subgoal.transform.cache import ValueCache
from torchrl_subgoal.transform.compiled import check_finite
from torchrl_subgoal.transform.keys import StepInputs
from torchrl_subgoal.transform.segments import segment_term
from torchrl_subgoal.transform.setup import BatchSetup, Settings
from torchrl_subgoal.transform.shaping import (
    accumulate,
    ancestral_max,
    closes,
    restart,
    shaped_reward,
    start_level,
)
from torchrl_subgoal.transform.transitions import transition

__all__ = ["monotone_values", "potential_value", "row_values", "start_entries", "torch_step"]


def potential_value(
    potential: TensorDictModuleBase,
    cache: ValueCache,
    entries: dict[str, torch.Tensor],
    batch_shape: torch.Size,
    slot: str,
) -> torch.Tensor:
    """``Φ`` of abstract-state entries, ``[*B, 1]``: given back by ``cache`` (under ``slot``) while the
    entries and the potential are unchanged, else evaluated and remembered.

    Examples:
        >>> from torchrl_subgoal import TabularPotential
        >>> v, cache = TabularPotential(3), ValueCache()
        >>> cache.check(v)
        >>> potential_value(v, cache, {"subgoal_index": torch.tensor([[2]])}, torch.Size([1]), "z").tolist()
        [[0.0]]
    """
    inputs = {k: entries[k] for k in potential.in_keys if k in entries}
    cached = cache.get(slot, inputs)
    if cached is not None:
        return cached
    value = potential(TensorDict(inputs, batch_size=batch_shape)).get(potential.out_keys[-1])
    value = check_value(value, batch_shape, f"the potential {type(potential).__name__}")
    cache.put(slot, inputs, value)
    return value


def torch_step(
    setup: BatchSetup,
    settings: Settings,
    potential: TensorDictModuleBase,
    cache: ValueCache,
    current: dict[str, torch.Tensor],
    step: StepInputs,
    update: Callable[[TensorDictBase], None] | None,
) -> dict[str, Any]:
    """One step of aggregation and shaping from the abstract-state entries ``current``, in torch.

    With ``update``, the potential is first trained on the transitions this step closes (the online
    update). Returns the next entries, as :func:`~torchrl_subgoal.transform.compiled.compiled_step`
    does (``"transition"``: the step's SMDP transition TensorDict).

    Examples:
        >>> from torchrl_subgoal import State, SubgoalPotentialTransform, SubgoalSeries, TabularPotential
        >>> series = SubgoalSeries([State(1)])
        >>> t = SubgoalPotentialTransform(series, TabularPotential(2), gamma=0.9).use_backend("torch")
        >>> batch = t._batch(torch.Size([2]), torch.zeros(2, 1, dtype=torch.long), 1, torch.zeros(2, 1), online=True)
        >>> z, zero = torch.zeros(2, 1, dtype=torch.long), torch.zeros(2, 1)
        >>> current = {"subgoal_index": z, "subgoal_return": zero, "subgoal_steps": z}
        >>> step = StepInputs(torch.tensor([[1], [0]]), zero, zero, z.bool(), z.bool(), None)
        >>> out = torch_step(batch, t._settings, t.potential, ValueCache(), current, step, update=None)
        >>> out["subgoal_index"].tolist()
        [[1], [0]]
    """
    keys, kept, batch_shape = settings.keys, settings.kept, setup.batch_shape
    check_finite(step.env_reward, step.obs, "reward", settings.observation_key)
    z = current[keys.index]
    advance = setup.abstraction.advance if setup.compiled_search else setup.abstraction.advance_eager
    z_next = advance(z, step.obs, step.td)
    achieved = z_next != z
    r_h, k = accumulate(current[keys.ret], current[keys.steps], step.env_reward, settings.value_gamma)
    closed = closes(z, z_next, step.done)
    nxt: dict[str, torch.Tensor] = {keys.index: z_next}
    if keys.achieved in kept:
        nxt[keys.achieved] = achieved
    if keys.anchor in kept:
        assert step.obs is not None
        anchor = step.obs.reshape(*batch_shape, -1).to(torch.float32)
        nxt[keys.anchor] = torch.where(achieved, anchor, current[keys.anchor])
    for carried in (keys.learner, keys.start):
        if carried in kept:
            nxt[carried] = current[carried]
    smdp = None
    if update is not None or settings.transitions:
        smdp = transition(
            batch_shape,
            {key: current[key] for key in settings.inputs},
            {key: nxt[key] for key in settings.inputs},
            r_h,
            k,
            closed,
            step.done,
            step.terminated,
            achieved,
        )
    if update is not None and bool(closed.any()):
        assert smdp is not None
        update(smdp)
    with torch.no_grad():
        if setup.ancestors is not None:  # a monotone table
            assert isinstance(potential, TabularPotential)
            phi, phi_next, v_start = monotone_values(
                potential, setup, [current[keys.index], z_next, start_entries(current, settings)[keys.index]]
            )
        else:
            # Φ(z) of this step is last step's Φ(z') (unless an env was reset), Φ(z') is Φ(z) until a subgoal is
            # achieved, and Φ(z_0) holds for the episode: none is evaluated again while the inputs and the
            # potential are unchanged
            cache.check(potential)
            phi = potential_value(potential, cache, current, batch_shape, "z")
            phi_next = potential_value(potential, cache, nxt, batch_shape, "z")
            v_start = None
            if settings.start != "value" and not isinstance(potential, NaivePotential):
                v_start = potential_value(potential, cache, start_entries(current, settings), batch_shape, "start")
        if settings.interpolate:  # Φ(s, z): the within-segment term on each side of the step
            assert isinstance(potential, TabularPotential) and isinstance(setup.abstraction, SubgoalTables)
            if step.obs_before is None or step.obs is None:
                raise KeyError(f"an interpolating potential reads {settings.observation_key!r} before and after a step")
            values = row_values(potential, setup)
            phi = phi + segment_term(setup.abstraction, values, current[keys.index], step.obs_before)
            phi_next = phi_next + segment_term(setup.abstraction, values, z_next, step.obs)
        if v_start is not None and settings.start != "value":
            level = start_level(v_start, settings.start)
            assert level is not None
            phi, phi_next = phi - level, phi_next - level
    shaped = shaped_reward(step.reward, phi, phi_next, step.terminated, settings.gamma, settings.zero_terminal)
    out: dict[str, Any] = dict(nxt)
    out[keys.ret], out[keys.steps] = restart(r_h, k, closed)
    out["reward"] = shaped
    if settings.transitions:
        out["transition"] = smdp
    return out


def monotone_values(potential: TabularPotential, setup: BatchSetup, indices: list[torch.Tensor]) -> list[torch.Tensor]:
    """``Φ`` at each of ``indices`` (``z`` entries, ``[*B, 1]``) read from each row's table made non-decreasing
    along its series (:func:`~torchrl_subgoal.transform.shaping.ancestral_max`).

    Examples:
        >>> from torchrl_subgoal import State, SubgoalSeries, TabularPotential
        >>> from torchrl_subgoal.transform.setup import Subgoals, monotone_ancestors
        >>> v, learner = TabularPotential(3, monotone=True), torch.zeros(1, 1, dtype=torch.long)
        >>> with torch.no_grad():
        ...     v.table[:] = torch.tensor([1.0, 0.5, 2.0])
        >>> subgoals = Subgoals(SubgoalSeries([State(1), State(2)]))
        >>> batch = BatchSetup(torch.Size([1]), subgoals.compile(learner, torch.Size([1]), 1, (1, False), "o"), learner,
        ...                    ancestors=monotone_ancestors(v, subgoals, learner, 1))
        >>> [phi.item() for phi in monotone_values(v, batch, [torch.tensor([[1]]), torch.tensor([[2]])])]
        [1.0, 2.0]
    """
    lifted = row_values(potential, setup)
    return [lifted.gather(1, z.reshape(-1, 1)).view(*setup.batch_shape, 1) for z in indices]


def row_values(potential: TabularPotential, setup: BatchSetup) -> torch.Tensor:
    """Each row's table as it shapes, ``[rows, n]``: its learner's, made non-decreasing along the series
    when the table is monotone.

    Examples:
        >>> from torchrl_subgoal import State, SubgoalSeries, TabularPotential
        >>> from torchrl_subgoal.transform.setup import Subgoals
        >>> v, learner = TabularPotential(3, init=[0.0, 2.0, 1.0]), torch.zeros(2, 1, dtype=torch.long)
        >>> subgoals = Subgoals(SubgoalSeries([State(1), State(2)]))
        >>> batch = BatchSetup(torch.Size([2]), subgoals.compile(learner, torch.Size([2]), 1, (1, False), "o"), learner)
        >>> row_values(v, batch).tolist()
        [[0.0, 2.0, 1.0], [0.0, 2.0, 1.0]]
    """
    rows = setup.learner.reshape(-1)
    table = potential.table.detach().reshape(-1, potential.num_states)
    per_row = table[rows // potential.envs_per_table] if potential.batch_shape else table.expand(rows.numel(), -1)
    return per_row if setup.ancestors is None else ancestral_max(per_row, setup.ancestors)


def start_entries(current: dict[str, torch.Tensor], settings: Settings) -> dict[str, torch.Tensor]:
    """The potential's inputs at the start of the episode: ``z_0`` (0 for a subgoal series) or ``o_0``.

    Examples:
        >>> from torchrl_subgoal import State, SubgoalPotentialTransform, SubgoalSeries, TabularPotential
        >>> t = SubgoalPotentialTransform(SubgoalSeries([State(1)]), TabularPotential(2), gamma=0.9)
        >>> start_entries({"subgoal_index": torch.tensor([[1]])}, t._settings)["subgoal_index"].tolist()
        [[0]]
    """
    keys = settings.keys
    start = dict(current)
    if keys.anchor in settings.kept:
        start[keys.anchor] = current[keys.start]
    else:
        start[keys.index] = current[keys.start] if keys.start in current else torch.zeros_like(current[keys.index])
    return start

"""The shaping math, as plain torch functions: the reference that the compiled kernels
(:mod:`torchrl_subgoal._kernels.shaping`) mirror and are tested against.

One env step from the abstract state ``(z, r_h, k)`` to ``z'``, with the env reward ``r``:

* the SMDP return accumulates, ``r_h ← r_h + γ_v^k r`` and ``k ← k + 1`` (:func:`accumulate`);
* a transition closes where ``z' ≠ z`` or the episode ended (:func:`closes`), and then
  ``r_h`` and ``k`` restart from 0 (:func:`restart`);
* the reward becomes ``r + γ Φ(z') − Φ(z)`` (:func:`shaped_reward`), with ``Φ = V − c`` where
  ``c`` is set by the start state's value (:func:`start_level`) and, optionally, ``Φ(z') = 0``
  at a terminal state; with ``monotone_potential`` ``V`` is first replaced by the nearest table
  that does not decrease along the series (:func:`nondecreasing`).

The online update of the potential (one SGD step of :class:`~torchrl_subgoal.SubgoalValueLoss` on
the closed transitions, before shaping) is the loss's own code.
"""

from __future__ import annotations

import math
from typing import Literal

import torch

__all__ = [
    "START_MODES",
    "StartPotential",
    "accumulate",
    "closes",
    "nondecreasing",
    "restart",
    "shaped_reward",
    "start_level",
]

StartPotential = Literal["value", "zero", "nonpositive"]
#: the start levels, and the code the compiled kernels read (``_kernels.shaping.START_*``)
START_MODES: dict[str, int] = {"value": 0, "zero": 1, "nonpositive": 2}


def accumulate(
    r_h: torch.Tensor, k: torch.Tensor, reward: torch.Tensor, value_gamma: float
) -> tuple[torch.Tensor, torch.Tensor]:
    """``(r_h + γ_v^k r, k + 1)``: one step of the SMDP return.

    Examples:
        >>> r_h, k = accumulate(torch.tensor([[1.0]]), torch.tensor([[2]]), torch.tensor([[1.0]]), 0.5)
        >>> r_h.item(), k.item()
        (1.25, 3)
    """
    return r_h + reward.to(r_h.dtype) * value_gamma**k, k + 1


def closes(z: torch.Tensor, z_next: torch.Tensor, done: torch.Tensor) -> torch.Tensor:
    """Where a transition closes: ``z`` changed or the episode ended.

    Examples:
        >>> closes(torch.tensor([[0], [1]]), torch.tensor([[1], [1]]), torch.tensor([[False], [False]])).tolist()
        [[True], [False]]
    """
    return (z_next != z) | done


def restart(r_h: torch.Tensor, k: torch.Tensor, closed: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """``r_h`` and ``k`` carried to the next step: 0 where a transition closed.

    Examples:
        >>> r_h, k = restart(torch.tensor([[2.0], [3.0]]), torch.tensor([[4], [5]]), torch.tensor([[True], [False]]))
        >>> r_h.tolist(), k.tolist()
        ([[0.0], [3.0]], [[0], [5]])
    """
    return r_h.masked_fill(closed, 0.0), k.masked_fill(closed, 0)


def start_level(v_start: torch.Tensor, mode: StartPotential) -> torch.Tensor | None:
    """``c`` of ``Φ = V − c``, from ``V`` of the state the episode started in: ``None`` for ``"value"``
    (``Φ = V``), ``V(z_0)`` for ``"zero"``, ``max(V(z_0), 0)`` for ``"nonpositive"``.

    Examples:
        >>> start_level(torch.tensor([[2.0], [-1.0]]), "nonpositive").tolist()
        [[2.0], [0.0]]
    """
    if mode == "value":
        return None
    return v_start if mode == "zero" else v_start.clamp(min=0.0)


def shaped_reward(
    reward: torch.Tensor,
    phi: torch.Tensor,
    phi_next: torch.Tensor,
    terminated: torch.Tensor,
    gamma: float,
    zero_terminal: bool,
) -> torch.Tensor:
    """``r + γ Φ(z') − Φ(z)``, with ``Φ(z') = 0`` at a terminal state when ``zero_terminal``.

    Examples:
        >>> shaped_reward(torch.tensor([[1.0]]), torch.tensor([[0.5]]), torch.tensor([[2.0]]),
        ...               torch.tensor([[True]]), 0.9, zero_terminal=True).item()
        0.5
    """
    if zero_terminal:
        phi_next = phi_next.masked_fill(terminated, 0.0)
    return reward + (gamma * phi_next - phi).to(reward.dtype)


def nondecreasing(values: torch.Tensor, lengths: torch.Tensor) -> torch.Tensor:
    """The nearest (least-squares) non-decreasing sequence to each row's first ``lengths`` entries;
    the entries past a row's length are left as they are.

    ``values`` is ``[R, n]`` (a table row per batch row), ``lengths`` ``[R]``. Entry ``i`` of the
    projection is ``max_{j ≤ i} min_{k ≥ i} mean(values[j..k])`` (the min-max formula of isotonic
    regression): where a later subgoal is valued below an earlier one, both get the mean of the
    run they form, so the shaping neither charges for reaching the later one nor pays for lingering
    before it.

    Examples:
        >>> nondecreasing(torch.tensor([[1.0, 0.5, 2.0], [1.0, 0.5, 0.0]]), torch.tensor([3, 2])).tolist()
        [[0.75, 0.75, 2.0], [0.75, 0.75, 0.0]]
    """
    n = values.shape[-1]
    idx = torch.arange(n, device=values.device)
    valid = idx < lengths[:, None]  # [R, n]
    sums = torch.nn.functional.pad(values.masked_fill(~valid, 0.0).cumsum(-1), (1, 0))  # [R, n + 1]
    first, last = idx[:, None], idx[None, :]  # run [first, last]
    means = (sums[:, None, 1:] - sums[:, :-1, None]) / (last - first + 1).clamp(min=1)  # [R, first, last]
    means = means.masked_fill((first > last) | (last >= lengths[:, None, None]), math.inf)
    lowest = means.flip(-1).cummin(-1).values.flip(-1)  # [R, j, i]: min over runs from j ending at i or later
    best = lowest.masked_fill(first > last, -math.inf).amax(-2)  # [R, i]: max over runs starting at j <= i
    return torch.where(valid, best, values)

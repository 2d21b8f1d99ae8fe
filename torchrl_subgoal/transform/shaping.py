"""The shaping math, as plain torch functions: the reference that the compiled kernels
(:mod:`torchrl_subgoal._kernels.shaping`) mirror and are tested against.

One env step from the abstract state ``(z, r_h, k)`` to ``z'``, with the env reward ``r``:

* the SMDP return accumulates, ``r_h ← r_h + γ_v^k r`` and ``k ← k + 1`` (:func:`accumulate`);
* a transition closes where ``z' ≠ z`` or the episode ended (:func:`closes`), and then
  ``r_h`` and ``k`` restart from 0 (:func:`restart`);
* the reward becomes ``r + γ Φ(z') − Φ(z)`` (:func:`shaped_reward`), with ``Φ = V − c`` where
  ``c`` is set by the start state's value (:func:`start_level`) and, optionally, ``Φ(z') = 0``
  at a terminal state; with a monotone table ``V(z)`` is first replaced by the largest value of ``z``
  and the states an episode passes through before it (:func:`ancestral_max`).

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
    "ancestral_max",
    "closes",
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


def ancestral_max(values: torch.Tensor, ancestors: torch.Tensor) -> torch.Tensor:
    """Each row's values made non-decreasing along its series: entry ``z`` becomes the largest value of
    ``z`` and of the states before it (``ancestors[r, z, a]``: ``a`` is ``z`` or comes before it).

    ``values`` is ``[R, n]`` (a table row per batch row), ``ancestors`` ``[R, n, n]`` boolean. A later
    subgoal valued below an earlier one (say, never reached, so still at its initial value) is shaped at
    the earlier one's value: reaching it is never charged, and no value is lowered.

    Examples:
        >>> chain = torch.ones(3, 3, dtype=torch.bool).tril()  # 0 ≺ 1 ≺ 2
        >>> ancestral_max(torch.tensor([[1.0, 0.5, 2.0], [0.9, 0.0, 0.1]]), chain.expand(2, 3, 3)).tolist()
        [[1.0, 1.0, 2.0], [0.8999999761581421, 0.8999999761581421, 0.8999999761581421]]
    """
    return values.unsqueeze(-2).masked_fill(~ancestors, -math.inf).amax(-1)

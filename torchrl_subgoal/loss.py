"""SubgoalValueLoss: trains a potential from the SMDP transitions the transform writes."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import ClassVar, Literal

import torch
from tensordict import TensorDict, TensorDictBase
from tensordict.utils import NestedKey
from torchrl.objectives import LossModule
from torchrl.objectives.value.functional import td0_return_estimate

from torchrl_subgoal.potentials import Potential

__all__ = ["SubgoalValueLoss"]


class SubgoalValueLoss(LossModule):
    """Semi-Markov TD(0) loss of a subgoal potential.

    Each SMDP transition ``(z, r_h, k, z', terminated)`` written by
    :class:`~torchrl_subgoal.SubgoalPotentialTransform` under ``("next",
    "smdp")`` gives the target ``r_h + γ_v^k V(z')`` (``V(z') = 0`` when the
    episode terminated), computed by TorchRL's
    :func:`~torchrl.objectives.value.functional.td0_return_estimate` with the
    discount raised to the ``"steps_to_next_obs"`` entry. The loss is
    ``½ Σ mask · (target − V(z))²`` with the target held fixed.

    With ``reduction="sum"`` and plain SGD of learning rate ``α_v`` on a
    :class:`~torchrl_subgoal.TabularPotential`, one optimiser step is exactly
    the paper's update ``V(z) ← V(z) + α_v (r_h + γ_v^k V(z') − V(z))`` for every
    emitted transition (a learner emits at most one per step).

    Args:
        potential: the learned potential — the same object the transform uses.

    Keyword Args:
        gamma: ``γ_v``, the discount of the abstract value function.
        reduction: ``"sum"`` (default; the tabular update above) or ``"mean"``
            over emitted transitions (for networks with adaptive optimisers).

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> from torchrl_subgoal import SubgoalValueLoss, TabularPotential
        >>> v = TabularPotential(3)
        >>> loss = SubgoalValueLoss(v, gamma=0.9)
        >>> smdp = TensorDict({
        ...     "subgoal_index": torch.tensor([[0]]),
        ...     "steps_to_next_obs": torch.tensor([[2]]),
        ...     "mask": torch.tensor([[True]]),
        ...     "next": {"subgoal_index": torch.tensor([[1]]), "reward": torch.tensor([[1.0]]),
        ...              "done": torch.tensor([[False]]), "terminated": torch.tensor([[False]])},
        ... }, batch_size=[1])
        >>> loss(smdp)["loss_value"]
        tensor(0.5000, grad_fn=<MulBackward0>)
    """

    @dataclass
    class _AcceptedKeys:
        """Keys read from the SMDP transition TensorDict.

        The potential's own inputs (``"subgoal_index"``, ``"subgoal_anchor"``…)
        are read at the root for ``z`` and under ``"next"`` for ``z'``.

        Attributes:
            reward: ``("next", reward)`` holds the discounted sum ``r_h``.
            terminated: ``("next", terminated)``; ``V(z') = 0`` when set.
            steps_to_next_obs: ``k``, steps spent in ``z``.
            mask: which entries are real transitions.
        """

        reward: NestedKey = "reward"
        terminated: NestedKey = "terminated"
        steps_to_next_obs: NestedKey = "steps_to_next_obs"
        mask: NestedKey = "mask"

    default_keys = _AcceptedKeys
    tensor_keys: _AcceptedKeys
    out_keys: ClassVar[list[str]] = ["loss_value"]

    def __init__(
        self,
        potential: Potential,
        *,
        gamma: float,
        reduction: Literal["sum", "mean"] = "sum",
    ) -> None:
        super().__init__()
        if reduction not in ("sum", "mean"):
            raise ValueError(f"reduction must be 'sum' or 'mean', got {reduction!r}")
        if not 0.0 <= gamma <= 1.0:
            raise ValueError(f"gamma must lie in [0, 1], got {gamma}")
        self.potential = potential
        self.gamma = float(gamma)
        self.reduction = reduction

    def _forward_value_estimator_keys(self, **kwargs) -> None:
        """No value estimator object: the SMDP target is the functional TD(0) estimate."""

    def smdp_loss(
        self,
        inputs: Sequence[torch.Tensor],
        next_inputs: Sequence[torch.Tensor],
        reward: torch.Tensor,
        steps: torch.Tensor,
        terminated: torch.Tensor,
        mask: torch.Tensor,
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Loss and TD errors from tensors: the potential's inputs for ``z`` and ``z'``,
        ``r_h``, ``k``, terminated and mask (all ``[*B, 1]`` but the inputs)."""
        with torch.no_grad():
            next_value = self.potential(*next_inputs)
            discount = self.gamma ** steps.to(next_value.dtype)
            target = td0_return_estimate(discount, next_value, reward.to(next_value.dtype), terminated)
        value = self.potential(*inputs)
        weight = mask.to(value.dtype)
        td_error = (target - value) * weight
        loss = 0.5 * td_error.square().sum()
        if self.reduction == "mean":
            loss = loss / weight.sum().clamp_min(1.0)
        return loss, td_error.detach()

    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        """Loss over the SMDP transitions in ``tensordict`` (e.g. ``data["next", "smdp"]``)."""
        keys = self.tensor_keys
        nxt = tensordict.get("next")
        in_keys = self.potential.in_keys
        loss, td_error = self.smdp_loss(
            [tensordict.get(k) for k in in_keys],
            [nxt.get(k) for k in in_keys],
            nxt.get(keys.reward),
            tensordict.get(keys.steps_to_next_obs),
            nxt.get(keys.terminated),
            tensordict.get(keys.mask),
        )
        return TensorDict({"loss_value": loss, "td_error": td_error}, batch_size=[])

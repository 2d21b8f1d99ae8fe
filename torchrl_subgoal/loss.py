"""SubgoalValueLoss: trains a potential from the SMDP transitions the transform writes."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar, Literal

import torch
from tensordict import TensorDict, TensorDictBase
from tensordict.nn import TensorDictModuleBase
from tensordict.utils import NestedKey
from torchrl.objectives import LossModule
from torchrl.objectives.utils import ValueEstimators
from torchrl.objectives.value import TD0Estimator, ValueEstimatorBase

from torchrl_subgoal.potentials import check_value

__all__ = ["SubgoalValueLoss"]

Reduction = Literal["sum", "mean", "none"]


class SubgoalValueLoss(LossModule):
    """Semi-Markov TD(0) loss of a subgoal potential.

    Each SMDP transition ``(z, r_h, k, z', terminated)`` written by
    :class:`~torchrl_subgoal.SubgoalPotentialTransform` under ``("next",
    "smdp")`` gives the target ``r_h + γ_v^k V(z')`` (``V(z') = 0`` when the
    episode terminated). The target is TorchRL's
    :class:`~torchrl.objectives.value.TD0Estimator` estimate, which raises ``γ``
    to the ``"steps_to_next_obs"`` entry; the potential is its value network.
    The loss is ``½ Σ mask · (target − V(z))²`` with the target held fixed.

    With ``reduction="sum"`` and plain SGD of learning rate ``α_v`` on a
    :class:`~torchrl_subgoal.TabularPotential`, one optimiser step is exactly
    the paper's update ``V(z) ← V(z) + α_v (r_h + γ_v^k V(z') − V(z))`` for every
    emitted transition (a learner emits at most one per step).

    The input is any TensorDict of transitions in that layout, of any batch
    shape: the real transitions of collected data
    (``transform.transitions(data)``, or
    :func:`~torchrl_subgoal.training.smdp_transitions`), e.g. sampled from a
    replay buffer, or every step's ``data["next", "smdp"]`` written with
    ``write_transitions=True`` (``"mask"`` tells the real ones; without a
    ``"mask"`` entry every row counts).

    Args:
        potential: the learned potential — the same object the transform uses
            (any TensorDict module writing one value entry).

    Keyword Args:
        gamma: ``γ_v``, the discount of the abstract value function.
        reduction: ``"sum"`` (default; the tabular update above), ``"mean"``
            over real transitions (for networks with adaptive optimisers) or
            ``"none"`` (per-row losses, zero where masked).

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
        >>> round(float(loss(smdp)["loss_value"]), 4)
        0.5
    """

    @dataclass
    class _AcceptedKeys:
        """Keys read from the SMDP transition TensorDict.

        The potential's own inputs (``"subgoal_index"``, ``"subgoal_anchor"``…)
        are read at the root for ``z`` and under ``"next"`` for ``z'``.

        Attributes:
            value: the potential's output entry.
            reward: ``("next", reward)`` holds the discounted sum ``r_h``.
            done: ``("next", done)``.
            terminated: ``("next", terminated)``; ``V(z') = 0`` when set.
            steps_to_next_obs: ``k``, steps spent in ``z``.
            mask: which entries are real transitions.
        """

        value: NestedKey = "subgoal_value"
        reward: NestedKey = "reward"
        done: NestedKey = "done"
        terminated: NestedKey = "terminated"
        steps_to_next_obs: NestedKey = "steps_to_next_obs"
        mask: NestedKey = "mask"

    default_keys = _AcceptedKeys
    tensor_keys: _AcceptedKeys
    default_value_estimator = ValueEstimators.TD0
    out_keys: ClassVar[list[str]] = ["loss_value"]

    def __init__(
        self,
        potential: TensorDictModuleBase,
        *,
        gamma: float,
        reduction: Reduction = "sum",
    ) -> None:
        super().__init__()
        if not isinstance(potential, TensorDictModuleBase) or not potential.out_keys:
            raise TypeError(
                "SubgoalValueLoss trains a TensorDict module whose (last) output entry is the value (a Potential, or a "
                f"TensorDictModule(net, in_keys=[...], out_keys=['subgoal_value'])), got {type(potential).__name__}"
            )
        if reduction not in ("sum", "mean", "none"):
            raise ValueError(f"reduction must be 'sum', 'mean' or 'none', got {reduction!r}")
        if not 0.0 <= gamma <= 1.0:
            raise ValueError(f"gamma must lie in [0, 1], got {gamma}")
        self.potential = potential
        self.gamma = float(gamma)
        self.reduction = reduction
        self.set_keys(value=potential.out_keys[-1])
        self.make_value_estimator()

    @property
    def in_keys(self) -> list[NestedKey]:
        """The entries read (root and ``"next"``)."""
        keys = self.tensor_keys
        nxt = [("next", k) for k in (*self.potential.in_keys, keys.reward, keys.done, keys.terminated)]
        return [*self.potential.in_keys, keys.steps_to_next_obs, keys.mask, *nxt]

    def make_value_estimator(self, value_type: ValueEstimators | None = None, **hyperparams) -> SubgoalValueLoss:
        """The TD(0) estimator over the potential (the SMDP target is one-step; ``gamma`` defaults to ``γ_v``)."""
        if value_type is None:
            value_type = self.default_value_estimator
        if isinstance(value_type, ValueEstimatorBase):
            if not isinstance(value_type, TD0Estimator):
                raise NotImplementedError("the SMDP target is a TD(0) estimate: give a TD0Estimator")
            self._value_estimator = value_type
        elif value_type in (ValueEstimators.TD0, TD0Estimator):
            hyperparams.setdefault("gamma", self.gamma)
            self._value_estimator = TD0Estimator(value_network=self.potential, **hyperparams)
        else:
            raise NotImplementedError(f"the SMDP target is a TD(0) estimate; {value_type} is not supported")
        self.value_type = TD0Estimator
        self._forward_value_estimator_keys()
        return self

    def _forward_value_estimator_keys(self, **kwargs) -> None:
        if getattr(self, "_value_estimator", None) is not None:
            keys = self.tensor_keys
            self._value_estimator.set_keys(
                value=keys.value, reward=keys.reward, done=keys.done, terminated=keys.terminated,
                steps_to_next_obs=keys.steps_to_next_obs,
            )

    def _check(self, tensordict: TensorDictBase) -> None:
        keys = self.tensor_keys
        optional = getattr(self.potential, "optional_in_keys", ())
        inputs = [k for k in self.potential.in_keys if k not in optional]
        needed = [*inputs, keys.steps_to_next_obs, *[("next", k) for k in (*inputs, keys.reward, keys.terminated)]]
        missing = [k for k in needed if not isinstance(tensordict.get(k, None), torch.Tensor)]
        if missing:
            have = set(tensordict.keys(True, True))
            raise ValueError(
                f"SubgoalValueLoss reads SMDP transitions (transform.transitions(data), or data['next', 'smdp'] "
                f"written with write_transitions=True); missing {missing}, the TensorDict has "
                f"{sorted(map(str, have))}"
            )
        if tensordict.batch_dims == 0:
            raise ValueError("SubgoalValueLoss needs transitions with a batch dimension, e.g. [N]")

    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        """Loss over the SMDP transitions in ``tensordict`` (e.g. ``data["next", "smdp"]``).

        Returns a TensorDict with ``"loss_value"`` and the masked ``"td_error"`` (``[*B, 1]``).
        """
        self._check(tensordict)
        keys = self.tensor_keys
        batch = tensordict.batch_size
        in_keys = self.potential.in_keys
        value_key = self.potential.out_keys[-1]
        root = tensordict.select(*in_keys, strict=False)
        value = check_value(self.potential(root).get(value_key), batch, type(self.potential).__name__)
        with torch.no_grad():
            nxt = tensordict.get("next").select(*in_keys, strict=False)
            next_value = check_value(self.potential(nxt).get(value_key), batch, type(self.potential).__name__)
            terminated = tensordict.get(("next", keys.terminated))
            estimate = TensorDict(
                {keys.steps_to_next_obs: tensordict.get(keys.steps_to_next_obs),
                 "next": {keys.reward: tensordict.get(("next", keys.reward)),
                          keys.done: tensordict.get(("next", keys.done), terminated),
                          keys.terminated: terminated}},
                batch_size=batch,
            )
            target = self._value_estimator.value_estimate(estimate, next_value=next_value).to(value.dtype)
        mask = tensordict.get(keys.mask, None)
        weight = torch.ones_like(value) if mask is None else mask.reshape(value.shape).to(value.dtype)
        td_error = (target - value) * weight
        losses = 0.5 * td_error.square()
        loss: torch.Tensor
        if self.reduction == "none":
            loss = losses
        elif self.reduction == "sum":
            loss = losses.sum()
        else:
            loss = losses.sum() / weight.sum().clamp_min(1.0)
        return TensorDict({"loss_value": loss, "td_error": td_error.detach()}, batch_size=[])

"""SubgoalValueLoss: trains a potential from the SMDP transitions the transform closes; ValueUpdate: the
transform's online update with it."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, ClassVar, Literal

import torch
from tensordict import TensorDict, TensorDictBase
from tensordict.nn import TensorDictModuleBase
from tensordict.utils import NestedKey
from torchrl.objectives import LossModule
from torchrl.objectives.utils import ValueEstimators, default_value_kwargs
from torchrl.objectives.value import TD0Estimator, ValueEstimatorBase

from torchrl_subgoal.potentials import TabularPotential, check_value

__all__ = ["SubgoalValueLoss", "ValueUpdate"]

Reduction = Literal["sum", "mean", "none"]


class SubgoalValueLoss(LossModule):
    """Semi-Markov TD(0) loss of a subgoal potential.

    Each SMDP transition ``(z, r_h, k, z', terminated)`` closed by
    :class:`~torchrl_subgoal.SubgoalPotentialTransform` gives the target
    ``r_h + γ_v^k V(z')`` (``V(z') = 0`` when the episode terminated). The
    target is TorchRL's :class:`~torchrl.objectives.value.TD0Estimator`
    estimate, which raises ``γ_v`` to the ``"steps_to_next_obs"`` entry; the
    potential is its value network. The loss is ``½ (target − V(z))²`` per
    real transition, with the target held fixed, weighted as an expectile
    regression (``2τ`` where the target lies above ``V(z)``, ``2(1 − τ)``
    below) and reduced by TorchRL's reduction (a masked row contributes
    nothing, not even a NaN it holds).

    The defaults make ``V`` an optimistic estimate of the value of
    *progressing* through the subgoals rather than the mean return of the
    agent's past behaviour: ``expectile=0.9`` leans towards the better
    outcomes seen from ``z``, and a time-out inside ``z``
    (``bootstrap_truncated=False``) trains nothing. Under a step cost the
    mean return of an early, wandering policy is very negative, and a
    potential that low pays the agent ``(1 − γ)|Φ|`` per step for staying
    where it is (docs/shaping_defaults.md has the measurements).
    ``expectile=0.5, bootstrap_truncated=True`` is the paper's mean TD target.

    ``γ_v`` is set as for TorchRL's losses, through
    :meth:`make_value_estimator` (``loss.make_value_estimator(gamma=0.99)``;
    TorchRL's default ``γ`` until then).

    With ``reduction="sum"`` and plain SGD of learning rate ``α_v`` on a
    :class:`~torchrl_subgoal.TabularPotential`, one optimiser step is exactly
    the paper's update ``V(z) ← V(z) + α_v (r_h + γ_v^k V(z') − V(z))`` for every
    transition (a learner closes at most one per step).

    The input is any TensorDict of transitions in that layout, of any batch
    shape: the real transitions of collected data
    (``transform.transitions(data)``, or
    :func:`~torchrl_subgoal.training.smdp_transitions`), e.g. sampled from a
    replay buffer, or every step's entry a transform with a
    ``SubgoalKeys(transitions=...)`` writes (``"mask"`` tells the real ones; without a
    ``"mask"`` entry every row counts).

    Args:
        potential: the learned potential — the same object the transform uses
            (any TensorDict module writing one value entry).

    Keyword Args:
        reduction: ``"sum"`` (default; the tabular update above), ``"mean"``
            over real transitions (for networks with adaptive optimisers) or
            ``"none"`` (per-row losses, zero where masked).
        expectile: ``τ`` in ``(0, 1)`` of the target (default 0.9; 0.5: the mean).
        bootstrap_truncated: whether a transition that ended in a time-out
            without leaving ``z`` trains ``V(z)`` (bootstrapping from ``V(z)``).
            Default ``False``: it is skipped, as a masked row. It is told by
            the transitions' ``"achieved"`` entry (``z' ≠ z``); without one,
            every truncated transition is skipped.
        achievement_reward: added to the target of a transition that reached the
            next subgoal (``z' ≠ z``), discounted as a reward of its last step, so
            that ``V`` also counts the subgoals still to be achieved from ``z``
            (default 0: the returns alone). The agent's shaped reward is unchanged
            in form. An investigated candidate, not a default: the count to come is
            largest before the first subgoal, so it makes ``V`` fall along the series
            (docs/shaping_defaults.md).
        gamma: not accepted: ``γ_v`` goes through :meth:`make_value_estimator`
            (a ``TypeError`` says so).

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> from torchrl_subgoal import SubgoalValueLoss, TabularPotential
        >>> v = TabularPotential(3)
        >>> loss = SubgoalValueLoss(v, expectile=0.5).make_value_estimator(gamma=0.9)
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
            value: the potential's output entry (its last ``out_keys`` entry by default).
            reward: ``("next", reward)`` holds the discounted sum ``r_h``.
            done: ``("next", done)``.
            terminated: ``("next", terminated)``; ``V(z') = 0`` when set.
            steps_to_next_obs: ``k``, steps spent in ``z``.
            mask: which entries are real transitions.
            achieved: whether the transition reached the next subgoal (``z' ≠ z``).
        """

        value: NestedKey = "subgoal_value"
        reward: NestedKey = "reward"
        done: NestedKey = "done"
        terminated: NestedKey = "terminated"
        steps_to_next_obs: NestedKey = "steps_to_next_obs"
        mask: NestedKey = "mask"
        achieved: NestedKey = "achieved"

    default_keys = _AcceptedKeys
    tensor_keys: _AcceptedKeys
    default_value_estimator = ValueEstimators.TD0
    out_keys: ClassVar[list[str]] = ["loss_value"]

    def __init__(
        self,
        potential: TensorDictModuleBase,
        *,
        reduction: Reduction = "sum",
        expectile: float = 0.9,
        bootstrap_truncated: bool = False,
        achievement_reward: float = 0.0,
        gamma: float | None = None,
    ) -> None:
        if gamma is not None:
            raise TypeError(
                f"SubgoalValueLoss takes gamma through make_value_estimator: "
                f"SubgoalValueLoss(potential).make_value_estimator(gamma={gamma})"
            )
        super().__init__()
        if not isinstance(potential, TensorDictModuleBase) or not potential.out_keys:
            raise TypeError(
                "SubgoalValueLoss trains a TensorDict module whose (last) output entry is the value (a Potential, or a "
                f"TensorDictModule(net, in_keys=[...], out_keys=['subgoal_value'])), got {type(potential).__name__}"
            )
        if reduction not in ("sum", "mean", "none"):
            raise ValueError(f"reduction must be 'sum', 'mean' or 'none', got {reduction!r}")
        if not 0.0 < float(expectile) < 1.0:
            raise ValueError(f"expectile must lie strictly between 0 and 1, got {expectile}")
        self.potential = potential
        self.reduction = reduction
        self.expectile = float(expectile)
        self.bootstrap_truncated = bool(bootstrap_truncated)
        if not math.isfinite(float(achievement_reward)):
            raise ValueError(f"achievement_reward must be finite, got {achievement_reward}")
        self.achievement_reward = float(achievement_reward)
        self._value_estimator: ValueEstimatorBase | None = None
        self._gamma: float | None = None
        self.set_keys(value=potential.out_keys[-1])

    @property
    def in_keys(self) -> list[NestedKey]:
        """The entries read (root and ``"next"``)."""
        keys = self.tensor_keys
        nxt = [("next", k) for k in (*self.potential.in_keys, keys.reward, keys.done, keys.terminated)]
        return [*self.potential.in_keys, keys.steps_to_next_obs, keys.mask, *nxt]

    @property
    def gamma(self) -> float:
        """``γ_v``: the value estimator's discount (see :meth:`make_value_estimator`), as it was given
        (the estimator keeps it as a float32 tensor)."""
        given = getattr(self, "_gamma", None)
        return float(self.value_estimator.gamma) if given is None else given

    def make_value_estimator(self, value_type: ValueEstimators | None = None, **hyperparams: Any) -> SubgoalValueLoss:
        """The TD(0) estimator over the potential (the SMDP target is one-step): ``gamma=γ_v``.

        Args:
            value_type: ``ValueEstimators.TD0`` (the default), or a
                :class:`~torchrl.objectives.value.TD0Estimator` to use as it is.
            **hyperparams: the estimator's settings (``gamma``; TorchRL's defaults otherwise).

        Examples:
            >>> from torchrl_subgoal import TabularPotential
            >>> SubgoalValueLoss(TabularPotential(3)).make_value_estimator(gamma=0.9).gamma
            0.9
        """
        if value_type is None:
            value_type = self.default_value_estimator
        if isinstance(value_type, ValueEstimatorBase):
            if not isinstance(value_type, TD0Estimator):
                raise NotImplementedError("the SMDP target is a TD(0) estimate: give a TD0Estimator")
            self._value_estimator = value_type
            self._gamma = None
        elif value_type in (ValueEstimators.TD0, TD0Estimator):
            kwargs = {**default_value_kwargs(ValueEstimators.TD0), **hyperparams}
            if not 0.0 <= float(kwargs["gamma"]) <= 1.0:
                raise ValueError(f"gamma must lie in [0, 1], got {kwargs['gamma']}")
            self._value_estimator = TD0Estimator(value_network=self.potential, **kwargs)
            self._gamma = float(kwargs["gamma"])
        else:
            raise NotImplementedError(f"the SMDP target is a TD(0) estimate; {value_type} is not supported")
        self.value_type = TD0Estimator
        self._forward_value_estimator_keys()
        return self

    def _forward_value_estimator_keys(self, **kwargs) -> None:
        keys = self.tensor_keys
        self.loss_mask_key = keys.mask  # TorchRL's reduction masks with it
        if self._value_estimator is not None:
            self._value_estimator.set_keys(
                value=keys.value,
                reward=keys.reward,
                done=keys.done,
                terminated=keys.terminated,
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
                f"SubgoalValueLoss reads SMDP transitions (transform.transitions(data), or the entries a transform "
                f"writes under its keys' transitions); missing {missing}, the TensorDict has {sorted(map(str, have))}"
            )
        if tensordict.batch_dims == 0:
            raise ValueError("SubgoalValueLoss needs transitions with a batch dimension, e.g. [N]")

    def _value(self, tensordict: TensorDictBase) -> torch.Tensor:
        """``V`` of the potential's inputs in ``tensordict``, read from the value entry (``tensor_keys.value``)."""
        out = self.potential(tensordict.select(*self.potential.in_keys, strict=False))
        return check_value(out.get(self.tensor_keys.value), tensordict.batch_size, type(self.potential).__name__)

    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        """Loss over the SMDP transitions in ``tensordict`` (e.g. ``transform.transitions(data)``).

        Returns a TensorDict with ``"loss_value"`` and the masked ``"td_error"`` (``[*B, 1]``).
        """
        self._check(tensordict)
        keys = self.tensor_keys
        batch = tensordict.batch_size
        value = self._value(tensordict)
        with torch.no_grad():
            next_value = self._value(tensordict.get("next"))
            terminated = tensordict.get(("next", keys.terminated))
            estimate = TensorDict(
                {
                    keys.steps_to_next_obs: tensordict.get(keys.steps_to_next_obs),
                    "next": {
                        keys.reward: tensordict.get(("next", keys.reward)),
                        keys.done: tensordict.get(("next", keys.done), terminated),
                        keys.terminated: terminated,
                    },
                },
                batch_size=batch,
            )
            target = self.value_estimator.value_estimate(estimate, next_value=next_value).to(value.dtype)
            if self.achievement_reward:
                target = target + self._achievement(tensordict).to(value.dtype)
        td_error = target - value
        real = self._trains(tensordict)
        if real is not None:  # selected, not multiplied: a masked row's NaN reaches neither the loss nor a gradient
            td_error = torch.where(self._expand_loss_mask(real, td_error), td_error, torch.zeros_like(td_error))
        losses = 0.5 * td_error.square()
        if self.expectile != 0.5:
            losses = losses * torch.where(td_error > 0, 2.0 * self.expectile, 2.0 * (1.0 - self.expectile))
        rows = tensordict if real is None else TensorDict({keys.mask: real}, batch_size=batch)
        loss = self._reduce_loss(losses, rows)
        return TensorDict({"loss_value": loss, "td_error": td_error.detach()}, batch_size=[])

    def _achievement(self, tensordict: TensorDictBase) -> torch.Tensor:
        """``achievement_reward · γ_v^(k − 1)`` where a transition reached the next subgoal, else 0 (told by the
        ``"achieved"`` entry, or without one by the potential's index entry changing)."""
        keys = self.tensor_keys
        achieved = tensordict.get(keys.achieved, None)
        if achieved is None:
            index = self.potential.in_keys[0]
            achieved = tensordict.get(index) != tensordict.get(("next", index))
        steps = tensordict.get(keys.steps_to_next_obs)
        discount = torch.as_tensor(self.gamma, dtype=torch.float64) ** (steps.to(torch.float64) - 1)
        return torch.where(achieved.bool(), self.achievement_reward * discount, torch.zeros_like(discount))

    def trains(self, tensordict: TensorDictBase) -> torch.Tensor:
        """Which rows of ``tensordict`` train ``V`` (``[*B, 1]`` bool): the real transitions, less the time-outs
        inside ``z`` unless ``bootstrap_truncated``."""
        real = self._trains(tensordict)
        shape = (*tensordict.batch_size, 1)
        return torch.ones(shape, dtype=torch.bool) if real is None else real.reshape(shape)

    def _trains(self, tensordict: TensorDictBase) -> torch.Tensor | None:
        """Which rows train ``V``: the real transitions, less the time-outs inside ``z`` unless
        ``bootstrap_truncated`` (``None``: every row)."""
        keys = self.tensor_keys
        mask = tensordict.get(keys.mask, None)
        real = None if mask is None else mask.bool()
        if self.bootstrap_truncated:
            return real
        terminated = tensordict.get(("next", keys.terminated))
        truncated = tensordict.get(("next", keys.done), terminated).bool() & ~terminated.bool()
        achieved = tensordict.get(keys.achieved, None)
        timeout = truncated if achieved is None else truncated & ~achieved.bool()
        return ~timeout if real is None else real & ~timeout


@dataclass(frozen=True)
class ValueUpdate:
    """How :class:`~torchrl_subgoal.SubgoalPotentialTransform` trains its potential online: at every env
    step, one SGD step of ``loss`` on the SMDP transitions that step closes, before shaping with the
    updated potential (the paper's algorithm).

    Give the transform ``value_update=ValueUpdate(lr)``, or the learning rate alone
    (``value_update=0.25``). The loss's ``γ_v`` also discounts the SMDP return ``r_h`` the
    transform accumulates.

    Args:
        lr: ``α_v``, the SGD learning rate.
        loss: the :class:`SubgoalValueLoss` to step, built on the transform's potential (configure
            it to change the target). Defaults to ``reduction="sum"`` with ``γ_v`` the transform's
            ``gamma``: with a :class:`~torchrl_subgoal.TabularPotential` one step is then exactly
            ``V(z) ← V(z) + α_v δ``, which the compiled path applies in its kernel.
        prior_weight: ``k`` > 0 hands a :class:`~torchrl_subgoal.TabularPotential`'s initial table (a
            prior) over to the learned values as each entry gathers transitions: its ``n``-th update steps by
            ``max(α_v, 1 / (k + n))``, so that with the mean target the entry is the average of the prior,
            counted ``k`` times, and its targets until ``1 / (k + n)`` falls to ``α_v`` (the potential's
            ``updates`` buffer keeps ``n``). 0 (the default): every step is ``α_v``. An investigated
            candidate, not a default (docs/shaping_defaults.md).

    Examples:
        >>> from torchrl_subgoal import TabularPotential
        >>> v = TabularPotential(3)
        >>> update = ValueUpdate(0.25, SubgoalValueLoss(v).make_value_estimator(gamma=0.95))
        >>> update.lr, update.loss.gamma
        (0.25, 0.95)
    """

    lr: float
    loss: SubgoalValueLoss | None = None
    prior_weight: float = 0.0

    def __post_init__(self) -> None:
        if not self.lr > 0:
            raise ValueError(f"ValueUpdate: lr must be positive, got {self.lr}")
        if not (math.isfinite(self.prior_weight) and self.prior_weight >= 0):
            raise ValueError(f"ValueUpdate: prior_weight must be >= 0 (transitions), got {self.prior_weight}")
        if self.loss is not None and not isinstance(self.loss, SubgoalValueLoss):
            raise TypeError(f"ValueUpdate: loss must be a SubgoalValueLoss, got {type(self.loss).__name__}")

    def step(self, transitions: TensorDictBase) -> None:
        """One SGD step of :attr:`loss` on ``transitions`` (SMDP layout, masked): ``θ ← θ − α_v ∇ℓ``
        for every trainable parameter of its potential, the gradients cleared after. With a
        :class:`~torchrl_subgoal.TabularPotential` and the default loss this is the TD update
        ``V(z) ← V(z) + α_v w δ`` the compiled kernels apply (``w``: the expectile's weight).

        Examples:
            >>> from torchrl_subgoal import TabularPotential
            >>> v = TabularPotential(2)
            >>> update = ValueUpdate(0.5, SubgoalValueLoss(v, reduction="sum").make_value_estimator(gamma=0.9))
            >>> update.step(TensorDict({"subgoal_index": torch.zeros(1, 1, dtype=torch.long),
            ...     "steps_to_next_obs": torch.ones(1, 1, dtype=torch.long), "mask": torch.ones(1, 1, dtype=torch.bool),
            ...     ("next", "subgoal_index"): torch.ones(1, 1, dtype=torch.long), ("next", "reward"): torch.ones(1, 1),
            ...     ("next", "done"): torch.ones(1, 1, dtype=torch.bool),
            ...     ("next", "terminated"): torch.ones(1, 1, dtype=torch.bool)}, [1]))
            >>> v.table.tolist()  # V(0) += 0.5 · 2τ (1 + 0 − 0), τ = 0.9
            [0.8999999761581421, 0.0]
        """
        if self.loss is None:
            raise ValueError("ValueUpdate.step needs a loss (the transform gives the default one)")
        parameters = [p for p in self.loss.potential.parameters() if p.requires_grad]
        if not parameters:
            return
        steps = self._counted_steps(transitions) if self.prior_weight > 0 else None
        with torch.enable_grad():
            for parameter in parameters:
                parameter.grad = None
            self.loss(transitions)["loss_value"].backward()
        with torch.no_grad():  # plain SGD: torch.optim.SGD's step without momentum, decay or state
            for parameter in parameters:
                if parameter.grad is not None:
                    if steps is not None and parameter is steps[0]:
                        parameter.sub_(parameter.grad * steps[1])
                    else:
                        parameter.add_(parameter.grad, alpha=-self.lr)
                parameter.grad = None

    def _counted_steps(self, transitions: TensorDictBase) -> tuple[torch.Tensor, torch.Tensor]:
        """With a ``prior_weight``: count this step's updates of each table entry (the gradient of the values of
        the rows that train), then each entry's step size ``max(α_v, 1 / (k + n))``."""
        assert self.loss is not None
        potential = self.loss.potential
        if not isinstance(potential, TabularPotential):
            kind = type(potential).__name__
            raise TypeError(f"ValueUpdate's prior_weight counts a TabularPotential's updates, not {kind}'s")
        rows = self.loss.trains(transitions)
        with torch.enable_grad():
            value = self.loss._value(transitions)
            hits = torch.where(rows, value, torch.zeros_like(value)).sum()
            (counts,) = torch.autograd.grad(hits, potential.table, allow_unused=True)
        with torch.no_grad():
            if counts is not None:
                potential.updates += counts.round()
            step = (1.0 / (self.prior_weight + potential.updates)).clamp(min=self.lr)
        return potential.table, step

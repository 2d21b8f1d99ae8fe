"""Training the shaping potential from collected data, and re-shaping replay samples with it.

* :class:`PotentialTrainer`: one optimiser step of :class:`~torchrl_subgoal.SubgoalValueLoss`
  on each collected batch's real SMDP transitions (when the transform does not train the
  potential online, the default);
* :class:`SampleReshaper`: an off-policy learner's replay samples re-shaped with ``Φ`` as it is now.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import torch
from tensordict import TensorDictBase
from tensordict.utils import NestedKey

from torchrl_subgoal.loss import SubgoalValueLoss
from torchrl_subgoal.training.envs import Shaping
from torchrl_subgoal.training.smdp import smdp_transitions
from torchrl_subgoal.transform import SubgoalPotentialTransform

__all__ = ["PotentialTrainer", "SampleReshaper"]


@dataclass
class PotentialTrainer:
    """Trains the shaping potential from collected batches: one optimiser step of
    :class:`~torchrl_subgoal.SubgoalValueLoss` on each batch's real SMDP transitions.

    Args:
        keeper: a shaping transform over the potential; it reads the transitions out of collected
            data (:meth:`~torchrl_subgoal.SubgoalPotentialTransform.transitions`).
        loss: the potential's loss.
        optimizer: the potential's own optimiser.

    Examples:
        >>> from torchrl_subgoal import Cell, SubgoalSeries, TabularPotential
        >>> from torchrl_subgoal.envs import FourRoomsEnv
        >>> from torchrl_subgoal.training import shaped_env
        >>> shaping = Shaping(SubgoalSeries([Cell(1, 2)]), TabularPotential(2), {"observation_key": "cell"})
        >>> trainer = PotentialTrainer.for_shaping(shaping, gamma=0.9, lr=0.5, optimizer="sgd")
        >>> data = shaped_env(FourRoomsEnv, 4, shaping=shaping, gamma=0.9).rollout(20, break_when_any_done=False)
        >>> import math
        >>> math.isnan(trainer.step(data))  # a transition closed: one step, its loss
        False
    """

    keeper: SubgoalPotentialTransform
    loss: SubgoalValueLoss
    optimizer: torch.optim.Optimizer

    @classmethod
    def for_shaping(
        cls, shaping: Shaping, gamma: float, lr: float, optimizer: Literal["adam", "sgd"] = "adam"
    ) -> PotentialTrainer:
        """Adam (the loss's mean reduction) or SGD (sum: the tabular update) on ``shaping.potential``, with the
        loss's settings ``shaping.loss``."""
        sgd = optimizer == "sgd"
        opt_class = torch.optim.SGD if sgd else torch.optim.Adam
        options = {"reduction": "sum" if sgd else "mean", **shaping.loss}
        loss = SubgoalValueLoss(shaping.potential, **options).make_value_estimator(gamma=gamma)
        return cls(
            shaping.transform(shaping.potential, gamma, None), loss, opt_class(shaping.potential.parameters(), lr=lr)
        )

    def step(self, data: TensorDictBase) -> float:
        """One step on the real SMDP transitions closed in ``data``; the loss, NaN when none closed."""
        real = smdp_transitions(data, self.keeper)
        if not len(real):  # (not real.numel(): a TensorDict of batch size [0] counts 1)
            return math.nan
        self.optimizer.zero_grad(set_to_none=True)
        out = self.loss(real)["loss_value"]
        out.backward()
        self.optimizer.step()
        return float(out.detach())


class SampleReshaper:
    """Re-shape off-policy samples with the potential as it is now.

    A replay buffer keeps the reward shaped at collection, ``r + γΦ_t(z') − Φ_t(z)``
    with ``Φ_t`` the potential of then. Called on a sample ``[B]`` (rows in any
    order, from any env of the batch), this recomputes the shaped reward with
    ``Φ`` as it is now, through the shaping transform's
    :meth:`~torchrl_subgoal.SubgoalPotentialTransform.forward` on the rows as
    ``[B, 1]`` trajectories: each row starts from the abstract-state entries
    stored at its root (``"subgoal_index"``, ``"subgoal_return"``,
    ``"subgoal_steps"``, …) and advances with its ``"next"`` observation, so
    ``z'`` is the one of collection and only ``Φ`` changes. The unshaped reward
    is read from ``("next", "env_reward")``. The potential is not trained.

    Args:
        transform: a shaping transform over the potential, with the collecting transform's
            options (:meth:`Shaping.transform`); one that has not stepped an env.
        extra_keys: more entries to keep (what condition predicates read besides the observation).

    Examples:
        >>> from torchrl.data import LazyTensorStorage, ReplayBuffer
        >>> from torchrl_subgoal import Cell, SubgoalSeries, TabularPotential
        >>> from torchrl_subgoal.envs import FourRoomsEnv
        >>> from torchrl_subgoal.training import shaped_env
        >>> shaping = Shaping(SubgoalSeries([Cell(1, 3)]), TabularPotential(2), {"observation_key": "cell"})
        >>> data = shaped_env(FourRoomsEnv, 4, shaping=shaping, gamma=0.9).rollout(50, break_when_any_done=False)
        >>> reshaper = SampleReshaper(shaping.transform(shaping.potential, 0.9, None))
        >>> buffer = ReplayBuffer(storage=LazyTensorStorage(200), batch_size=64)
        >>> _ = buffer.extend(data.select(*reshaper.keys).reshape(-1))
        >>> sample = buffer.sample()
        >>> with torch.no_grad():
        ...     _ = shaping.potential.table.copy_(torch.tensor([0.0, 5.0]))
        >>> new = reshaper(sample.clone())
        >>> z, z_next = sample["subgoal_index"], new["next", "subgoal_index"]
        >>> bool(torch.allclose(new["next", "reward"], sample["next", "env_reward"] + 0.9 * 5.0 * z_next - 5.0 * z))
        True
    """

    def __init__(self, transform: SubgoalPotentialTransform, extra_keys: Sequence[NestedKey] = ()) -> None:
        self.transform = transform
        self.extra_keys = tuple(extra_keys)

    @property
    def keys(self) -> list[NestedKey]:
        """The entries a replay buffer must keep for this (besides the learner's own): the abstract-state
        entries, the observation the predicates read (``observation_key``) now and next, the unshaped
        reward, the transform's other :attr:`~torchrl_subgoal.SubgoalPotentialTransform.in_keys` under
        ``"next"`` (done and terminated), and ``extra_keys`` (the ``"next"`` entries condition predicates
        read, e.g. ``("next", "has_key")``)."""
        t = self.transform
        _reward, *read = t.in_keys  # the reward shaped is recomputed from the unshaped one
        keys: list[NestedKey] = [
            *t.state_keys,
            t.observation_key,
            ("next", t.observation_key),
            ("next", t.env_reward_key),
            *(("next", k) for k in read),
        ]
        return list(dict.fromkeys([*keys, *self.extra_keys]))

    def __call__(self, sample: TensorDictBase) -> TensorDictBase:
        """``sample`` (any batch shape: ``[B]``, a learner batch's ``[K, B]``) with ``("next", reward)`` and
        the next abstract-state entries recomputed."""
        with torch.no_grad():
            return self.transform(sample.unsqueeze(-1)).squeeze(-1)

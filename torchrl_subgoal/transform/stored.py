"""Stored data: which learner each row of a replay sample belongs to, when that matters."""

from __future__ import annotations

import torch
from tensordict import TensorDictBase
from tensordict.nn import TensorDictModuleBase

from torchrl_subgoal.potentials import TabularPotential
from torchrl_subgoal.transform.setup import Subgoals

__all__ = ["learners_of", "time_dim"]


def time_dim(data: TensorDictBase) -> int:
    """The time dimension of stored trajectories: the one named ``"time"``, else the last.

    Raises:
        ValueError: the data has no batch dimension.
    """
    if data.batch_dims == 0:
        raise ValueError("forward() shapes stored trajectories [*B, T]; got a TensorDict without batch dims")
    names = data.names
    return names.index("time") if "time" in names else data.batch_dims - 1


def learners_of(
    stored: torch.Tensor | None,
    batch_shape: torch.Size,
    time: int,
    subgoals: Subgoals,
    potential: TensorDictModuleBase,
    env_learners: int | None,
    learner_key: str,
) -> tuple[torch.Tensor, int]:
    """Each row's learner (``[*B, 1]``) and the number of learners, for stored rows of ``batch_shape``.

    A row's learner matters when learners differ: their own table (a :class:`TabularPotential` with a
    batch shape) or their own pattern. Then it is the row's ``stored`` learner entry, or the row's
    position when the rows are the env batch in order; else every row is learner 0, whatever the order
    (a shuffled replay sample with one shared table and one series is shaped as it is).

    Raises:
        ValueError: learners differ and the rows' learners are unknown; the message says what to keep.
    """
    per_learner = (isinstance(potential, TabularPotential) and bool(potential.batch_shape)) or subgoals.per_env
    if not per_learner:
        return torch.zeros((*batch_shape, 1), dtype=torch.long), 1
    n_learners = (
        env_learners if env_learners is not None
        else potential.learners if isinstance(potential, TabularPotential) and potential.batch_shape
        else subgoals.envs or 1
    )
    if stored is not None:
        learner = stored.long().select(time, 0)
        if not (stored.long() == learner.unsqueeze(time)).all():
            raise ValueError(f"rows of the data mix learners along time ({learner_key!r} changes)")
        if learner.shape != (*batch_shape, 1):
            raise ValueError(f"{learner_key!r} has shape {tuple(stored.shape)}; expected one entry per step")
        if learner.numel() and (int(learner.min()) < 0 or int(learner.max()) >= n_learners):
            raise ValueError(f"{learner_key!r} values must lie in [0, {n_learners})")
        return learner, n_learners
    if batch_shape.numel() == n_learners:
        return torch.arange(n_learners).reshape(*batch_shape, 1), n_learners
    raise ValueError(
        f"data of batch shape {tuple(batch_shape)} (time excluded) from {n_learners} learners with their own patterns "
        f"or tables: each row's learner is unknown. Keep the {learner_key!r} entry in the stored data (the transform "
        "writes it when the potential reads it), or pass rows in env order"
    )

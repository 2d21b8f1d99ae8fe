"""The real SMDP transitions of collected data, for training a potential from a replay buffer."""

from __future__ import annotations

from tensordict import TensorDictBase
from tensordict.utils import NestedKey
from torchrl.data import ReplayBuffer

from torchrl_subgoal.transform import SubgoalPotentialTransform

__all__ = ["extend_transitions", "smdp_transitions"]


def smdp_transitions(
    data: TensorDictBase,
    transform: SubgoalPotentialTransform | None = None,
    *,
    key: NestedKey = ("next", "smdp"),
) -> TensorDictBase:
    """The real SMDP transitions of collected ``data`` (``[*B, T]`` or any shape), as ``[N]``.

    Only steps that achieve a subgoal or end an episode close a transition:
    typically a few percent. With ``transform``, they are rebuilt from the
    entries it keeps (:meth:`SubgoalPotentialTransform.transitions`, nothing
    extra stored per step); without, they are read from the entries a
    transform with ``SubgoalKeys(transitions=...)`` wrote under ``key`` and the
    padding rows (``mask`` false) are dropped. With a per-env potential the
    rows keep their ``"subgoal_learner"`` entry: they find their table by key,
    whatever order a replay buffer gives them back in.

    Args:
        data: collected data.
        transform: the shaping transform that produced it.
        key: where written transitions are (without ``transform``).

    Examples:
        >>> import torch
        >>> from torchrl.envs import TransformedEnv
        >>> from torchrl_subgoal import SubgoalKeys, SubgoalPotentialTransform, SubgoalSeries, TabularPotential
        >>> from torchrl_subgoal.envs import FourRoomsEnv
        >>> from torchrl_subgoal.subgoals import Cell
        >>> t = SubgoalPotentialTransform(SubgoalSeries([Cell(1, 2)]), TabularPotential(2), gamma=0.9,
        ...                               observation_key="cell", keys=SubgoalKeys(transitions="smdp"))
        >>> data = TransformedEnv(FourRoomsEnv(4, max_steps=10), t).rollout(30, break_when_any_done=False)
        >>> real = smdp_transitions(data)
        >>> bool(real["mask"].all()), real.batch_dims, len(real) == int(data["next", "smdp", "mask"].sum())
        (True, 1, True)
        >>> rebuilt = smdp_transitions(data, t)
        >>> torch.allclose(rebuilt["next", "reward"], real["next", "reward"])
        True
    """
    if transform is not None:
        return transform.transitions(data)
    if key not in data.keys(True):
        raise KeyError(
            f"no SMDP transitions under {key!r}: pass the transform (smdp_transitions(data, transform)) to "
            f"rebuild them from its entries, or create it with keys=SubgoalKeys(transitions={key[-1]!r})"
        )
    flat = data.get(key).reshape(-1)
    return flat[flat.get("mask").reshape(-1)]


def extend_transitions(
    buffer: ReplayBuffer,
    data: TensorDictBase,
    transform: SubgoalPotentialTransform | None = None,
    *,
    key: NestedKey = ("next", "smdp"),
) -> int:
    """Write the real SMDP transitions of ``data`` (see :func:`smdp_transitions`) into ``buffer``;
    returns how many.

    Examples:
        >>> import torch
        >>> from torchrl.data import LazyTensorStorage, ReplayBuffer
        >>> from tensordict import TensorDict
        >>> buffer = ReplayBuffer(storage=LazyTensorStorage(100))
        >>> data = TensorDict({("next", "smdp", "mask"): torch.tensor([[[True], [False]]]),
        ...                    ("next", "smdp", "subgoal_index"): torch.zeros(1, 2, 1, dtype=torch.long)}, [1, 2])
        >>> extend_transitions(buffer, data), len(buffer)
        (1, 1)
        >>> none = data.clone().fill_(("next", "smdp", "mask"), False)  # a batch that closed no transition
        >>> extend_transitions(buffer, none), len(buffer)
        (0, 1)
    """
    real = smdp_transitions(data, transform, key=key)
    count = real.batch_size[0]  # (not real.numel(): a TensorDict of batch size [0] counts 1)
    if count:
        buffer.extend(real)
    return count

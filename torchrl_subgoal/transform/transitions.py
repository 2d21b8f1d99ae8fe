"""SMDP transitions: the layout TorchRL's value estimators (and :class:`~torchrl_subgoal.SubgoalValueLoss`)
read, and their rebuilding from the entries the transform keeps in collected data."""

from __future__ import annotations

import torch
from tensordict import TensorDict, TensorDictBase
from tensordict.utils import NestedKey

from torchrl_subgoal.transform.keys import EnvKeys, SubgoalKeys, at
from torchrl_subgoal.transform.shaping import accumulate, closes

__all__ = ["empty_transition", "rebuild", "transition"]


def transition(
    batch_shape: torch.Size,
    inputs: dict[str, torch.Tensor],
    next_inputs: dict[str, torch.Tensor],
    r_h: torch.Tensor,
    k: torch.Tensor,
    mask: torch.Tensor,
    done: torch.Tensor,
    terminated: torch.Tensor,
    achieved: torch.Tensor,
) -> TensorDict:
    """An SMDP transition ``(z, r_h, k, z', done, terminated)`` in the layout of TorchRL's value estimators:
    the potential's ``inputs`` at ``z`` (root) and at ``z'`` (``"next"``), ``r_h`` as the next reward and
    ``k`` as ``"steps_to_next_obs"``; ``mask`` tells the real ones, ``achieved`` those that reached the
    next subgoal (``z' ≠ z``; the others closed with the episode).

    Examples:
        >>> one = torch.ones(1, 1)
        >>> t = transition(torch.Size([1]), {"subgoal_index": one.long() * 0}, {"subgoal_index": one.long()},
        ...                one, one.long(), one.bool(), one.bool(), one.bool(), one.bool())
        >>> t["next", "subgoal_index"].item(), t["steps_to_next_obs"].item()
        (1, 1)
    """
    nxt = TensorDict({**next_inputs, "reward": r_h, "done": done, "terminated": terminated}, batch_size=batch_shape)
    return TensorDict(
        {**inputs, "steps_to_next_obs": k, "mask": mask, "achieved": achieved, "next": nxt}, batch_size=batch_shape
    )


def empty_transition(
    batch_shape: torch.Size, state: dict[str, torch.Tensor], inputs: tuple[NestedKey, ...], keys: SubgoalKeys
) -> TensorDict:
    """The transition entry at a reset: no transition (``mask`` false), the potential's ``inputs`` at the reset
    ``state`` on both sides.

    Examples:
        >>> state = {"subgoal_index": torch.zeros(2, 1, dtype=torch.long), "subgoal_return": torch.zeros(2, 1),
        ...          "subgoal_steps": torch.zeros(2, 1, dtype=torch.long)}
        >>> empty_transition(torch.Size([2]), state, ("subgoal_index",), SubgoalKeys())["mask"].any().item()
        False
    """
    at_reset = {k: state[k] for k in inputs}
    false = torch.zeros_like(state[keys.index], dtype=torch.bool)
    return transition(
        batch_shape,
        at_reset,
        at_reset,
        torch.zeros_like(state[keys.ret]),
        state[keys.steps],
        false,
        false,
        false,
        false,
    )


def rebuild(
    data: TensorDictBase, keys: SubgoalKeys, env: EnvKeys, in_keys: list[NestedKey], value_gamma: float
) -> TensorDictBase:
    """The real SMDP transitions closed in collected ``data`` (any batch shape), as ``[N]``.

    A step closes a transition when ``z`` changed or the episode ended; its ``r_h`` and ``k`` are the
    root's kept ``r_h`` and ``k`` plus this step's env reward
    (:func:`~torchrl_subgoal.transform.shaping.accumulate`).

    Examples:
        >>> from tensordict import TensorDict
        >>> from torchrl_subgoal.transform.keys import EnvKeys
        >>> zero, one = torch.zeros(1, 2, 1, dtype=torch.long), torch.ones(1, 2, 1, dtype=torch.long)
        >>> data = TensorDict({"subgoal_index": zero, "subgoal_return": torch.zeros(1, 2, 1), "subgoal_steps": zero,
        ...                    "next": {"subgoal_index": torch.tensor([[[0], [1]]]), "reward": torch.ones(1, 2, 1),
        ...                             "done": zero.bool(), "terminated": zero.bool()}}, [1, 2])
        >>> real = rebuild(data, SubgoalKeys(), EnvKeys.resolve(None), ["subgoal_index"], 0.9)
        >>> real["next", "subgoal_index"].tolist()
        [[1]]
    """
    index, ret, steps = (at(env.group, name) for name in (keys.index, keys.ret, keys.steps))
    nxt = data.get("next", None)
    missing: list[NestedKey] = [k for k in (index, ret, steps) if data.get(k, None) is None]
    missing += [("next", k) for k in (index, env.done) if nxt is None or nxt.get(k, None) is None]
    if missing:
        raise KeyError(
            f"SubgoalPotentialTransform.transitions: the data has no {missing}; pass data collected "
            "through the transform (or shaped by it)"
        )
    group = data.get(env.group) if env.group else data
    n, dims = group.batch_size.numel(), group.batch_dims
    nxt_group = nxt.get(env.group) if env.group else nxt

    def flat(td: TensorDictBase, key: NestedKey) -> torch.Tensor | None:
        value = td.get(key, None)  # entry by entry: cheaper than reshaping and indexing the TensorDict
        return None if value is None else value.reshape(n, *value.shape[dims:])

    z, z_next = flat(group, keys.index), flat(nxt_group, keys.index)
    done, terminated = flat(nxt, env.done), flat(nxt, env.terminated)
    assert z is not None and z_next is not None and done is not None
    achieved = z_next != z
    rows = closes(z, z_next, done).reshape(-1).nonzero().squeeze(1)  # found once, gathered per entry
    reward = flat(nxt, env.env_reward)
    reward = flat(nxt, env.reward) if reward is None else reward
    k, r_h = flat(group, keys.steps), flat(group, keys.ret)
    assert reward is not None and k is not None and r_h is not None
    r_h, k = accumulate(r_h.index_select(0, rows), k.index_select(0, rows), reward.index_select(0, rows), value_gamma)
    inputs = {key: v.index_select(0, rows) for key in in_keys if (v := flat(group, key)) is not None}
    next_inputs = {key: v.index_select(0, rows) for key in in_keys if (v := flat(nxt_group, key)) is not None}
    done = done.index_select(0, rows)
    return transition(
        torch.Size([done.shape[0]]),
        inputs,
        next_inputs,
        r_h.to(torch.float32),
        k,
        torch.ones_like(done),
        done,
        done if terminated is None else terminated.index_select(0, rows),
        achieved.index_select(0, rows),
    )

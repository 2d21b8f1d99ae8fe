"""Stored data: shaping trajectories along their time dimension, and which learner each row of a replay
sample belongs to, when that matters."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import torch
from tensordict import TensorDict, TensorDictBase
from tensordict.nn import TensorDictModuleBase
from tensordict.utils import NestedKey

from torchrl_subgoal.potentials import TabularPotential
from torchrl_subgoal.transform.keys import ENV_REWARD, EnvKeys, StepInputs, at, read
from torchrl_subgoal.transform.setup import BatchSetup, Settings, Subgoals, initial_state

__all__ = ["learners_of", "shape_stored", "time_dim"]


def time_dim(data: TensorDictBase) -> int:
    """The time dimension of stored trajectories: the one named ``"time"``, else the last.

    Raises:
        ValueError: the data has no batch dimension.

    Examples:
        >>> from tensordict import TensorDict
        >>> time_dim(TensorDict({}, [4, 10])), time_dim(TensorDict({}, [10, 4], names=["time", None]))
        (1, 0)
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

    Examples:
        >>> from torchrl_subgoal import State, SubgoalSeries, TabularPotential
        >>> subgoals = Subgoals(SubgoalSeries([State(1)]))
        >>> one_table = learners_of(None, torch.Size([5]), 1, subgoals, TabularPotential(2), 8, "subgoal_learner")
        >>> one_table[0].reshape(-1).tolist(), one_table[1]  # no row's learner matters: all are learner 0
        ([0, 0, 0, 0, 0], 1)
    """
    per_learner = (isinstance(potential, TabularPotential) and bool(potential.batch_shape)) or subgoals.per_env
    if not per_learner:
        return torch.zeros((*batch_shape, 1), dtype=torch.long), 1
    n_learners = (
        env_learners
        if env_learners is not None
        else potential.learners
        if isinstance(potential, TabularPotential) and potential.batch_shape
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


def shape_stored(
    data: TensorDictBase,
    env: EnvKeys,
    settings: Settings,
    in_keys: list[NestedKey],
    transitions_key: NestedKey | None,
    set_up: Callable[[torch.Size, torch.Tensor | None, int, torch.Tensor | None], BatchSetup],
    advance: Callable[[BatchSetup, dict[str, torch.Tensor], StepInputs], dict[str, Any]],
) -> TensorDictBase:
    """Shape stored trajectories ``data`` ``[*B, T]`` (``SubgoalPotentialTransform.forward``):
    ``set_up(batch_shape, stored learner entry, time dim, first observation)`` sets the rows up,
    ``advance`` makes one step without training.

    The data holds the root observation and the step's ``in_keys`` under ``"next"``. The abstract state
    starts from the stored entries of the first step when the data has them (a slice from the middle of an
    episode), else from the first observation as at a reset, and restarts after every ``done``. The reward
    shaped is the env reward (``"env_reward"`` when stored).

    Examples:
        >>> from torchrl.envs import TransformedEnv
        >>> from torchrl_subgoal import Cell, SubgoalPotentialTransform, SubgoalSeries, TabularPotential
        >>> from torchrl_subgoal.envs import FourRoomsEnv
        >>> series = SubgoalSeries([Cell(1, 2)])
        >>> t = SubgoalPotentialTransform(series, TabularPotential(2), gamma=0.9, observation_key="cell")
        >>> data = TransformedEnv(FourRoomsEnv(2), t).rollout(6)
        >>> bool((t(data.clone())["next", "reward"] == data["next", "reward"]).all())  # forward() calls it
        True
    """
    time = time_dim(data)
    if data.batch_size.numel() == 0:  # an empty sample ([0], [B, 0]): no step to shape
        return data
    nxt = data.get("next", None)
    stored_reward = nxt is not None and read(nxt, env.env_reward) is not None  # then the one shaped
    missing = [
        ("next", key)
        for key in in_keys
        if key != env.env_reward
        and not (key == env.reward and stored_reward)
        and (nxt is None or read(nxt, key) is None)
    ]
    if missing:
        raise KeyError(
            f"SubgoalPotentialTransform: the stored data has no {missing}; store the steps' entries the "
            "transform reads (in_keys)"
        )
    steps = data.unbind(time)
    group: Callable[[TensorDictBase], TensorDictBase] = lambda td: td.get(env.group) if env.group else td  # noqa: E731
    first, keys, kept = group(steps[0]), settings.keys, settings.kept
    setup = set_up(
        first.batch_size, group(data).get(keys.learner, None), time, read(steps[0], settings.observation_key)
    )
    if all(first.get(name, None) is not None for name in kept):  # a slice from the middle of an episode
        current = {name: first.get(name) for name in kept}
        if keys.learner in current:
            current[keys.learner] = setup.learner
    else:
        current = initial_state(setup, settings, read(steps[0], settings.observation_key))
    outs = []
    for t, step in enumerate(steps):
        step_next = step.get("next")
        reward = read(step_next, env.env_reward)
        reward = read(step_next, env.reward) if reward is None else reward
        done, terminated = read(step_next, env.done), read(step_next, env.terminated)
        obs = read(step_next, settings.observation_key) if settings.reads_observation else None
        before = read(step, settings.observation_key) if settings.interpolate else None
        terminated = done if terminated is None else terminated
        out = advance(setup, current, StepInputs(obs, reward, reward, done, terminated, step_next, before))
        outs.append({**out, ENV_REWARD: reward})
        if t + 1 < len(steps):
            restart = initial_state(setup, settings, read(steps[t + 1], settings.observation_key))
            ended = done.reshape(*setup.batch_shape, 1)
            current = {name: torch.where(ended, restart[name], out[name]) for name in current}
    written: dict[str, NestedKey] = {name: at(env.group, name) for name in kept}
    written |= {"reward": env.reward, ENV_REWARD: env.env_reward}
    written |= {"transition": transitions_key} if transitions_key is not None else {}
    for name, key in written.items():
        values = [out[name] for out in outs]
        value = torch.stack(values, time) if isinstance(values[0], torch.Tensor) else TensorDict.stack(values, time)
        data.set(("next", *key) if isinstance(key, tuple) else ("next", key), value)
    return data

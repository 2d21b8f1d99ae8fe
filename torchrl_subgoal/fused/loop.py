"""The online learning loop shared by the recipes: step a batched env, learn every step, record episodes."""

from __future__ import annotations

from collections.abc import Callable
from typing import Literal, Protocol

import numpy as np
import torch
from tensordict import TensorDictBase
from tensordict.utils import NestedKey
from torchrl.envs import EnvBase

from torchrl_subgoal.fused._kernels.records import record_episodes
from torchrl_subgoal.fused.records import EpisodeRecords

__all__ = ["EpisodeRecords", "OnlineAgent", "run_episodes"]


class OnlineAgent(Protocol):
    """What :func:`run_episodes` needs from a learner batched like the env.

    Examples:
        >>> from torchrl_subgoal.fused import SARSA_PRESETS, SoftmaxSarsa
        >>> from torchrl_subgoal.envs import FourRoomsEnv
        >>> env = FourRoomsEnv(num_envs=4)
        >>> agent = SoftmaxSarsa(4, env.num_states, 4, SARSA_PRESETS["released"], seed=0)
        >>> callable(agent.act) and callable(agent.step)  # a structural type: SoftmaxSarsa is one
        True
    """

    def act(self, tensordict: TensorDictBase) -> TensorDictBase:
        """Write ``"action"`` for every env of ``tensordict`` (the first step)."""
        ...

    def step(self, transition: TensorDictBase, next_root: TensorDictBase) -> None:
        """Learn from ``transition`` (``s, a`` and ``("next", …)``) and write ``next_root["action"]``.

        ``next_root`` is the next step's input: ``s'`` where the episode goes
        on, the reset observation where it ended.
        """
        ...


def run_episodes(
    env: EnvBase,
    agent: OnlineAgent,
    episodes: int,
    *,
    return_key: NestedKey | None = None,
    progress: Callable[[int], None] | None = None,
    engine: Literal["torchrl", "fused"] = "torchrl",
) -> EpisodeRecords:
    """Run every learner of a batched env for ``episodes`` episodes, learning online.

    Uses :meth:`~torchrl.envs.EnvBase.step_and_maybe_reset`, so partial resets
    go through the env's transforms. Learners that finish early keep stepping
    (their data is no longer recorded) until the slowest one is done.

    Args:
        env: a batched env (any batch shape; learners are its flattened batch).
        agent: the learner (see :class:`OnlineAgent`).
        episodes: episodes to record per learner.
        return_key: reward summed into the episode return; defaults to
            ``"env_reward"`` (the unshaped reward kept by
            :class:`~torchrl_subgoal.SubgoalPotentialTransform`) when the env
            has it, else ``"reward"``.
        progress: called with the number of learner-episodes just finished.
        engine: ``"torchrl"`` steps the env with ``step_and_maybe_reset``;
            ``"fused"`` runs the same objects in one compiled loop with
            identical records, much faster (FourRoomsEnv with SoftmaxSarsa,
            PinBallEnv with FourierActorCritic, or an env and a learner whose
            records implement its steps; see :mod:`torchrl_subgoal.fused.engine`).

    Returns:
        steps, (unshaped) return and success (terminated) of every episode.

    Examples:
        >>> from torchrl_subgoal.fused import SARSA_PRESETS, SoftmaxSarsa
        >>> from torchrl_subgoal.envs import FourRoomsEnv
        >>> env = FourRoomsEnv(num_envs=4)
        >>> agent = SoftmaxSarsa(4, env.num_states, 4, SARSA_PRESETS["released"], seed=0)
        >>> records = run_episodes(env, agent, episodes=3, engine="fused")  # same episodes, compiled
        >>> records.steps.shape
        torch.Size([4, 3])
    """
    if engine == "fused":
        from torchrl_subgoal.fused.engine import run_episodes_fused

        if return_key is not None:
            raise ValueError("the fused engine records the unshaped reward; return_key is not supported")
        return run_episodes_fused(env, agent, episodes, progress=progress)  # type: ignore[arg-type]
    if engine != "torchrl":
        raise ValueError(f"engine must be 'torchrl' or 'fused', got {engine!r}")
    if return_key is None:
        return_key = "env_reward" if "env_reward" in env.reward_keys else "reward"
    n = max(1, env.batch_size.numel())
    steps = torch.zeros(n, episodes, dtype=torch.long)
    returns = torch.zeros(n, episodes)
    success = torch.zeros(n, episodes, dtype=torch.bool)
    t = np.zeros(n, dtype=np.int64)
    ret = np.zeros(n)
    done_episodes = np.zeros(n, dtype=np.int64)
    outputs = (steps.numpy(), returns.numpy(), success.numpy())
    env_steps = 0
    td = agent.act(env.reset())
    while True:
        td, root = env.step_and_maybe_reset(td)
        agent.step(td, root)
        nxt = td.get("next")
        env_steps += 1
        filed = record_episodes(
            _flat(nxt.get("done")),
            _flat(nxt.get("terminated")),
            _flat(nxt.get(return_key)),
            t,
            ret,
            done_episodes,
            *outputs,
        )
        if filed:
            if progress is not None:
                progress(filed)
            if done_episodes.min() >= episodes:
                break
        td = root
    return EpisodeRecords(steps, returns, success, env_steps)


def _flat(t: torch.Tensor) -> np.ndarray:
    return t.numpy().reshape(-1)

"""The online learning loop shared by the recipes: step a batched env, learn every step, record episodes."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

import torch
from tensordict import TensorDictBase
from tensordict.utils import NestedKey
from torchrl.envs import EnvBase

__all__ = ["EpisodeRecords", "OnlineAgent", "run_episodes"]


class OnlineAgent(Protocol):
    """What :func:`run_episodes` needs from a learner batched like the env."""

    def act(self, tensordict: TensorDictBase) -> TensorDictBase:
        """Write ``"action"`` for every env of ``tensordict`` (the first step)."""
        ...

    def step(self, transition: TensorDictBase, next_root: TensorDictBase) -> None:
        """Learn from ``transition`` (``s, a`` and ``("next", …)``) and write ``next_root["action"]``.

        ``next_root`` is the next step's input: ``s'`` where the episode goes
        on, the reset observation where it ended.
        """
        ...


@dataclass
class EpisodeRecords:
    """Per-learner, per-episode results: ``[num_learners, num_episodes]`` tensors."""

    steps: torch.Tensor
    returns: torch.Tensor
    success: torch.Tensor
    env_steps: int = 0

    @property
    def num_learners(self) -> int:
        return int(self.steps.shape[0])


def run_episodes(
    env: EnvBase,
    agent: OnlineAgent,
    episodes: int,
    *,
    return_key: NestedKey | None = None,
    progress: Callable[[int], None] | None = None,
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

    Returns:
        steps, (unshaped) return and success (terminated) of every episode.
    """
    if return_key is None:
        return_key = "env_reward" if "env_reward" in list(env.observation_spec.keys()) else "reward"
    n = max(1, env.batch_size.numel())
    steps = torch.zeros(n * episodes, dtype=torch.long)
    returns = torch.zeros(n * episodes)
    success = torch.zeros(n * episodes, dtype=torch.bool)
    t = torch.zeros(n, dtype=torch.long)
    ret = torch.zeros(n)
    done_episodes = torch.zeros(n, dtype=torch.long)
    env_steps = 0
    td = agent.act(env.reset())
    while True:
        td, root = env.step_and_maybe_reset(td)
        agent.step(td, root)
        nxt = td.get("next")
        t += 1
        ret += nxt.get(return_key).reshape(n)
        env_steps += 1
        done = nxt.get("done").reshape(n)
        if done.any():
            rows = done.nonzero().squeeze(-1)
            ep = done_episodes[rows]
            keep = ep < episodes
            rows_kept, ep = rows[keep], ep[keep]
            flat = rows_kept * episodes + ep
            steps[flat] = t[rows_kept]
            returns[flat] = ret[rows_kept]
            success[flat] = nxt.get("terminated").reshape(n)[rows_kept]
            done_episodes[rows] += 1
            t.masked_fill_(done, 0)
            ret.masked_fill_(done, 0.0)
            if progress is not None and len(rows_kept):
                progress(len(rows_kept))
            if bool((done_episodes >= episodes).all()):
                break
        td = root
    shape = (n, episodes)
    return EpisodeRecords(steps.view(shape), returns.view(shape), success.view(shape), env_steps)

"""What a run of learners records: one module that both engines (``loop``, ``fused``) import."""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
import torch

__all__ = ["EpisodeArrays", "EpisodeRecords"]


@dataclass
class EpisodeRecords:
    """Per-learner, per-episode results: ``[num_learners, num_episodes]`` tensors.

    Examples:
        >>> from torchrl_subgoal.fused import SARSA_PRESETS, SoftmaxSarsa, run_episodes
        >>> from torchrl_subgoal.envs import FourRoomsEnv
        >>> env = FourRoomsEnv(num_envs=4)
        >>> agent = SoftmaxSarsa(4, env.num_states, 4, SARSA_PRESETS["released"], seed=0)
        >>> records = run_episodes(env, agent, episodes=2)
        >>> records.steps.shape, records.returns.shape, records.success.dtype
        (torch.Size([4, 2]), torch.Size([4, 2]), torch.bool)
    """

    steps: torch.Tensor
    returns: torch.Tensor
    success: torch.Tensor
    env_steps: int = 0


class EpisodeArrays(NamedTuple):
    """The arrays a compiled loop files episodes into (numpy, updated in place): per-learner
    counters, then ``[num_learners, num_episodes]`` results (views of an :class:`EpisodeRecords`'s).

    Examples:
        >>> arrays = EpisodeArrays.zeros(EpisodeRecords(torch.zeros(2, 3, dtype=torch.long), torch.zeros(2, 3),
        ...                                             torch.zeros(2, 3, dtype=torch.bool)))
        >>> arrays.steps.shape, arrays.episode.tolist()
        ((2, 3), [0, 0])
    """

    t: np.ndarray  #: ``[N]`` steps into the current episode
    ret: np.ndarray  #: ``[N]`` return of the current episode so far
    episode: np.ndarray  #: ``[N]`` episodes filed
    steps: np.ndarray  #: ``[N, E]`` steps of every episode
    returns: np.ndarray  #: ``[N, E]`` returns
    success: np.ndarray  #: ``[N, E]`` whether it terminated

    @classmethod
    def zeros(cls, records: EpisodeRecords) -> EpisodeArrays:
        """Zero counters and views of ``records``' tensors (CPU)."""
        n = records.steps.shape[0]
        return cls(
            np.zeros(n, np.int64),
            np.zeros(n),
            np.zeros(n, np.int64),
            records.steps.numpy(),
            records.returns.numpy(),
            records.success.numpy(),
        )

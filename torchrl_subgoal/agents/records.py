"""What a run of learners records: one module that both engines (``loop``, ``fused``) import."""

from __future__ import annotations

from dataclasses import dataclass

import torch

__all__ = ["EpisodeRecords"]


@dataclass
class EpisodeRecords:
    """Per-learner, per-episode results: ``[num_learners, num_episodes]`` tensors.

    Examples:
        >>> from torchrl_subgoal.agents import SARSA_PRESETS, SoftmaxSarsa, run_episodes
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

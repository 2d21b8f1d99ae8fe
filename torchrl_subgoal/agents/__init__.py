"""Batched learners (one table or parameter set per learner) and the online loop."""

from torchrl_subgoal.agents.loop import EpisodeRecords, OnlineAgent, run_episodes
from torchrl_subgoal.agents.sarsa import SARSA_PRESETS, SarsaConfig, SoftmaxSarsa

__all__ = ["SARSA_PRESETS", "EpisodeRecords", "OnlineAgent", "SarsaConfig", "SoftmaxSarsa", "run_episodes"]

"""Batched learners (one table or parameter set per learner) and the online loop."""

from torchrl_subgoal.agents.actor_critic import AC_PRESETS, ActorCriticConfig, FourierActorCritic
from torchrl_subgoal.agents.loop import EpisodeRecords, OnlineAgent, run_episodes
from torchrl_subgoal.agents.sarsa import SARSA_PRESETS, SarsaConfig, SoftmaxSarsa

__all__ = [
    "AC_PRESETS",
    "SARSA_PRESETS",
    "ActorCriticConfig",
    "EpisodeRecords",
    "FourierActorCritic",
    "OnlineAgent",
    "SarsaConfig",
    "SoftmaxSarsa",
    "run_episodes",
]

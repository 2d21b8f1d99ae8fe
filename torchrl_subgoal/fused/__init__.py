"""The paper reproductions' learners and the two engines that run them online.

* the learners, batched (one table or parameter set per learner): :class:`SoftmaxSarsa`
  (four-rooms, :mod:`~torchrl_subgoal.fused.sarsa`) and :class:`FourierActorCritic` (PinBall,
  :mod:`~torchrl_subgoal.fused.actor_critic`), modules whose buffers compiled kernels update in
  place (:class:`~torchrl_subgoal.fused.module.KernelLearner`);
* :func:`run_episodes` (:mod:`~torchrl_subgoal.fused.loop`): step a batched TorchRL env, learn
  every step, record episodes (:class:`EpisodeRecords`, :mod:`~torchrl_subgoal.fused.records`);
  with ``engine="fused"``, the same env, shaping transform and learner in one compiled loop
  (:mod:`~torchrl_subgoal.fused.engine`);
* :mod:`torchrl_subgoal.fused._kernels`: the numba kernels these call (the learners' steps, the
  engine's loop, filing episodes); the ones they share with the envs and the shaping transform
  are in :mod:`torchrl_subgoal._kernels`.

The TorchRL building blocks (A2C, PPO, DQN, DDPG and TD3, tabular Q-learning) and their modules
(:class:`~torchrl_subgoal.training.ddpg_parts.DDPGAgent`, :class:`~torchrl_subgoal.training.stack.LearnerStack`,
:class:`~torchrl_subgoal.training.subgoal_input.SubgoalInput`) are in :mod:`torchrl_subgoal.training`.
"""

from torchrl_subgoal.fused.actor_critic import AC_PRESETS, ActorCriticConfig, FourierActorCritic
from torchrl_subgoal.fused.loop import EpisodeRecords, OnlineAgent, run_episodes
from torchrl_subgoal.fused.sarsa import SARSA_PRESETS, SarsaConfig, SoftmaxSarsa

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

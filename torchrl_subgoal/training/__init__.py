"""TorchRL-native training with subgoal shaping: one building block per learner, batched by construction.

Every block trains ``len(seeds)`` learners as one program (one learner is a batch of one):
``train_<algo>(make_env, config, *, seeds=[...], shaping=...) -> Trained``.

* the blocks: :mod:`~torchrl_subgoal.training.a2c` (:func:`train_a2c`),
  :mod:`~torchrl_subgoal.training.ppo` (:func:`train_ppo`; what the two share:
  :mod:`~torchrl_subgoal.training.on_policy`),
  :mod:`~torchrl_subgoal.training.dqn` (:func:`train_dqn`),
  :mod:`~torchrl_subgoal.training.ddpg` (:func:`train_ddpg`, DDPG or TD3; its learners are one
  :class:`~torchrl_subgoal.training.ddpg_parts.DDPGAgent`, which the pick-and-place reproduction
  also drives with its own loop) and tabular Q-learning (:mod:`~torchrl_subgoal.training.qlearning`);
* their settings: :mod:`~torchrl_subgoal.training.config` (:class:`LearnerConfig`, the fields
  and the one check every learner shares; each config adds its own);
* what they share: :mod:`~torchrl_subgoal.training.envs` (the shaped env :func:`shaped_env`,
  :class:`Shaping`, one env batch for many learners :func:`learner_envs`),
  :mod:`~torchrl_subgoal.training.networks` (input layers, the learner seeing ``z``:
  :mod:`~torchrl_subgoal.training.subgoal_input`),
  :mod:`~torchrl_subgoal.training.collection` (:func:`make_collector`),
  :mod:`~torchrl_subgoal.training.recording` (:class:`LearningCurve`, :class:`SuccessSignal`),
  :mod:`~torchrl_subgoal.training.potential` (:class:`PotentialTrainer`, :class:`SampleReshaper`),
  :mod:`~torchrl_subgoal.training.batch` (:class:`LearnerBatch`: ``K`` learners' env batch,
  stacked networks, one table per learner), :mod:`~torchrl_subgoal.training.stack` (``K``
  networks and replay buffers as one);
* what they return: :mod:`~torchrl_subgoal.training.result` (:class:`Trained`: curves, modules,
  save and load; :func:`evaluate`);
* :mod:`~torchrl_subgoal.training.smdp`: keep only the real SMDP transitions
  (:func:`smdp_transitions`, :func:`extend_transitions` into a replay buffer);
* :mod:`~torchrl_subgoal.training.shared`: :class:`EnvFactory`, one potential
  for envs in collector worker processes (shared memory);
* :mod:`~torchrl_subgoal.training.learners`: the building blocks by name (:data:`LEARNERS`), reloading
  what one saved (:func:`load_trained`) and the check that an env's actions suit one (:func:`check_actions`);
* :mod:`~torchrl_subgoal.training.domains`: what a domain registers for the learner recipes
  (:class:`LearnerDomain`).

The paper's four-rooms and PinBall learners (tabular SARSA, linear actor-critics) and the engines that
run them online are in :mod:`torchrl_subgoal.fused`.
"""

from __future__ import annotations

from importlib.util import find_spec
from pathlib import Path
from typing import Literal

from torchrl.record.loggers import CSVLogger, Logger

from torchrl_subgoal.training.a2c import A2CConfig, A2CUpdate, train_a2c
from torchrl_subgoal.training.batch import (
    LearnerBatch,
    LearnerReplay,
    LearnerStack,
    batch_shaping,
    clip_grad_norm_per_learner,
    learner_means,
    per_learner,
)
from torchrl_subgoal.training.collection import close_collector, make_collector, seed_collector
from torchrl_subgoal.training.config import ActorCriticConfig, LearnerConfig, NetworkConfig, OffPolicyConfig, Settings
from torchrl_subgoal.training.ddpg import DDPGHooks, DDPGTrainConfig, ddpg_agent, ddpg_modules, train_ddpg
from torchrl_subgoal.training.domains import A2CDomain, LearnerDomain
from torchrl_subgoal.training.dqn import DQN_PRESETS, DQNConfig, DQNUpdate, dqn_modules, train_dqn
from torchrl_subgoal.training.envs import (
    EPISODE_RETURN,
    Shaping,
    batched,
    close_probe,
    learner_envs,
    probe_env,
    shaped_env,
)
from torchrl_subgoal.training.learners import LEARNERS, Learner, action_kind, check_actions, load_trained
from torchrl_subgoal.training.networks import FourierFeatures, q_network, subgoal_states
from torchrl_subgoal.training.on_policy import actor_critic, actor_critic_modules, train_on_policy
from torchrl_subgoal.training.potential import PotentialTrainer, SampleReshaper
from torchrl_subgoal.training.ppo import PPOConfig, PPOUpdate, ppo_actor_critic, train_ppo
from torchrl_subgoal.training.recording import CurveRecorder, EpisodeWindow, LearningCurve, SuccessSignal
from torchrl_subgoal.training.result import Evaluation, Trained, evaluate
from torchrl_subgoal.training.shared import EnvFactory
from torchrl_subgoal.training.smdp import extend_transitions, smdp_transitions

__all__ = [
    "DQN_PRESETS",
    "EPISODE_RETURN",
    "LEARNERS",
    "A2CConfig",
    "A2CDomain",
    "A2CUpdate",
    "ActorCriticConfig",
    "CurveRecorder",
    "DDPGHooks",
    "DDPGTrainConfig",
    "DQNConfig",
    "DQNUpdate",
    "EnvFactory",
    "EpisodeWindow",
    "Evaluation",
    "FourierFeatures",
    "Learner",
    "LearnerBatch",
    "LearnerConfig",
    "LearnerDomain",
    "LearnerReplay",
    "LearnerStack",
    "LearningCurve",
    "NetworkConfig",
    "OffPolicyConfig",
    "PPOConfig",
    "PPOUpdate",
    "PotentialTrainer",
    "SampleReshaper",
    "Settings",
    "Shaping",
    "SuccessSignal",
    "Trained",
    "action_kind",
    "actor_critic",
    "actor_critic_modules",
    "batch_shaping",
    "batched",
    "check_actions",
    "clip_grad_norm_per_learner",
    "close_collector",
    "close_probe",
    "ddpg_agent",
    "ddpg_modules",
    "dqn_modules",
    "evaluate",
    "experiment_logger",
    "extend_transitions",
    "learner_envs",
    "learner_means",
    "load_trained",
    "make_collector",
    "per_learner",
    "ppo_actor_critic",
    "probe_env",
    "q_network",
    "seed_collector",
    "shaped_env",
    "smdp_transitions",
    "subgoal_states",
    "train_a2c",
    "train_ddpg",
    "train_dqn",
    "train_on_policy",
    "train_ppo",
]


def experiment_logger(
    log_dir: str | Path,
    name: str,
    backend: Literal["csv", "tensorboard", "wandb", "none"] = "csv",
    *,
    fresh: bool = False,
) -> Logger | None:
    """A TorchRL logger writing under ``log_dir/name``: CSV (default), TensorBoard, Weights & Biases, or none.

    The learners log ``episode_length``, ``episode_return`` and ``success`` per collected batch, at the
    frames collected so far (the ``logger`` argument of ``train_a2c`` and the others); the recipes'
    ``--logger`` picks the backend, one log per learner under ``RESULTS/logs``.

    Args:
        log_dir: the directory of every learner's log.
        name: this learner's (its subdirectory; the W&B run's name).
        backend: ``"csv"`` (TorchRL's ``CSVLogger``: ``scalars/*.csv``), ``"tensorboard"``
            (``TensorboardLogger``: event files; the ``tensorboard`` extra), ``"wandb"`` (``WandbLogger``, in
            ``log_dir``; the ``wandb`` extra; ``WANDB_MODE=offline`` logs without an account, ``wandb sync``
            uploads later) or ``"none"``.
        fresh: start the learner's log afresh: remove what an earlier attempt of it logged (its
            ``scalars/*.csv``, its TensorBoard event files), so a learner run again from its start
            (a resumed sweep reruns the learners it had not finished) logs one series, not the
            restarted one appended to the interrupted one. Nothing else in the directory is touched.

    Examples:
        >>> import tempfile
        >>> logger = experiment_logger(tempfile.mkdtemp(), "HRS_p1_0")
        >>> type(logger).__name__
        'CSVLogger'
        >>> logger.log_scalar("episode_length", 30.0, step=256)
        >>> again = experiment_logger(logger.log_dir, "HRS_p1_0", fresh=True)  # the learner starts over
        >>> sorted(p.name for p in (Path(logger.log_dir) / "HRS_p1_0" / "scalars").iterdir())
        []
    """
    if fresh:
        own = Path(log_dir) / name
        for stale in [*own.glob("scalars/*.csv"), *own.glob("events.out.tfevents.*")]:
            if stale.is_file() and not stale.is_symlink():
                stale.unlink()
    if backend == "none":
        return None
    if backend == "tensorboard":
        if find_spec("tensorboard") is None:
            raise ValueError("logger 'tensorboard' needs the tensorboard package: pip install tensorboard")
        from torchrl.record.loggers import TensorboardLogger

        return TensorboardLogger(exp_name=name, log_dir=str(log_dir))
    if backend == "wandb":
        if find_spec("wandb") is None:
            raise ValueError("logger 'wandb' needs the wandb package: pip install wandb")
        from torchrl.record.loggers import WandbLogger

        # one run per learner, grouped by the results directory; a learner after another in one process
        # finishes the one before
        group = Path(log_dir).resolve().parent.name
        return WandbLogger(
            exp_name=name, save_dir=str(log_dir), project="torchrl_subgoal", group=group, reinit="finish_previous"
        )
    return CSVLogger(exp_name=name, log_dir=str(log_dir))

"""TorchRL-native training with subgoal shaping: one building block per learner, and what they share.

* :mod:`~torchrl_subgoal.training.common`: the shaped env (:func:`shaped_env`), the
  collector, the potential's training (:class:`PotentialTrainer`), re-shaping replay
  samples (:class:`SampleReshaper`), the learner seeing ``z`` (:func:`subgoal_states`)
  and the records (:class:`LearningCurve`);
* :mod:`~torchrl_subgoal.training.a2c` (:func:`train_a2c`),
  :mod:`~torchrl_subgoal.training.ppo` (:func:`train_ppo`),
  :mod:`~torchrl_subgoal.training.dqn` (:func:`train_dqn`) and
  :mod:`~torchrl_subgoal.training.ddpg` (:func:`train_ddpg`, DDPG or TD3): one learner
  each, ``train_<algo>(make_env, config, shaping=..., seed=...) -> LearningCurve``; A2C and PPO also
  as a batch of learners (:func:`train_a2c_batch`, :func:`train_ppo_batch`; seeds as a batch
  dimension: :mod:`~torchrl_subgoal.training.batch`);
* :mod:`~torchrl_subgoal.training.smdp`: keep only the real SMDP transitions
  (:func:`smdp_transitions`, :func:`extend_transitions` into a replay buffer);
* :mod:`~torchrl_subgoal.training.shared`: :class:`EnvFactory`, one potential
  for envs in collector worker processes (shared memory);
* :mod:`~torchrl_subgoal.training.learners`: the building blocks by name (:data:`LEARNERS`) and the
  check that an env's actions suit one (:func:`check_actions`);
* :mod:`~torchrl_subgoal.training.domains`: what a domain registers for the learner recipes
  (:class:`LearnerDomain`).
"""

from __future__ import annotations

from importlib.util import find_spec
from pathlib import Path
from typing import Literal

from torchrl.record.loggers import CSVLogger, Logger

from torchrl_subgoal.training.a2c import A2CConfig, actor_critic, train_a2c, train_a2c_batch
from torchrl_subgoal.training.common import (
    CurveRecorder,
    EpisodeWindow,
    FourierFeatures,
    LearnerSettings,
    LearningCurve,
    PotentialTrainer,
    SampleReshaper,
    Shaping,
    batched,
    check_settings,
    close_collector,
    learner_env,
    make_collector,
    shaped_env,
    subgoal_states,
)
from torchrl_subgoal.training.ddpg import DDPGTrainConfig, ddpg_agent, train_ddpg
from torchrl_subgoal.training.domains import A2CDomain, LearnerDomain
from torchrl_subgoal.training.dqn import DQN_PRESETS, DQNConfig, q_network, train_dqn
from torchrl_subgoal.training.learners import LEARNERS, Learner, action_kind, check_actions
from torchrl_subgoal.training.ppo import PPOConfig, ppo_actor_critic, train_ppo, train_ppo_batch
from torchrl_subgoal.training.shared import EnvFactory
from torchrl_subgoal.training.smdp import extend_transitions, smdp_transitions

__all__ = [
    "DQN_PRESETS",
    "LEARNERS",
    "A2CConfig",
    "A2CDomain",
    "CurveRecorder",
    "DDPGTrainConfig",
    "DQNConfig",
    "EnvFactory",
    "EpisodeWindow",
    "FourierFeatures",
    "Learner",
    "LearnerDomain",
    "LearnerSettings",
    "LearningCurve",
    "PPOConfig",
    "PotentialTrainer",
    "SampleReshaper",
    "Shaping",
    "action_kind",
    "actor_critic",
    "batched",
    "check_actions",
    "check_settings",
    "close_collector",
    "ddpg_agent",
    "experiment_logger",
    "extend_transitions",
    "learner_env",
    "make_collector",
    "ppo_actor_critic",
    "q_network",
    "shaped_env",
    "smdp_transitions",
    "subgoal_states",
    "train_a2c",
    "train_a2c_batch",
    "train_ddpg",
    "train_dqn",
    "train_ppo",
    "train_ppo_batch",
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

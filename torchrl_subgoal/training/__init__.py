"""TorchRL-native training with subgoal shaping: the building blocks of the A2C recipe.

* :mod:`~torchrl_subgoal.training.smdp`: keep only the real SMDP transitions
  (:func:`smdp_transitions`, :func:`extend_transitions` into a replay buffer);
* :mod:`~torchrl_subgoal.training.shared`: :class:`EnvFactory`, one potential
  for envs in collector worker processes (shared memory);
* :mod:`~torchrl_subgoal.training.a2c`: env, networks, collector and the A2C
  loop (:func:`train_a2c`);
* :mod:`~torchrl_subgoal.training.domains`: the four-rooms and PinBall set-ups.
"""

from __future__ import annotations

from pathlib import Path
from typing import Literal

from torchrl.record.loggers import CSVLogger, Logger

from torchrl_subgoal.training.a2c import (
    A2CConfig,
    FourierFeatures,
    LearningCurve,
    Shaping,
    actor_critic,
    batched,
    close_collector,
    make_collector,
    shaped_env,
    train_a2c,
)
from torchrl_subgoal.training.domains import A2CDomain, a2c_domain
from torchrl_subgoal.training.shared import EnvFactory
from torchrl_subgoal.training.smdp import extend_transitions, smdp_transitions

__all__ = [
    "A2CConfig",
    "A2CDomain",
    "EnvFactory",
    "FourierFeatures",
    "LearningCurve",
    "Shaping",
    "a2c_domain",
    "actor_critic",
    "batched",
    "close_collector",
    "experiment_logger",
    "extend_transitions",
    "make_collector",
    "shaped_env",
    "smdp_transitions",
    "train_a2c",
]


def experiment_logger(
    log_dir: str | Path, name: str, backend: Literal["csv", "tensorboard", "none"] = "csv", *, fresh: bool = False
) -> Logger | None:
    """A TorchRL logger writing under ``log_dir/name``: CSV (default), TensorBoard, or none.

    Args:
        log_dir: the directory of every learner's log.
        name: this learner's (its subdirectory).
        backend: ``"csv"``, ``"tensorboard"`` or ``"none"``.
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
        try:
            from torchrl.record.loggers import TensorboardLogger
        except ImportError as exc:
            raise ValueError(f"logger 'tensorboard' needs the tensorboard package ({exc})") from None
        return TensorboardLogger(exp_name=name, log_dir=str(log_dir))
    return CSVLogger(exp_name=name, log_dir=str(log_dir))

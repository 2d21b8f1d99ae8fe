"""A batch of gymnasium envs stepped in one process, as one TorchRL env.

TorchRL's ``GymEnv(name, num_envs=n)`` runs ``n`` envs in an
``AsyncVectorEnv``: ``n`` processes, which on a machine of two cores cost more
than the envs themselves for cheap tasks (MountainCar, a MuJoCo point mass).
:func:`gym_batch` wraps gymnasium's ``SyncVectorEnv`` instead, in TorchRL's
``GymWrapper`` (``GymEnv``'s base): the envs step in a loop in the calling
process, with gymnasium's automatic reset disabled so that TorchRL resets the
finished envs (``"_reset"``) as it does for any batched env.

:class:`GymTask` is the env factory ``make_env(num_envs)`` of one gymnasium task
(its single-env constructor and time limit); factories of different tasks join
into one batch (:meth:`GymTask.join`), so learners with their own tasks (a
PointMaze start and goal each) step as one env.

Needs ``gymnasium`` (``pip install gymnasium``, or the ``fetch`` extra).
"""

from __future__ import annotations

import contextlib
import io
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

from torchrl.envs import EnvBase

__all__ = ["GymTask", "gym_batch", "import_robotics", "require_gymnasium"]


def require_gymnasium(what: str, *, robotics: bool = False) -> Any:
    """Import gymnasium (with gymnasium-robotics' envs registered when ``robotics``), or say how to install it.

    Args:
        what: what needs it (for the message).
        robotics: also import gymnasium-robotics and MuJoCo.

    Raises:
        ImportError: naming the install command.

    Examples:
        >>> require_gymnasium("MountainCar").__name__
        'gymnasium'
    """
    try:
        import gymnasium
    except ImportError:
        raise ImportError(
            f"{what} needs gymnasium: pip install gymnasium (or the fetch extra: pip install 'torchrl_subgoal[fetch]')"
        ) from None
    if robotics:
        try:
            gymnasium_robotics = import_robotics()
            import mujoco  # noqa: F401
        except ImportError as exc:
            raise ImportError(
                f"{what} needs MuJoCo and gymnasium-robotics ({exc.name} is missing): "
                "pip install 'torchrl_subgoal[fetch]'  (or `make install` in a checkout)"
            ) from None
        gymnasium.register_envs(gymnasium_robotics)
    return gymnasium


def import_robotics() -> Any:
    """``gymnasium_robotics``, imported without the notice it prints on stderr at import (about its Adroit hand
    envs' rewards, which this package does not use), so that a recipe's one-line errors stay one line.

    Examples:
        >>> import_robotics().__name__
        'gymnasium_robotics'
    """
    with contextlib.redirect_stderr(io.StringIO()):
        import gymnasium_robotics
    return gymnasium_robotics


def gym_batch(make_envs: Sequence[Callable[[], Any]], *, max_steps: int | None = None, **kwargs: Any) -> EnvBase:
    """``len(make_envs)`` gymnasium envs stepped together in this process: TorchRL's ``GymWrapper`` over
    gymnasium's ``SyncVectorEnv`` (automatic reset disabled; TorchRL resets finished envs).

    Args:
        make_envs: one function per env returning a gymnasium env.
        max_steps: the envs' time limit, kept as the TorchRL env's ``max_steps`` attribute (the
            episode length the training records report before any episode ended).
        **kwargs: more keyword arguments of ``GymWrapper`` (``device``…); discrete actions are
            categorical (an index) unless ``categorical_action_encoding=False`` (one-hot, ``GymEnv``'s default).

    Examples:
        >>> import functools, gymnasium
        >>> env = gym_batch([functools.partial(gymnasium.make, "MountainCar-v0")] * 3, max_steps=200)
        >>> env.batch_size, env.max_steps
        (torch.Size([3]), 200)
        >>> env.rollout(4)["next", "observation"].shape
        torch.Size([3, 4, 2])
    """
    gymnasium = require_gymnasium("gym_batch")
    from torchrl.envs import GymWrapper

    vector = gymnasium.vector.SyncVectorEnv(list(make_envs), autoreset_mode=gymnasium.vector.AutoresetMode.DISABLED)
    env = GymWrapper(vector, **{"categorical_action_encoding": True, **kwargs})
    env.max_steps = max_steps
    return env


@dataclass(frozen=True)
class GymTask:
    """``make_env(num_envs)`` of one gymnasium task: ``num_envs`` copies of ``make_single`` stepped together
    (:func:`gym_batch`). Picklable when ``make_single`` is.

    Args:
        make_single: builds one gymnasium env of the task.
        max_steps: the task's time limit (the TorchRL env's ``max_steps``).

    Examples:
        >>> import functools, gymnasium
        >>> car = GymTask(functools.partial(gymnasium.make, "MountainCar-v0"), max_steps=200)
        >>> car(2).batch_size
        torch.Size([2])
        >>> faster = GymTask(functools.partial(gymnasium.make, "MountainCar-v0", goal_velocity=0.1), 200)
        >>> GymTask.join([car, faster], 3).batch_size  # 3 envs of each task, learner-major
        torch.Size([6])
    """

    make_single: Callable[[], Any]
    max_steps: int | None = None

    def __call__(self, num_envs: int) -> EnvBase:
        if num_envs < 1:
            raise ValueError(f"num_envs must be >= 1, got {num_envs}")
        return gym_batch([self.make_single] * num_envs, max_steps=self.max_steps)

    @classmethod
    def join(cls, tasks: Sequence[GymTask], envs_each: int) -> EnvBase:
        """One env of ``envs_each`` envs of every task in ``tasks``, in order (task ``k``'s envs are rows
        ``k·envs_each … (k+1)·envs_each − 1``); its ``max_steps`` is the tasks' longest."""
        limits = [t.max_steps for t in tasks if t.max_steps is not None]
        makers = [t.make_single for t in tasks for _ in range(envs_each)]
        return gym_batch(makers, max_steps=max(limits) if limits else None)

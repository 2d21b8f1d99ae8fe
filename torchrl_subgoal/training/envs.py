"""A learner's envs: its task's env factory, the shaping transform on the outer env, one batch for many learners.

* an env factory ``make_env(num_envs)`` (:func:`batched` builds one from a single-env factory)
  and, for shaping, a :class:`Shaping` (a subgoal series and its potential ``Φ``);
* :func:`shaped_env`: the envs, then on the *outer* env a reward scaling, the shaping
  transform, a step counter and the episode's env return; the potential reaches collector
  worker processes through shared memory (:class:`~torchrl_subgoal.training.EnvFactory`);
* :func:`learner_envs`: the env factory of a batch of learners, learner-major (learner
  ``k``'s envs are rows ``k·M … (k+1)·M − 1``), from one factory (every learner's task) or
  one per learner (each its own task: their factories must join into one env,
  as :class:`~torchrl_subgoal.envs.gym_batch.GymTask` s do);
* :func:`probe_env`: one env to read specs from, and the episode cap the records start at.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

from tensordict.nn import TensorDictModuleBase
from tensordict.utils import NestedKey
from torchrl.envs import (
    Compose,
    EnvBase,
    ParallelEnv,
    RewardScaling,
    RewardSum,
    SerialEnv,
    StepCounter,
    TransformedEnv,
)

from torchrl_subgoal.loss import SubgoalValueLoss, ValueUpdate
from torchrl_subgoal.subgoals import StateAggregation, SubgoalSeries
from torchrl_subgoal.transform import SubgoalPotentialTransform

__all__ = ["EPISODE_RETURN", "Shaping", "batched", "close_probe", "learner_envs", "probe_env", "shaped_env"]

#: The env return of the episode so far (a ``RewardSum`` over the unshaped reward), in ``"next"``.
EPISODE_RETURN = "episode_return"


@dataclass
class Shaping:
    """The shaping transform of one learner, built in every process that steps its envs.

    Args:
        subgoals: a :class:`~torchrl_subgoal.SubgoalSeries` (or one per env) or a
            :class:`~torchrl_subgoal.StateAggregation`.
        potential: ``Φ``, shared by every env of the learner (e.g.
            ``TabularPotential.for_subgoals(series)``, the default); trained unless it is
            a :class:`~torchrl_subgoal.NaivePotential` or frozen.
        options: further keyword arguments of
            :class:`~torchrl_subgoal.SubgoalPotentialTransform` (``observation_key``,
            ``zero_terminal_potential``…), and ``"backend"`` for its
            :meth:`~torchrl_subgoal.SubgoalPotentialTransform.use_backend`; ``gamma`` and the online
            update's learning rate come from the learner's config.
        loss: keyword arguments of :class:`~torchrl_subgoal.SubgoalValueLoss`, for the transform's online
            update and where the potential is trained per batch (``online_potential=False``); e.g. the
            paper's mean target, ``{"expectile": 0.5, "bootstrap_truncated": True}``.
        prior_weight: the online update's ``prior_weight`` (:class:`~torchrl_subgoal.ValueUpdate`; 0: none).

    Examples:
        >>> from torchrl_subgoal import Cell, SubgoalSeries, TabularPotential
        >>> series = SubgoalSeries([Cell(3, 6), Cell(7, 9)])
        >>> shaping = Shaping(series, TabularPotential.for_subgoals(series), {"observation_key": "cell"})
        >>> shaping.trained
        True
        >>> type(shaping.transform(shaping.potential, gamma=0.99, value_lr=None)).__name__
        'SubgoalPotentialTransform'
    """

    subgoals: SubgoalSeries | Sequence[SubgoalSeries] | StateAggregation
    potential: TensorDictModuleBase
    options: dict[str, Any] = field(default_factory=dict)
    loss: dict[str, Any] = field(default_factory=dict)
    prior_weight: float = 0.0

    @property
    def trained(self) -> bool:
        """Whether the potential has parameters to learn."""
        return any(p.requires_grad for p in self.potential.parameters())

    def transform(
        self, potential: TensorDictModuleBase, gamma: float, value_lr: float | None
    ) -> SubgoalPotentialTransform:
        """The transform over ``potential`` (the process's view of the shared one)."""
        options = dict(self.options)
        backend = options.pop("backend", "auto")
        update: ValueUpdate | float | None = value_lr
        if value_lr is not None and (self.loss or self.prior_weight):
            loss = SubgoalValueLoss(potential, **{"reduction": "sum", **self.loss}).make_value_estimator(gamma=gamma)
            update = ValueUpdate(value_lr, loss, prior_weight=self.prior_weight)
        transform = SubgoalPotentialTransform(self.subgoals, potential, gamma=gamma, value_update=update, **options)
        return transform.use_backend(backend)


def batched(make_single: Callable[[], EnvBase]) -> Callable[[int], EnvBase]:
    """``make_env(num_envs)`` for an env that is not batched: a ``SerialEnv`` of ``num_envs`` copies.

    Args:
        make_single: builds one env (picklable, e.g. a ``functools.partial``, for worker processes).

    Examples:
        >>> from torchrl.envs import GymEnv
        >>> make_env = batched(functools.partial(GymEnv, "CartPole-v1"))
        >>> make_env(2).batch_size
        torch.Size([2])
    """
    return functools.partial(_serial, make_single)


def _serial(make_single: Callable[[], EnvBase], num_envs: int) -> EnvBase:
    return SerialEnv(num_envs, make_single)


def shaped_env(
    make_env: Callable[[int], EnvBase],
    num_envs: int,
    *,
    env_workers: int = 0,
    shaping: Shaping | None = None,
    potential: TensorDictModuleBase | None = None,
    gamma: float = 0.99,
    value_lr: float | None = None,
    reward_scale: float = 1.0,
    episode_stats: bool = True,
) -> EnvBase:
    """The env one collecting process steps: ``num_envs`` envs (in ``env_workers`` processes), then
    on the outer env a reward scaling, the shaping transform, a step counter and the episode's env return.

    ``potential`` is this process's view of the shaping potential (by default ``shaping.potential``).
    ``episode_stats=False`` leaves out the step counter and the episode return (``"step_count"``,
    ``"episode_return"``), for a caller that reads neither: two transforms less on every step; with
    no other transform either, the env itself is returned.

    Args:
        make_env: ``make_env(n)`` returns an env with batch size ``[n]``.
        num_envs: envs stepped by this process.
        env_workers: ``ParallelEnv`` processes holding them (0: stepped here).
        shaping: the shaping transform's pieces (``None``: no shaping).
        potential: this process's view of the potential.
        gamma: ``γ`` of the shaping term.
        value_lr: the transform's online learning rate (``None``: not trained online).
        reward_scale: the env reward is multiplied by this before shaping.
        episode_stats: add the step counter and the episode's env return.

    Examples:
        >>> from torchrl_subgoal import Cell, SubgoalSeries, TabularPotential
        >>> from torchrl_subgoal.envs import FourRoomsEnv
        >>> shaping = Shaping(SubgoalSeries([Cell(3, 6)]), TabularPotential(2), {"observation_key": "cell"})
        >>> env = shaped_env(FourRoomsEnv, 4, shaping=shaping)
        >>> data = env.rollout(3)
        >>> data["next", "subgoal_index"].shape, data["next", "episode_return"].shape
        (torch.Size([4, 3, 1]), torch.Size([4, 3, 1]))
    """
    if env_workers:
        base: EnvBase = ParallelEnv(env_workers, functools.partial(make_env, num_envs // env_workers))
    else:
        base = make_env(num_envs)
    transforms: list[Any] = [StepCounter()] if episode_stats else []
    if reward_scale != 1.0:
        transforms.append(RewardScaling(loc=0.0, scale=reward_scale))
    reward_key: NestedKey = "reward"
    if shaping is not None:
        transform = shaping.transform(potential if potential is not None else shaping.potential, gamma, value_lr)
        transforms.append(transform)
        reward_key = transform.env_reward_key
    if episode_stats:
        transforms.append(RewardSum(in_keys=[reward_key], out_keys=[EPISODE_RETURN]))
    return TransformedEnv(base, Compose(*transforms)) if transforms else base


@dataclass(frozen=True)
class _Joined:
    """The env factory of learners with their own tasks: ``num_envs / K`` envs of each learner's factory,
    joined by the factories' ``join`` (picklable for worker processes)."""

    factories: tuple[Callable[[int], EnvBase], ...]

    def __call__(self, num_envs: int) -> EnvBase:
        k = len(self.factories)
        if num_envs % k:
            raise ValueError(f"{num_envs} envs do not split over {k} learners")
        return type(self.factories[0]).join(self.factories, num_envs // k)  # type: ignore[attr-defined]


def learner_envs(make_env: Callable[[int], EnvBase] | Sequence[Callable[[int], EnvBase]]) -> Callable[[int], EnvBase]:
    """The env factory of a learner batch: ``make_env`` itself when every learner has the same task, else
    (one factory per learner, each its own task) one that builds every learner's share of the envs
    from its own factory, learner-major, as one env.

    Args:
        make_env: ``make_env(num_envs)`` (every learner's task), or one such factory per learner.
            Factories of different tasks must be of one class with a ``join(factories, envs_each)``
            classmethod that builds one env of ``envs_each`` envs per factory, in order
            (:class:`~torchrl_subgoal.envs.gym_batch.GymTask` has one).

    Raises:
        ValueError: learners with different tasks whose factories cannot be joined.

    Examples:
        >>> from torchrl_subgoal.envs import FourRoomsEnv
        >>> learner_envs([FourRoomsEnv, FourRoomsEnv]) is FourRoomsEnv
        True
        >>> from torchrl_subgoal.envs.point_maze import point_maze_env
        >>> tasks = learner_envs([point_maze_env("umaze", 0), point_maze_env("umaze", 1)])
        >>> env = tasks(4)  # two envs of each learner's task
        >>> env.reset()["observation"][:, :2].round()  # learner 0 starts at (-1, -1), learner 1 at (-1, 1)
        tensor([[-1., -1.],
                [-1., -1.],
                [-1.,  1.],
                [-1.,  1.]])
    """
    if callable(make_env):
        return make_env
    factories = tuple(make_env)
    if not factories:
        raise ValueError("a learner batch needs at least one env factory")
    if all(f == factories[0] for f in factories):
        return factories[0]
    kind = type(factories[0])
    if not all(type(f) is kind for f in factories) or not callable(getattr(kind, "join", None)):
        raise ValueError(
            "learners with their own tasks need env factories that join into one env batch (one class with "
            f"a join(factories, envs_each) classmethod, such as gym_batch's GymTask); got {kind.__name__}"
        )
    return _Joined(factories)


def probe_env(make_env: Callable[[int], EnvBase], episode_cap: float | None = None) -> tuple[EnvBase, float]:
    """One env to read specs from, and the episode cap the curve records before any episode ended
    (``episode_cap``, else the env's ``max_steps`` when it has one). Close it with :func:`close_probe`.

    Examples:
        >>> from torchrl_subgoal.envs import FourRoomsEnv
        >>> env, cap = probe_env(FourRoomsEnv)
        >>> env.batch_size, cap
        (torch.Size([1]), 1000.0)
        >>> close_probe(env)
    """
    probe = make_env(1)
    return probe, episode_cap if episode_cap is not None else _max_steps(probe)


def _max_steps(env: EnvBase) -> float:
    """The env's (or its base env's) own ``max_steps``; NaN where it has none. A batched env that was never
    started is not asked (it would start its workers to answer)."""
    while isinstance(env, TransformedEnv):
        env = env.base_env
    if isinstance(env, SerialEnv | ParallelEnv):
        return math.nan
    return float(getattr(env, "max_steps", None) or math.nan)


def close_probe(probe: EnvBase) -> None:
    """Close a probe env (a batched env that was never started, a ``SerialEnv`` from :func:`batched`,
    is closed already).

    Examples:
        >>> import functools
        >>> from torchrl.envs import GymEnv
        >>> env, cap = probe_env(batched(functools.partial(GymEnv, "CartPole-v1")))
        >>> cap  # no max_steps attribute: not known
        nan
        >>> close_probe(env)  # a SerialEnv never started: nothing to close, no error
    """
    if not probe.is_closed:
        probe.close()

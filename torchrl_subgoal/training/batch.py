"""Learners as a batch: what every building block needs to train ``K`` seeds as one program.

``K`` independent learners, each stepping ``M`` envs, become one env batch of
``K·M`` envs (learner-major: envs ``k·M … (k+1)·M − 1`` are learner ``k``'s),
one collector and one optimiser step per update; one learner is a batch of one.

* the networks and replay (:mod:`torchrl_subgoal.training.stack`, re-exported here):
  :class:`~torchrl_subgoal.training.stack.LearnerStack` (``K`` networks' parameters stacked,
  applied with ``torch.vmap``; :func:`stack_actor_critic`, :func:`seeded`),
  :func:`~torchrl_subgoal.training.stack.learner_means`,
  :func:`~torchrl_subgoal.training.stack.clip_grad_norm_per_learner`,
  :class:`~torchrl_subgoal.training.stack.LearnerReplay`;
* :func:`batch_shaping`: the learners' shapings as one transform's, one table
  per learner (``TabularPotential(envs_per_table=M)``), each trained online
  exactly as the learner's own table would be;
* :class:`LearnerBatch`: the checks, the env batch and its collector, the potential's
  training, each learner's records and what the block returns.

Learners of a batch are statistically, not bitwise, the learners run one
by one: the networks start from each learner's seed as alone, but actions are
sampled from one random stream and the envs are seeded once for the batch.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Generator, Mapping, Sequence
from typing import Any, Generic, TypedDict, TypeVar

import torch
from tensordict import TensorDictBase
from tensordict.nn import TensorDictModuleBase
from tensordict.utils import NestedKey
from torch import nn
from torchrl.collectors import Collector, MultiSyncCollector
from torchrl.envs import EnvBase
from torchrl.modules import ProbabilisticActor, ValueOperator
from torchrl.record.loggers import Logger

from torchrl_subgoal.potentials import NaivePotential, TabularPotential
from torchrl_subgoal.subgoals import StateAggregation, SubgoalSeries
from torchrl_subgoal.training.collection import close_collector, make_collector, seed_collector
from torchrl_subgoal.training.config import LearnerConfig
from torchrl_subgoal.training.envs import Shaping, close_probe, learner_envs, probe_env, shaped_env
from torchrl_subgoal.training.networks import subgoal_states
from torchrl_subgoal.training.potential import PotentialTrainer, SampleReshaper
from torchrl_subgoal.training.recording import CurveRecorder, LearningCurve, SuccessSignal
from torchrl_subgoal.training.result import Trained
from torchrl_subgoal.training.shared import EnvFactory
from torchrl_subgoal.training.stack import (
    LearnerReplay,
    LearnerStack,
    clip_grad_norm_per_learner,
    learner_means,
    per_learner,
)

__all__ = [
    "LEARNER",
    "LearnerBatch",
    "LearnerOptions",
    "LearnerReplay",
    "LearnerStack",
    "batch_shaping",
    "clip_grad_norm_per_learner",
    "label_learners",
    "learner_means",
    "learner_rows",
    "per_learner",
    "seeded",
    "stack_actor_critic",
]

C = TypeVar("C", bound=LearnerConfig)
T = TypeVar("T")
#: The learner of each row of a batch's data (:meth:`LearnerBatch.labelled`), e.g. a ``GAE`` ``group_key``.
LEARNER = "learner"
ShapingArg = Shaping | Sequence[Shaping | None] | None


def seeded(seeds: Sequence[int], make: Callable[[], T]) -> list[T]:
    """``make()`` once per seed, torch seeded with it first: each learner's networks as they start alone.

    Examples:
        >>> nets = seeded([0, 1, 0], lambda: nn.Linear(2, 1))
        >>> torch.equal(nets[0].weight, nets[2].weight), torch.equal(nets[0].weight, nets[1].weight)
        (True, False)
    """
    out = []
    for seed in seeds:
        torch.manual_seed(seed)
        out.append(make())
    return out


def stack_actor_critic(
    pairs: Sequence[tuple[ProbabilisticActor, ValueOperator]],
) -> tuple[ProbabilisticActor, ValueOperator]:
    """One actor and one critic for ``K`` learners' ``(actor, critic)`` pairs (one building block's, e.g.
    :func:`~torchrl_subgoal.training.actor_critic`): the first pair with each network replaced by the
    :class:`LearnerStack` of every learner's.

    Examples:
        >>> from torchrl_subgoal.envs import FourRoomsEnv
        >>> from torchrl_subgoal.training import actor_critic
        >>> env = FourRoomsEnv(6)
        >>> actor, critic = stack_actor_critic([actor_critic(env, features="one_hot") for _ in range(3)])
        >>> critic(actor(env.reset()))["state_value"].shape, type(critic.module).__name__
        (torch.Size([6, 1]), 'LearnerStack')
    """
    actor, critic = pairs[0]
    actor.module[0].module = LearnerStack([a.module[0].module for a, _ in pairs])
    critic.module = LearnerStack([c.module for _, c in pairs])
    return actor, critic


def label_learners(data: TensorDictBase, learners: int) -> TensorDictBase:
    """``data`` (first dim the learners' env batch, learner-major) with each row's learner under :data:`LEARNER`
    (e.g. a GAE's ``group_key``: advantages standardised learner by learner); unchanged for one learner.

    Examples:
        >>> from tensordict import TensorDict
        >>> label_learners(TensorDict({}, [4, 2]), 2)[LEARNER].tolist()
        [[0, 0], [0, 0], [1, 1], [1, 1]]
    """
    if learners > 1:
        rows = torch.arange(learners, device=data.device).repeat_interleave(data.shape[0] // learners)
        data.set(LEARNER, rows.view(-1, *([1] * (data.batch_dims - 1))).expand(data.batch_size))
    return data


def learner_rows(learners: int, rows: int) -> list[slice]:
    """Each learner's rows of a learner-major env batch of ``rows`` rows.

    Examples:
        >>> learner_rows(2, 6)
        [slice(0, 3, None), slice(3, 6, None)]
    """
    per = rows // learners
    return [slice(k * per, (k + 1) * per) for k in range(learners)]


def batch_shaping(shapings: Sequence[Shaping | None], envs_per_learner: int) -> Shaping | None:
    """The learners' shapings as one transform's over their learner-major env batch.

    One learner keeps its shaping as it is (its potential is the one trained). In a batch of several, each
    learner keeps its subgoals (one series per env) and gets its own table, which starts from (and, if
    frozen, stays at) the learner's table: a :class:`TabularPotential` of the learners' batch with
    ``envs_per_table = envs_per_learner``. Naive potentials (no table) with one ``η`` are shared.

    Raises:
        ValueError: the learners mix shaped and unshaped, potentials of other kinds or settings,
            frozen and trained tables, aggregations, or transform options.

    Examples:
        >>> from torchrl_subgoal import Cell
        >>> a, b = SubgoalSeries([Cell(3, 6)]), SubgoalSeries([Cell(7, 9)])
        >>> shaping = batch_shaping([Shaping(a, TabularPotential(2)), Shaping(b, TabularPotential(2))], 3)
        >>> shaping.potential.table.shape, shaping.potential.envs_per_table, len(shaping.subgoals)
        (torch.Size([2, 2]), 3, 6)
        >>> batch_shaping([None, None], 3) is None
        True
    """
    if all(s is None for s in shapings):
        return None
    if any(s is None for s in shapings):
        raise ValueError("a learner batch cannot mix shaped and unshaped learners")
    given = [s for s in shapings if s is not None]
    if len(given) == 1:
        return given[0]
    options = given[0].options
    if any(s.options != options for s in given):
        raise ValueError("the learners of a batch must share the shaping transform's options")
    if any((s.loss, s.prior_weight) != (given[0].loss, given[0].prior_weight) for s in given):
        raise ValueError("the learners of a batch must share the potential's loss and update settings")
    subgoals: SubgoalSeries | list[SubgoalSeries] | StateAggregation
    if all(isinstance(s.subgoals, StateAggregation) for s in given):
        if any(s.subgoals is not given[0].subgoals for s in given):
            raise ValueError("the learners of a batch must share one state aggregation")
        subgoals = given[0].subgoals  # type: ignore[assignment]
    elif not any(isinstance(s.subgoals, StateAggregation) for s in given):
        per_env = [x for s in given for x in _per_env(s.subgoals, envs_per_learner)]  # type: ignore[arg-type]
        subgoals = per_env[0] if len(set(per_env)) == 1 else per_env
    else:
        raise ValueError("the learners of a batch must all follow subgoal series or all one aggregation")
    potential = _batch_potential([s.potential for s in given], envs_per_learner)
    return Shaping(subgoals, potential, dict(options), dict(given[0].loss), given[0].prior_weight)


def _per_env(subgoals: SubgoalSeries | Sequence[SubgoalSeries], envs: int) -> list[SubgoalSeries]:
    """A learner's subgoal series for each of its ``envs`` envs (one for all of them, or one each)."""
    series = [subgoals] if isinstance(subgoals, SubgoalSeries) else list(subgoals)
    if len(series) == 1:
        return series * envs
    if len(series) != envs:
        raise ValueError(f"a learner of {envs} envs was given {len(series)} subgoal series: give one, or one per env")
    return series


def _batch_potential(potentials: Sequence[nn.Module], envs_per_learner: int) -> nn.Module:
    """One potential for the learners' env batch: their tables stacked, or their shared naive potential."""
    first = potentials[0]
    if all(isinstance(p, NaivePotential) for p in potentials):
        etas = {float(p.eta) for p in potentials if isinstance(p, NaivePotential)}
        if len(etas) > 1:
            raise ValueError(f"the learners of a batch have naive potentials of different eta: {sorted(etas)}")
        return first
    if not all(isinstance(p, TabularPotential) and not p.batch_shape for p in potentials):
        raise ValueError("a learner batch needs one TabularPotential (one shared table) or NaivePotential per learner")
    tables = [p for p in potentials if isinstance(p, TabularPotential)]
    if len({p.monotone for p in tables}) > 1:
        raise ValueError("the learners of a batch must all or none use a monotone table")
    frozen = {not p.table.requires_grad for p in tables}
    if len(frozen) > 1:
        raise ValueError("a learner batch cannot mix frozen and trained tables")
    states = max(p.num_states for p in tables)
    batch = TabularPotential(
        states, (len(tables),), monotone=tables[0].monotone, interpolate=tables[0].interpolate,
        envs_per_table=envs_per_learner,
    )  # fmt: skip
    with torch.no_grad():
        for k, p in enumerate(tables):
            batch.table[k, : p.num_states] = p.table
    if frozen == {True}:
        batch.table.requires_grad_(False)
    return batch


def _shapings(shaping: ShapingArg, learners: int) -> list[Shaping | None]:
    """One shaping per learner: ``None`` for all, one for every learner, or one each."""
    if shaping is None or isinstance(shaping, Shaping):
        return [shaping] * learners
    given = list(shaping)
    if len(given) != learners:
        raise ValueError(f"{learners} seeds need one shaping or {learners} shapings, got {len(given)}")
    return given


class LearnerOptions(TypedDict, total=False):
    """What every ``train_<algo>(make_env, config, **options)`` takes besides the envs and the settings.

    Attributes:
        seeds: one per learner: its networks' initial weights (torch's sampling and the envs are seeded with
            the first); default ``[0]``, one learner.
        shaping: one for every learner (each starts from its potential), or one per learner; ``None`` (the
            default): unshaped. See :func:`batch_shaping`.
        observation_key: what the networks read (default ``"observation"``).
        episode_cap: what the curves record before any episode finished (default: the env's ``max_steps``).
        loggers: one TorchRL logger (CSV, TensorBoard…) per learner, for losses and episode statistics.
        progress: called with 1 after every batch for every learner.
        success: how a finished episode's success is read (default: the env's ``"is_success"`` or
            ``"success"`` entry, else not recorded).

    Examples:
        >>> from torchrl_subgoal.envs import FourRoomsEnv
        >>> from torchrl_subgoal.training import A2CConfig, train_a2c
        >>> options: LearnerOptions = {"seeds": [0, 1], "observation_key": "observation"}
        >>> config = A2CConfig(num_envs=2, frames_per_batch=8, total_frames=8, features="one_hot")
        >>> len(train_a2c(FourRoomsEnv, config, **options).curves)
        2
    """

    seeds: Sequence[int]
    shaping: ShapingArg
    observation_key: NestedKey
    episode_cap: float | None
    loggers: Sequence[Logger | None] | None
    progress: Callable[[int], None] | None
    success: SuccessSignal | None


class LearnerBatch(Generic[C]):
    """What a building block's batch of ``K`` learners shares: the checks, the env batch and its collector,
    the potential's training, each learner's networks started from its seed, and one
    :class:`~torchrl_subgoal.training.CurveRecorder` per learner.

    Args:
        make_env: ``make_env(num_envs)``, every learner's task, or one such factory per learner (each its
            own task; see :func:`~torchrl_subgoal.training.learner_envs`).
        config: every learner's settings; the batch steps ``K × num_envs`` envs and collects
            ``K × frames_per_batch`` frames per batch (:attr:`config`), as many batches as one learner.

    The keyword arguments (the learners' seeds, shapings, loggers…) are :class:`LearnerOptions`'s.

    Raises:
        ValueError: settings a batch of several learners cannot have (``collector_workers``, a potential
            trained outside the transform, ``env_workers`` with a task per learner), a device that is not
            there, or seeds, shapings and loggers of different numbers.

    Examples:
        >>> from torchrl_subgoal.envs import FourRoomsEnv
        >>> from torchrl_subgoal.training import A2CConfig
        >>> config = A2CConfig(num_envs=4, frames_per_batch=64, total_frames=256)
        >>> batch = LearnerBatch(FourRoomsEnv, config, seeds=[0, 1, 2])
        >>> batch.config.num_envs, batch.config.frames_per_batch, batch.config.total_frames
        (12, 192, 768)
    """

    def __init__(
        self,
        make_env: Callable[[int], EnvBase] | Sequence[Callable[[int], EnvBase]],
        config: C,
        *,
        seeds: Sequence[int] = (0,),
        shaping: ShapingArg = None,
        observation_key: NestedKey = "observation",
        episode_cap: float | None = None,
        loggers: Sequence[Logger | None] | None = None,
        progress: Callable[[int], None] | None = None,
        success: SuccessSignal | None = None,
    ) -> None:
        seeds = [int(s) for s in seeds]
        k = self.learners = len(seeds)
        if k < 1:
            raise ValueError("a learner batch needs at least one seed")
        shapings = _shapings(shaping, k)
        loggers = list(loggers) if loggers is not None else [None] * k
        if len(loggers) != k:
            raise ValueError(f"{k} seeds need {k} loggers, got {len(loggers)}")
        factories = [make_env] if callable(make_env) else list(make_env)
        if len(factories) not in (1, k):
            raise ValueError(f"{k} seeds need one env factory or {k}, got {len(factories)}")
        self.device = _check_device(config.device)
        if k > 1 and config.collector_workers:
            raise ValueError(
                "a batch of several learners needs collector_workers 0: its per-learner version is not built"
            )
        self.make_env = learner_envs(factories if len(factories) > 1 else factories[0])
        if k > 1 and config.env_workers and self.make_env not in factories:
            raise ValueError("learners with their own tasks step their envs here: env_workers must be 0")
        self.shaping = batch_shaping(shapings, config.num_envs)
        trained = self.shaping is not None and self.shaping.trained
        if k > 1 and trained and not config.online_potential:
            raise ValueError("a batch of several learners trains its tables online: online_potential must be True")
        self.seeds, self.settings, self.observation_key = seeds, config, observation_key
        iterations = math.ceil(config.total_frames / config.frames_per_batch)
        self.config: C = dataclasses.replace(
            config,
            num_envs=k * config.num_envs,
            frames_per_batch=k * config.frames_per_batch,
            total_frames=k * config.frames_per_batch * iterations,
        )
        online = trained and config.online_potential
        self.factory: EnvFactory[EnvBase] = EnvFactory(
            shaped_env,
            make_env=self.make_env,
            num_envs=self.config.num_envs,
            env_workers=config.env_workers,
            shaping=self.shaping,
            potential=self.shaping.potential if self.shaping is not None else None,
            gamma=config.gamma,
            value_lr=config.value_lr if online else None,
            reward_scale=config.reward_scale,
        )
        self.trainer: PotentialTrainer | None = None
        if self.shaping is not None and trained and not online:
            self.trainer = PotentialTrainer.for_shaping(
                self.shaping, config.gamma, config.value_lr, config.value_optimizer
            )
        self.subgoal_states = subgoal_states(config, self.shaping)
        self.probe, self.cap = probe_env(factories[0], episode_cap)
        self.loggers, self.progress, self.success = loggers, progress, success
        self.frames = 0  # per learner
        self.collector: Collector | MultiSyncCollector | None = None
        potential = self.shaping.potential if self.shaping is not None else None
        tables = potential.table if isinstance(potential, TabularPotential) else None
        self.recorders = [
            CurveRecorder(
                config.record_window,
                self.cap,
                config.reward_scale,
                loggers[j],
                progress,
                (tables if k == 1 else tables[j]) if tables is not None else None,
                success,
            )
            for j in range(k)
        ]

    def modules(self, build: Callable[..., dict[str, nn.Module]], **extra: Any) -> dict[str, nn.Module]:
        """The block's modules, ``build(env, config, observation_key, subgoal_states, seeds, **extra)`` (each
        learner's networks from its seed, stacked; ``env`` a probe of one env for the specs), on the config's
        device; then torch is seeded with the first seed for the batch's sampling."""
        modules = build(self.probe, self.settings, self.observation_key, self.subgoal_states, self.seeds, **extra)
        close_probe(self.probe)
        torch.manual_seed(self.seeds[0])
        return {name: module.to(self.device) for name, module in modules.items()}

    def reshaper(self) -> SampleReshaper:
        """What re-shapes the batch's replay samples with the potential as it is now (``reshape_samples``)."""
        if self.shaping is None:
            raise ValueError("reshape_samples needs shaping: there is no potential to re-shape samples with")
        return SampleReshaper(self.shaping.transform(self.shaping.potential, self.settings.gamma, None))

    def result(self, algo: str, modules: dict[str, nn.Module]) -> Trained:
        """What the block returns: the curves and its ``modules`` (:class:`~torchrl_subgoal.training.Trained`)."""
        return Trained(
            algo,
            self.settings,
            self.seeds,
            self.curves,
            modules,
            self.observation_key,
            self.subgoal_states,
            self.shaping,
        )

    def collect(
        self,
        policy: TensorDictModuleBase,
        *,
        init_random_frames: int = 0,
        start: Callable[[], None] | None = None,
    ) -> Generator[TensorDictBase, None, None]:
        """The batch's collected batches (collector seeded with the first seed, closed at the end);
        :attr:`frames` counts one learner's frames so far. ``init_random_frames`` is one learner's; ``start`` is
        called once the collector is built (:attr:`collector`), before the first batch."""
        collector = make_collector(
            self.factory,
            policy,
            self.config,
            init_random_frames=self.learners * init_random_frames,
            device=self.device,
        )
        self.collector = collector
        seed_collector(collector, self.seeds[0])
        try:
            if start is not None:
                start()
            for data in collector:
                self.frames += data.numel() // self.learners
                yield data
        finally:
            close_collector(collector)

    def record(self, data: TensorDictBase, scalars: Mapping[str, torch.Tensor | float]) -> None:
        """After a batch's update: the potential's step (when it is trained outside the transform), the new
        weights to collector workers, and each learner's rows of ``data`` and its ``scalars`` (``[K]`` each,
        or one number for one learner) to its recorder."""
        potential_loss = self.trainer.step(data) if self.trainer is not None else math.nan
        if self.settings.collector_workers and self.collector is not None:
            self.collector.update_policy_weights_()
        rows = learner_rows(self.learners, data.shape[0])
        for k, recorder in enumerate(self.recorders):
            own = {name: _entry(values, k) for name, values in scalars.items()}
            recorder.add(data[rows[k]], self.frames, {**own, "loss_potential": potential_loss})

    @property
    def curves(self) -> list[LearningCurve]:
        """Each learner's curve."""
        return [r.curve for r in self.recorders]


def _entry(values: torch.Tensor | float, k: int) -> float:
    if isinstance(values, torch.Tensor) and values.dim():
        return float(values[k].detach())
    return float(values)


def _check_device(device: str) -> torch.device:
    """``device`` as a ``torch.device``, refused (naming the field) where it is not there."""
    out = torch.device(device)
    if out.type == "cuda" and not torch.cuda.is_available():
        raise ValueError(f"device {device!r}: CUDA is not available here (torch {torch.__version__}); use 'cpu'")
    if out.type == "cuda" and out.index is not None and out.index >= torch.cuda.device_count():
        raise ValueError(f"device {device!r}: there are {torch.cuda.device_count()} CUDA devices here")
    if out.type not in ("cpu", "cuda"):
        raise ValueError(f"device {device!r}: the learners run on cpu or cuda")
    return out

"""Several learners of one algorithm as one batch: what a building block needs to train ``K`` seeds at once.

``K`` independent learners, each stepping ``M`` envs, become one env batch of
``K·M`` envs (learner-major: envs ``k·M … (k+1)·M − 1`` are learner ``k``'s),
one collector and one optimiser step per batch:

* :class:`LearnerStack`: ``K`` copies of a network, each with its own
  parameters (stacked ``[K, …]``, applied with ``torch.vmap``), over inputs whose
  first dim is the env batch;
* :func:`batch_shaping`: the learners' shapings as one transform's, one table
  per learner (``TabularPotential(envs_per_table=M)``), each trained online
  exactly as the learner's own table would be;
* :func:`learner_means`: per-sample losses as each learner's mean, whose sum
  gives every learner the gradient it gets alone;
* :func:`clip_grad_norm_per_learner`: gradient clipping learner by learner.

Learners of a batch are statistically, not bitwise, the learners run one by
one: the networks start from each learner's seed as alone, but actions are
sampled from one random stream and the envs are seeded once for the batch.
"""

from __future__ import annotations

import copy
import dataclasses
import math
from collections.abc import Callable, Iterable, Mapping, Sequence
from typing import Any

import torch
from tensordict import TensorDict, TensorDictBase
from tensordict.nn import TensorDictModuleBase
from tensordict.utils import NestedKey
from torch import nn
from torchrl.collectors import Collector, MultiSyncCollector
from torchrl.envs import EnvBase
from torchrl.modules import ProbabilisticActor, ValueOperator
from torchrl.record.loggers import Logger

from torchrl_subgoal.potentials import NaivePotential, TabularPotential
from torchrl_subgoal.subgoals import StateAggregation, SubgoalSeries
from torchrl_subgoal.training.common import (
    CurveRecorder,
    LearnerSettings,
    LearningCurve,
    Shaping,
    _close_probe,
    _probe_env,
    _seed_collector,
    learner_env,
    make_collector,
    subgoal_states,
)

__all__ = [
    "LearnerBatch",
    "LearnerStack",
    "batch_shaping",
    "clip_grad_norm_per_learner",
    "learner_means",
    "learner_rows",
    "stack_actor_critic",
]


class LearnerStack(nn.Module):
    """``K`` networks of one architecture as one module: each learner's rows go through its own parameters.

    Args:
        networks: one network per learner (same architecture; their parameters and buffers are
            copied, stacked along a new first dim).

    The inputs' first dim is the env batch, learner-major (``K·M`` rows, the first
    ``M`` learner 0's), or the learners themselves (``K`` rows of samples); any further
    dims (time, minibatch, a ``vmap`` of TorchRL's value estimators) follow.

    Examples:
        >>> _ = torch.manual_seed(0)
        >>> nets = [nn.Linear(3, 2) for _ in range(2)]
        >>> stack = LearnerStack(nets)
        >>> x = torch.randn(4, 5, 3)  # 2 learners x 2 envs, 5 steps
        >>> out = stack(x)
        >>> out.shape, torch.allclose(out[2:], nets[1](x[2:]), atol=1e-6)
        (torch.Size([4, 5, 2]), True)
    """

    def __init__(self, networks: Sequence[nn.Module]) -> None:
        super().__init__()
        if not networks:
            raise ValueError("LearnerStack needs at least one network")
        self.learners = len(networks)
        self.params = TensorDict.from_modules(*networks, as_module=True)
        base = copy.deepcopy(networks[0])
        self.params[0].data.to("meta").to_module(base)  # the architecture, without its own weights
        self.__dict__["_base"] = base  # not a submodule: its (meta) parameters are not this module's

    def forward(self, *inputs: torch.Tensor) -> torch.Tensor | tuple[torch.Tensor, ...]:
        k = self.learners
        for x in inputs:
            if x.shape[0] % k:
                raise ValueError(f"LearnerStack of {k} learners got {x.shape[0]} rows: not a multiple of {k}")

        base: nn.Module = self.__dict__["_base"]

        def call(params: TensorDictBase, *xs: torch.Tensor) -> torch.Tensor:
            with params.to_module(base):
                return base(*xs)

        grouped = [x.unflatten(0, (k, -1)) for x in inputs]
        out = torch.vmap(call, (0,) * (len(inputs) + 1))(self.params, *grouped)
        if isinstance(out, tuple):  # several outputs (a location and a scale)
            return tuple(o.flatten(0, 1) for o in out)
        return out.flatten(0, 1)


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


def learner_rows(learners: int, rows: int) -> list[slice]:
    """Each learner's rows of a learner-major env batch of ``rows`` rows.

    Examples:
        >>> learner_rows(2, 6)
        [slice(0, 3, None), slice(3, 6, None)]
    """
    per = rows // learners
    return [slice(k * per, (k + 1) * per) for k in range(learners)]


def learner_means(values: torch.Tensor, learners: int) -> torch.Tensor:
    """Each learner's mean of per-sample ``values`` (first dim the learner-major env batch), ``[K]``.

    A learner's mean is its loss alone; the sum over learners is the batch's loss, whose
    gradient for each learner's parameters is its gradient alone.

    Examples:
        >>> learner_means(torch.tensor([[1.0, 3.0], [2.0, 2.0], [5.0, 7.0], [6.0, 6.0]]), 2).tolist()
        [2.0, 6.0]
    """
    return values.reshape(learners, -1).mean(1)


def clip_grad_norm_per_learner(parameters: Iterable[torch.Tensor], max_norm: float, learners: int) -> torch.Tensor:
    """``torch.nn.utils.clip_grad_norm_`` for each learner of stacked parameters (first dim ``K``): each
    learner's gradients scaled by ``min(1, max_norm / (‖g_k‖ + 1e-6))``; the learners' norms.

    Examples:
        >>> p = nn.Parameter(torch.zeros(2, 2))
        >>> p.grad = torch.tensor([[3.0, 4.0], [0.3, 0.4]])
        >>> clip_grad_norm_per_learner([p], 1.0, 2).tolist()
        [5.0, 0.5]
        >>> [round(g, 4) for g in p.grad.reshape(-1).tolist()]  # learner 0 clipped to norm 1, learner 1 kept
        [0.6, 0.8, 0.3, 0.4]
    """
    grads = [p.grad for p in parameters if p.grad is not None]
    for g in grads:
        if g.shape[0] != learners:
            raise ValueError(f"a parameter of shape {tuple(g.shape)} is not stacked over {learners} learners")
    if not grads:
        return torch.zeros(learners)
    norms = torch.stack([g.reshape(learners, -1).pow(2).sum(1) for g in grads]).sum(0).sqrt()
    scale = (max_norm / (norms + 1e-6)).clamp(max=1.0)
    for g in grads:
        g.mul_(scale.view(learners, *([1] * (g.dim() - 1))))
    return norms


def batch_shaping(shapings: Sequence[Shaping | None], envs_per_learner: int) -> Shaping | None:
    """The learners' shapings as one transform's over their learner-major env batch.

    Each learner keeps its subgoals (one series per env) and gets its own table, which starts
    from (and, if frozen, stays at) the learner's table: a :class:`TabularPotential` of the
    learners' batch with ``envs_per_table = envs_per_learner``. Naive potentials (no table) with
    one ``η`` are shared.

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
    options = given[0].options
    if any(s.options != options for s in given):
        raise ValueError("the learners of a batch must share the shaping transform's options")
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
    return Shaping(subgoals, _batch_potential([s.potential for s in given], envs_per_learner), dict(options))


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
    batch = TabularPotential(states, (len(tables),), monotone=tables[0].monotone, envs_per_table=envs_per_learner)
    with torch.no_grad():
        for k, p in enumerate(tables):
            batch.table[k, : p.num_states] = p.table
    if frozen == {True}:
        batch.table.requires_grad_(False)
    return batch


class LearnerBatch:
    """What a building block's batch of ``K`` learners shares: the checks, the env batch and its collector,
    each learner's networks started from its seed, and one :class:`~torchrl_subgoal.training.CurveRecorder`
    per learner.

    Args:
        make_env: ``make_env(num_envs)``, every learner's task.
        config: every learner's settings; the batch steps ``K × num_envs`` envs and collects
            ``K × frames_per_batch`` frames per batch (:attr:`config`), as many batches as one learner.
        seeds: one per learner: its networks' initial weights (the envs and the actions are seeded with
            the first).
        shapings: one per learner (``None``: all unshaped); see :func:`batch_shaping`.
        loggers: one TorchRL logger per learner (``None``: none).
        progress: called with 1 after every batch for every learner.
        episode_cap: what the curves record before any episode finished (default: the env's ``max_steps``).

    Raises:
        ValueError: ``collector_workers`` is not 0, or a trained potential is not trained online (their
            per-learner versions are not built), or the seeds, shapings and loggers differ in number.

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
        make_env: Callable[[int], EnvBase],
        config: LearnerSettings,
        seeds: Sequence[int],
        *,
        shapings: Sequence[Shaping | None] | None = None,
        loggers: Sequence[Logger | None] | None = None,
        progress: Callable[[int], None] | None = None,
        episode_cap: float | None = None,
    ) -> None:
        k = self.learners = len(seeds)
        if k < 1:
            raise ValueError("a learner batch needs at least one seed")
        shapings = list(shapings) if shapings is not None else [None] * k
        loggers = list(loggers) if loggers is not None else [None] * k
        if len(shapings) != k or len(loggers) != k:
            raise ValueError(f"{k} seeds need {k} shapings and {k} loggers, got {len(shapings)} and {len(loggers)}")
        if config.collector_workers:
            raise ValueError("a learner batch needs collector_workers off (0): its per-learner version is not built")
        self.shaping = batch_shaping(shapings, config.num_envs)
        if self.shaping is not None and self.shaping.trained and not config.online_potential:
            raise ValueError("a learner batch trains its tables online: online_potential must be True")
        self.seeds = list(seeds)
        self.settings = config
        iterations = math.ceil(config.total_frames / config.frames_per_batch)
        self.config: Any = dataclasses.replace(
            config,  # type: ignore[type-var]
            num_envs=k * config.num_envs,
            frames_per_batch=k * config.frames_per_batch,
            total_frames=k * config.frames_per_batch * iterations,
        )
        self.factory, _ = learner_env(make_env, self.config, self.shaping)
        self.subgoal_states = subgoal_states(config, self.shaping)
        self.make_env, self.episode_cap = make_env, episode_cap
        self.loggers, self.progress = loggers, progress
        self.recorders: list[CurveRecorder] = []

    def networks(
        self,
        build: Callable[[EnvBase, NestedKey], tuple[ProbabilisticActor, ValueOperator]],
        observation_key: NestedKey,
    ) -> tuple[ProbabilisticActor, ValueOperator]:
        """Each learner's ``build(env, observation_key)`` from its seed, stacked (:func:`stack_actor_critic`); then
        torch is seeded with the first seed for the batch's sampling. Sets up the recorders (they need the
        env's episode cap)."""
        probe, cap = _probe_env(self.make_env, self.episode_cap)
        pairs = []
        for seed in self.seeds:  # each learner's networks start as they would alone
            torch.manual_seed(seed)
            pairs.append(build(probe, observation_key))
        _close_probe(probe)
        torch.manual_seed(self.seeds[0])
        potential = self.shaping.potential if self.shaping is not None else None
        tables = potential.table if isinstance(potential, TabularPotential) else None
        c = self.settings
        self.recorders = [
            CurveRecorder(
                c.record_window,
                cap,
                c.reward_scale,
                self.loggers[k],
                self.progress,
                _LearnerTable(tables[k]) if tables is not None else None,
            )
            for k in range(self.learners)
        ]
        return stack_actor_critic(pairs)

    def collector(self, actor: TensorDictModuleBase) -> Collector | MultiSyncCollector:
        """The batch's collector over its env batch, seeded with the first seed."""
        collector = make_collector(self.factory, actor, self.config)
        _seed_collector(collector, self.seeds[0])
        return collector

    def record(self, data: TensorDictBase, frames: int, scalars: Mapping[str, torch.Tensor]) -> None:
        """Add each learner's rows of a collected batch (``frames`` per learner so far) and its ``scalars``
        (``[K]`` each) to its recorder."""
        for k, rows in enumerate(learner_rows(self.learners, data.shape[0])):
            own = {name: float(values[k].detach()) for name, values in scalars.items()}
            self.recorders[k].add(data[rows], frames, {**own, "loss_potential": math.nan})

    @property
    def curves(self) -> list[LearningCurve]:
        """Each learner's curve."""
        return [r.curve for r in self.recorders]


class _LearnerTable(nn.Module):
    """One learner's row of a batch of tables (a view), as :class:`CurveRecorder` logs a potential's ``table``."""

    def __init__(self, table: torch.Tensor) -> None:
        super().__init__()
        self.table = table

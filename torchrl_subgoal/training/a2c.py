"""A2C on TorchRL's collectors with subgoal shaping: the building blocks of ``recipes/a2c.py``.

One learner is one A2C agent: a policy and a value network
(:class:`~tensordict.nn.TensorDictModule` s) trained by TorchRL's
:class:`~torchrl.objectives.A2CLoss` with :class:`~torchrl.objectives.value.GAE`
advantages, on batches from a :class:`~torchrl.collectors.Collector` (or a
:class:`~torchrl.collectors.MultiSyncCollector` of worker processes) over a
batch of envs (or a :class:`~torchrl.envs.ParallelEnv` of env workers). The
shaping transform sits on the *outer* env of each collecting process; its
potential is shared with the main process (:class:`EnvFactory`), where
:class:`~torchrl_subgoal.SubgoalValueLoss` trains it from the collected SMDP
transitions with its own optimiser — or the transform trains it online.

A user's env needs an env factory ``make_env(num_envs) -> EnvBase`` (an env
with batch size ``[num_envs]``; :func:`batched` builds one from a single-env
factory) and, for shaping, a subgoal series::

    shaping = Shaping(series, TabularPotential(series.num_abstract_states), observation_key="observation")
    curve = train_a2c(make_env, A2CConfig(total_frames=200_000), shaping=shaping, seed=0)
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Literal

import torch
from tensordict.nn import TensorDictModule
from tensordict.utils import NestedKey
from torch import nn
from torchrl.data import Categorical, OneHot
from torchrl.envs import EnvBase
from torchrl.modules import OneHotCategorical, ProbabilisticActor, ValueOperator
from torchrl.objectives import A2CLoss
from torchrl.objectives.value import GAE
from torchrl.record.loggers import Logger

from torchrl_subgoal.training.batch import LearnerBatch, clip_grad_norm_per_learner, learner_means
from torchrl_subgoal.training.common import (
    EPISODE_RETURN,
    CurveRecorder,
    Features,
    FourierFeatures,
    LearningCurve,
    Shaping,
    _close_probe,
    _network,
    _probe_env,
    _seed_collector,
    _subgoal_keys,
    _trunk,
    batched,
    close_collector,
    learner_env,
    make_collector,
    shaped_env,
    subgoal_states,
)

__all__ = [
    "EPISODE_RETURN",
    "A2CConfig",
    "FourierFeatures",
    "LearningCurve",
    "Shaping",
    "actor_critic",
    "batched",
    "close_collector",
    "make_collector",
    "shaped_env",
    "train_a2c",
    "train_a2c_batch",
]


@dataclass
class A2CConfig:
    """Settings of one A2C learner.

    Attributes:
        num_envs: envs per learner (the batch a collector steps).
        env_workers: ``ParallelEnv`` worker processes holding the envs (0: the batched env
            in the collecting process).
        collector_workers: 0: one :class:`~torchrl.collectors.Collector` in this process;
            ``k ≥ 1``: a :class:`~torchrl.collectors.MultiSyncCollector` of ``k`` processes,
            each with ``num_envs`` envs.
        frames_per_batch: frames per collected batch (one A2C update), over all collector
            workers (each collects ``frames_per_batch / k``).
        total_frames: frames per learner.
        gamma: discount.
        gae_lambda: GAE's λ.
        lr: Adam learning rate of the policy and the value network.
        entropy_coeff: entropy bonus.
        critic_coeff: weight of the value loss.
        max_grad_norm: gradient clipping.
        normalize_advantage: standardise advantages per batch.
        features: the networks' input layer: ``"one_hot"`` (a categorical observation),
            ``"fourier"`` (Fourier basis of a bounded observation) or ``"mlp"``.
        hidden: hidden layer sizes (``()``: linear in the features).
        fourier_order: order of the Fourier basis.
        reward_scale: the env reward is multiplied by this before shaping and learning
            (records keep the env's units).
        value_lr: ``α_v`` of the transform's online update, ``V(z) += α_v · δ`` per SMDP
            transition (with ``online_potential=False``: the potential's optimiser's learning rate).
        value_optimizer: with ``online_potential=False``: ``"adam"`` (reduction mean) or ``"sgd"``
            (reduction sum: the tabular update).
        online_potential: train the potential in the transform at every step (the paper's
            update; the default: its step scales with the TD error, so it suits any reward scale)
            instead of one optimiser step per batch on the batch's transitions.
        record_window: batches the recorded mean episode length is estimated over (frames per
            finished episode in the window).
        sees_subgoal: the policy and the value network also read the subgoal index ``z`` (one-hot),
            which the shaping transform keeps (see
            :class:`~torchrl_subgoal.agents.subgoal_input.SubgoalInput`).

    Examples:
        >>> config = A2CConfig(num_envs=8, frames_per_batch=128, total_frames=1024)
        >>> config.iterations
        8
        >>> A2CConfig(num_envs=8, frames_per_batch=100)
        Traceback (most recent call last):
        ...
        ValueError: frames_per_batch (100) must be a multiple of num_envs (8)
    """

    num_envs: int = 16
    env_workers: int = 0
    collector_workers: int = 0
    frames_per_batch: int = 256
    total_frames: int = 200_000
    gamma: float = 0.99
    gae_lambda: float = 0.95
    lr: float = 1e-3
    entropy_coeff: float = 0.01
    critic_coeff: float = 0.5
    max_grad_norm: float = 1.0
    normalize_advantage: bool = False
    features: Features = "mlp"
    hidden: tuple[int, ...] = (64,)
    fourier_order: int = 3
    reward_scale: float = 1.0
    value_lr: float = 0.05
    value_optimizer: Literal["adam", "sgd"] = "adam"
    online_potential: bool = True
    record_window: int = 8
    sees_subgoal: bool = False

    def __post_init__(self) -> None:
        for name in ("num_envs", "frames_per_batch", "total_frames", "record_window"):
            if getattr(self, name) < 1:
                raise ValueError(f"{name} must be >= 1, got {getattr(self, name)}")
        for name in ("env_workers", "collector_workers"):
            if getattr(self, name) < 0:
                raise ValueError(f"{name} must be >= 0, got {getattr(self, name)}")
        if self.env_workers and self.num_envs % self.env_workers:
            raise ValueError(f"num_envs ({self.num_envs}) must be a multiple of env_workers ({self.env_workers})")
        if self.frames_per_batch % self.num_envs:
            raise ValueError(
                f"frames_per_batch ({self.frames_per_batch}) must be a multiple of num_envs ({self.num_envs})"
            )
        if self.frames_per_batch % (self.num_envs * max(1, self.collector_workers)):
            raise ValueError(
                f"frames_per_batch ({self.frames_per_batch}) must be a multiple of num_envs x "
                f"collector_workers ({self.num_envs} x {self.collector_workers}): each worker "
                "collects an equal share with its num_envs envs"
            )
        if self.features not in ("one_hot", "fourier", "mlp"):
            raise ValueError(f"features must be one_hot, fourier or mlp, got {self.features!r}")
        if self.value_optimizer not in ("adam", "sgd"):
            raise ValueError(f"value_optimizer must be adam or sgd, got {self.value_optimizer!r}")
        self.hidden = tuple(int(h) for h in self.hidden)

    @property
    def iterations(self) -> int:
        """Collected batches (A2C updates) per learner (a ``MultiSyncCollector``'s batch holds
        ``frames_per_batch`` frames of all its workers)."""
        return math.ceil(self.total_frames / self.frames_per_batch)


def actor_critic(
    env: EnvBase,
    observation_key: NestedKey = "observation",
    *,
    features: Features = "mlp",
    hidden: Sequence[int] = (64,),
    fourier_order: int = 3,
    subgoal_states: int = 0,
) -> tuple[ProbabilisticActor, ValueOperator]:
    """A categorical policy and a value network over ``observation_key`` for ``env``'s discrete actions.

    Args:
        env: gives the observation and action specs.
        observation_key: the networks' input.
        features: ``"one_hot"`` for a categorical observation (a table lookup when
            ``hidden=()``), ``"fourier"`` for a bounded one, ``"mlp"`` otherwise.
        hidden: hidden layer sizes.
        fourier_order: order of the Fourier basis.
        subgoal_states: if positive, both networks also read ``"subgoal_index"`` (``z``, one-hot
            over this many abstract states): joined to the features as their product for one-hot
            features with ``hidden=()`` (a table over ``(s, z)``), else concatenated.

    Examples:
        >>> from torchrl_subgoal.envs import FourRoomsEnv
        >>> actor, critic = actor_critic(FourRoomsEnv(3), features="one_hot")
        >>> td = critic(actor(FourRoomsEnv(3).reset()))
        >>> td["action"].shape, td["state_value"].shape
        (torch.Size([3]), torch.Size([3, 1]))
        >>> actor, critic = actor_critic(FourRoomsEnv(3), features="one_hot", subgoal_states=3)
        >>> critic.in_keys
        ['observation', 'subgoal_index']
    """
    spec = env.observation_spec[observation_key]
    action_spec = env.full_action_spec[env.action_key]
    if not isinstance(action_spec, Categorical | OneHot):
        raise ValueError(f"A2C here needs discrete actions (Categorical or OneHot), got {type(action_spec).__name__}")
    n_actions = int(action_spec.space.n)
    policy_trunk, size = _trunk(spec, features, hidden, fourier_order, subgoal_states=subgoal_states)
    value_trunk, _ = _trunk(spec, features, hidden, fourier_order, subgoal_states=subgoal_states)
    policy_head, value_head = nn.Linear(size, n_actions), nn.Linear(size, 1)
    for last in (policy_head, value_head):  # start from a uniform policy and a zero value
        nn.init.zeros_(last.weight)
        nn.init.zeros_(last.bias)
    in_keys = _subgoal_keys(observation_key, subgoal_states)
    distribution = OneHotCategorical if isinstance(action_spec, OneHot) else torch.distributions.Categorical
    actor = ProbabilisticActor(
        TensorDictModule(_network(policy_trunk, policy_head), in_keys=in_keys, out_keys=["logits"]),
        in_keys=["logits"],
        spec=action_spec,
        distribution_class=distribution,
        return_log_prob=True,
    )
    critic = ValueOperator(_network(value_trunk, value_head), in_keys=in_keys)
    return actor, critic


def train_a2c(
    make_env: Callable[[int], EnvBase],
    config: A2CConfig,
    *,
    shaping: Shaping | None = None,
    observation_key: NestedKey = "observation",
    seed: int = 0,
    episode_cap: float | None = None,
    logger: Logger | None = None,
    progress: Callable[[int], None] | None = None,
) -> LearningCurve:
    """Train one A2C learner on ``make_env(config.num_envs)`` (shaped by ``shaping``); its curve.

    Every batch: GAE advantages and one A2C step; then, unless the potential is
    trained online or fixed, one step of ``shaping.potential`` on the batch's
    real SMDP transitions with its own optimiser. The potential is in shared
    memory, so envs in collector or env worker processes shape with the one
    trained here (see :mod:`torchrl_subgoal.training.shared`).

    Args:
        make_env: ``make_env(num_envs)`` returns an env with batch size ``[num_envs]``.
        config: the settings.
        shaping: the shaping transform's pieces (``None``: plain A2C).
        observation_key: what the policy and value network read.
        seed: seeds torch (networks, sampling) and the envs.
        episode_cap: what the curve records before any episode finished (default: the env's
            ``max_steps`` when it has one).
        logger: a TorchRL logger (CSV, TensorBoard…) for losses and episode statistics.
        progress: called with 1 after every batch.

    Examples:
        >>> from torchrl_subgoal import Cell, SubgoalSeries, TabularPotential
        >>> from torchrl_subgoal.envs import FourRoomsEnv
        >>> shaping = Shaping(SubgoalSeries([Cell(3, 6)]), TabularPotential(2), {"observation_key": "cell"})
        >>> config = A2CConfig(num_envs=4, frames_per_batch=64, total_frames=256, features="one_hot", hidden=())
        >>> curve = train_a2c(FourRoomsEnv, config, shaping=shaping, seed=0)
        >>> curve.frames
        [64, 128, 192, 256]
    """
    torch.manual_seed(seed)
    factory, trainer = learner_env(make_env, config, shaping)
    states = subgoal_states(config, shaping)
    probe, cap = _probe_env(make_env, episode_cap)
    actor, critic = actor_critic(
        probe,
        observation_key,
        features=config.features,
        hidden=config.hidden,
        fourier_order=config.fourier_order,
        subgoal_states=states,
    )
    _close_probe(probe)
    advantage = GAE(
        gamma=config.gamma, lmbda=config.gae_lambda, value_network=critic, average_gae=config.normalize_advantage
    )
    loss = A2CLoss(
        actor, critic, entropy_coeff=config.entropy_coeff, critic_coeff=config.critic_coeff, loss_critic_type="l2"
    )
    optimizer = torch.optim.Adam(loss.parameters(), lr=config.lr)
    collector = make_collector(factory, actor, config)
    _seed_collector(collector, seed)
    recorder = CurveRecorder(
        config.record_window, cap, config.reward_scale, logger, progress, shaping.potential if shaping else None
    )
    frames = 0
    try:
        for data in collector:
            frames += data.numel()
            with torch.no_grad():
                advantage(data)
            losses = loss(data)
            total = losses["loss_objective"] + losses["loss_critic"] + losses["loss_entropy"]
            optimizer.zero_grad(set_to_none=True)
            total.backward()
            nn.utils.clip_grad_norm_(loss.parameters(), config.max_grad_norm)
            optimizer.step()
            potential_loss = trainer.step(data) if trainer is not None else math.nan
            if config.collector_workers:
                collector.update_policy_weights_()
            recorder.add(
                data,
                frames,
                {
                    "loss_objective": float(losses["loss_objective"].detach()),
                    "loss_critic": float(losses["loss_critic"].detach()),
                    "loss_entropy": float(losses["loss_entropy"].detach()),
                    "loss_potential": potential_loss,
                },
            )
    finally:
        close_collector(collector)
    return recorder.curve


def train_a2c_batch(
    make_env: Callable[[int], EnvBase],
    config: A2CConfig,
    seeds: Sequence[int],
    *,
    shapings: Sequence[Shaping | None] | None = None,
    observation_key: NestedKey = "observation",
    episode_cap: float | None = None,
    loggers: Sequence[Logger | None] | None = None,
    progress: Callable[[int], None] | None = None,
) -> list[LearningCurve]:
    """Train ``len(seeds)`` independent A2C learners as one batch; each learner's curve.

    Learner ``k`` is :func:`train_a2c` with ``config``, ``shapings[k]`` and ``seeds[k]``: its own
    networks (started as alone from its seed), ``config.num_envs`` envs, its own table trained
    online, its own loss, gradient clipping and Adam state. The learners share one env batch of
    ``K × num_envs`` envs, one collector and one optimiser step per batch
    (:class:`~torchrl_subgoal.training.batch.LearnerBatch`), which is what makes a batch faster
    than ``K`` runs on one core. Statistically, not bitwise, equal to the learners run one by one
    (one random stream for the batch's actions; the envs seeded with ``seeds[0]``).

    Args:
        make_env: ``make_env(num_envs)`` returns an env with batch size ``[num_envs]`` (every learner's task).
        config: every learner's settings; ``collector_workers=0``, ``normalize_advantage=False`` and,
            with a trained potential, ``online_potential=True`` (per-learner versions of the others are
            not built).
        seeds: one per learner: its networks' initial weights.
        shapings: one per learner (``None``: all unshaped).
        observation_key: what the networks read.
        episode_cap: as in :func:`train_a2c`.
        loggers: one TorchRL logger per learner (or ``None``).
        progress: called with 1 after every batch for every learner.

    Examples:
        >>> from torchrl_subgoal import Cell, SubgoalSeries, TabularPotential
        >>> from torchrl_subgoal.envs import FourRoomsEnv
        >>> series = SubgoalSeries([Cell(3, 6)])
        >>> shapings = [Shaping(series, TabularPotential(2), {"observation_key": "cell"}) for _ in range(3)]
        >>> config = A2CConfig(num_envs=4, frames_per_batch=64, total_frames=256, features="one_hot", hidden=())
        >>> curves = train_a2c_batch(FourRoomsEnv, config, [0, 1, 2], shapings=shapings)
        >>> len(curves), curves[2].frames
        (3, [64, 128, 192, 256])
    """
    if config.normalize_advantage:
        raise ValueError("a learner batch needs normalize_advantage off (False): its per-learner version is not built")
    batch = LearnerBatch(
        make_env, config, seeds, shapings=shapings, loggers=loggers, progress=progress, episode_cap=episode_cap
    )
    k, states = batch.learners, batch.subgoal_states
    actor, critic = batch.networks(
        lambda env, key: actor_critic(
            env,
            key,
            features=config.features,
            hidden=config.hidden,
            fourier_order=config.fourier_order,
            subgoal_states=states,
        ),
        observation_key,
    )
    advantage = GAE(gamma=config.gamma, lmbda=config.gae_lambda, value_network=critic)
    loss = A2CLoss(
        actor,
        critic,
        entropy_coeff=config.entropy_coeff,
        critic_coeff=config.critic_coeff,
        loss_critic_type="l2",
        reduction="none",
    )
    optimizer = torch.optim.Adam(loss.parameters(), lr=config.lr)
    collector = batch.collector(actor)
    frames = 0
    try:
        for data in collector:
            frames += data.numel() // k
            with torch.no_grad():
                advantage(data)
            losses = loss(data)
            means = {name: learner_means(losses[name], k) for name in ("loss_objective", "loss_critic", "loss_entropy")}
            optimizer.zero_grad(set_to_none=True)
            torch.stack([m.sum() for m in means.values()]).sum().backward()
            clip_grad_norm_per_learner(loss.parameters(), config.max_grad_norm, k)
            optimizer.step()
            batch.record(data, frames, means)
    finally:
        close_collector(collector)
    return batch.curves

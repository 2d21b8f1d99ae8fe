"""PPO on TorchRL's collectors with subgoal shaping.

One learner is one PPO agent: a policy (categorical for discrete actions,
``TanhNormal`` with a state-independent scale for bounded continuous ones) and
a value network, trained by TorchRL's :class:`~torchrl.objectives.ClipPPOLoss`
with :class:`~torchrl.objectives.value.GAE` advantages: every collected batch
is split into minibatches, ``epochs`` times over (GAE recomputed before each
epoch), through a TorchRL replay buffer that samples without replacement. The
env, the shaping transform and the potential's training are the shared
plumbing of :mod:`~torchrl_subgoal.training.common`::

    shaping = Shaping(series, TabularPotential(series.num_abstract_states))
    curve = train_ppo(make_env, PPOConfig(total_frames=500_000), shaping=shaping, seed=0)
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Literal

import torch
from tensordict.nn import AddStateIndependentNormalScale, TensorDictModule
from tensordict.utils import NestedKey
from torch import nn
from torchrl.data import Bounded, Categorical, LazyTensorStorage, OneHot, ReplayBuffer
from torchrl.data.replay_buffers import SamplerWithoutReplacement
from torchrl.envs import EnvBase
from torchrl.modules import ProbabilisticActor, TanhNormal, ValueOperator
from torchrl.objectives import ClipPPOLoss
from torchrl.objectives.value import GAE
from torchrl.record.loggers import Logger

from torchrl_subgoal.training.a2c import actor_critic
from torchrl_subgoal.training.batch import LearnerBatch, clip_grad_norm_per_learner, learner_means
from torchrl_subgoal.training.common import (
    CurveRecorder,
    Features,
    LearningCurve,
    Shaping,
    _close_probe,
    _network,
    _probe_env,
    _seed_collector,
    _subgoal_keys,
    _trunk,
    check_settings,
    close_collector,
    learner_env,
    make_collector,
    subgoal_states,
)

__all__ = ["PPOConfig", "ppo_actor_critic", "train_ppo", "train_ppo_batch"]


@dataclass
class PPOConfig:
    """Settings of one PPO learner.

    The PPO defaults are those of TorchRL's own PPO examples
    (``sota-implementations/ppo`` in the TorchRL repository; MuJoCo configuration:
    2,048 frames per batch, 10 epochs of minibatches of 64, Adam 3e-4 with ε 1e-5
    annealed linearly to 0, clip 0.2, GAE λ 0.95, γ 0.99, critic coefficient 0.25,
    no entropy bonus, an L2 critic loss, advantages standardised per minibatch,
    two hidden layers of 64 ``tanh`` units); the gradient clipping at 0.5 is their
    Atari configuration's (the MuJoCo one does not clip). Unlike the examples,
    the output layers start at zero (a uniform or centred policy, a zero value),
    as the A2C learner's do.

    Examples:
        >>> config = PPOConfig(num_envs=4, frames_per_batch=256, minibatch_size=64, total_frames=1024)
        >>> config.iterations, config.updates_per_batch
        (4, 40)
        >>> PPOConfig(frames_per_batch=256, minibatch_size=100)
        Traceback (most recent call last):
        ...
        ValueError: minibatch_size (100) must divide frames_per_batch (256)
    """

    num_envs: int = 8
    """envs per collecting process (the batch a collector steps)"""
    env_workers: int = 0
    """``ParallelEnv`` worker processes holding the envs (0: the batched env in the collecting process)"""
    collector_workers: int = 0
    """0: one ``Collector`` in this process; ``k``: a ``MultiSyncCollector`` of ``k`` processes"""
    frames_per_batch: int = 2048
    """frames per collected batch (over all collector workers)"""
    total_frames: int = 1_000_000
    """frames per learner"""
    gamma: float = 0.99
    """discount"""
    gae_lambda: float = 0.95
    """GAE's λ"""
    epochs: int = 10
    """passes over each collected batch"""
    minibatch_size: int = 64
    """frames per gradient step"""
    lr: float = 3e-4
    """Adam learning rate of the policy and the value network"""
    adam_eps: float = 1e-5
    """Adam's ε"""
    anneal_lr: bool = True
    """decrease the learning rate linearly to 0 over the learner's gradient steps"""
    clip_epsilon: float = 0.2
    """PPO's clip of the probability ratio"""
    critic_coeff: float = 0.25
    """weight of the value loss"""
    entropy_coeff: float = 0.0
    """entropy bonus (0: none)"""
    loss_critic_type: Literal["l2", "smooth_l1", "l1"] = "l2"
    """the value loss"""
    normalize_advantage: bool = True
    """standardise advantages per minibatch"""
    max_grad_norm: float = 0.5
    """gradient clipping (0: none)"""
    features: Features = "mlp"
    """the networks' input layer: ``"one_hot"`` (a categorical observation), ``"fourier"`` (a Fourier
    basis of a bounded observation) or ``"mlp"``"""
    hidden: tuple[int, ...] = (64, 64)
    """hidden layer sizes (``tanh``; ``()``: linear in the features)"""
    fourier_order: int = 3
    """order of the Fourier basis"""
    reward_scale: float = 1.0
    """the env reward is multiplied by this before shaping and learning (records keep the env's units)"""
    value_lr: float = 0.05
    """step size of the transform's online update, ``V(z) += value_lr * w * delta`` per closed SMDP
    transition (with ``online_potential=False``: the learning rate of the potential's optimiser)"""
    value_optimizer: Literal["adam", "sgd"] = "adam"
    """with ``online_potential=False``, the potential's optimiser: ``"adam"`` (loss reduction mean) or
    ``"sgd"`` (sum: the tabular update)"""
    online_potential: bool = True
    """train the potential in the transform at every step (the default: its step scales with the
    TD error, so it suits any reward scale; docs/does_it_help.md) instead of one optimiser step
    per batch on the batch's transitions"""
    record_window: int = 8
    """batches the recorded mean episode length is estimated over"""
    sees_subgoal: bool = False
    """the policy and the value network also read the subgoal index ``z`` (one-hot)"""

    def __post_init__(self) -> None:
        self.hidden = tuple(int(h) for h in self.hidden)
        check_settings(self)
        if self.features not in ("one_hot", "fourier", "mlp"):
            raise ValueError(f"features must be one_hot, fourier or mlp, got {self.features!r}")
        for name in ("epochs", "minibatch_size"):
            if getattr(self, name) < 1:
                raise ValueError(f"{name} must be >= 1, got {getattr(self, name)}")
        if self.frames_per_batch % self.minibatch_size:
            raise ValueError(
                f"minibatch_size ({self.minibatch_size}) must divide frames_per_batch ({self.frames_per_batch})"
            )
        for name in ("lr", "adam_eps", "clip_epsilon"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)}")
        for name in ("critic_coeff", "entropy_coeff", "max_grad_norm"):
            if getattr(self, name) < 0:
                raise ValueError(f"{name} must be >= 0, got {getattr(self, name)}")
        if not 0.0 <= self.gae_lambda <= 1.0:
            raise ValueError(f"gae_lambda must lie in [0, 1], got {self.gae_lambda}")
        if self.loss_critic_type not in ("l2", "smooth_l1", "l1"):
            raise ValueError(f"loss_critic_type must be l2, smooth_l1 or l1, got {self.loss_critic_type!r}")

    @property
    def iterations(self) -> int:
        """Collected batches per learner."""
        return math.ceil(self.total_frames / self.frames_per_batch)

    @property
    def updates_per_batch(self) -> int:
        """Gradient steps per collected batch."""
        return self.epochs * (self.frames_per_batch // self.minibatch_size)


def ppo_actor_critic(
    env: EnvBase,
    observation_key: NestedKey = "observation",
    *,
    features: Features = "mlp",
    hidden: Sequence[int] = (64, 64),
    fourier_order: int = 3,
    subgoal_states: int = 0,
) -> tuple[ProbabilisticActor, ValueOperator]:
    """A policy and a value network over ``observation_key`` for ``env``'s actions.

    Discrete actions (``Categorical``, ``OneHot``): a categorical policy (as
    :func:`~torchrl_subgoal.training.actor_critic`). Bounded continuous actions:
    a ``TanhNormal`` over the action bounds whose location is the network's
    output and whose scale is a learned state-independent parameter (starting
    at 1).

    Args:
        env: gives the observation and action specs.
        observation_key: the networks' input.
        features: ``"one_hot"``, ``"fourier"`` or ``"mlp"`` (see :class:`PPOConfig`).
        hidden: hidden layer sizes (``tanh``).
        fourier_order: order of the Fourier basis.
        subgoal_states: if positive, both networks also read ``"subgoal_index"`` (one-hot ``z``).

    Examples:
        >>> from torchrl.envs import GymEnv
        >>> env = GymEnv("Pendulum-v1")
        >>> actor, critic = ppo_actor_critic(env, hidden=(16,))
        >>> td = critic(actor(env.reset()))
        >>> td["action"].shape, bool(td["action"].abs().max() <= 2.0), td["state_value"].shape
        (torch.Size([1]), True, torch.Size([1]))
    """
    action_spec = env.full_action_spec[env.action_key]
    if isinstance(action_spec, Categorical | OneHot):
        return actor_critic(
            env,
            observation_key,
            features=features,
            hidden=hidden,
            fourier_order=fourier_order,
            subgoal_states=subgoal_states,
        )
    if not isinstance(action_spec, Bounded):
        raise ValueError(f"PPO here needs discrete or bounded continuous actions, got {type(action_spec).__name__}")
    spec = env.observation_spec[observation_key]
    action_size = int(action_spec.shape[-1])
    policy_trunk, size = _trunk(spec, features, hidden, fourier_order, subgoal_states=subgoal_states)
    value_trunk, _ = _trunk(spec, features, hidden, fourier_order, subgoal_states=subgoal_states)
    loc_head, value_head = nn.Linear(size, action_size), nn.Linear(size, 1)
    for last in (loc_head, value_head):  # start centred in the action bounds, with a zero value
        nn.init.zeros_(last.weight)
        nn.init.zeros_(last.bias)
    in_keys = _subgoal_keys(observation_key, subgoal_states)
    low, high = action_spec.space.low, action_spec.space.high
    while low.ndim > 1:
        low, high = low[0], high[0]
    policy = _network(policy_trunk, loc_head, AddStateIndependentNormalScale(action_size))
    actor = ProbabilisticActor(
        TensorDictModule(policy, in_keys=in_keys, out_keys=["loc", "scale"]),
        in_keys=["loc", "scale"],
        spec=action_spec,
        distribution_class=TanhNormal,
        distribution_kwargs={"low": low, "high": high, "tanh_loc": False},
        return_log_prob=True,
    )
    critic = ValueOperator(_network(value_trunk, value_head), in_keys=in_keys)
    return actor, critic


def train_ppo(
    make_env: Callable[[int], EnvBase],
    config: PPOConfig,
    *,
    shaping: Shaping | None = None,
    observation_key: NestedKey = "observation",
    seed: int = 0,
    episode_cap: float | None = None,
    logger: Logger | None = None,
    progress: Callable[[int], None] | None = None,
) -> LearningCurve:
    """Train one PPO learner on ``make_env(config.num_envs)`` (shaped by ``shaping``); its curve.

    Every batch: ``config.epochs`` passes, each recomputing GAE advantages with the
    current value network and taking one Adam step per minibatch of
    :class:`~torchrl.objectives.ClipPPOLoss`; then, unless the potential is trained
    online or fixed, one step of ``shaping.potential`` on the batch's real SMDP
    transitions with its own optimiser.

    Args:
        make_env: ``make_env(num_envs)`` returns an env with batch size ``[num_envs]``.
        config: the settings.
        shaping: the shaping transform's pieces (``None``: plain PPO).
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
        >>> config = PPOConfig(num_envs=4, frames_per_batch=64, minibatch_size=32, epochs=2, total_frames=128,
        ...                    features="one_hot", hidden=())
        >>> train_ppo(FourRoomsEnv, config, shaping=shaping, seed=0).frames
        [64, 128]
    """
    torch.manual_seed(seed)
    factory, trainer = learner_env(make_env, config, shaping)
    states = subgoal_states(config, shaping)
    probe, cap = _probe_env(make_env, episode_cap)
    actor, critic = ppo_actor_critic(
        probe,
        observation_key,
        features=config.features,
        hidden=config.hidden,
        fourier_order=config.fourier_order,
        subgoal_states=states,
    )
    _close_probe(probe)
    advantage = GAE(gamma=config.gamma, lmbda=config.gae_lambda, value_network=critic, average_gae=False)
    loss = ClipPPOLoss(
        actor,
        critic,
        clip_epsilon=config.clip_epsilon,
        entropy_bonus=config.entropy_coeff > 0,
        entropy_coeff=config.entropy_coeff,
        critic_coeff=config.critic_coeff,
        loss_critic_type=config.loss_critic_type,
        normalize_advantage=config.normalize_advantage,
    )
    optimizer = torch.optim.Adam(loss.parameters(), lr=config.lr, eps=config.adam_eps)
    minibatches = ReplayBuffer(
        storage=LazyTensorStorage(config.frames_per_batch),
        sampler=SamplerWithoutReplacement(),
        batch_size=config.minibatch_size,
    )
    total_updates = config.iterations * config.updates_per_batch
    collector = make_collector(factory, actor, config)
    _seed_collector(collector, seed)
    recorder = CurveRecorder(
        config.record_window, cap, config.reward_scale, logger, progress, shaping.potential if shaping else None
    )
    frames = updates = 0
    try:
        for data in collector:
            frames += data.numel()
            sums = torch.zeros(3)
            for _ in range(config.epochs):
                with torch.no_grad():
                    advantage(data)
                minibatches.extend(data.reshape(-1))
                for batch in minibatches:
                    if config.anneal_lr:
                        for group in optimizer.param_groups:
                            group["lr"] = config.lr * (1.0 - updates / total_updates)
                    losses = loss(batch)
                    parts = [
                        losses["loss_objective"],
                        losses["loss_critic"],
                        losses.get("loss_entropy", torch.zeros(())),
                    ]
                    optimizer.zero_grad(set_to_none=True)
                    sum(parts).backward()
                    if config.max_grad_norm:
                        nn.utils.clip_grad_norm_(loss.parameters(), config.max_grad_norm)
                    optimizer.step()
                    sums += torch.stack([p.detach() for p in parts])
                    updates += 1
            potential_loss = trainer.step(data) if trainer is not None else math.nan
            if config.collector_workers:
                collector.update_policy_weights_()
            means = (sums / config.updates_per_batch).tolist()
            recorder.add(
                data,
                frames,
                {
                    "loss_objective": means[0],
                    "loss_critic": means[1],
                    "loss_entropy": means[2],
                    "loss_potential": potential_loss,
                },
            )
    finally:
        close_collector(collector)
    return recorder.curve


def train_ppo_batch(
    make_env: Callable[[int], EnvBase],
    config: PPOConfig,
    seeds: Sequence[int],
    *,
    shapings: Sequence[Shaping | None] | None = None,
    observation_key: NestedKey = "observation",
    episode_cap: float | None = None,
    loggers: Sequence[Logger | None] | None = None,
    progress: Callable[[int], None] | None = None,
) -> list[LearningCurve]:
    """Train ``len(seeds)`` independent PPO learners as one batch; each learner's curve.

    Learner ``k`` is :func:`train_ppo` with ``config``, ``shapings[k]`` and ``seeds[k]``: its own
    networks (started as alone from its seed), envs and table (trained online), and every gradient
    step on a minibatch of its own frames, with its advantages standardised over its own minibatch,
    its own gradient clipping and Adam state. The learners share one env batch, one collector and
    one optimiser step per minibatch (:class:`~torchrl_subgoal.training.batch.LearnerBatch`): each
    step takes every learner's minibatch at the same positions of its own batch, in a fresh random
    order every epoch. Statistically, not bitwise, equal to the learners run one by one.

    Args:
        make_env: ``make_env(num_envs)`` returns an env with batch size ``[num_envs]`` (every learner's task).
        config: every learner's settings (``collector_workers=0``; with a trained potential,
            ``online_potential=True``).
        seeds: one per learner: its networks' initial weights.
        shapings: one per learner (``None``: all unshaped).
        observation_key: what the networks read.
        episode_cap: as in :func:`train_ppo`.
        loggers: one TorchRL logger per learner (or ``None``).
        progress: called with 1 after every batch for every learner.

    Examples:
        >>> from torchrl_subgoal import Cell, SubgoalSeries, TabularPotential
        >>> from torchrl_subgoal.envs import FourRoomsEnv
        >>> shapings = [Shaping(SubgoalSeries([Cell(3, 6)]), TabularPotential(2), {"observation_key": "cell"})] * 2
        >>> config = PPOConfig(num_envs=4, frames_per_batch=64, minibatch_size=32, epochs=2, total_frames=128,
        ...                    features="one_hot", hidden=())
        >>> [c.frames for c in train_ppo_batch(FourRoomsEnv, config, [0, 1], shapings=shapings)]
        [[64, 128], [64, 128]]
    """
    batch = LearnerBatch(
        make_env, config, seeds, shapings=shapings, loggers=loggers, progress=progress, episode_cap=episode_cap
    )
    k, states = batch.learners, batch.subgoal_states
    actor, critic = batch.networks(
        lambda env, key: ppo_actor_critic(
            env,
            key,
            features=config.features,
            hidden=config.hidden,
            fourier_order=config.fourier_order,
            subgoal_states=states,
        ),
        observation_key,
    )
    advantage = GAE(gamma=config.gamma, lmbda=config.gae_lambda, value_network=critic, average_gae=False)
    loss = ClipPPOLoss(
        actor,
        critic,
        clip_epsilon=config.clip_epsilon,
        entropy_bonus=config.entropy_coeff > 0,
        entropy_coeff=config.entropy_coeff,
        critic_coeff=config.critic_coeff,
        loss_critic_type=config.loss_critic_type,
        normalize_advantage=config.normalize_advantage,
        normalize_advantage_exclude_dims=(0,),  # minibatches are [K, size]: standardised learner by learner
        reduction="none",
    )
    optimizer = torch.optim.Adam(loss.parameters(), lr=config.lr, eps=config.adam_eps)
    total_updates = config.iterations * config.updates_per_batch
    names = ("loss_objective", "loss_critic", "loss_entropy")
    collector = batch.collector(actor)
    frames = updates = 0
    try:
        for data in collector:
            frames += data.numel() // k
            sums = torch.zeros(3, k)
            for _ in range(config.epochs):
                with torch.no_grad():
                    advantage(data)
                own = data.reshape(k, -1)  # each learner's frames (its envs are consecutive rows)
                order = torch.randperm(own.shape[1])
                for start in range(0, own.shape[1], config.minibatch_size):
                    if config.anneal_lr:
                        for group in optimizer.param_groups:
                            group["lr"] = config.lr * (1.0 - updates / total_updates)
                    losses = loss(own[:, order[start : start + config.minibatch_size]])
                    parts = torch.stack([learner_means(losses.get(n, torch.zeros(k)), k) for n in names])
                    optimizer.zero_grad(set_to_none=True)
                    parts.sum().backward()
                    if config.max_grad_norm:
                        clip_grad_norm_per_learner(loss.parameters(), config.max_grad_norm, k)
                    optimizer.step()
                    sums += parts.detach()
                    updates += 1
            means = sums / config.updates_per_batch
            batch.record(data, frames, dict(zip(names, means, strict=True)))
    finally:
        close_collector(collector)
    return batch.curves

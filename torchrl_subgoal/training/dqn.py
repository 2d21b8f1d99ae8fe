"""DQN on TorchRL's collectors with subgoal shaping.

One learner is one DQN agent: an MLP Q-network (a TorchRL
:class:`~torchrl.modules.QValueActor`), explored ε-greedily by TorchRL's
:class:`~torchrl.modules.EGreedyModule` (ε annealed linearly over collected
frames), trained by :class:`~torchrl.objectives.DQNLoss` (double DQN optional)
on samples of a TorchRL replay buffer, against a target network that TorchRL's
:class:`~torchrl.objectives.HardUpdate` (or :class:`~torchrl.objectives.SoftUpdate`)
keeps. The env, the shaping transform and the potential's training are the
shared plumbing of :mod:`~torchrl_subgoal.training.common`; with
``reshape_samples`` every replay sample is re-shaped with the potential as it is
now (:class:`~torchrl_subgoal.training.SampleReshaper`) before the loss reads it::

    shaping = Shaping(series, TabularPotential(series.num_abstract_states))
    curve = train_dqn(make_env, DQNConfig.preset("mountain_car"), shaping=shaping, seed=0)
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Literal

import torch
from tensordict.nn import TensorDictSequential
from tensordict.utils import NestedKey
from torch import nn
from torchrl.data import Categorical, LazyTensorStorage, OneHot, ReplayBuffer
from torchrl.data.replay_buffers import RandomSampler
from torchrl.envs import EnvBase
from torchrl.modules import EGreedyModule, QValueActor
from torchrl.objectives import DQNLoss, HardUpdate, SoftUpdate
from torchrl.record.loggers import Logger

from torchrl_subgoal.training.common import (
    CurveRecorder,
    Features,
    LearningCurve,
    SampleReshaper,
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

__all__ = ["DQN_PRESETS", "DQNConfig", "q_network", "train_dqn"]

#: Named settings (overrides of :class:`DQNConfig`'s defaults, which are TorchRL's DQN example's).
DQN_PRESETS: dict[str, dict[str, Any]] = {
    "torchrl": {},
    # rl-baselines3-zoo's tuned DQN hyper-parameters for MountainCar-v0 (hyperparams/dqn.yml): 1.2e5 steps,
    # lr 4e-3, batch 128, buffer 1e4, learning starts 1e3, γ 0.98, target update every 600 steps, train every
    # 16 steps with 8 gradient steps, ε annealed over 20% of the run to 0.07, [256, 256] hidden; the rest
    # are Stable-Baselines3's DQN defaults (Huber loss, gradients clipped at norm 10, ε from 1).
    "mountain_car": {
        "num_envs": 1,
        "frames_per_batch": 16,
        "gradient_steps": 8,
        "total_frames": 120_000,
        "lr": 4e-3,
        "batch_size": 128,
        "buffer_size": 10_000,
        "learning_starts": 1_000,
        "gamma": 0.98,
        "target_update_interval": 300,  # gradient steps: 600 frames at 8 gradient steps per 16 frames
        "eps_init": 1.0,
        "eps_end": 0.07,
        "exploration_frames": 24_000,
        "hidden": (256, 256),
        "loss_function": "smooth_l1",
        "max_grad_norm": 10.0,
        "record_window": 100,  # 1,600 frames: the recorded episode length spans several 200-step episodes
    },
}


@dataclass
class DQNConfig:
    """Settings of one DQN learner.

    The defaults are those of TorchRL's own DQN example (``sota-implementations/dqn``
    in the TorchRL repository, CartPole configuration: one env, 1,000 frames per
    batch and 100 gradient steps after each, batches of 128 from a buffer of 10,000,
    10,000 random frames first, Adam 2.5e-4, gradients clipped at norm 10, γ 0.99,
    an L2 loss, the target network copied every 50 gradient steps, ε from 1 to
    0.05 over 250,000 frames, a ReLU MLP with hidden layers of 120 and 84 units).
    :data:`DQN_PRESETS` holds other named settings (``DQNConfig.preset(name)``):
    ``"mountain_car"`` is rl-baselines3-zoo's for ``MountainCar-v0``.

    Examples:
        >>> config = DQNConfig.preset("mountain_car")
        >>> config.lr, config.hidden, config.exploration_frames, config.iterations
        (0.004, (256, 256), 24000, 7500)
        >>> DQNConfig(target_update="soft", tau=0.0)
        Traceback (most recent call last):
        ...
        ValueError: tau must lie in (0, 1], got 0.0
    """

    num_envs: int = 1
    """envs per collecting process (the batch a collector steps)"""
    env_workers: int = 0
    """``ParallelEnv`` worker processes holding the envs (0: the batched env in the collecting process)"""
    collector_workers: int = 0
    """0: one ``Collector`` in this process; ``k``: a ``MultiSyncCollector`` of ``k`` processes"""
    frames_per_batch: int = 1000
    """frames per collected batch (over all collector workers): the training frequency"""
    total_frames: int = 500_000
    """frames per learner"""
    gamma: float = 0.99
    """discount"""
    learning_starts: int = 10_000
    """frames collected with uniformly random actions before the first gradient step"""
    gradient_steps: int = 100
    """gradient steps after each collected batch"""
    batch_size: int = 128
    """transitions per gradient step"""
    buffer_size: int = 10_000
    """replay capacity (transitions)"""
    lr: float = 2.5e-4
    """Adam learning rate of the Q-network"""
    max_grad_norm: float = 10.0
    """gradient clipping (0: none)"""
    loss_function: Literal["l2", "smooth_l1", "l1"] = "l2"
    """the TD loss"""
    double_dqn: bool = False
    """double DQN: the online network picks the next action, the target network values it"""
    target_update: Literal["hard", "soft"] = "hard"
    """``"hard"``: copy the online network every ``target_update_interval`` gradient steps;
    ``"soft"``: Polyak averaging with ``tau`` after every gradient step"""
    target_update_interval: int = 50
    """gradient steps between hard target updates"""
    tau: float = 0.005
    """soft target updates: target <- (1 - tau) * target + tau * online"""
    eps_init: float = 1.0
    """ε at the start"""
    eps_end: float = 0.05
    """ε after ``exploration_frames``"""
    exploration_frames: int = 250_000
    """frames over which ε decreases linearly"""
    features: Features = "mlp"
    """the Q-network's input layer: ``"one_hot"`` (a categorical observation), ``"fourier"``
    (a Fourier basis of a bounded observation) or ``"mlp"``"""
    hidden: tuple[int, ...] = (120, 84)
    """hidden layer sizes (ReLU)"""
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
    sees_subgoal: bool | None = None
    """the Q-network also reads the subgoal index ``z`` (one-hot); ``None`` (the default): whenever a
    shaping transform keeps it. A Q-network over ``s`` alone learns a blend of the shaped values under
    every ``z``: HRS was significantly slower than DQN without ``z`` on four-rooms and MountainCar,
    not with it (docs/does_it_help.md)"""
    reshape_samples: bool = False
    """re-shape every replay sample with the potential as it is now before the loss (else the loss reads
    the reward shaped at collection)"""

    def __post_init__(self) -> None:
        self.hidden = tuple(int(h) for h in self.hidden)
        check_settings(self)
        if self.features not in ("one_hot", "fourier", "mlp"):
            raise ValueError(f"features must be one_hot, fourier or mlp, got {self.features!r}")
        for name in ("gradient_steps", "batch_size", "buffer_size", "target_update_interval", "exploration_frames"):
            if getattr(self, name) < 1:
                raise ValueError(f"{name} must be >= 1, got {getattr(self, name)}")
        if self.learning_starts < 0:
            raise ValueError(f"learning_starts must be >= 0, got {self.learning_starts}")
        if not self.lr > 0:
            raise ValueError(f"lr must be > 0, got {self.lr}")
        if self.max_grad_norm < 0:
            raise ValueError(f"max_grad_norm must be >= 0, got {self.max_grad_norm}")
        if not 0.0 < self.tau <= 1.0:
            raise ValueError(f"tau must lie in (0, 1], got {self.tau}")
        for name in ("eps_init", "eps_end"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise ValueError(f"{name} must lie in [0, 1], got {getattr(self, name)}")
        if self.eps_end > self.eps_init:
            raise ValueError(f"eps_end ({self.eps_end}) must not exceed eps_init ({self.eps_init})")
        if self.loss_function not in ("l2", "smooth_l1", "l1"):
            raise ValueError(f"loss_function must be l2, smooth_l1 or l1, got {self.loss_function!r}")
        if self.target_update not in ("hard", "soft"):
            raise ValueError(f"target_update must be hard or soft, got {self.target_update!r}")

    @classmethod
    def preset(cls, name: str, **overrides: Any) -> DQNConfig:
        """The settings of :data:`DQN_PRESETS` ``[name]``, with ``overrides``.

        Args:
            name: a key of :data:`DQN_PRESETS`.
            **overrides: fields to set differently.
        """
        if name not in DQN_PRESETS:
            raise ValueError(f"unknown DQN preset {name!r}; known: {', '.join(DQN_PRESETS)}")
        return cls(**{**DQN_PRESETS[name], **overrides})

    @property
    def iterations(self) -> int:
        """Collected batches per learner."""
        return math.ceil(self.total_frames / self.frames_per_batch)


def q_network(
    env: EnvBase,
    observation_key: NestedKey = "observation",
    *,
    features: Features = "mlp",
    hidden: Sequence[int] = (120, 84),
    fourier_order: int = 3,
    subgoal_states: int = 0,
) -> QValueActor:
    """A Q-network over ``observation_key`` for ``env``'s discrete actions: a ReLU MLP, one output per
    action, as TorchRL's ``QValueActor`` (writes ``"action_value"``, ``"chosen_action_value"`` and the
    greedy ``"action"``). With one-hot features and no hidden layer it is a Q-table: the output layer has
    no bias.

    Args:
        env: gives the observation and action specs.
        observation_key: the network's input.
        features: ``"one_hot"``, ``"fourier"`` or ``"mlp"`` (see :class:`DQNConfig`).
        hidden: hidden layer sizes.
        fourier_order: order of the Fourier basis.
        subgoal_states: if positive, the network also reads ``"subgoal_index"`` (one-hot ``z``).

    Examples:
        >>> from torchrl.envs import GymEnv
        >>> env = GymEnv("MountainCar-v0")
        >>> q = q_network(env, hidden=(16,))
        >>> td = q(env.reset())
        >>> td["action_value"].shape, td["action"].shape
        (torch.Size([3]), torch.Size([3]))
    """
    action_spec = env.full_action_spec_unbatched[env.action_key]
    if not isinstance(action_spec, Categorical | OneHot):
        raise ValueError(f"DQN needs discrete actions (Categorical or OneHot), got {type(action_spec).__name__}")
    spec = env.observation_spec[observation_key]
    trunk, size = _trunk(spec, features, hidden, fourier_order, activation=nn.ReLU, subgoal_states=subgoal_states)
    # one-hot features and no hidden layer: a Q-table; a bias would give every state's value of an action a
    # shared term (four-rooms: greedy loops through rarely visited cells valued at that term)
    table = features == "one_hot" and not hidden
    net = _network(trunk, nn.Linear(size, int(action_spec.space.n), bias=not table))
    return QValueActor(net, in_keys=_subgoal_keys(observation_key, subgoal_states), spec=action_spec)


def train_dqn(
    make_env: Callable[[int], EnvBase],
    config: DQNConfig,
    *,
    shaping: Shaping | None = None,
    observation_key: NestedKey = "observation",
    seed: int = 0,
    episode_cap: float | None = None,
    logger: Logger | None = None,
    progress: Callable[[int], None] | None = None,
) -> LearningCurve:
    """Train one DQN learner on ``make_env(config.num_envs)`` (shaped by ``shaping``); its curve.

    Every batch: store it in the replay buffer, anneal ε, and (once
    ``learning_starts`` frames are collected) take ``gradient_steps`` Adam steps
    of :class:`~torchrl.objectives.DQNLoss` on replay samples (re-shaped with the
    current potential when ``reshape_samples``), updating the target network;
    then, unless the potential is trained online or fixed, one step of
    ``shaping.potential`` on the batch's real SMDP transitions.

    Args:
        make_env: ``make_env(num_envs)`` returns an env with batch size ``[num_envs]``.
        config: the settings.
        shaping: the shaping transform's pieces (``None``: plain DQN).
        observation_key: what the Q-network reads.
        seed: seeds torch (networks, sampling, exploration) and the envs.
        episode_cap: what the curve records before any episode finished (default: the env's
            ``max_steps`` when it has one).
        logger: a TorchRL logger (CSV, TensorBoard…) for losses and episode statistics.
        progress: called with 1 after every batch.

    Examples:
        >>> from torchrl_subgoal.envs import FourRoomsEnv
        >>> config = DQNConfig(num_envs=4, frames_per_batch=64, total_frames=256, learning_starts=64,
        ...                    gradient_steps=2, batch_size=32, features="one_hot", hidden=(16,))
        >>> train_dqn(FourRoomsEnv, config, seed=0).frames
        [64, 128, 192, 256]
    """
    if config.reshape_samples and shaping is None:
        raise ValueError("reshape_samples needs shaping: there is no potential to re-shape samples with")
    torch.manual_seed(seed)
    factory, trainer = learner_env(make_env, config, shaping)
    states = subgoal_states(config, shaping)
    probe, cap = _probe_env(make_env, episode_cap)
    qnet = q_network(
        probe,
        observation_key,
        features=config.features,
        hidden=config.hidden,
        fourier_order=config.fourier_order,
        subgoal_states=states,
    )
    action_spec = probe.full_action_spec_unbatched[probe.action_key]
    _close_probe(probe)
    explore = EGreedyModule(
        action_spec, eps_init=config.eps_init, eps_end=config.eps_end, annealing_num_steps=config.exploration_frames
    )
    policy = TensorDictSequential(qnet, explore)
    loss = DQNLoss(
        qnet,
        loss_function=config.loss_function,
        delay_value=True,
        double_dqn=config.double_dqn,
        action_space=action_spec,
    )
    loss.make_value_estimator(gamma=config.gamma)
    updater = (
        HardUpdate(loss, value_network_update_interval=config.target_update_interval)
        if config.target_update == "hard"
        else SoftUpdate(loss, tau=config.tau)
    )
    optimizer = torch.optim.Adam(loss.parameters(), lr=config.lr)
    reshaper = None
    keys: list[NestedKey] = list(loss.in_keys)
    if config.reshape_samples:
        assert shaping is not None
        reshaper = SampleReshaper(shaping.transform(shaping.potential, config.gamma, None))
        keys += reshaper.keys
    keys = list(dict.fromkeys(keys))
    replay = ReplayBuffer(
        storage=LazyTensorStorage(config.buffer_size), sampler=RandomSampler(), batch_size=config.batch_size
    )
    collector = make_collector(factory, policy, config, init_random_frames=config.learning_starts)
    _seed_collector(collector, seed)
    recorder = CurveRecorder(
        config.record_window, cap, config.reward_scale, logger, progress, shaping.potential if shaping else None
    )
    frames = 0
    parameters = list(loss.parameters())
    try:
        for data in collector:
            frames += data.numel()
            replay.extend(data.select(*keys).reshape(-1))
            explore.step(data.numel())
            q_loss = math.nan
            if frames >= config.learning_starts:
                total = torch.zeros(())
                for _ in range(config.gradient_steps):
                    sample = replay.sample()
                    if reshaper is not None:
                        sample = reshaper(sample)
                    out = loss(sample)["loss"]
                    optimizer.zero_grad(set_to_none=True)
                    out.backward()
                    if config.max_grad_norm:
                        nn.utils.clip_grad_norm_(parameters, config.max_grad_norm)
                    optimizer.step()
                    updater.step()
                    total += out.detach()
                q_loss = float(total) / config.gradient_steps
            potential_loss = trainer.step(data) if trainer is not None else math.nan
            if config.collector_workers:
                collector.update_policy_weights_()
            recorder.add(
                data, frames, {"loss_q": q_loss, "epsilon": float(explore.eps), "loss_potential": potential_loss}
            )
    finally:
        close_collector(collector)
    return recorder.curve

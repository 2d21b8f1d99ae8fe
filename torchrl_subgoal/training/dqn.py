"""DQN on TorchRL's collectors with subgoal shaping: ``K`` learners as one batch (one is a batch of one).

One learner is one DQN agent: an MLP Q-network (a TorchRL
:class:`~torchrl.modules.QValueActor`), explored ε-greedily by TorchRL's
:class:`~torchrl.modules.EGreedyModule` (ε annealed linearly over each learner's
frames), trained by :class:`~torchrl.objectives.DQNLoss` (double DQN optional)
on samples of its replay buffer, against a target network that TorchRL's
:class:`~torchrl.objectives.HardUpdate` (or :class:`~torchrl.objectives.SoftUpdate`)
keeps. ``K`` learners train as one program (:mod:`~torchrl_subgoal.training.batch`):
stacked Q-networks and targets, one replay buffer with a learner dim
(:class:`~torchrl_subgoal.training.LearnerReplay`: each learner samples its own
transitions), each learner its own loss mean, gradient clipping and Adam state.
With ``reshape_samples`` every replay sample is re-shaped with the potential as it
is now (:class:`~torchrl_subgoal.training.SampleReshaper`) before the loss reads it::

    shaping = Shaping(series, TabularPotential.for_subgoals(series))
    trained = train_dqn(make_env, DQNConfig.preset("mountain_car"), seeds=range(10), shaping=shaping)
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Literal, Unpack

import torch
from tensordict import TensorDictBase
from tensordict.nn import TensorDictSequential
from tensordict.utils import NestedKey
from torch import nn
from torchrl.data import TensorSpec
from torchrl.envs import EnvBase
from torchrl.modules import EGreedyModule, QValueActor
from torchrl.objectives import DQNLoss, HardUpdate, SoftUpdate

from torchrl_subgoal.training.batch import (
    LearnerBatch,
    LearnerOptions,
    LearnerReplay,
    LearnerStack,
    clip_grad_norm_per_learner,
    learner_means,
    seeded,
)
from torchrl_subgoal.training.config import NetworkConfig, OffPolicyConfig, frames_of
from torchrl_subgoal.training.networks import q_network
from torchrl_subgoal.training.result import Trained

__all__ = ["DQN_PRESETS", "DQNConfig", "DQNUpdate", "dqn_modules", "train_dqn"]

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
class DQNConfig(NetworkConfig, OffPolicyConfig):
    """Settings of a DQN learner (the shared ones: :class:`~torchrl_subgoal.training.LearnerConfig`).

    The defaults are those of TorchRL's own DQN example (``sota-implementations/dqn``
    in the TorchRL repository, CartPole configuration: one env, 1,000 frames per
    batch and 100 gradient steps after each, batches of 128 from a buffer of 10,000,
    Adam 2.5e-4, gradients clipped at norm 10, γ 0.99, an L2 loss, the target network
    copied every 50 gradient steps, ε from 1 to 0.05, a ReLU MLP with hidden layers of
    120 and 84 units), with the warm-up and the exploration schedule as fractions of
    the budget (the example's 10,000 random frames first and ε annealed over 250,000
    are 2% and 50% of its 500,000): a short run needs only ``total_frames``.
    :data:`DQN_PRESETS` holds other named settings (``DQNConfig.preset(name)``):
    ``"mountain_car"`` is rl-baselines3-zoo's for ``MountainCar-v0``.

    Examples:
        >>> config = DQNConfig.preset("mountain_car")
        >>> config.lr, config.hidden, config.exploration_steps, config.iterations
        (0.004, (256, 256), 24000, 7500)
        >>> small = DQNConfig(total_frames=20_000)
        >>> small.warmup_frames, small.exploration_steps
        (400, 10000)
        >>> DQNConfig(target_update="soft", tau=0.0)
        Traceback (most recent call last):
        ...
        ValueError: tau must lie in (0, 1], got 0.0
    """

    frames_per_batch: int = 1000
    total_frames: int = 500_000
    lr: float = 2.5e-4
    hidden: tuple[int, ...] = (120, 84)
    max_grad_norm: float = 10.0
    sees_subgoal: bool | None = None
    """the Q-network also reads the subgoal index ``z`` (one-hot); ``None`` (the default): whenever a
    shaping transform keeps it. A Q-network over ``s`` alone learns a blend of the shaped values under
    every ``z``: HRS was significantly slower than DQN without ``z`` on four-rooms and MountainCar,
    not with it (docs/does_it_help.md)"""
    batch_size: int = 128
    buffer_size: int = 10_000
    gradient_steps: int = 100
    """gradient steps after each collected batch"""
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
    exploration_frames: float = 0.5
    """frames over which ε decreases linearly (a value below 1: that fraction of ``total_frames``)"""

    def check(self) -> None:
        super().check()
        if self.eps_end > self.eps_init:
            raise ValueError(f"eps_end ({self.eps_end}) must not exceed eps_init ({self.eps_init})")

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
    def exploration_steps(self) -> int:
        """Frames over which ε anneals (``exploration_frames`` resolved)."""
        return max(1, frames_of(self.exploration_frames, self.total_frames))


def dqn_modules(
    env: EnvBase,
    config: DQNConfig,
    observation_key: NestedKey = "observation",
    subgoal_states: int = 0,
    seeds: Sequence[int] = (0,),
) -> dict[str, nn.Module]:
    """The Q-networks of ``len(seeds)`` DQN learners, each started from its seed, stacked: ``"q"``, also the
    greedy ``"policy"``.

    Examples:
        >>> from torchrl_subgoal.envs import FourRoomsEnv
        >>> q = dqn_modules(FourRoomsEnv(1), DQNConfig(features="one_hot", hidden=(8,)), seeds=[0, 1])["q"]
        >>> q(FourRoomsEnv(6).reset())["action_value"].shape  # 2 learners x 3 envs, 4 actions
        torch.Size([6, 4])
    """
    options = config.network_options()
    nets = seeded(seeds, lambda: q_network(env, observation_key, subgoal_states=subgoal_states, **options))
    q = nets[0]
    q.module[0].module = LearnerStack([n.module[0].module for n in nets])
    return {"q": q, "policy": q}


class DQNUpdate:
    """One DQN gradient step of ``K`` learners on a replay sample: TorchRL's :class:`~torchrl.objectives.DQNLoss`
    per sample against the target networks, each learner's mean, its own gradient clipping and Adam state,
    then the target update (:class:`~torchrl.objectives.HardUpdate` or :class:`~torchrl.objectives.SoftUpdate`).

    Args:
        q: the learners' stacked Q-network (:func:`dqn_modules`).
        config: the settings.
        action_spec: the env's (unbatched) discrete action spec.
        learners: ``K``.

    Examples:
        >>> from torchrl_subgoal.envs import FourRoomsEnv
        >>> env, config = FourRoomsEnv(4), DQNConfig(features="one_hot", hidden=())
        >>> q = dqn_modules(env, config, seeds=[0, 1])["q"]
        >>> update = DQNUpdate(q, config, env.full_action_spec_unbatched["action"], learners=2)
        >>> sample = env.rollout(3, q).reshape(2, -1)  # [K, B]: each learner's transitions
        >>> update(sample).shape  # each learner's loss
        torch.Size([2])
    """

    def __init__(self, q: QValueActor, config: DQNConfig, action_spec: TensorSpec, learners: int) -> None:
        self.learners, self.max_grad_norm = learners, config.max_grad_norm
        self.loss = DQNLoss(
            q,
            loss_function=config.loss_function,
            delay_value=True,
            double_dqn=config.double_dqn,
            action_space=action_spec,
            reduction="none",
        )
        self.loss.make_value_estimator(gamma=config.gamma)
        self.target = (
            HardUpdate(self.loss, value_network_update_interval=config.target_update_interval)
            if config.target_update == "hard"
            else SoftUpdate(self.loss, tau=config.tau)
        )
        self.optimizer = torch.optim.Adam(self.loss.parameters(), lr=config.lr, fused=True)  # one kernel
        self.parameters = list(self.loss.parameters())

    def __call__(self, sample: TensorDictBase) -> torch.Tensor:
        """One step on ``sample`` (``[K, B]``: learner ``k``'s transitions in row ``k``); each learner's loss."""
        means = learner_means(self.loss(sample)["loss"], self.learners)
        self.optimizer.zero_grad(set_to_none=True)
        means.sum().backward()
        if self.max_grad_norm:
            clip_grad_norm_per_learner(self.parameters, self.max_grad_norm, self.learners)
        self.optimizer.step()
        self.target.step()
        return means.detach()


def train_dqn(
    make_env: Callable[[int], EnvBase] | Sequence[Callable[[int], EnvBase]],
    config: DQNConfig,
    **options: Unpack[LearnerOptions],
) -> Trained:
    """Train ``len(seeds)`` DQN learners as one batch on ``make_env`` (shaped by ``shaping``).

    Every batch: store it in the replay buffer (every learner its own transitions), anneal ε, and (once
    ``learning_starts`` frames per learner are collected) take ``gradient_steps`` steps of :class:`DQNUpdate`
    on replay samples (re-shaped with the current potential when ``reshape_samples``); then, unless the
    potential is trained online or fixed, one step of the potential on the batch's real SMDP transitions
    (one learner only).

    ``make_env``, ``config`` and ``**options`` (``seeds``, ``shaping``…): as for
    :func:`~torchrl_subgoal.training.train_a2c`.

    Examples:
        >>> from torchrl_subgoal.envs import FourRoomsEnv
        >>> config = DQNConfig(num_envs=4, frames_per_batch=64, total_frames=256, gradient_steps=2, batch_size=32,
        ...                    features="one_hot", hidden=(16,))
        >>> [c.frames for c in train_dqn(FourRoomsEnv, config, seeds=[0, 1]).curves]
        [[64, 128, 192, 256], [64, 128, 192, 256]]
    """
    if config.reshape_samples and options.get("shaping") is None:
        raise ValueError("reshape_samples needs shaping: there is no potential to re-shape samples with")
    batch = LearnerBatch(make_env, config, **options)
    k = batch.learners
    action_spec = batch.probe.full_action_spec_unbatched[batch.probe.action_key]
    modules = batch.modules(dqn_modules)
    q = modules["q"]
    explore = EGreedyModule(
        action_spec, eps_init=config.eps_init, eps_end=config.eps_end, annealing_num_steps=config.exploration_steps
    ).to(batch.device)
    update = DQNUpdate(q, config, action_spec, k)
    reshaper = batch.reshaper() if config.reshape_samples else None
    keys = [*update.loss.in_keys, *(reshaper.keys if reshaper is not None else [])]
    replay = LearnerReplay(k, config.buffer_size, config.batch_size, keys, batch.device)
    warmup = config.warmup_frames
    for data in batch.collect(TensorDictSequential(q, explore), init_random_frames=warmup):
        replay.extend(data)
        explore.step(data.numel() // k)
        q_loss = torch.full((k,), float("nan"))
        if batch.frames >= warmup:
            q_loss = torch.zeros(k, device=batch.device)
            for _ in range(config.gradient_steps):
                sample = replay.sample()
                q_loss += update(reshaper(sample) if reshaper is not None else sample)
            q_loss /= config.gradient_steps
        batch.record(data, {"loss_q": q_loss, "epsilon": float(explore.eps)})
    return batch.result("dqn", modules)

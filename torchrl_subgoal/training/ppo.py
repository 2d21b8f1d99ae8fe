"""PPO on TorchRL's collectors with subgoal shaping: ``K`` learners as one batch (one is a batch of one).

One learner is one PPO agent: a policy (categorical for discrete actions,
``TanhNormal`` with a state-independent scale for bounded continuous ones) and
a value network, trained by TorchRL's :class:`~torchrl.objectives.ClipPPOLoss`
with :class:`~torchrl.objectives.value.GAE` advantages: every collected batch
is split into minibatches, ``epochs`` times over (GAE recomputed before each
epoch). ``K`` learners train as one program (:mod:`~torchrl_subgoal.training.batch`):
each gradient step takes every learner's minibatch at the same positions of its
own frames, with its advantages standardised over its own minibatch, its own
clipping and Adam state::

    shaping = Shaping(series, TabularPotential.for_subgoals(series))
    trained = train_ppo(make_env, PPOConfig(total_frames=500_000), seeds=range(10), shaping=shaping)
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Literal, Unpack

import torch
from tensordict import TensorDictBase
from torchrl.envs import EnvBase
from torchrl.modules import ProbabilisticActor, ValueOperator
from torchrl.objectives import ClipPPOLoss
from torchrl.objectives.value import GAE

from torchrl_subgoal.training.batch import (
    LearnerOptions,
    clip_grad_norm_per_learner,
    learner_means,
)
from torchrl_subgoal.training.config import ActorCriticConfig
from torchrl_subgoal.training.on_policy import actor_critic, train_on_policy
from torchrl_subgoal.training.result import Trained

__all__ = ["PPOConfig", "PPOUpdate", "ppo_actor_critic", "train_ppo"]

#: The policy and value network of a PPO learner: :func:`~torchrl_subgoal.training.actor_critic`.
ppo_actor_critic = actor_critic


@dataclass
class PPOConfig(ActorCriticConfig):
    """Settings of a PPO learner (the shared ones: :class:`~torchrl_subgoal.training.LearnerConfig`).

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
    frames_per_batch: int = 2048
    total_frames: int = 1_000_000
    lr: float = 3e-4
    hidden: tuple[int, ...] = (64, 64)
    max_grad_norm: float = 0.5
    gae_lambda: float = 0.95
    """GAE's λ"""
    epochs: int = 10
    """passes over each collected batch"""
    minibatch_size: int = 64
    """frames per learner per gradient step"""
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
    """standardise advantages per minibatch (each learner's over its own)"""

    def check(self) -> None:
        super().check()
        if self.frames_per_batch % self.minibatch_size:
            raise ValueError(
                f"minibatch_size ({self.minibatch_size}) must divide frames_per_batch ({self.frames_per_batch})"
            )

    @property
    def updates_per_batch(self) -> int:
        """Gradient steps per collected batch."""
        return self.epochs * (self.frames_per_batch // self.minibatch_size)


class PPOUpdate:
    """PPO's epochs of ``K`` learners on a collected batch: GAE advantages before each epoch, then one Adam
    step per minibatch of TorchRL's :class:`~torchrl.objectives.ClipPPOLoss` (every learner its own minibatch
    of its own frames, its advantages standardised over it, its own clipping and Adam state), the learning
    rate annealed over the learner's ``total_updates`` steps.

    Args:
        actor: the learners' stacked actor (:func:`~torchrl_subgoal.training.actor_critic_modules`).
        critic: their stacked critic.
        config: the settings.
        learners: ``K``.

    Examples:
        >>> from torchrl_subgoal.envs import FourRoomsEnv
        >>> from torchrl_subgoal.training import actor_critic_modules
        >>> config = PPOConfig(num_envs=2, frames_per_batch=10, minibatch_size=5, epochs=2, features="one_hot")
        >>> modules = actor_critic_modules(FourRoomsEnv(1), config, seeds=[0, 1])
        >>> update = PPOUpdate(modules["actor"], modules["critic"], config, learners=2)
        >>> with torch.no_grad():  # what a collector does
        ...     data = FourRoomsEnv(4).rollout(5, modules["actor"], break_when_any_done=False)
        >>> update(data)["loss_critic"].shape  # each learner's mean loss
        torch.Size([2])
    """

    NAMES = ("loss_objective", "loss_critic", "loss_entropy")

    def __init__(self, actor: ProbabilisticActor, critic: ValueOperator, config: PPOConfig, learners: int) -> None:
        self.config, self.learners, self.updates = config, learners, 0
        self.advantage = GAE(gamma=config.gamma, lmbda=config.gae_lambda, value_network=critic, average_gae=False)
        self.loss = ClipPPOLoss(
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
        self.optimizer = torch.optim.Adam(self.loss.parameters(), lr=config.lr, eps=config.adam_eps, fused=True)
        self.total_updates = config.iterations * config.updates_per_batch

    def __call__(self, data: TensorDictBase) -> dict[str, torch.Tensor]:
        """The epochs on ``data`` (first dim the learners' env batch, learner-major); each learner's mean losses."""
        k, config = self.learners, self.config
        sums = torch.zeros(len(self.NAMES), k, device=data.device)
        for _ in range(config.epochs):
            with torch.no_grad():
                self.advantage(data)
            own = data.reshape(k, -1)  # each learner's frames (its envs are consecutive rows)
            order = torch.randperm(own.shape[1])
            for start in range(0, own.shape[1], config.minibatch_size):
                sums += self.step(own[:, order[start : start + config.minibatch_size]])
        return dict(zip(self.NAMES, sums / config.updates_per_batch, strict=True))

    def step(self, minibatch: TensorDictBase) -> torch.Tensor:
        """One Adam step on ``minibatch`` (``[K, size]``, advantages set); each learner's losses ``[3, K]``."""
        k, config = self.learners, self.config
        if config.anneal_lr:
            for group in self.optimizer.param_groups:
                group["lr"] = config.lr * (1.0 - self.updates / self.total_updates)
        losses = self.loss(minibatch)
        parts = torch.stack(
            [learner_means(losses.get(n, torch.zeros(k, device=minibatch.device)), k) for n in self.NAMES]
        )
        self.optimizer.zero_grad(set_to_none=True)
        parts.sum().backward()
        if config.max_grad_norm:
            clip_grad_norm_per_learner(self.loss.parameters(), config.max_grad_norm, k)
        self.optimizer.step()
        self.updates += 1
        return parts.detach()


def train_ppo(
    make_env: Callable[[int], EnvBase] | Sequence[Callable[[int], EnvBase]],
    config: PPOConfig,
    **options: Unpack[LearnerOptions],
) -> Trained:
    """Train ``len(seeds)`` PPO learners as one batch on ``make_env`` (shaped by ``shaping``).

    Every batch: one :class:`PPOUpdate` (``config.epochs`` passes of minibatches); then, unless the
    potential is trained online or fixed, one step of the potential on the batch's real SMDP transitions
    (one learner only).

    ``make_env``, ``config`` and ``**options`` (``seeds``, ``shaping``…): as for
    :func:`~torchrl_subgoal.training.train_a2c`.

    Examples:
        >>> from torchrl_subgoal import Cell, SubgoalSeries, TabularPotential
        >>> from torchrl_subgoal.envs import FourRoomsEnv
        >>> from torchrl_subgoal.training import Shaping
        >>> shaping = Shaping(SubgoalSeries([Cell(3, 6)]), TabularPotential(2), {"observation_key": "cell"})
        >>> config = PPOConfig(num_envs=4, frames_per_batch=64, minibatch_size=32, epochs=2, total_frames=128,
        ...                    features="one_hot", hidden=())
        >>> [c.frames for c in train_ppo(FourRoomsEnv, config, seeds=[0, 1], shaping=shaping).curves]
        [[64, 128], [64, 128]]
    """
    return train_on_policy("ppo", PPOUpdate, make_env, config, options)

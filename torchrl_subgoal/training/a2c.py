"""A2C on TorchRL's collectors with subgoal shaping: ``K`` learners as one batch (one is a batch of one).

One learner is one A2C agent: a policy and a value network
(:class:`~tensordict.nn.TensorDictModule` s) trained by TorchRL's
:class:`~torchrl.objectives.A2CLoss` with :class:`~torchrl.objectives.value.GAE`
advantages, on batches from a :class:`~torchrl.collectors.Collector` over a
batch of envs. ``K`` learners (one per seed) train as one program
(:mod:`~torchrl_subgoal.training.batch`): their networks stacked, each with its
own loss mean, gradient clipping and Adam state, their envs one env batch. The
shaping transform sits on the *outer* env; its potential (one table per learner)
is trained online in the transform, or by :class:`~torchrl_subgoal.SubgoalValueLoss`
from the collected SMDP transitions.

A user's env needs an env factory ``make_env(num_envs) -> EnvBase`` (an env
with batch size ``[num_envs]``; :func:`batched` builds one from a single-env
factory) and, for shaping, a subgoal series::

    shaping = Shaping(series, TabularPotential.for_subgoals(series), {"observation_key": "observation"})
    trained = train_a2c(make_env, A2CConfig(total_frames=200_000), seeds=range(10), shaping=shaping)
    trained.curves[3].episode_length, trained.policy(3)
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Unpack

import torch
from tensordict import TensorDictBase
from torchrl.envs import EnvBase
from torchrl.modules import ProbabilisticActor, ValueOperator
from torchrl.objectives import A2CLoss
from torchrl.objectives.value import GAE

from torchrl_subgoal.training.batch import (
    LEARNER,
    LearnerOptions,
    clip_grad_norm_per_learner,
    label_learners,
    learner_means,
)
from torchrl_subgoal.training.config import ActorCriticConfig
from torchrl_subgoal.training.on_policy import train_on_policy
from torchrl_subgoal.training.result import Trained

__all__ = ["A2CConfig", "A2CUpdate", "train_a2c"]


@dataclass
class A2CConfig(ActorCriticConfig):
    """Settings of an A2C learner (the shared ones: :class:`~torchrl_subgoal.training.LearnerConfig`).

    Examples:
        >>> config = A2CConfig(num_envs=8, frames_per_batch=128, total_frames=1024, features="one_hot")
        >>> config.iterations, config.network_options()
        (8, {'features': 'one_hot', 'hidden': (64,), 'fourier_order': 3})
    """

    num_envs: int = 16
    frames_per_batch: int = 256
    total_frames: int = 200_000
    lr: float = 1e-3
    gae_lambda: float = 0.95
    """GAE's λ"""
    entropy_coeff: float = 0.01
    """entropy bonus"""
    critic_coeff: float = 0.5
    """weight of the value loss"""
    normalize_advantage: bool = False
    """standardise advantages per batch (each learner's over its own)"""


class A2CUpdate:
    """One A2C step of ``K`` learners on a collected batch: GAE advantages (standardised learner by learner
    with ``normalize_advantage``), TorchRL's :class:`~torchrl.objectives.A2CLoss` per sample, each learner's
    mean, its own gradient clipping and Adam state.

    Args:
        actor: the learners' stacked actor (:func:`actor_critic_modules`).
        critic: their stacked critic.
        config: the settings.
        learners: ``K``.

    Examples:
        >>> from torchrl_subgoal.envs import FourRoomsEnv
        >>> from torchrl_subgoal.training import actor_critic_modules
        >>> config = A2CConfig(features="one_hot", hidden=())
        >>> modules = actor_critic_modules(FourRoomsEnv(1), config, seeds=[0, 1])
        >>> update = A2CUpdate(modules["actor"], modules["critic"], config, learners=2)
        >>> with torch.no_grad():  # what a collector does
        ...     data = FourRoomsEnv(4).rollout(5, modules["actor"], break_when_any_done=False)
        >>> update(data)["loss_critic"].shape  # each learner's loss
        torch.Size([2])
    """

    NAMES = ("loss_objective", "loss_critic", "loss_entropy")

    def __init__(self, actor: ProbabilisticActor, critic: ValueOperator, config: A2CConfig, learners: int) -> None:
        self.learners = learners
        self.advantage = GAE(
            gamma=config.gamma,
            lmbda=config.gae_lambda,
            value_network=critic,
            average_gae=config.normalize_advantage,
            group_key=LEARNER if learners > 1 else None,  # standardised learner by learner
        )
        self.loss = A2CLoss(
            actor,
            critic,
            entropy_bonus=config.entropy_coeff > 0,  # without one, TorchRL writes no "loss_entropy"
            entropy_coeff=config.entropy_coeff,
            critic_coeff=config.critic_coeff,
            loss_critic_type="l2",
            reduction="none",
        )
        self.optimizer = torch.optim.Adam(self.loss.parameters(), lr=config.lr, fused=True)  # one kernel
        self.max_grad_norm = config.max_grad_norm

    def __call__(self, data: TensorDictBase) -> dict[str, torch.Tensor]:
        """One step on ``data`` (first dim the learners' env batch, learner-major); each learner's losses ``[K]``."""
        k = self.learners
        with torch.no_grad():
            self.advantage(label_learners(data, k))
        losses = self.loss(data)
        none = torch.zeros(k, device=data.device)  # a loss TorchRL did not write (no entropy bonus)
        means = {name: learner_means(losses.get(name, none), k) for name in self.NAMES}
        self.optimizer.zero_grad(set_to_none=True)
        torch.stack([m.sum() for m in means.values()]).sum().backward()
        if self.max_grad_norm:
            clip_grad_norm_per_learner(self.loss.parameters(), self.max_grad_norm, k)
        self.optimizer.step()
        return {name: m.detach() for name, m in means.items()}


def train_a2c(
    make_env: Callable[[int], EnvBase] | Sequence[Callable[[int], EnvBase]],
    config: A2CConfig,
    **options: Unpack[LearnerOptions],
) -> Trained:
    """Train ``len(seeds)`` A2C learners as one batch on ``make_env`` (shaped by ``shaping``).

    Learner ``k`` has its own networks (started as alone from ``seeds[k]``), ``config.num_envs`` envs
    and potential. Every batch: one :class:`A2CUpdate`; then, unless the potential is trained online or
    fixed, one step of the potential on the batch's real SMDP transitions with its own optimiser (one
    learner only).

    Args:
        make_env: ``make_env(num_envs)`` returns an env with batch size ``[num_envs]`` (every learner's
            task), or one such factory per learner (each its own task).
        config: every learner's settings.
        **options: ``seeds``, ``shaping``, ``observation_key``, ``loggers``, ``progress``… (one learner,
            unshaped, by default): :class:`~torchrl_subgoal.training.batch.LearnerOptions`.

    Returns:
        the curves, the stacked actor and critic, the potential (:class:`~torchrl_subgoal.training.Trained`).

    Examples:
        >>> from torchrl_subgoal import Cell, SubgoalSeries, TabularPotential
        >>> from torchrl_subgoal.envs import FourRoomsEnv
        >>> from torchrl_subgoal.training import Shaping
        >>> shaping = Shaping(SubgoalSeries([Cell(3, 6)]), TabularPotential(2), {"observation_key": "cell"})
        >>> config = A2CConfig(num_envs=4, frames_per_batch=64, total_frames=256, features="one_hot", hidden=())
        >>> trained = train_a2c(FourRoomsEnv, config, seeds=[0, 1, 2], shaping=shaping)
        >>> len(trained.curves), trained.curves[2].frames
        (3, [64, 128, 192, 256])
    """
    return train_on_policy("a2c", A2CUpdate, make_env, config, options)

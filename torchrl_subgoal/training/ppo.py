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

    shaping = Shaping(series, TabularPotential(series.num_abstract_states))
    trained = train_ppo(make_env, PPOConfig(total_frames=500_000), seeds=range(10), shaping=shaping)
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Literal

import torch
from tensordict.nn import AddStateIndependentNormalScale, TensorDictModule
from tensordict.utils import NestedKey
from torch import nn
from torchrl.data import Bounded, Categorical, OneHot
from torchrl.envs import EnvBase
from torchrl.modules import ProbabilisticActor, TanhNormal, ValueOperator
from torchrl.objectives import ClipPPOLoss
from torchrl.objectives.value import GAE
from torchrl.record.loggers import Logger

from torchrl_subgoal.training.a2c import actor_critic
from torchrl_subgoal.training.batch import (
    LearnerBatch,
    ShapingArg,
    clip_grad_norm_per_learner,
    learner_means,
    seeded,
    stack_actor_critic,
)
from torchrl_subgoal.training.config import Features, NetworkConfig
from torchrl_subgoal.training.networks import network, subgoal_keys, trunk
from torchrl_subgoal.training.recording import SuccessSignal
from torchrl_subgoal.training.result import Trained

__all__ = ["PPOConfig", "ppo_actor_critic", "ppo_modules", "train_ppo"]


@dataclass
class PPOConfig(NetworkConfig):
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
    policy_trunk, size = trunk(spec, features, hidden, fourier_order, subgoal_states=subgoal_states)
    value_trunk, _ = trunk(spec, features, hidden, fourier_order, subgoal_states=subgoal_states)
    loc_head, value_head = nn.Linear(size, action_size), nn.Linear(size, 1)
    for last in (loc_head, value_head):  # start centred in the action bounds, with a zero value
        nn.init.zeros_(last.weight)
        nn.init.zeros_(last.bias)
    in_keys = subgoal_keys(observation_key, subgoal_states)
    low, high = action_spec.space.low, action_spec.space.high
    while low.ndim > 1:
        low, high = low[0], high[0]
    policy = network(policy_trunk, loc_head, AddStateIndependentNormalScale(action_size))
    actor = ProbabilisticActor(
        TensorDictModule(policy, in_keys=in_keys, out_keys=["loc", "scale"]),
        in_keys=["loc", "scale"],
        spec=action_spec,
        distribution_class=TanhNormal,
        distribution_kwargs={"low": low, "high": high, "tanh_loc": False},
        return_log_prob=True,
    )
    critic = ValueOperator(network(value_trunk, value_head), in_keys=in_keys)
    return actor, critic


def ppo_modules(
    env: EnvBase,
    config: PPOConfig,
    observation_key: NestedKey = "observation",
    subgoal_states: int = 0,
    seeds: Sequence[int] = (0,),
) -> dict[str, nn.Module]:
    """The networks of ``len(seeds)`` PPO learners, each started from its seed, stacked: ``"actor"``,
    ``"critic"`` and the greedy ``"policy"`` (the actor).

    Examples:
        >>> from torchrl.envs import GymEnv
        >>> modules = ppo_modules(GymEnv("Pendulum-v1"), PPOConfig(hidden=(8,)), seeds=[0, 1, 2])
        >>> modules["actor"].module[0].module.learners
        3
    """

    def make() -> tuple[ProbabilisticActor, ValueOperator]:
        return ppo_actor_critic(
            env,
            observation_key,
            features=config.features,
            hidden=config.hidden,
            fourier_order=config.fourier_order,
            subgoal_states=subgoal_states,
        )

    actor, critic = stack_actor_critic(seeded(seeds, make))
    return {"actor": actor, "critic": critic, "policy": actor}


def train_ppo(
    make_env: Callable[[int], EnvBase] | Sequence[Callable[[int], EnvBase]],
    config: PPOConfig,
    *,
    seeds: Sequence[int] = (0,),
    shaping: ShapingArg = None,
    observation_key: NestedKey = "observation",
    episode_cap: float | None = None,
    loggers: Sequence[Logger | None] | None = None,
    progress: Callable[[int], None] | None = None,
    success: SuccessSignal | None = None,
) -> Trained:
    """Train ``len(seeds)`` PPO learners as one batch on ``make_env`` (shaped by ``shaping``).

    Every batch: ``config.epochs`` passes, each recomputing GAE advantages with the current value
    networks and taking one Adam step per minibatch of :class:`~torchrl.objectives.ClipPPOLoss` (every
    learner its own minibatch of its own frames, in a fresh random order each epoch); then, unless the
    potential is trained online or fixed, one step of the potential on the batch's real SMDP
    transitions (one learner only).

    Args:
        make_env: ``make_env(num_envs)``, every learner's task, or one such factory per learner.
        config: every learner's settings.
        seeds: one per learner; torch (sampling) and the envs are seeded with the first.
        shaping: one for every learner or one per learner (``None``: plain PPO).
        observation_key: what the policy and value network read.
        episode_cap: what the curves record before any episode finished (default: the env's ``max_steps``).
        loggers: one TorchRL logger per learner.
        progress: called with 1 after every batch for every learner.
        success: how an episode's success is read.

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
    batch = LearnerBatch(
        make_env,
        config,
        seeds,
        shaping=shaping,
        loggers=loggers,
        progress=progress,
        episode_cap=episode_cap,
        success=success,
    )
    k = batch.learners
    modules = batch.modules(lambda env, own: ppo_modules(env, config, observation_key, batch.subgoal_states, own))
    actor, critic = modules["actor"], modules["critic"]
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
    updates = 0
    for data in batch.collect(actor):
        sums = torch.zeros(3, k, device=batch.device)
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
        batch.record(data, dict(zip(names, sums / config.updates_per_batch, strict=True)))
    return batch.result("ppo", modules, observation_key)

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

    shaping = Shaping(series, TabularPotential(series.num_abstract_states), {"observation_key": "observation"})
    trained = train_a2c(make_env, A2CConfig(total_frames=200_000), seeds=range(10), shaping=shaping)
    trained.curves[3].episode_length, trained.policy(3)
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Unpack

import torch
from tensordict import TensorDictBase
from tensordict.nn import AddStateIndependentNormalScale, TensorDictModule
from tensordict.utils import NestedKey
from torch import nn
from torchrl.data import Bounded, Categorical, OneHot
from torchrl.envs import EnvBase
from torchrl.modules import OneHotCategorical, ProbabilisticActor, TanhNormal, ValueOperator
from torchrl.objectives import A2CLoss
from torchrl.objectives.value import GAE

from torchrl_subgoal.training.batch import (
    LEARNER,
    LearnerBatch,
    LearnerOptions,
    clip_grad_norm_per_learner,
    label_learners,
    learner_means,
    seeded,
    stack_actor_critic,
)
from torchrl_subgoal.training.config import Features, NetworkConfig
from torchrl_subgoal.training.networks import network, subgoal_keys, trunk
from torchrl_subgoal.training.result import Trained

__all__ = ["A2CConfig", "A2CUpdate", "actor_critic", "actor_critic_modules", "train_a2c"]


@dataclass
class A2CConfig(NetworkConfig):
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


def actor_critic(
    env: EnvBase,
    observation_key: NestedKey = "observation",
    *,
    features: Features = "mlp",
    hidden: Sequence[int] = (64,),
    fourier_order: int = 3,
    subgoal_states: int = 0,
) -> tuple[ProbabilisticActor, ValueOperator]:
    """A policy and a value network over ``observation_key`` for ``env``'s actions (A2C's and PPO's).

    Discrete actions (``Categorical``, ``OneHot``): a categorical policy. Bounded continuous actions:
    a ``TanhNormal`` over the action bounds whose location is the network's output and whose scale is
    a learned state-independent parameter (starting at 1). The output layers start at zero (a uniform
    or centred policy, a zero value).

    Args:
        env: gives the observation and action specs.
        observation_key: the networks' input.
        features: ``"one_hot"`` for a categorical observation (a table lookup when
            ``hidden=()``), ``"fourier"`` for a bounded one, ``"mlp"`` otherwise.
        hidden: hidden layer sizes (``tanh``).
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
        >>> from torchrl.envs import GymEnv
        >>> actor, critic = actor_critic(GymEnv("Pendulum-v1"), hidden=(16,))
        >>> td = actor(GymEnv("Pendulum-v1").reset())
        >>> td["action"].shape, bool(td["action"].abs().max() <= 2.0)
        (torch.Size([1]), True)
    """
    spec = env.observation_spec[observation_key]
    action_spec = env.full_action_spec[env.action_key]
    discrete = isinstance(action_spec, Categorical | OneHot)
    if not discrete and not isinstance(action_spec, Bounded):
        raise ValueError(
            f"an actor-critic here needs discrete or bounded continuous actions, got {type(action_spec).__name__}"
        )
    outputs = int(action_spec.space.n) if discrete else int(action_spec.shape[-1])
    policy_trunk, size = trunk(spec, features, hidden, fourier_order, subgoal_states=subgoal_states)
    value_trunk, _ = trunk(spec, features, hidden, fourier_order, subgoal_states=subgoal_states)
    policy_head, value_head = nn.Linear(size, outputs), nn.Linear(size, 1)
    for last in (policy_head, value_head):  # start from a uniform (or centred) policy and a zero value
        nn.init.zeros_(last.weight)
        nn.init.zeros_(last.bias)
    in_keys = subgoal_keys(observation_key, subgoal_states)
    if discrete:
        policy = TensorDictModule(network(policy_trunk, policy_head), in_keys=in_keys, out_keys=["logits"])
        distribution = OneHotCategorical if isinstance(action_spec, OneHot) else torch.distributions.Categorical
        options: dict[str, Any] = {}
    else:
        scale = AddStateIndependentNormalScale(outputs)
        policy = TensorDictModule(network(policy_trunk, policy_head, scale), in_keys=in_keys, out_keys=["loc", "scale"])
        low, high = action_spec.space.low, action_spec.space.high
        while low.ndim > 1:
            low, high = low[0], high[0]
        distribution, options = TanhNormal, {"low": low, "high": high, "tanh_loc": False}
    actor = ProbabilisticActor(
        policy,
        in_keys=policy.out_keys,
        spec=action_spec,
        distribution_class=distribution,
        distribution_kwargs=options,
        return_log_prob=True,
    )
    critic = ValueOperator(network(value_trunk, value_head), in_keys=in_keys)
    return actor, critic


def actor_critic_modules(
    env: EnvBase,
    config: NetworkConfig,
    observation_key: NestedKey = "observation",
    subgoal_states: int = 0,
    seeds: Sequence[int] = (0,),
) -> dict[str, nn.Module]:
    """The networks of ``len(seeds)`` A2C (or PPO) learners, each started from its seed, stacked:
    ``"actor"``, ``"critic"`` and the greedy ``"policy"`` (the actor).

    Examples:
        >>> from torchrl_subgoal.envs import FourRoomsEnv
        >>> modules = actor_critic_modules(FourRoomsEnv(1), A2CConfig(features="one_hot"), seeds=[0, 1])
        >>> modules["critic"](FourRoomsEnv(4).reset())["state_value"].shape  # 2 learners x 2 envs
        torch.Size([4, 1])
    """
    options = config.network_options()
    pairs = seeded(seeds, lambda: actor_critic(env, observation_key, subgoal_states=subgoal_states, **options))
    actor, critic = stack_actor_critic(pairs)
    return {"actor": actor, "critic": critic, "policy": actor}


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
        means = {name: learner_means(losses[name], k) for name in self.NAMES}
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


def train_on_policy(
    algo: str,
    update: Callable[
        [ProbabilisticActor, ValueOperator, Any, int], Callable[[TensorDictBase], dict[str, torch.Tensor]]
    ],
    make_env: Callable[[int], EnvBase] | Sequence[Callable[[int], EnvBase]],
    config: NetworkConfig,
    options: LearnerOptions,
) -> Trained:
    """The loop of an on-policy actor-critic (A2C, PPO): the learners' networks, and ``update(actor, critic,
    config, K)`` (:class:`A2CUpdate`, :class:`~torchrl_subgoal.training.PPOUpdate`) on every collected batch.

    Examples:
        >>> from torchrl_subgoal.envs import FourRoomsEnv
        >>> config = A2CConfig(num_envs=2, frames_per_batch=8, total_frames=16, features="one_hot")
        >>> train_on_policy("a2c", A2CUpdate, FourRoomsEnv, config, {"seeds": [0]}).curve.frames
        [8, 16]
    """
    batch = LearnerBatch(make_env, config, **options)
    modules = batch.modules(actor_critic_modules)
    step = update(modules["actor"], modules["critic"], config, batch.learners)
    for data in batch.collect(modules["actor"]):
        batch.record(data, step(data))
    return batch.result(algo, modules)

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

from torchrl_subgoal.training.batch import (
    LEARNER,
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

__all__ = ["A2CConfig", "a2c_modules", "actor_critic", "train_a2c"]


@dataclass
class A2CConfig(NetworkConfig):
    """Settings of an A2C learner (the shared ones: :class:`~torchrl_subgoal.training.LearnerConfig`).

    Examples:
        >>> config = A2CConfig(num_envs=8, frames_per_batch=128, total_frames=1024)
        >>> config.iterations
        8
        >>> A2CConfig(gae_lambda=1.5)
        Traceback (most recent call last):
        ...
        ValueError: gae_lambda must lie in [0, 1], got 1.5
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
    policy_trunk, size = trunk(spec, features, hidden, fourier_order, subgoal_states=subgoal_states)
    value_trunk, _ = trunk(spec, features, hidden, fourier_order, subgoal_states=subgoal_states)
    policy_head, value_head = nn.Linear(size, n_actions), nn.Linear(size, 1)
    for last in (policy_head, value_head):  # start from a uniform policy and a zero value
        nn.init.zeros_(last.weight)
        nn.init.zeros_(last.bias)
    in_keys = subgoal_keys(observation_key, subgoal_states)
    distribution = OneHotCategorical if isinstance(action_spec, OneHot) else torch.distributions.Categorical
    actor = ProbabilisticActor(
        TensorDictModule(network(policy_trunk, policy_head), in_keys=in_keys, out_keys=["logits"]),
        in_keys=["logits"],
        spec=action_spec,
        distribution_class=distribution,
        return_log_prob=True,
    )
    critic = ValueOperator(network(value_trunk, value_head), in_keys=in_keys)
    return actor, critic


def a2c_modules(
    env: EnvBase,
    config: A2CConfig,
    observation_key: NestedKey = "observation",
    subgoal_states: int = 0,
    seeds: Sequence[int] = (0,),
) -> dict[str, nn.Module]:
    """The networks of ``len(seeds)`` A2C learners, each started from its seed, stacked: ``"actor"``,
    ``"critic"`` and the greedy ``"policy"`` (the actor).

    Examples:
        >>> from torchrl_subgoal.envs import FourRoomsEnv
        >>> modules = a2c_modules(FourRoomsEnv(1), A2CConfig(features="one_hot"), seeds=[0, 1])
        >>> modules["critic"](FourRoomsEnv(4).reset())["state_value"].shape  # 2 learners x 2 envs
        torch.Size([4, 1])
    """

    def make() -> tuple[ProbabilisticActor, ValueOperator]:
        return actor_critic(
            env,
            observation_key,
            features=config.features,
            hidden=config.hidden,
            fourier_order=config.fourier_order,
            subgoal_states=subgoal_states,
        )

    actor, critic = stack_actor_critic(seeded(seeds, make))
    return {"actor": actor, "critic": critic, "policy": actor}


def train_a2c(
    make_env: Callable[[int], EnvBase] | Sequence[Callable[[int], EnvBase]],
    config: A2CConfig,
    *,
    seeds: Sequence[int] = (0,),
    shaping: ShapingArg = None,
    observation_key: NestedKey = "observation",
    episode_cap: float | None = None,
    loggers: Sequence[Logger | None] | None = None,
    progress: Callable[[int], None] | None = None,
    success: SuccessSignal | None = None,
) -> Trained:
    """Train ``len(seeds)`` A2C learners as one batch on ``make_env`` (shaped by ``shaping``).

    Learner ``k`` has its own networks (started as alone from ``seeds[k]``), ``config.num_envs`` envs
    and potential. Every batch: GAE advantages and one A2C step (each learner its own loss mean,
    clipping and Adam state); then, unless the potential is trained online or fixed, one step of the
    potential on the batch's real SMDP transitions with its own optimiser (one learner only).

    Args:
        make_env: ``make_env(num_envs)`` returns an env with batch size ``[num_envs]`` (every learner's
            task), or one such factory per learner (each its own task).
        config: every learner's settings.
        seeds: one per learner; torch (sampling) and the envs are seeded with the first.
        shaping: one for every learner (each starts from its potential) or one per learner; ``None``: plain A2C.
        observation_key: what the policy and value network read.
        episode_cap: what the curves record before any episode finished (default: the env's ``max_steps``).
        loggers: one TorchRL logger (CSV, TensorBoard…) per learner for losses and episode statistics.
        progress: called with 1 after every batch for every learner.
        success: how an episode's success is read (default: the env's ``"is_success"``/``"success"`` entry).

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
    modules = batch.modules(lambda env, own: a2c_modules(env, config, observation_key, batch.subgoal_states, own))
    actor, critic = modules["actor"], modules["critic"]
    advantage = GAE(
        gamma=config.gamma,
        lmbda=config.gae_lambda,
        value_network=critic,
        average_gae=config.normalize_advantage,
        group_key=LEARNER if k > 1 else None,  # standardised learner by learner
    )
    loss = A2CLoss(
        actor,
        critic,
        entropy_coeff=config.entropy_coeff,
        critic_coeff=config.critic_coeff,
        loss_critic_type="l2",
        reduction="none",
    )
    optimizer = torch.optim.Adam(loss.parameters(), lr=config.lr)
    names = ("loss_objective", "loss_critic", "loss_entropy")
    for data in batch.collect(actor):
        with torch.no_grad():
            advantage(batch.labelled(data))
        losses = loss(data)
        means = {name: learner_means(losses[name], k) for name in names}
        optimizer.zero_grad(set_to_none=True)
        torch.stack([m.sum() for m in means.values()]).sum().backward()
        clip_grad_norm_per_learner(loss.parameters(), config.max_grad_norm, k)
        optimizer.step()
        batch.record(data, means)
    return batch.result("a2c", modules, observation_key)

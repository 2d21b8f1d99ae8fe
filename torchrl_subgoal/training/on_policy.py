"""What A2C and PPO share: the policy and value network, the learners' stacked networks, the loop.

* :func:`actor_critic`: a categorical (discrete actions) or ``TanhNormal`` (bounded continuous
  actions) policy and a value network over an observation, with the input layer of
  :mod:`~torchrl_subgoal.training.networks`;
* :func:`actor_critic_modules`: ``K`` learners' networks, each from its seed, stacked;
* :func:`train_on_policy`: the loop, ``update(data)`` (:class:`~torchrl_subgoal.training.A2CUpdate`,
  :class:`~torchrl_subgoal.training.PPOUpdate`) on every collected batch.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import torch
from tensordict import TensorDictBase
from tensordict.nn import AddStateIndependentNormalScale, TensorDictModule
from tensordict.utils import NestedKey
from torch import nn
from torchrl.data import Bounded, Categorical, OneHot
from torchrl.envs import EnvBase
from torchrl.modules import OneHotCategorical, ProbabilisticActor, TanhNormal, ValueOperator

from torchrl_subgoal.training.batch import LearnerBatch, LearnerOptions, seeded, stack_actor_critic
from torchrl_subgoal.training.config import ActorCriticConfig, Features
from torchrl_subgoal.training.networks import network, subgoal_keys, trunk
from torchrl_subgoal.training.result import Trained

__all__ = ["actor_critic", "actor_critic_modules", "train_on_policy"]


def actor_critic(
    env: EnvBase,
    observation_key: NestedKey = "observation",
    *,
    features: Features = "mlp",
    hidden: Sequence[int] = (64,),
    fourier_order: int = 3,
    subgoal_states: int = 0,
    actor_sees_subgoal: bool = True,
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
            over this many abstract states): joined to the features as their product with ``hidden=()``
            (one linear function per ``z``; over one-hot features a table over ``(s, z)``), else concatenated.
        actor_sees_subgoal: ``False``: only the value network reads ``z``; the policy reads the observation.

    Examples:
        >>> from torchrl_subgoal.envs import FourRoomsEnv
        >>> actor, critic = actor_critic(FourRoomsEnv(3), features="one_hot")
        >>> td = critic(actor(FourRoomsEnv(3).reset()))
        >>> td["action"].shape, td["state_value"].shape
        (torch.Size([3]), torch.Size([3, 1]))
        >>> actor, critic = actor_critic(FourRoomsEnv(3), features="one_hot", subgoal_states=3)
        >>> critic.in_keys
        ['observation', 'subgoal_index']
        >>> actor_critic(FourRoomsEnv(3), subgoal_states=3, actor_sees_subgoal=False)[0].in_keys
        ['observation']
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
    actor_states = subgoal_states if actor_sees_subgoal else 0
    policy_trunk, size = trunk(spec, features, hidden, fourier_order, subgoal_states=actor_states)
    value_trunk, value_size = trunk(spec, features, hidden, fourier_order, subgoal_states=subgoal_states)
    policy_head, value_head = nn.Linear(size, outputs), nn.Linear(value_size, 1)
    for last in (policy_head, value_head):  # start from a uniform (or centred) policy and a zero value
        nn.init.zeros_(last.weight)
        nn.init.zeros_(last.bias)
    in_keys = subgoal_keys(observation_key, actor_states)
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
    critic = ValueOperator(network(value_trunk, value_head), in_keys=subgoal_keys(observation_key, subgoal_states))
    return actor, critic


def actor_critic_modules(
    env: EnvBase,
    config: ActorCriticConfig,
    observation_key: NestedKey = "observation",
    subgoal_states: int = 0,
    seeds: Sequence[int] = (0,),
) -> dict[str, nn.Module]:
    """The networks of ``len(seeds)`` A2C (or PPO) learners, each started from its seed, stacked:
    ``"actor"``, ``"critic"`` and the greedy ``"policy"`` (the actor). With ``subgoal_states`` and
    ``config.sees_subgoal == "critic"``, only the critic reads ``z``.

    Examples:
        >>> from torchrl_subgoal.envs import FourRoomsEnv
        >>> from torchrl_subgoal.training import A2CConfig
        >>> modules = actor_critic_modules(FourRoomsEnv(1), A2CConfig(features="one_hot"), seeds=[0, 1])
        >>> modules["critic"](FourRoomsEnv(4).reset())["state_value"].shape  # 2 learners x 2 envs
        torch.Size([4, 1])
    """
    options = config.network_options()
    actor_sees = config.sees_subgoal != "critic"
    pairs = seeded(
        seeds,
        lambda: actor_critic(
            env, observation_key, subgoal_states=subgoal_states, actor_sees_subgoal=actor_sees, **options
        ),
    )
    actor, critic = stack_actor_critic(pairs)
    return {"actor": actor, "critic": critic, "policy": actor}


def train_on_policy(
    algo: str,
    update: Callable[
        [ProbabilisticActor, ValueOperator, Any, int], Callable[[TensorDictBase], dict[str, torch.Tensor]]
    ],
    make_env: Callable[[int], EnvBase] | Sequence[Callable[[int], EnvBase]],
    config: ActorCriticConfig,
    options: LearnerOptions,
) -> Trained:
    """The loop of an on-policy actor-critic (A2C, PPO): the learners' networks, and ``update(actor, critic,
    config, K)`` (:class:`~torchrl_subgoal.training.A2CUpdate`, :class:`~torchrl_subgoal.training.PPOUpdate`)
    on every collected batch.

    Examples:
        >>> from torchrl_subgoal.envs import FourRoomsEnv
        >>> from torchrl_subgoal.training import A2CConfig, A2CUpdate
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

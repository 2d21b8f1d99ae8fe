"""DDPG (or TD3) on TorchRL's collectors with subgoal shaping, for any bounded continuous-action env:
``K`` learners as one batch (one is a batch of one).

The learners are one :class:`~torchrl_subgoal.training.ddpg_parts.DDPGAgent` (the
implementation the pick-and-place reproduction uses: actor and critic MLPs
over the observation normalised by running statistics, TorchRL's
:class:`~torchrl.objectives.DDPGLoss` or :class:`~torchrl.objectives.TD3Loss`,
Polyak-averaged target networks, Gaussian exploration, a TorchRL replay
buffer), each network stacked over the learners, the replay buffer with a
learner dim, each learner its own loss means and Adam state; trained on batches
of a TorchRL collector: after each batch, ``updates_per_batch`` gradient steps,
each followed by a soft target update. With ``reshape_samples`` every replay
sample is re-shaped with the potential as it is now
(:class:`~torchrl_subgoal.training.SampleReshaper`)::

    shaping = Shaping(series, TabularPotential.for_subgoals(series))
    trained = train_ddpg(make_env, DDPGTrainConfig(total_frames=300_000), seeds=range(10), shaping=shaping)
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Literal, Unpack

import torch
from tensordict import TensorDictBase
from tensordict.utils import NestedKey
from torch import nn
from torchrl.data import Bounded
from torchrl.envs import EnvBase

from torchrl_subgoal.training.batch import LearnerBatch, LearnerOptions
from torchrl_subgoal.training.config import OffPolicyConfig
from torchrl_subgoal.training.ddpg_parts import DDPGAgent, DDPGConfig, TD3Settings
from torchrl_subgoal.training.result import Trained

__all__ = ["DDPGHooks", "DDPGTrainConfig", "ddpg_agent", "ddpg_modules", "train_ddpg"]


@dataclass
class DDPGTrainConfig(OffPolicyConfig):
    """Settings of a DDPG (or TD3) learner (the shared ones: :class:`~torchrl_subgoal.training.LearnerConfig`).

    The defaults are those of TorchRL's own DDPG example (``sota-implementations/ddpg``
    in the TorchRL repository: one env, 1,000 frames per batch followed by as many
    gradient steps (an update-to-data ratio of 1), batches of 256 from a buffer of 10⁶,
    Adam 3e-4 for actor and critic, γ 0.99, Polyak 0.995 after every gradient step,
    two ReLU hidden layers of 256), with the example's 25,000 random frames first of
    its 10⁶ as a fraction (2.5% of the budget), and except for the exploration:
    Gaussian noise of s.d. 0.1 (the TD3 paper's) in place of the example's
    Ornstein–Uhlenbeck noise, and no weight decay. ``td3=True`` takes the TD3 settings of
    TorchRL's TD3 example (two critics, target noise 0.2 clipped at 0.5, actor and targets
    updated every second step). The pick-and-place reproduction's settings (the authors')
    are :class:`~torchrl_subgoal.training.ddpg_parts.DDPGConfig`'s.

    Examples:
        >>> config = DDPGTrainConfig(frames_per_batch=100, total_frames=1000)
        >>> config.iterations, config.warmup_frames, config.agent().polyak
        (10, 25, 0.995)
        >>> DDPGTrainConfig(noise_eps=-0.1)
        Traceback (most recent call last):
        ...
        ValueError: noise_eps must be >= 0, got -0.1
    """

    total_frames: int = 1_000_000
    lr: float = 3e-4
    learning_starts: float = 0.025
    updates_per_batch: int = 1000
    """gradient steps after each collected batch (each followed by a soft target update)"""
    polyak: float = 0.995
    """target <- polyak * target + (1 - polyak) * online, after every gradient step (or every batch)"""
    polyak_every: Literal["update", "batch"] = "update"
    """when the targets move: after every gradient step (TorchRL's examples) or once per collected batch,
    after its gradient steps (the pick-and-place authors')"""
    hidden: tuple[int, ...] = (256, 256)
    """hidden layer sizes of actor and critic (ReLU)"""
    noise_eps: float = 0.1
    """s.d. of the Gaussian exploration noise (action units; actions clipped to their bounds)"""
    random_eps: float = 0.0
    """probability of a uniformly random action while collecting"""
    action_l2: float = 0.0
    """weight of an L2 penalty on the actor's actions (DDPG only; the pick-and-place authors' 1.0 keeps
    a tanh actor off its bounds while the critic has nothing to say)"""
    norm_clip: float = 5.0
    """normalised observations are clipped to ``+-norm_clip``"""
    clip_return: float | None = None
    """the critic's TD targets are clipped to ``[-clip_return, ...]`` (the return range of a -1/0 reward:
    ``1/(1-gamma)``, the pick-and-place authors'); ``None``: not clipped below"""
    clip_positive: bool = False
    """the critic's TD targets are clipped above at 0 (the pick-and-place authors' ``clip_pos_returns``)"""
    td3: bool = False
    """TD3 (two critics, smoothed targets, delayed actor updates) instead of DDPG"""
    policy_delay: int = 2
    """TD3: critic updates per actor and target update"""
    target_noise: float = 0.2
    """TD3: s.d. of the noise on the target action (action units)"""
    noise_clip: float = 0.5
    """TD3: bound of that noise"""

    def check(self) -> None:
        super().check()
        if self.td3 and self.action_l2:
            raise ValueError(f"action_l2 ({self.action_l2}) is DDPG's actor penalty; TD3 here has none: set it to 0")

    def agent(self) -> DDPGConfig:
        """The agent's hyper-parameters (its fields of these settings; one learning rate for actor and critic)."""
        shared = {f.name for f in dataclasses.fields(DDPGConfig)} & {f.name for f in dataclasses.fields(self)}
        return DDPGConfig(actor_lr=self.lr, critic_lr=self.lr, **{name: getattr(self, name) for name in shared})

    def td3_settings(self) -> TD3Settings | None:
        """TD3's settings, or ``None`` for DDPG."""
        return TD3Settings(self.policy_delay, self.target_noise, self.noise_clip) if self.td3 else None


def ddpg_agent(
    env: EnvBase,
    config: DDPGTrainConfig,
    observation_key: NestedKey = "observation",
    *,
    subgoal_states: int = 0,
    keys: tuple[NestedKey, ...] = (),
    seeds: Sequence[int] | None = None,
) -> DDPGAgent:
    """The DDPG (or TD3) agent of ``config`` for ``env``'s observation vector and bounded actions.

    Args:
        env: gives the observation and action specs.
        config: the settings.
        observation_key: the observation vector the networks read.
        subgoal_states: if positive, actor and critic also read ``"subgoal_index"`` (one-hot ``z``).
        keys: more entries the replay buffer keeps.
        seeds: one per learner (``None``: one learner, from torch's current state).

    Examples:
        >>> from torchrl.envs import GymEnv
        >>> agent = ddpg_agent(GymEnv("Pendulum-v1"), DDPGTrainConfig(hidden=(16,)))
        >>> agent.policy(GymEnv("Pendulum-v1").reset())["action"].shape
        torch.Size([1])
    """
    action_spec = env.full_action_spec_unbatched[env.action_key]
    if not isinstance(action_spec, Bounded):
        raise ValueError(f"DDPG needs bounded continuous actions, got {type(action_spec).__name__}")
    spec = env.observation_spec[observation_key]
    if len(spec.shape) != len(env.batch_size) + 1:
        raise ValueError(
            f"DDPG reads a vector observation; {observation_key!r} has shape {tuple(spec.shape[len(env.batch_size) :])}"
        )
    return DDPGAgent(
        int(spec.shape[-1]),
        action_spec,
        config.agent(),
        config.device,
        observation_key=observation_key,
        subgoal_states=subgoal_states,
        td3=config.td3_settings(),
        keys=keys,
        seeds=seeds,
    )


def ddpg_modules(
    env: EnvBase,
    config: DDPGTrainConfig,
    observation_key: NestedKey = "observation",
    subgoal_states: int = 0,
    seeds: Sequence[int] = (0,),
    keys: tuple[NestedKey, ...] = (),
) -> dict[str, nn.Module]:
    """The DDPG (or TD3) agent of ``len(seeds)`` learners (each learner's networks started from its seed):
    ``"agent"`` and its greedy ``"policy"``.

    Examples:
        >>> from torchrl.envs import GymEnv
        >>> modules = ddpg_modules(GymEnv("Pendulum-v1"), DDPGTrainConfig(hidden=(16,)), seeds=[0, 1])
        >>> modules["agent"].learners, sorted(modules)
        (2, ['agent', 'policy'])
    """
    agent = ddpg_agent(env, config, observation_key, subgoal_states=subgoal_states, keys=keys, seeds=seeds)
    return {"agent": agent, "policy": agent.greedy}


@dataclass(frozen=True)
class DDPGHooks:
    """Calls into :func:`train_ddpg`'s loop, for a recipe's own schedule (pick and place: a test and a
    checkpoint after every epoch, a learning resumed from its checkpoint).

    Attributes:
        start: ``start(agent, batch)``, once the collector is built (``batch.collector``), before the first
            batch: restore a checkpoint, seed the collector.
        batch: ``batch(agent, batch, data)`` after every batch's update and the potential's; a true return
            stops the learning.

    Examples:
        >>> import functools
        >>> from torchrl.envs import GymEnv
        >>> from torchrl_subgoal.training import batched
        >>> config = DDPGTrainConfig(frames_per_batch=20, total_frames=100, learning_starts=0, updates_per_batch=1,
        ...                          batch_size=8, hidden=(8,))
        >>> seen = []
        >>> hooks = DDPGHooks(batch=lambda agent, batch, data: seen.append(batch.frames) or batch.frames >= 40)
        >>> _ = train_ddpg(batched(functools.partial(GymEnv, "Pendulum-v1")), config, hooks=hooks, episode_cap=200)
        >>> seen  # stopped after the second batch
        [20, 40]
    """

    start: Callable[[DDPGAgent, LearnerBatch[DDPGTrainConfig]], None] | None = None
    batch: Callable[[DDPGAgent, LearnerBatch[DDPGTrainConfig], TensorDictBase], bool | None] | None = None


def train_ddpg(
    make_env: Callable[[int], EnvBase] | Sequence[Callable[[int], EnvBase]],
    config: DDPGTrainConfig,
    *,
    hooks: DDPGHooks | None = None,
    **options: Unpack[LearnerOptions],
) -> Trained:
    """Train ``len(seeds)`` DDPG (or TD3) learners as one batch on ``make_env`` (shaped by ``shaping``).

    Every batch: the batch into the replay buffer (and each learner's observation normaliser); then,
    once ``learning_starts`` frames per learner are collected, ``updates_per_batch`` gradient steps on
    replay samples (:meth:`~torchrl_subgoal.training.ddpg_parts.DDPGAgent.update_on`: every learner its own
    samples, re-shaped with the current potential when ``reshape_samples``), each followed by a soft
    target update (or one after them all: ``polyak_every="batch"``); then, unless the potential is
    trained online or fixed, one step of the potential on the batch's real SMDP transitions (one
    learner only); then ``hooks.batch``.

    ``make_env``, ``config`` and ``**options`` (``seeds``, ``shaping``…): as for
    :func:`~torchrl_subgoal.training.train_a2c`; ``hooks``: :class:`DDPGHooks`.

    Examples:
        >>> import functools
        >>> from torchrl.envs import GymEnv
        >>> from torchrl_subgoal.training import batched
        >>> config = DDPGTrainConfig(frames_per_batch=50, total_frames=100, learning_starts=50,
        ...                          updates_per_batch=2, batch_size=16, hidden=(16,))
        >>> trained = train_ddpg(batched(functools.partial(GymEnv, "Pendulum-v1")), config, episode_cap=200)
        >>> trained.curve.frames
        [50, 100]
    """
    if config.reshape_samples and options.get("shaping") is None:
        raise ValueError("reshape_samples needs shaping: there is no potential to re-shape samples with")
    hooks = hooks or DDPGHooks()
    batch = LearnerBatch(make_env, config, **options)
    k = batch.learners
    reshaper = batch.reshaper() if config.reshape_samples else None
    modules = batch.modules(ddpg_modules, keys=tuple(reshaper.keys) if reshaper is not None else ())
    agent = modules["agent"]
    assert isinstance(agent, DDPGAgent)
    start = functools.partial(hooks.start, agent, batch) if hooks.start is not None else None
    warmup = config.warmup_frames
    with contextlib.closing(batch.collect(agent.policy, init_random_frames=warmup, start=start)) as batches:
        for data in batches:
            agent.extend(data)
            sums = {"loss_value": torch.zeros(k), "loss_actor": torch.zeros(k)}
            counts = dict.fromkeys(sums, 0)
            if batch.frames >= warmup:
                for _ in range(config.updates_per_batch):
                    sample = agent.replay.sample()
                    for name, value in agent.update_on(reshaper(sample) if reshaper is not None else sample).items():
                        sums[name] += value.cpu()
                        counts[name] += 1
                    if config.polyak_every == "update":
                        agent.soft_update()
                if config.polyak_every == "batch":
                    agent.soft_update()
            batch.record(data, {name: sums[name] / counts[name] if counts[name] else float("nan") for name in sums})
            if hooks.batch is not None and hooks.batch(agent, batch, data):
                break
    return batch.result("ddpg", modules)

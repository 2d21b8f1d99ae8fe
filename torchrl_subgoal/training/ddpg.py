"""DDPG (or TD3) on TorchRL's collectors with subgoal shaping, for any bounded continuous-action env.

One learner is one :class:`~torchrl_subgoal.agents.ddpg.DDPGAgent` (the
implementation the pick-and-place reproduction uses: actor and critic MLPs
over the observation normalised by running statistics, TorchRL's
:class:`~torchrl.objectives.DDPGLoss` or :class:`~torchrl.objectives.TD3Loss`,
Polyak-averaged target networks, Gaussian exploration, a TorchRL replay
buffer) trained on batches of a TorchRL collector: after each batch,
``updates_per_batch`` gradient steps, each followed by a soft target update.
The env, the shaping transform and the potential's training are the shared
plumbing of :mod:`~torchrl_subgoal.training.common`; with ``reshape_samples``
every replay sample is re-shaped with the potential as it is now
(:class:`~torchrl_subgoal.training.SampleReshaper`)::

    shaping = Shaping(series, TabularPotential(series.num_abstract_states))
    curve = train_ddpg(make_env, DDPGTrainConfig(total_frames=300_000), shaping=shaping, seed=0)
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal

import torch
from tensordict.utils import NestedKey
from torchrl.data import Bounded
from torchrl.envs import EnvBase
from torchrl.record.loggers import Logger

from torchrl_subgoal.agents.ddpg import DDPGAgent, DDPGConfig, TD3Settings
from torchrl_subgoal.training.common import (
    CurveRecorder,
    LearningCurve,
    SampleReshaper,
    Shaping,
    _close_probe,
    _probe_env,
    _seed_collector,
    check_settings,
    close_collector,
    learner_env,
    make_collector,
    subgoal_states,
)

__all__ = ["DDPGTrainConfig", "ddpg_agent", "train_ddpg"]


@dataclass
class DDPGTrainConfig:
    """Settings of one DDPG (or TD3) learner.

    The defaults are those of TorchRL's own DDPG example (``sota-implementations/ddpg``
    in the TorchRL repository: one env, 1,000 frames per batch followed by as many
    gradient steps (an update-to-data ratio of 1), 25,000 random frames first,
    batches of 256 from a buffer of 10⁶, Adam 3e-4 for actor and critic, γ 0.99,
    Polyak 0.995 after every gradient step, two ReLU hidden layers of 256), except
    for the exploration: Gaussian noise of s.d. 0.1 (the TD3 paper's) in place of
    the example's Ornstein–Uhlenbeck noise, and no weight decay. ``td3=True``
    takes the TD3 settings of TorchRL's TD3 example (two critics, target noise 0.2
    clipped at 0.5, actor and targets updated every second step). The pick-and-place
    reproduction's settings (the authors') are :class:`~torchrl_subgoal.agents.ddpg.DDPGConfig`'s.

    Examples:
        >>> config = DDPGTrainConfig(frames_per_batch=100, total_frames=1000)
        >>> config.iterations, config.agent().polyak
        (10, 0.995)
        >>> DDPGTrainConfig(noise_eps=-0.1)
        Traceback (most recent call last):
        ...
        ValueError: noise_eps must be >= 0, got -0.1
    """

    num_envs: int = 1
    """envs per collecting process (the batch a collector steps)"""
    env_workers: int = 0
    """``ParallelEnv`` worker processes holding the envs (0: the batched env in the collecting process)"""
    collector_workers: int = 0
    """0: one ``Collector`` in this process; ``k``: a ``MultiSyncCollector`` of ``k`` processes"""
    frames_per_batch: int = 1000
    """frames per collected batch (over all collector workers)"""
    total_frames: int = 1_000_000
    """frames per learner"""
    gamma: float = 0.99
    """discount"""
    learning_starts: int = 25_000
    """frames collected with uniformly random actions before the first gradient step"""
    updates_per_batch: int = 1000
    """gradient steps after each collected batch (each followed by a soft target update)"""
    batch_size: int = 256
    """transitions per gradient step"""
    buffer_size: int = 1_000_000
    """replay capacity (transitions)"""
    lr: float = 3e-4
    """Adam learning rate of the actor and the critic"""
    polyak: float = 0.995
    """target <- polyak * target + (1 - polyak) * online, after every gradient step"""
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
    td3: bool = False
    """TD3 (two critics, smoothed targets, delayed actor updates) instead of DDPG"""
    policy_delay: int = 2
    """TD3: critic updates per actor and target update"""
    target_noise: float = 0.2
    """TD3: s.d. of the noise on the target action (action units)"""
    noise_clip: float = 0.5
    """TD3: bound of that noise"""
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
    """actor and critic also read the subgoal index ``z`` (one-hot)"""
    reshape_samples: bool = False
    """re-shape every replay sample with the potential as it is now before the loss (else the loss reads
    the reward shaped at collection)"""

    def __post_init__(self) -> None:
        self.hidden = tuple(int(h) for h in self.hidden)
        check_settings(self)
        for name in ("updates_per_batch", "batch_size", "buffer_size", "policy_delay"):
            if getattr(self, name) < 1:
                raise ValueError(f"{name} must be >= 1, got {getattr(self, name)}")
        if self.td3 and self.action_l2:
            raise ValueError(f"action_l2 ({self.action_l2}) is DDPG's actor penalty; TD3 here has none: set it to 0")
        for name in ("learning_starts", "noise_eps", "target_noise", "noise_clip", "action_l2"):
            if getattr(self, name) < 0:
                raise ValueError(f"{name} must be >= 0, got {getattr(self, name)}")
        for name in ("lr", "norm_clip"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)}")
        for name in ("polyak", "random_eps"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise ValueError(f"{name} must lie in [0, 1], got {getattr(self, name)}")

    @property
    def iterations(self) -> int:
        """Collected batches per learner."""
        return math.ceil(self.total_frames / self.frames_per_batch)

    def agent(self) -> DDPGConfig:
        """The agent's hyper-parameters (no return clipping)."""
        return DDPGConfig(
            hidden=self.hidden,
            actor_lr=self.lr,
            critic_lr=self.lr,
            gamma=self.gamma,
            polyak=self.polyak,
            batch_size=self.batch_size,
            buffer_size=self.buffer_size,
            random_eps=self.random_eps,
            noise_eps=self.noise_eps,
            action_l2=self.action_l2,
            clip_return=None,
            clip_positive=False,
            norm_clip=self.norm_clip,
        )

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
) -> DDPGAgent:
    """The DDPG (or TD3) agent of ``config`` for ``env``'s observation vector and bounded actions.

    Args:
        env: gives the observation and action specs.
        config: the settings.
        observation_key: the observation vector the networks read.
        subgoal_states: if positive, actor and critic also read ``"subgoal_index"`` (one-hot ``z``).
        keys: more entries the replay buffer keeps.

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
        observation_key=observation_key,
        subgoal_states=subgoal_states,
        td3=config.td3_settings(),
        keys=keys,
    )


def train_ddpg(
    make_env: Callable[[int], EnvBase],
    config: DDPGTrainConfig,
    *,
    shaping: Shaping | None = None,
    observation_key: NestedKey = "observation",
    seed: int = 0,
    episode_cap: float | None = None,
    logger: Logger | None = None,
    progress: Callable[[int], None] | None = None,
) -> LearningCurve:
    """Train one DDPG (or TD3) learner on ``make_env(config.num_envs)`` (shaped by ``shaping``); its curve.

    Every batch: unless the potential is trained online or fixed, one step of
    ``shaping.potential`` on the batch's real SMDP transitions; the batch into the
    replay buffer (and the observation normaliser); then, once ``learning_starts``
    frames are collected, ``updates_per_batch`` gradient steps on replay samples
    (re-shaped with the current potential when ``reshape_samples``), each followed
    by a soft target update.

    Args:
        make_env: ``make_env(num_envs)`` returns an env with batch size ``[num_envs]``.
        config: the settings.
        shaping: the shaping transform's pieces (``None``: plain DDPG).
        observation_key: the observation vector actor and critic read.
        seed: seeds torch (networks, sampling, exploration) and the envs.
        episode_cap: what the curve records before any episode finished (default: the env's
            ``max_steps`` when it has one).
        logger: a TorchRL logger (CSV, TensorBoard…) for losses and episode statistics.
        progress: called with 1 after every batch.

    Examples:
        >>> from torchrl.envs import GymEnv
        >>> from torchrl_subgoal.training import batched
        >>> config = DDPGTrainConfig(frames_per_batch=50, total_frames=100, learning_starts=50,
        ...                          updates_per_batch=2, batch_size=16, hidden=(16,))
        >>> import functools
        >>> train_ddpg(batched(functools.partial(GymEnv, "Pendulum-v1")), config, episode_cap=200).frames
        [50, 100]
    """
    if config.reshape_samples and shaping is None:
        raise ValueError("reshape_samples needs shaping: there is no potential to re-shape samples with")
    torch.manual_seed(seed)
    factory, trainer = learner_env(make_env, config, shaping)
    states = subgoal_states(config, shaping)
    reshaper = None
    if config.reshape_samples:
        assert shaping is not None
        reshaper = SampleReshaper(shaping.transform(shaping.potential, config.gamma, None))
    probe, cap = _probe_env(make_env, episode_cap)
    agent = ddpg_agent(
        probe, config, observation_key, subgoal_states=states, keys=tuple(reshaper.keys) if reshaper is not None else ()
    )
    _close_probe(probe)
    collector = make_collector(factory, agent.policy, config, init_random_frames=config.learning_starts)
    _seed_collector(collector, seed)
    recorder = CurveRecorder(
        config.record_window, cap, config.reward_scale, logger, progress, shaping.potential if shaping else None
    )
    frames = 0
    try:
        for data in collector:
            frames += data.numel()
            potential_loss = trainer.step(data) if trainer is not None else math.nan
            agent.extend(data)
            sums = {"loss_value": 0.0, "loss_actor": 0.0}
            counts = {"loss_value": 0, "loss_actor": 0}
            if frames >= config.learning_starts:
                for _ in range(config.updates_per_batch):
                    sample = agent.replay.sample()
                    if reshaper is not None:
                        sample = reshaper(sample)
                    for name, value in agent.update_on(sample).items():
                        sums[name] += value
                        counts[name] += 1
                    agent.soft_update()
            if config.collector_workers:
                collector.update_policy_weights_()
            recorder.add(
                data,
                frames,
                {
                    **{name: sums[name] / counts[name] if counts[name] else math.nan for name in sums},
                    "loss_potential": potential_loss,
                },
            )
    finally:
        close_collector(collector)
    return recorder.curve

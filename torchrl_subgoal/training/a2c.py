"""A2C on TorchRL's collectors with subgoal shaping: the building blocks of ``recipes/a2c.py``.

One learner is one A2C agent: a policy and a value network
(:class:`~tensordict.nn.TensorDictModule` s) trained by TorchRL's
:class:`~torchrl.objectives.A2CLoss` with :class:`~torchrl.objectives.value.GAE`
advantages, on batches from a :class:`~torchrl.collectors.Collector` (or a
:class:`~torchrl.collectors.MultiSyncCollector` of worker processes) over a
batch of envs (or a :class:`~torchrl.envs.ParallelEnv` of env workers). The
shaping transform sits on the *outer* env of each collecting process; its
potential is shared with the main process (:class:`EnvFactory`), where
:class:`~torchrl_subgoal.SubgoalValueLoss` trains it from the collected SMDP
transitions with its own optimiser — or the transform trains it online.

A user's env needs an env factory ``make_env(num_envs) -> EnvBase`` (an env
with batch size ``[num_envs]``; :func:`batched` builds one from a single-env
factory) and, for shaping, a subgoal series::

    shaping = Shaping(series, TabularPotential(series.num_abstract_states), observation_key="observation")
    curve = train_a2c(make_env, A2CConfig(total_frames=200_000), shaping=shaping, seed=0)
"""

from __future__ import annotations

import functools
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
import torch
from tensordict import TensorDictBase
from tensordict.nn import TensorDictModule, TensorDictModuleBase
from tensordict.utils import NestedKey
from torch import nn
from torchrl.collectors import Collector, MultiSyncCollector
from torchrl.data import Bounded, Categorical, OneHot, TensorSpec
from torchrl.envs import (
    Compose,
    EnvBase,
    ParallelEnv,
    RewardScaling,
    RewardSum,
    SerialEnv,
    StepCounter,
    TransformedEnv,
)
from torchrl.modules import OneHotCategorical, ProbabilisticActor, ValueOperator
from torchrl.objectives import A2CLoss
from torchrl.objectives.value import GAE
from torchrl.record.loggers import Logger

from torchrl_subgoal.loss import SubgoalValueLoss
from torchrl_subgoal.subgoals import StateAggregation, SubgoalSeries
from torchrl_subgoal.training.shared import EnvFactory
from torchrl_subgoal.training.smdp import smdp_transitions
from torchrl_subgoal.transform import SubgoalPotentialTransform

__all__ = [
    "A2CConfig",
    "FourierFeatures",
    "LearningCurve",
    "Shaping",
    "actor_critic",
    "batched",
    "make_collector",
    "shaped_env",
    "train_a2c",
]

Features = Literal["one_hot", "fourier", "mlp"]
EPISODE_RETURN = "episode_return"


@dataclass
class A2CConfig:
    """Settings of one A2C learner.

    Attributes:
        num_envs: envs per learner (the batch a collector steps).
        env_workers: ``ParallelEnv`` worker processes holding the envs (0: the batched env
            in the collecting process).
        collector_workers: 0: one :class:`~torchrl.collectors.Collector` in this process;
            ``k ≥ 1``: a :class:`~torchrl.collectors.MultiSyncCollector` of ``k`` processes,
            each with ``num_envs`` envs.
        frames_per_batch: frames per collected batch (one A2C update), over all collector
            workers (each collects ``frames_per_batch / k``).
        total_frames: frames per learner.
        gamma: discount.
        gae_lambda: GAE's λ.
        lr: Adam learning rate of the policy and the value network.
        entropy_coeff: entropy bonus.
        critic_coeff: weight of the value loss.
        max_grad_norm: gradient clipping.
        normalize_advantage: standardise advantages per batch.
        features: the networks' input layer: ``"one_hot"`` (a categorical observation),
            ``"fourier"`` (Fourier basis of a bounded observation) or ``"mlp"``.
        hidden: hidden layer sizes (``()``: linear in the features).
        fourier_order: order of the Fourier basis.
        reward_scale: the env reward is multiplied by this before shaping and learning
            (records keep the env's units).
        value_lr: learning rate of the potential's optimiser (or ``α_v`` online).
        value_optimizer: ``"adam"`` (reduction mean) or ``"sgd"`` (reduction sum: the tabular update).
        online_potential: train the potential in the transform at every step (the paper's
            update) instead of from each batch's transitions.
        record_window: batches the recorded mean episode length is estimated over (frames per
            finished episode in the window).

    Examples:
        >>> config = A2CConfig(num_envs=8, frames_per_batch=128, total_frames=1024)
        >>> config.iterations
        8
        >>> A2CConfig(num_envs=8, frames_per_batch=100)
        Traceback (most recent call last):
        ...
        ValueError: frames_per_batch (100) must be a multiple of num_envs (8)
    """

    num_envs: int = 16
    env_workers: int = 0
    collector_workers: int = 0
    frames_per_batch: int = 256
    total_frames: int = 200_000
    gamma: float = 0.99
    gae_lambda: float = 0.95
    lr: float = 1e-3
    entropy_coeff: float = 0.01
    critic_coeff: float = 0.5
    max_grad_norm: float = 1.0
    normalize_advantage: bool = False
    features: Features = "mlp"
    hidden: tuple[int, ...] = (64,)
    fourier_order: int = 3
    reward_scale: float = 1.0
    value_lr: float = 0.05
    value_optimizer: Literal["adam", "sgd"] = "adam"
    online_potential: bool = False
    record_window: int = 8

    def __post_init__(self) -> None:
        for name in ("num_envs", "frames_per_batch", "total_frames", "record_window"):
            if getattr(self, name) < 1:
                raise ValueError(f"{name} must be >= 1, got {getattr(self, name)}")
        for name in ("env_workers", "collector_workers"):
            if getattr(self, name) < 0:
                raise ValueError(f"{name} must be >= 0, got {getattr(self, name)}")
        if self.env_workers and self.num_envs % self.env_workers:
            raise ValueError(f"num_envs ({self.num_envs}) must be a multiple of env_workers ({self.env_workers})")
        if self.frames_per_batch % self.num_envs:
            raise ValueError(f"frames_per_batch ({self.frames_per_batch}) must be a multiple of num_envs "
                             f"({self.num_envs})")
        if self.frames_per_batch % (self.num_envs * max(1, self.collector_workers)):
            raise ValueError(f"frames_per_batch ({self.frames_per_batch}) must be a multiple of num_envs x "
                             f"collector_workers ({self.num_envs} x {self.collector_workers}): each worker "
                             "collects an equal share with its num_envs envs")
        if self.features not in ("one_hot", "fourier", "mlp"):
            raise ValueError(f"features must be one_hot, fourier or mlp, got {self.features!r}")
        if self.value_optimizer not in ("adam", "sgd"):
            raise ValueError(f"value_optimizer must be adam or sgd, got {self.value_optimizer!r}")
        self.hidden = tuple(int(h) for h in self.hidden)

    @property
    def iterations(self) -> int:
        """Collected batches (A2C updates) per learner (a ``MultiSyncCollector``'s batch holds
        ``frames_per_batch`` frames of all its workers)."""
        return math.ceil(self.total_frames / self.frames_per_batch)


@dataclass
class Shaping:
    """The shaping transform of one learner, built in every process that steps its envs.

    Args:
        subgoals: a :class:`~torchrl_subgoal.SubgoalSeries` (or one per env) or a
            :class:`~torchrl_subgoal.StateAggregation`.
        potential: ``Φ``, shared by every env of the learner (e.g.
            ``TabularPotential(series.num_abstract_states)``); trained unless it is
            a :class:`~torchrl_subgoal.NaivePotential` or frozen.
        options: further keyword arguments of
            :class:`~torchrl_subgoal.SubgoalPotentialTransform` (``observation_key``,
            ``zero_terminal_potential``…); ``gamma`` and the online update's learning
            rate come from the :class:`A2CConfig`.

    Examples:
        >>> from torchrl_subgoal import Cell, SubgoalSeries, TabularPotential
        >>> series = SubgoalSeries([Cell(3, 6), Cell(7, 9)])
        >>> shaping = Shaping(series, TabularPotential(series.num_abstract_states), {"observation_key": "cell"})
        >>> shaping.trained
        True
        >>> type(shaping.transform(shaping.potential, gamma=0.99, value_lr=None)).__name__
        'SubgoalPotentialTransform'
    """

    subgoals: SubgoalSeries | Sequence[SubgoalSeries] | StateAggregation
    potential: TensorDictModuleBase
    options: dict[str, Any] = field(default_factory=dict)

    @property
    def trained(self) -> bool:
        """Whether the potential has parameters to learn."""
        return any(p.requires_grad for p in self.potential.parameters())

    def transform(self, potential: TensorDictModuleBase, gamma: float, value_lr: float | None) -> SubgoalPotentialTransform:
        """The transform over ``potential`` (the process's view of the shared one)."""
        return SubgoalPotentialTransform(self.subgoals, potential, gamma=gamma, value_update=value_lr, **self.options)


def batched(make_single: Callable[[], EnvBase]) -> Callable[[int], EnvBase]:
    """``make_env(num_envs)`` for an env that is not batched: a ``SerialEnv`` of ``num_envs`` copies.

    Examples:
        >>> from torchrl.envs import GymEnv
        >>> make_env = batched(functools.partial(GymEnv, "CartPole-v1"))
        >>> make_env(2).batch_size
        torch.Size([2])
    """
    return functools.partial(_serial, make_single)


def _serial(make_single: Callable[[], EnvBase], num_envs: int) -> EnvBase:
    return SerialEnv(num_envs, make_single)


def shaped_env(
    make_env: Callable[[int], EnvBase],
    num_envs: int,
    *,
    env_workers: int = 0,
    shaping: Shaping | None = None,
    potential: TensorDictModuleBase | None = None,
    gamma: float = 0.99,
    value_lr: float | None = None,
    reward_scale: float = 1.0,
    episode_stats: bool = True,
) -> EnvBase:
    """The env one collecting process steps: ``num_envs`` envs (in ``env_workers`` processes), then
    on the outer env a reward scaling, the shaping transform, a step counter and the episode's env return.

    ``potential`` is this process's view of the shaping potential (by default ``shaping.potential``).
    ``episode_stats=False`` leaves out the step counter and the episode return (``"step_count"``,
    ``"episode_return"``), for a caller that reads neither: two transforms less on every step; with
    no other transform either, the env itself is returned.

    Examples:
        >>> from torchrl_subgoal import Cell, SubgoalSeries, TabularPotential
        >>> from torchrl_subgoal.envs import FourRoomsEnv
        >>> shaping = Shaping(SubgoalSeries([Cell(3, 6)]), TabularPotential(2), {"observation_key": "cell"})
        >>> env = shaped_env(FourRoomsEnv, 4, shaping=shaping)
        >>> data = env.rollout(3)
        >>> data["next", "subgoal_index"].shape, data["next", "episode_return"].shape
        (torch.Size([4, 3, 1]), torch.Size([4, 3, 1]))
    """
    if env_workers:
        base: EnvBase = ParallelEnv(env_workers, functools.partial(make_env, num_envs // env_workers))
    else:
        base = make_env(num_envs)
    transforms: list[Any] = [StepCounter()] if episode_stats else []
    if reward_scale != 1.0:
        transforms.append(RewardScaling(loc=0.0, scale=reward_scale))
    reward_key: NestedKey = "reward"
    if shaping is not None:
        transform = shaping.transform(potential if potential is not None else shaping.potential, gamma, value_lr)
        transforms.append(transform)
        reward_key = transform.env_reward_key
    if episode_stats:
        transforms.append(RewardSum(in_keys=[reward_key], out_keys=[EPISODE_RETURN]))
    return TransformedEnv(base, Compose(*transforms)) if transforms else base


class FourierFeatures(nn.Module):
    """``cos(π c · s̃)`` for every ``c ∈ {0..order}^D``, ``s̃ = clip((s − low) / (high − low), 0, 1)``.

    Args:
        low: lower bounds of the observation, ``[D]``.
        high: upper bounds, ``[D]``.
        order: the basis order (``(order + 1)^D`` features).

    Examples:
        >>> f = FourierFeatures(torch.zeros(2), torch.ones(2), order=1)
        >>> f(torch.tensor([[0.0, 1.0]])).round().tolist()
        [[1.0, -1.0, 1.0, -1.0]]
    """

    def __init__(self, low: torch.Tensor, high: torch.Tensor, order: int) -> None:
        super().__init__()
        low, high = torch.as_tensor(low, dtype=torch.float32), torch.as_tensor(high, dtype=torch.float32)
        dims = low.numel()
        grids = torch.meshgrid(*[torch.arange(order + 1, dtype=torch.float32)] * dims, indexing="ij")
        self.register_buffer("coefficients", torch.stack([g.reshape(-1) for g in grids], -1))  # [F, D]
        self.register_buffer("low", low.reshape(-1))
        self.register_buffer("scale", 1.0 / (high - low).reshape(-1))
        self.num_features = int(self.coefficients.shape[0])

    low: torch.Tensor
    scale: torch.Tensor
    coefficients: torch.Tensor

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        x = ((obs.float() - self.low) * self.scale).clamp(0.0, 1.0)
        return torch.cos(math.pi * x @ self.coefficients.T)


class _OneHot(nn.Module):
    def __init__(self, n: int) -> None:
        super().__init__()
        self.n = n

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        return nn.functional.one_hot(obs.long(), self.n).float()


def _trunk(spec: TensorSpec, features: Features, hidden: Sequence[int], order: int) -> tuple[nn.Module, int]:
    """The input layers for an observation spec: a module and its output size."""
    layers: list[nn.Module]
    if features == "one_hot":
        if not isinstance(spec, Categorical | OneHot):
            raise ValueError(f"one_hot features need a categorical observation, got {type(spec).__name__}")
        n = int(spec.space.n)
        layers, size = ([_OneHot(n)] if isinstance(spec, Categorical) else [nn.Flatten(-1)]), n
    elif features == "fourier":
        if not isinstance(spec, Bounded):
            raise ValueError(f"fourier features need a bounded observation, got {type(spec).__name__}")
        low, high = spec.space.low, spec.space.high
        while low.ndim > 1:
            low, high = low[0], high[0]
        basis = FourierFeatures(low, high, order)
        layers, size = [basis], basis.num_features
    else:
        size = int(spec.shape[-1]) if spec.shape else 1
        layers = [nn.Identity()]
    for width in hidden:
        layers += [nn.Linear(size, width), nn.Tanh()]
        size = width
    return nn.Sequential(*layers), size


def actor_critic(
    env: EnvBase,
    observation_key: NestedKey = "observation",
    *,
    features: Features = "mlp",
    hidden: Sequence[int] = (64,),
    fourier_order: int = 3,
) -> tuple[ProbabilisticActor, ValueOperator]:
    """A categorical policy and a value network over ``observation_key`` for ``env``'s discrete actions.

    Args:
        env: gives the observation and action specs.
        observation_key: the networks' input.
        features: ``"one_hot"`` for a categorical observation (a table lookup when
            ``hidden=()``), ``"fourier"`` for a bounded one, ``"mlp"`` otherwise.
        hidden: hidden layer sizes.
        fourier_order: order of the Fourier basis.

    Examples:
        >>> from torchrl_subgoal.envs import FourRoomsEnv
        >>> actor, critic = actor_critic(FourRoomsEnv(3), features="one_hot")
        >>> td = critic(actor(FourRoomsEnv(3).reset()))
        >>> td["action"].shape, td["state_value"].shape
        (torch.Size([3]), torch.Size([3, 1]))
    """
    spec = env.observation_spec[observation_key]
    action_spec = env.full_action_spec[env.action_key]
    if not isinstance(action_spec, Categorical | OneHot):
        raise ValueError(f"A2C here needs discrete actions (Categorical or OneHot), got {type(action_spec).__name__}")
    n_actions = int(action_spec.space.n)
    policy_trunk, size = _trunk(spec, features, hidden, fourier_order)
    value_trunk, _ = _trunk(spec, features, hidden, fourier_order)
    policy_net = nn.Sequential(policy_trunk, nn.Linear(size, n_actions))
    value_net = nn.Sequential(value_trunk, nn.Linear(size, 1))
    for net in (policy_net, value_net):  # start from a uniform policy and a zero value
        last = net[-1]
        assert isinstance(last, nn.Linear)
        nn.init.zeros_(last.weight)
        nn.init.zeros_(last.bias)
    distribution = OneHotCategorical if isinstance(action_spec, OneHot) else torch.distributions.Categorical
    actor = ProbabilisticActor(
        TensorDictModule(policy_net, in_keys=[observation_key], out_keys=["logits"]),
        in_keys=["logits"], spec=action_spec, distribution_class=distribution, return_log_prob=True,
    )
    critic = ValueOperator(value_net, in_keys=[observation_key])
    return actor, critic


def make_collector(
    env_factory: Callable[[], EnvBase],
    policy: TensorDictModuleBase,
    config: A2CConfig,
) -> Collector | MultiSyncCollector:
    """A ``Collector`` over ``env_factory()`` in this process, or a ``MultiSyncCollector`` of
    ``config.collector_workers`` processes each building its env from ``env_factory``.

    Examples:
        >>> import functools
        >>> from torchrl_subgoal.envs import FourRoomsEnv
        >>> config = A2CConfig(num_envs=4, frames_per_batch=32, total_frames=64)
        >>> actor, _ = actor_critic(FourRoomsEnv(4), features="one_hot")
        >>> collector = make_collector(functools.partial(FourRoomsEnv, 4), actor, config)
        >>> [batch.shape for batch in collector]
        [torch.Size([4, 8]), torch.Size([4, 8])]
        >>> close_collector(collector)
    """
    if config.collector_workers == 0:
        return Collector(env_factory(), policy, frames_per_batch=config.frames_per_batch,
                         total_frames=config.total_frames, auto_register_policy_transforms=False)
    return MultiSyncCollector(
        [env_factory] * config.collector_workers, policy, frames_per_batch=config.frames_per_batch,
        total_frames=config.total_frames, cat_results="stack", auto_register_policy_transforms=False,
    )


def close_collector(collector: Collector | MultiSyncCollector) -> None:
    """Shut ``collector`` down with its weight-sync schemes.

    TorchRL 0.14's ``MultiSyncCollector.shutdown`` stops the workers but leaves the schemes that
    send them the policy's weights to their ``__del__``, which puts a message on a multiprocessing
    queue. Where the collector is still alive at interpreter exit (a script's global, or one held by
    a reference cycle not yet collected), that starts a queue feeder thread that never runs, and the
    process hangs after its last line (measured: such scripts never exited). Shutting the schemes
    down here, while the interpreter is alive, leaves ``__del__`` nothing to do.

    Examples:
        >>> from torchrl_subgoal.envs import FourRoomsEnv
        >>> collector = Collector(FourRoomsEnv(2), None, frames_per_batch=8, total_frames=16)
        >>> [batch.numel() for batch in collector]
        [8, 8]
        >>> close_collector(collector)
    """
    collector.shutdown()
    for scheme in (getattr(collector, "_weight_sync_schemes", None) or {}).values():
        scheme.shutdown()


@dataclass
class LearningCurve:
    """One learner's record, one entry per collected batch.

    Attributes:
        frames: frames collected after each batch.
        episode_length: the mean episode length, estimated as frames per finished episode
            over the last ``record_window`` batches (the env's episode cap when none finished).
        episode_return: mean env return of the recent finished episodes (env units).
        success: whether the last finished episode terminated (reached its goal).
        episodes: episodes finished so far.

    Examples:
        >>> curve = LearningCurve(frames=[256, 512, 768], episode_length=[900.0, 120.0, 40.0])
        >>> curve.frames_to(100), curve.frames_to(10)
        (768, None)
    """

    frames: list[int] = field(default_factory=list)
    episode_length: list[float] = field(default_factory=list)
    episode_return: list[float] = field(default_factory=list)
    success: list[bool] = field(default_factory=list)
    episodes: list[int] = field(default_factory=list)

    def frames_to(self, length: float) -> int | None:
        """Frames until the mean episode length first falls below ``length`` (``None`` if never)."""
        for frames, value in zip(self.frames, self.episode_length, strict=True):
            if value < length:
                return frames
        return None


class _EpisodeWindow:
    """Episode statistics over the last ``window`` batches.

    The mean episode length is estimated as frames per finished episode over
    the window (the rate at which episodes end): unlike a mean over the last
    finished episodes, it does not favour the short episodes that finish
    first while long ones are still running. With no episode finished in the
    window it is the env's episode cap.
    """

    def __init__(self, window: int, cap: float, reward_scale: float) -> None:
        self.batches: list[tuple[int, int]] = []  # (frames, episodes finished) per batch
        self.returns: list[float] = []
        self.last_success = False
        self.count = 0
        self.window, self.cap, self.reward_scale = window, cap, reward_scale

    def add(self, data: TensorDictBase) -> None:
        done = data.get(("next", "done")).reshape(-1)
        finished = int(done.sum())
        self.batches = [*self.batches, (data.numel(), finished)][-self.window:]
        if not finished:
            return
        nxt = data.get("next")
        returns = (nxt.get(EPISODE_RETURN).reshape(-1)[done] / self.reward_scale).tolist()
        terminated = nxt.get("terminated").reshape(-1)[done]
        self.returns = (self.returns + returns)[-4 * self.window:]
        self.last_success = bool(terminated[-1])
        self.count += finished

    def mean_length(self) -> float:
        frames = sum(f for f, _ in self.batches)
        episodes = sum(e for _, e in self.batches)
        return min(self.cap, frames / episodes) if episodes else self.cap

    def mean_return(self) -> float:
        return float(np.mean(self.returns)) if self.returns else 0.0


def train_a2c(
    make_env: Callable[[int], EnvBase],
    config: A2CConfig,
    *,
    shaping: Shaping | None = None,
    observation_key: NestedKey = "observation",
    seed: int = 0,
    episode_cap: float | None = None,
    logger: Logger | None = None,
    progress: Callable[[int], None] | None = None,
) -> LearningCurve:
    """Train one A2C learner on ``make_env(config.num_envs)`` (shaped by ``shaping``); its curve.

    Every batch: GAE advantages and one A2C step; then, unless the potential is
    trained online or fixed, one step of ``shaping.potential`` on the batch's
    real SMDP transitions with its own optimiser. The potential is in shared
    memory, so envs in collector or env worker processes shape with the one
    trained here (see :mod:`torchrl_subgoal.training.shared`).

    Args:
        make_env: ``make_env(num_envs)`` returns an env with batch size ``[num_envs]``.
        config: the settings.
        shaping: the shaping transform's pieces (``None``: plain A2C).
        observation_key: what the policy and value network read.
        seed: seeds torch (networks, sampling) and the envs.
        episode_cap: what the curve records before any episode finished (default: the env's
            ``max_steps`` when it has one).
        logger: a TorchRL logger (CSV, TensorBoard…) for losses and episode statistics.
        progress: called with 1 after every batch.

    Examples:
        >>> from torchrl_subgoal import Cell, SubgoalSeries, TabularPotential
        >>> from torchrl_subgoal.envs import FourRoomsEnv
        >>> shaping = Shaping(SubgoalSeries([Cell(3, 6)]), TabularPotential(2), {"observation_key": "cell"})
        >>> config = A2CConfig(num_envs=4, frames_per_batch=64, total_frames=256, features="one_hot", hidden=())
        >>> curve = train_a2c(FourRoomsEnv, config, shaping=shaping, seed=0)
        >>> curve.frames
        [64, 128, 192, 256]
    """
    torch.manual_seed(seed)
    online = shaping is not None and config.online_potential and shaping.trained
    factory = EnvFactory(
        shaped_env, make_env=make_env, num_envs=config.num_envs, env_workers=config.env_workers, shaping=shaping,
        potential=shaping.potential if shaping is not None else None, gamma=config.gamma,
        value_lr=config.value_lr if online else None, reward_scale=config.reward_scale,
    )
    probe = make_env(1)
    actor, critic = actor_critic(probe, observation_key, features=config.features, hidden=config.hidden,
                                 fourier_order=config.fourier_order)
    cap = episode_cap if episode_cap is not None else float(getattr(probe, "max_steps", math.nan))
    if not probe.is_closed:  # a batched env that was never started (a SerialEnv from batched()) is closed already
        probe.close()
    advantage = GAE(gamma=config.gamma, lmbda=config.gae_lambda, value_network=critic,
                    average_gae=config.normalize_advantage)
    loss = A2CLoss(actor, critic, entropy_coeff=config.entropy_coeff, critic_coeff=config.critic_coeff,
                   loss_critic_type="l2")
    optimizer = torch.optim.Adam(loss.parameters(), lr=config.lr)
    value_loss: SubgoalValueLoss | None = None
    value_optimizer: torch.optim.Optimizer | None = None
    keeper: SubgoalPotentialTransform | None = None  # reads the transitions out of the collected data
    if shaping is not None and shaping.trained and not online:
        keeper = shaping.transform(shaping.potential, config.gamma, None)
        value_loss = SubgoalValueLoss(shaping.potential, reduction="sum" if config.value_optimizer == "sgd" else "mean")
        value_loss.make_value_estimator(gamma=config.gamma)
        opt_class = torch.optim.SGD if config.value_optimizer == "sgd" else torch.optim.Adam
        value_optimizer = opt_class(shaping.potential.parameters(), lr=config.value_lr)
    collector = make_collector(factory, actor, config)
    # a MultiSyncCollector's workers seed numpy with the seed, which takes 32 bits (sweep seeds take 63)
    collector.set_seed(seed % 2**32 if isinstance(collector, MultiSyncCollector) else seed)
    episodes = _EpisodeWindow(config.record_window, cap, config.reward_scale)
    curve = LearningCurve()
    frames = 0
    start = time.perf_counter()
    try:
        for data in collector:
            frames += data.numel()
            with torch.no_grad():
                advantage(data)
            losses = loss(data)
            total = losses["loss_objective"] + losses["loss_critic"] + losses["loss_entropy"]
            optimizer.zero_grad(set_to_none=True)
            total.backward()
            nn.utils.clip_grad_norm_(loss.parameters(), config.max_grad_norm)
            optimizer.step()
            potential_loss = math.nan
            if value_loss is not None and value_optimizer is not None:
                real = smdp_transitions(data, keeper)
                if len(real):
                    value_optimizer.zero_grad(set_to_none=True)
                    out = value_loss(real)["loss_value"]
                    out.backward()
                    value_optimizer.step()
                    potential_loss = float(out.detach())
            if config.collector_workers:
                collector.update_policy_weights_()
            episodes.add(data)
            curve.frames.append(frames)
            curve.episode_length.append(episodes.mean_length())
            curve.episode_return.append(episodes.mean_return())
            curve.success.append(episodes.last_success)
            curve.episodes.append(episodes.count)
            if logger is not None:
                scalars = {
                    "episode_length": curve.episode_length[-1], "episode_return": curve.episode_return[-1],
                    "episodes": float(episodes.count), "loss_objective": float(losses["loss_objective"]),
                    "loss_critic": float(losses["loss_critic"]), "loss_entropy": float(losses["loss_entropy"]),
                    "frames_per_second": frames / max(time.perf_counter() - start, 1e-9),
                }
                if not math.isnan(potential_loss):
                    scalars["loss_potential"] = potential_loss
                for name, value in scalars.items():
                    logger.log_scalar(name, value, step=frames)
            if progress is not None:
                progress(1)
    finally:
        close_collector(collector)
    return curve


"""What every TorchRL learner here shares: the shaped env, networks' input layers, collectors, records.

One learner, whatever its algorithm, is the same pipeline:

* an env factory ``make_env(num_envs)`` and, for shaping, a :class:`Shaping` (a
  subgoal series and its potential ``Φ``);
* :func:`shaped_env`: the envs, then on the *outer* env a reward scaling, the
  shaping transform, a step counter and the episode's env return; the potential
  reaches collector worker processes through shared memory
  (:class:`~torchrl_subgoal.training.EnvFactory`);
* :func:`make_collector`: a TorchRL ``Collector`` (or ``MultiSyncCollector``);
* per collected batch, the learner's own update, then the potential's: :class:`PotentialTrainer` (one
  step of :class:`~torchrl_subgoal.SubgoalValueLoss` on the batch's SMDP transitions), unless online;
* :class:`CurveRecorder`: the :class:`LearningCurve`, a TorchRL logger and a progress callback.

Two options any deep learner may need: the learner sees ``z``
(:func:`subgoal_states` and :class:`~torchrl_subgoal.agents.subgoal_input.SubgoalInput`,
the one-hot subgoal index as an extra network input) and, for off-policy
learners, :class:`SampleReshaper` (re-shape replay samples with ``Φ`` as it is now).
"""

from __future__ import annotations

import functools
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, Literal, Protocol

import numpy as np
import torch
from tensordict import TensorDictBase
from tensordict.nn import TensorDictModuleBase
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
from torchrl.record.loggers import Logger

from torchrl_subgoal.agents.subgoal_input import SUBGOAL_INDEX, SubgoalInput
from torchrl_subgoal.loss import SubgoalValueLoss
from torchrl_subgoal.subgoals import StateAggregation, SubgoalSeries
from torchrl_subgoal.training.shared import EnvFactory
from torchrl_subgoal.training.smdp import smdp_transitions
from torchrl_subgoal.transform import SubgoalPotentialTransform

# fmt: off
__all__ = [
    "EPISODE_RETURN", "SUBGOAL_INDEX", "CurveRecorder", "EpisodeWindow", "FourierFeatures", "LearnerSettings",
    "LearningCurve", "PotentialTrainer", "SampleReshaper", "Shaping", "batched", "check_settings",
    "close_collector", "learner_env", "make_collector", "shaped_env", "subgoal_states",
]
# fmt: on

Features = Literal["one_hot", "fourier", "mlp"]
#: The env return of the episode so far (a ``RewardSum`` over the unshaped reward), in ``"next"``.
EPISODE_RETURN = "episode_return"


class LearnerSettings(Protocol):
    """The settings every learner's config has (:class:`~torchrl_subgoal.training.A2CConfig`,
    :class:`~torchrl_subgoal.training.PPOConfig`, …), as the shared plumbing reads them.

    Examples:
        >>> from torchrl_subgoal.training import DQNConfig
        >>> config: LearnerSettings = DQNConfig()
        >>> config.num_envs, config.collector_workers
        (1, 0)
    """

    num_envs: int
    env_workers: int
    collector_workers: int
    frames_per_batch: int
    total_frames: int
    gamma: float
    reward_scale: float
    value_lr: float
    value_optimizer: Literal["adam", "sgd"]
    online_potential: bool
    record_window: int

    @property
    def sees_subgoal(self) -> bool | None: ...  # None: whenever there is shaping


def check_settings(config: LearnerSettings) -> None:
    """Refuse bad values of the shared settings, one line naming the field.

    Examples:
        >>> from torchrl_subgoal.training import PPOConfig
        >>> PPOConfig(num_envs=0)
        Traceback (most recent call last):
        ...
        ValueError: num_envs must be >= 1, got 0
    """
    for name in ("num_envs", "frames_per_batch", "total_frames", "record_window"):
        if getattr(config, name) < 1:
            raise ValueError(f"{name} must be >= 1, got {getattr(config, name)}")
    for name in ("env_workers", "collector_workers"):
        if getattr(config, name) < 0:
            raise ValueError(f"{name} must be >= 0, got {getattr(config, name)}")
    if config.env_workers and config.num_envs % config.env_workers:
        raise ValueError(f"num_envs ({config.num_envs}) must be a multiple of env_workers ({config.env_workers})")
    if config.frames_per_batch % (config.num_envs * max(1, config.collector_workers)):
        raise ValueError(
            f"frames_per_batch ({config.frames_per_batch}) must be a multiple of num_envs x "
            f"collector_workers ({config.num_envs} x {max(1, config.collector_workers)}): each "
            "collecting process steps its num_envs envs an equal number of times"
        )
    if not 0.0 <= config.gamma <= 1.0:
        raise ValueError(f"gamma must lie in [0, 1], got {config.gamma}")
    if not config.reward_scale > 0:
        raise ValueError(f"reward_scale must be > 0, got {config.reward_scale}")
    if not config.value_lr > 0:
        raise ValueError(f"value_lr must be > 0, got {config.value_lr}")
    if config.value_optimizer not in ("adam", "sgd"):
        raise ValueError(f"value_optimizer must be adam or sgd, got {config.value_optimizer!r}")


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
            rate come from the learner's config.

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

    def transform(
        self, potential: TensorDictModuleBase, gamma: float, value_lr: float | None
    ) -> SubgoalPotentialTransform:
        """The transform over ``potential`` (the process's view of the shared one)."""
        return SubgoalPotentialTransform(self.subgoals, potential, gamma=gamma, value_update=value_lr, **self.options)


def batched(make_single: Callable[[], EnvBase]) -> Callable[[int], EnvBase]:
    """``make_env(num_envs)`` for an env that is not batched: a ``SerialEnv`` of ``num_envs`` copies.

    Args:
        make_single: builds one env (picklable, e.g. a ``functools.partial``, for worker processes).

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

    Args:
        make_env: ``make_env(n)`` returns an env with batch size ``[n]``.
        num_envs: envs stepped by this process.
        env_workers: ``ParallelEnv`` processes holding them (0: stepped here).
        shaping: the shaping transform's pieces (``None``: no shaping).
        potential: this process's view of the potential.
        gamma: ``γ`` of the shaping term.
        value_lr: the transform's online learning rate (``None``: not trained online).
        reward_scale: the env reward is multiplied by this before shaping.
        episode_stats: add the step counter and the episode's env return.

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


class _Float(nn.Module):
    """A vector observation as float32 (a float64 gymnasium observation, an integer one)."""

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        return obs.float()


class _Chain(nn.Sequential):
    """``nn.Sequential`` whose first module takes every input (a network over ``(s, z)``)."""

    def forward(self, *inputs: torch.Tensor) -> torch.Tensor:
        modules = list(self)
        x = modules[0](*inputs)
        for module in modules[1:]:
            x = module(x)
        return x


def _input_layer(spec: TensorSpec, features: Features, order: int) -> tuple[nn.Module, int]:
    """The features of an observation spec: a module and its output size."""
    if features == "one_hot":
        if not isinstance(spec, Categorical | OneHot):
            raise ValueError(f"one_hot features need a categorical observation, got {type(spec).__name__}")
        n = int(spec.space.n)
        return (_OneHot(n) if isinstance(spec, Categorical) else nn.Flatten(-1)), n
    if features == "fourier":
        if not isinstance(spec, Bounded):
            raise ValueError(f"fourier features need a bounded observation, got {type(spec).__name__}")
        low, high = spec.space.low, spec.space.high
        while low.ndim > 1:
            low, high = low[0], high[0]
        basis = FourierFeatures(low, high, order)
        return basis, basis.num_features
    if features != "mlp":
        raise ValueError(f"features must be one_hot, fourier or mlp, got {features!r}")
    return (nn.Identity() if spec.dtype == torch.float32 else _Float()), (int(spec.shape[-1]) if spec.shape else 1)


def _trunk(
    spec: TensorSpec,
    features: Features,
    hidden: Sequence[int],
    order: int,
    *,
    activation: type[nn.Module] = nn.Tanh,
    subgoal_states: int = 0,
) -> tuple[nn.Module, int]:
    """The input layers for an observation spec (with ``subgoal_states``, the one-hot ``z`` joined:
    their product for one-hot features and no hidden layer, a table over ``(s, z)``; else concatenated),
    then the hidden layers: a module over ``observation`` (or ``(observation, z)``) and its output size."""
    first, size = _input_layer(spec, features, order)
    product = not hidden and features == "one_hot"
    if subgoal_states:
        size = SubgoalInput.size(size, subgoal_states, product=product)
    layers: list[nn.Module] = []
    for width in hidden:
        layers += [nn.Linear(size, width), activation()]
        size = width
    if subgoal_states:
        return SubgoalInput(subgoal_states, first, nn.Sequential(*layers), product=product), size
    return nn.Sequential(first, *layers), size


def _network(trunk: nn.Module, *layers: nn.Module) -> nn.Module:
    """The ``layers`` after ``trunk(...)``; the trunk may read several inputs."""
    return _Chain(trunk, *layers)


def subgoal_states(config: LearnerSettings, shaping: Shaping | None) -> int:
    """Abstract states the networks' one-hot ``z`` input spans; 0 when they do not see ``z``.

    Args:
        config: ``config.sees_subgoal`` asks for the input (``None``: whenever there is shaping).
        shaping: the shaping whose transform keeps ``z`` (``"subgoal_index"``).

    Raises:
        ValueError: ``sees_subgoal=True`` without shaping (no transform keeps ``z``).

    Examples:
        >>> from torchrl_subgoal import Cell, SubgoalSeries, TabularPotential
        >>> from torchrl_subgoal.training import DQNConfig
        >>> shaping = Shaping(SubgoalSeries([Cell(3, 6), Cell(7, 9)]), TabularPotential(3))
        >>> subgoal_states(DQNConfig(), shaping), subgoal_states(DQNConfig(sees_subgoal=False), shaping)
        (3, 0)
    """
    if config.sees_subgoal is False or (config.sees_subgoal is None and shaping is None):
        return 0
    if shaping is None:
        raise ValueError("sees_subgoal needs shaping: the subgoal index z is kept by the shaping transform")
    return shaping.transform(shaping.potential, config.gamma, None).num_abstract_states


def _subgoal_keys(observation_key: NestedKey, states: int) -> list[NestedKey]:
    """What a network reads: the observation, and ``z`` when it sees it."""
    return [observation_key, SUBGOAL_INDEX] if states else [observation_key]


class _CollectorSettings(Protocol):
    """What :func:`make_collector` reads of a config."""

    collector_workers: int
    frames_per_batch: int
    total_frames: int


def make_collector(
    env_factory: Callable[[], EnvBase],
    policy: TensorDictModuleBase,
    config: _CollectorSettings,
    *,
    init_random_frames: int | None = None,
) -> Collector | MultiSyncCollector:
    """A ``Collector`` over ``env_factory()`` in this process, or a ``MultiSyncCollector`` of
    ``config.collector_workers`` processes each building its env from ``env_factory``.

    Args:
        env_factory: builds a collecting process's env (picklable for worker processes).
        policy: the acting policy (its weights are sent to the workers).
        config: ``collector_workers``, ``frames_per_batch`` and ``total_frames``.
        init_random_frames: frames collected with random actions first (off-policy learners), rounded
            up to whole batches.

    Examples:
        >>> import functools
        >>> from torchrl_subgoal.envs import FourRoomsEnv
        >>> from torchrl_subgoal.training import A2CConfig, actor_critic
        >>> config = A2CConfig(num_envs=4, frames_per_batch=32, total_frames=64)
        >>> actor, _ = actor_critic(FourRoomsEnv(4), features="one_hot")
        >>> collector = make_collector(functools.partial(FourRoomsEnv, 4), actor, config)
        >>> [batch.shape for batch in collector]
        [torch.Size([4, 8]), torch.Size([4, 8])]
        >>> close_collector(collector)
    """
    extra: dict[str, Any] = {}
    if init_random_frames:  # whole batches (what the collector would do, with a warning)
        extra["init_random_frames"] = -(-init_random_frames // config.frames_per_batch) * config.frames_per_batch
    if config.collector_workers == 0:
        return Collector(
            env_factory(),
            policy,
            frames_per_batch=config.frames_per_batch,
            total_frames=config.total_frames,
            auto_register_policy_transforms=False,
            **extra,
        )
    return MultiSyncCollector(
        [env_factory] * config.collector_workers,
        policy,
        frames_per_batch=config.frames_per_batch,
        total_frames=config.total_frames,
        cat_results="stack",
        auto_register_policy_transforms=False,
        **extra,
    )


def close_collector(collector: Collector | MultiSyncCollector) -> None:
    """Shut ``collector`` down with its weight-sync schemes.

    TorchRL 0.14's ``MultiSyncCollector.shutdown`` stops the workers but leaves the schemes that
    send them the policy's weights to their ``__del__``, which puts a message on a multiprocessing
    queue. Where the collector is still alive at interpreter exit (a script's global, or one held by
    a reference cycle not yet collected), that starts a queue feeder thread that never runs, and the
    process hangs after its last line (measured: such scripts never exited). Shutting the schemes
    down here, while the interpreter is alive, leaves ``__del__`` nothing to do.

    Args:
        collector: the collector to close.

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


def _seed_collector(collector: Collector | MultiSyncCollector, seed: int) -> None:
    """Seed the collector's envs and policy noise (a ``MultiSyncCollector``'s workers seed numpy with
    the seed, which takes 32 bits; sweep seeds take 63)."""
    collector.set_seed(seed % 2**32 if isinstance(collector, MultiSyncCollector) else seed)


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


class EpisodeWindow:
    """Episode statistics over the last ``window`` batches.

    The mean episode length is estimated as frames per finished episode over
    the window (the rate at which episodes end): unlike a mean over the last
    finished episodes, it does not favour the short episodes that finish
    first while long ones are still running. With no episode finished in the
    window it is the env's episode cap.

    Args:
        window: batches the statistics span.
        cap: the episode length recorded while no episode finished in the window.
        reward_scale: returns are divided by it (records in the env's units).

    Examples:
        >>> from tensordict import TensorDict
        >>> window = EpisodeWindow(2, cap=100.0, reward_scale=1.0)
        >>> done = torch.tensor([[False], [True], [False], [True]])
        >>> window.add(TensorDict({("next", "done"): done, ("next", "terminated"): done,
        ...                        ("next", "episode_return"): torch.ones(4, 1)}, [4]))
        >>> window.mean_length(), window.mean_return(), window.count
        (2.0, 1.0, 2)
    """

    def __init__(self, window: int, cap: float, reward_scale: float) -> None:
        self.batches: list[tuple[int, int]] = []  # (frames, episodes finished) per batch
        self.returns: list[float] = []
        self.last_success = False
        self.count = 0
        self.window, self.cap, self.reward_scale = window, cap, reward_scale

    def add(self, data: TensorDictBase) -> None:
        """Add a collected batch (any batch shape)."""
        done = data.get(("next", "done")).reshape(-1)
        finished = int(done.sum())
        self.batches = [*self.batches, (data.numel(), finished)][-self.window :]
        if not finished:
            return
        nxt = data.get("next")
        returns = (nxt.get(EPISODE_RETURN).reshape(-1)[done] / self.reward_scale).tolist()
        terminated = nxt.get("terminated").reshape(-1)[done]
        self.returns = (self.returns + returns)[-4 * self.window :]
        self.last_success = bool(terminated[-1])
        self.count += finished

    def mean_length(self) -> float:
        """Frames per finished episode over the window (the cap when none finished)."""
        frames = sum(f for f, _ in self.batches)
        episodes = sum(e for _, e in self.batches)
        return min(self.cap, frames / episodes) if episodes else self.cap

    def mean_return(self) -> float:
        """Mean env return of the recent finished episodes."""
        return float(np.mean(self.returns)) if self.returns else 0.0


class CurveRecorder:
    """A training loop's bookkeeping after every batch: the curve, the logger, the progress callback.

    Args:
        window: batches the recorded episode statistics span.
        cap: the episode length recorded before any episode finished.
        reward_scale: the env reward's scale in the learner (records are in env units).
        logger: a TorchRL logger (``None``: none).
        progress: called with 1 after every batch (``None``: none).
        potential: the shaping potential; one shared table of at most :attr:`LOGGED_ENTRIES` values is
            logged after every batch, one scalar ``potential_z{i}`` per entry (what ``V(z)`` learned).

    Examples:
        >>> from tensordict import TensorDict
        >>> recorder = CurveRecorder(8, cap=50.0, reward_scale=1.0)
        >>> done = torch.zeros(4, 1, dtype=torch.bool)
        >>> recorder.add(TensorDict({("next", "done"): done, ("next", "terminated"): done}, [4]), 4, {})
        >>> recorder.curve.frames, recorder.curve.episode_length
        ([4], [50.0])
    """

    LOGGED_ENTRIES = 32

    def __init__(
        self,
        window: int,
        cap: float,
        reward_scale: float,
        logger: Logger | None = None,
        progress: Callable[[int], None] | None = None,
        potential: nn.Module | None = None,
    ) -> None:
        self.episodes = EpisodeWindow(window, cap, reward_scale)
        self.curve = LearningCurve()
        self.logger, self.progress = logger, progress
        table = getattr(potential, "table", None)
        small = isinstance(table, torch.Tensor) and table.dim() == 1 and len(table) <= self.LOGGED_ENTRIES
        self.table = table if small else None  # one shared table (not one per env), small enough to log
        self.start = time.perf_counter()

    def add(self, data: TensorDictBase, frames: int, scalars: dict[str, float]) -> None:
        """Record a batch collected when ``frames`` frames have been; log ``scalars`` (NaN ones are left out)."""
        episodes, curve = self.episodes, self.curve
        episodes.add(data)
        curve.frames.append(frames)
        curve.episode_length.append(episodes.mean_length())
        curve.episode_return.append(episodes.mean_return())
        curve.success.append(episodes.last_success)
        curve.episodes.append(episodes.count)
        if self.logger is not None:
            logged = {
                "episode_length": curve.episode_length[-1],
                "episode_return": curve.episode_return[-1],
                "episodes": float(episodes.count),
                **scalars,
                "frames_per_second": frames / max(time.perf_counter() - self.start, 1e-9),
            }
            if self.table is not None:
                logged.update({f"potential_z{i}": v for i, v in enumerate(self.table.detach().reshape(-1).tolist())})
            for name, value in logged.items():
                if not math.isnan(value):
                    self.logger.log_scalar(name, value, step=frames)
        if self.progress is not None:
            self.progress(1)


@dataclass
class PotentialTrainer:
    """Trains the shaping potential from collected batches: one optimiser step of
    :class:`~torchrl_subgoal.SubgoalValueLoss` on each batch's real SMDP transitions.

    Args:
        keeper: a shaping transform over the potential; it reads the transitions out of collected
            data (:meth:`~torchrl_subgoal.SubgoalPotentialTransform.transitions`).
        loss: the potential's loss.
        optimizer: the potential's own optimiser.

    Examples:
        >>> from torchrl_subgoal import Cell, SubgoalSeries, TabularPotential
        >>> from torchrl_subgoal.envs import FourRoomsEnv
        >>> shaping = Shaping(SubgoalSeries([Cell(1, 2)]), TabularPotential(2), {"observation_key": "cell"})
        >>> trainer = PotentialTrainer.for_shaping(shaping, gamma=0.9, lr=0.5, optimizer="sgd")
        >>> data = shaped_env(FourRoomsEnv, 4, shaping=shaping, gamma=0.9).rollout(20, break_when_any_done=False)
        >>> import math
        >>> math.isnan(trainer.step(data))  # a transition closed: one step, its loss
        False
    """

    keeper: SubgoalPotentialTransform
    loss: SubgoalValueLoss
    optimizer: torch.optim.Optimizer

    @classmethod
    def for_shaping(
        cls, shaping: Shaping, gamma: float, lr: float, optimizer: Literal["adam", "sgd"] = "adam"
    ) -> PotentialTrainer:
        """Adam (the loss's mean reduction) or SGD (sum: the tabular update) on ``shaping.potential``."""
        sgd = optimizer == "sgd"
        opt_class = torch.optim.SGD if sgd else torch.optim.Adam
        loss = SubgoalValueLoss(shaping.potential, reduction="sum" if sgd else "mean").make_value_estimator(gamma=gamma)
        return cls(
            shaping.transform(shaping.potential, gamma, None), loss, opt_class(shaping.potential.parameters(), lr=lr)
        )

    def step(self, data: TensorDictBase) -> float:
        """One step on the real SMDP transitions closed in ``data``; the loss, NaN when none closed."""
        real = smdp_transitions(data, self.keeper)
        if not len(real):  # (not real.numel(): a TensorDict of batch size [0] counts 1)
            return math.nan
        self.optimizer.zero_grad(set_to_none=True)
        out = self.loss(real)["loss_value"]
        out.backward()
        self.optimizer.step()
        return float(out.detach())


class SampleReshaper:
    """Re-shape off-policy samples with the potential as it is now.

    A replay buffer keeps the reward shaped at collection, ``r + γΦ_t(z') − Φ_t(z)``
    with ``Φ_t`` the potential of then. Called on a sample ``[B]`` (rows in any
    order, from any env of the batch), this recomputes the shaped reward with
    ``Φ`` as it is now, through the shaping transform's
    :meth:`~torchrl_subgoal.SubgoalPotentialTransform.forward` on the rows as
    ``[B, 1]`` trajectories: each row starts from the abstract-state entries
    stored at its root (``"subgoal_index"``, ``"subgoal_return"``,
    ``"subgoal_steps"``, …) and advances with its ``"next"`` observation, so
    ``z'`` is the one of collection and only ``Φ`` changes. The unshaped reward
    is read from ``("next", "env_reward")``. The potential is not trained.

    Args:
        transform: a shaping transform over the potential, with the collecting transform's
            options (:meth:`Shaping.transform`); one that has not stepped an env.
        extra_keys: more entries to keep (what condition predicates read besides the observation).

    Examples:
        >>> from torchrl.data import LazyTensorStorage, ReplayBuffer
        >>> from torchrl_subgoal import Cell, SubgoalSeries, TabularPotential
        >>> from torchrl_subgoal.envs import FourRoomsEnv
        >>> shaping = Shaping(SubgoalSeries([Cell(1, 3)]), TabularPotential(2), {"observation_key": "cell"})
        >>> data = shaped_env(FourRoomsEnv, 4, shaping=shaping, gamma=0.9).rollout(50, break_when_any_done=False)
        >>> reshaper = SampleReshaper(shaping.transform(shaping.potential, 0.9, None))
        >>> buffer = ReplayBuffer(storage=LazyTensorStorage(200), batch_size=64)
        >>> _ = buffer.extend(data.select(*reshaper.keys).reshape(-1))
        >>> sample = buffer.sample()
        >>> with torch.no_grad():
        ...     _ = shaping.potential.table.copy_(torch.tensor([0.0, 5.0]))
        >>> new = reshaper(sample.clone())
        >>> z, z_next = sample["subgoal_index"], new["next", "subgoal_index"]
        >>> bool(torch.allclose(new["next", "reward"], sample["next", "env_reward"] + 0.9 * 5.0 * z_next - 5.0 * z))
        True
    """

    def __init__(self, transform: SubgoalPotentialTransform, extra_keys: Sequence[NestedKey] = ()) -> None:
        self.transform = transform
        self.extra_keys = tuple(extra_keys)

    @property
    def keys(self) -> list[NestedKey]:
        """The entries a replay buffer must keep for this (besides the learner's own): the abstract-state
        entries, the observation the predicates read (``observation_key``) now and next, the unshaped
        reward, the transform's other :attr:`~torchrl_subgoal.SubgoalPotentialTransform.in_keys` under
        ``"next"`` (done and terminated), and ``extra_keys`` (the ``"next"`` entries condition predicates
        read, e.g. ``("next", "has_key")``)."""
        t = self.transform
        _reward, *read = t.in_keys  # the reward shaped is recomputed from the unshaped one
        keys: list[NestedKey] = [
            *t.state_keys,
            t.observation_key,
            ("next", t.observation_key),
            ("next", t.env_reward_key),
            *(("next", k) for k in read),
        ]
        return list(dict.fromkeys([*keys, *self.extra_keys]))

    def __call__(self, sample: TensorDictBase) -> TensorDictBase:
        """``sample`` (``[B]``) with ``("next", reward)`` and the next abstract-state entries recomputed."""
        with torch.no_grad():
            return self.transform(sample.unsqueeze(-1)).squeeze(-1)


def learner_env(
    make_env: Callable[[int], EnvBase],
    config: LearnerSettings,
    shaping: Shaping | None,
) -> tuple[EnvFactory[EnvBase], PotentialTrainer | None]:
    """A learner's collecting env factory and, unless its potential is fixed or trained online in the
    transform, the trainer of its potential.

    Args:
        make_env: ``make_env(num_envs)`` returns an env with batch size ``[num_envs]``.
        config: the learner's settings (``num_envs``, ``env_workers``, ``gamma``, ``reward_scale``,
            ``value_lr``, ``value_optimizer``, ``online_potential``).
        shaping: the shaping (``None``: none).

    Examples:
        >>> from torchrl_subgoal import Cell, SubgoalSeries, TabularPotential
        >>> from torchrl_subgoal.envs import FourRoomsEnv
        >>> from torchrl_subgoal.training import DQNConfig
        >>> shaping = Shaping(SubgoalSeries([Cell(1, 2)]), TabularPotential(2), {"observation_key": "cell"})
        >>> factory, trainer = learner_env(FourRoomsEnv, DQNConfig(num_envs=2, frames_per_batch=2), shaping)
        >>> factory().batch_size, trainer  # the default: the transform trains the potential online
        (torch.Size([2]), None)
    """
    online = shaping is not None and config.online_potential and shaping.trained
    factory: EnvFactory[EnvBase] = EnvFactory(
        shaped_env,
        make_env=make_env,
        num_envs=config.num_envs,
        env_workers=config.env_workers,
        shaping=shaping,
        potential=shaping.potential if shaping is not None else None,
        gamma=config.gamma,
        value_lr=config.value_lr if online else None,
        reward_scale=config.reward_scale,
    )
    trainer = None
    if shaping is not None and shaping.trained and not online:
        trainer = PotentialTrainer.for_shaping(shaping, config.gamma, config.value_lr, config.value_optimizer)
    return factory, trainer


def _probe_env(make_env: Callable[[int], EnvBase], episode_cap: float | None) -> tuple[EnvBase, float]:
    """One env to read specs from, and the episode cap the curve records before any episode ended
    (``episode_cap``, else the env's ``max_steps`` when it has one)."""
    probe = make_env(1)
    cap = episode_cap if episode_cap is not None else float(getattr(probe, "max_steps", math.nan))
    return probe, cap


def _close_probe(probe: EnvBase) -> None:
    """Close a probe env (a batched env that was never started, a ``SerialEnv`` from :func:`batched`,
    is closed already)."""
    if not probe.is_closed:
        probe.close()

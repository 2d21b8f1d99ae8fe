"""What a training loop records: each learner's :class:`LearningCurve`, its logger, its progress.

One learner's record is one entry per collected batch: the frames so far, the
mean episode length (frames per finished episode over the last batches), the
mean env return and the success rate of the recent finished episodes, and how
many episodes have finished. Success is what the env says it is
(:class:`SuccessSignal`): an entry the env writes (``"is_success"``,
``"success"``) or, where the env has none, a documented return threshold; an
episode that merely *terminated* is not a success (it may have fallen into a hole).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import torch
from tensordict import TensorDictBase
from tensordict.utils import NestedKey
from torch import nn
from torchrl.record.loggers import Logger

from torchrl_subgoal.potentials import INDEX
from torchrl_subgoal.training.envs import EPISODE_RETURN

__all__ = ["CurveRecorder", "EpisodeWindow", "LearningCurve", "SuccessSignal"]

#: The entries an env may write under ``"next"`` to say an episode succeeded (gymnasium-robotics'
#: ``"is_success"``, its PointMaze's ``"success"``), looked for in this order.
SUCCESS_KEYS: tuple[NestedKey, ...] = ("is_success", "success")
#: the shaping transform's abstract state (its default keys): the subgoals an episode achieved
REACHED: NestedKey = INDEX


@dataclass(frozen=True)
class SuccessSignal:
    """How a finished episode's success is read: the env's own entry, or a documented threshold.

    Args:
        key: the entry under ``"next"`` that says so at the episode's last step (e.g. ``"is_success"``);
            ``None``: the first of :data:`SUCCESS_KEYS` the env writes.
        min_return: where the env writes none, an episode succeeded when its env return (env units) is at
            least this (e.g. ``1.0`` for a reward of 1 at the goal and 0 otherwise).
        final_reward: where the env writes none, an episode succeeded when the env reward of its last step
            is at least this (e.g. Taxi's +20 for the delivery that ends it, which a return cannot tell
            from a time-out after illegal moves).

    With none of them and no entry, success is not measured (``NaN`` in the curves).

    Examples:
        >>> from tensordict import TensorDict
        >>> nxt = TensorDict({"is_success": torch.tensor([[True], [False]])}, [2])
        >>> SuccessSignal().read(nxt, torch.tensor([-3.0, -50.0])).tolist()
        [True, False]
        >>> SuccessSignal(min_return=1.0).read(TensorDict({}, [2]), torch.tensor([1.0, 0.0])).tolist()
        [True, False]
        >>> last = TensorDict({"reward": torch.tensor([[20.0], [-1.0]])}, [2])
        >>> SuccessSignal(final_reward=20.0).read(last, torch.tensor([-5.0, -200.0])).tolist()
        [True, False]
        >>> SuccessSignal().read(TensorDict({}, [2]), torch.tensor([1.0, 0.0])) is None
        True
    """

    key: NestedKey | None = None
    min_return: float | None = None
    final_reward: float | None = None

    def at_end(self, last: TensorDictBase) -> torch.Tensor | None:
        """Success read from episodes' last ``"next"`` entries ``last`` (one per row, flat), where the signal
        is an entry or a final reward; ``None`` where it needs the return or is not measured."""
        keys = [self.key] if self.key is not None else [k for k in SUCCESS_KEYS if k in last.keys()]  # noqa: SIM118
        if keys:
            return last.get(keys[0]).reshape(-1).bool()
        if self.final_reward is not None:
            reward = last.get("env_reward") if "env_reward" in last.keys() else last.get("reward")  # noqa: SIM118
            return reward.reshape(-1) >= self.final_reward
        return None

    def read(self, finished: TensorDictBase, returns: torch.Tensor) -> torch.Tensor | None:
        """Success of the finished episodes whose last ``"next"`` entries are ``finished`` and env returns
        ``returns``; ``None`` when not measured."""
        flags = self.at_end(finished)
        if flags is not None:
            return flags.reshape(returns.shape)
        return returns >= self.min_return if self.min_return is not None else None


@dataclass
class LearningCurve:
    """One learner's record, one entry per collected batch.

    Attributes:
        frames: frames collected after each batch.
        episode_length: the mean episode length, estimated as frames per finished episode
            over the last ``record_window`` batches (the env's episode cap when none finished).
        episode_return: mean env return of the recent finished episodes (env units).
        success: the fraction of the recent finished episodes that succeeded (:class:`SuccessSignal`;
            ``NaN`` before any finished, or where the env gives no success signal).
        episodes: episodes finished so far.

    Examples:
        >>> curve = LearningCurve(frames=[256, 512, 768], episode_length=[900.0, 120.0, 40.0])
        >>> curve.frames_to(100), curve.frames_to(10)
        (768, None)
    """

    frames: list[int] = field(default_factory=list)
    episode_length: list[float] = field(default_factory=list)
    episode_return: list[float] = field(default_factory=list)
    success: list[float] = field(default_factory=list)
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
    window it is the env's episode cap. Returns, successes and the subgoals
    reached (a shaped env's ``"subgoal_index"`` where the episode ended) are
    those of the last ``4 × window`` finished episodes.

    Args:
        window: batches the statistics span.
        cap: the episode length recorded while no episode finished in the window.
        reward_scale: returns are divided by it (records in the env's units).
        success: how a finished episode's success is read.

    Examples:
        >>> from tensordict import TensorDict
        >>> window = EpisodeWindow(2, cap=100.0, reward_scale=1.0, success=SuccessSignal(min_return=1.0))
        >>> done = torch.tensor([[False], [True], [False], [True]])
        >>> window.add(TensorDict({("next", "done"): done, ("next", "terminated"): done,
        ...                        ("next", "episode_return"): torch.tensor([[0.0], [1.0], [0.0], [0.0]])}, [4]))
        >>> window.mean_length(), window.mean_return(), window.success_rate(), window.count
        (2.0, 0.5, 0.5, 2)
    """

    def __init__(self, window: int, cap: float, reward_scale: float, success: SuccessSignal | None = None) -> None:
        self.batches: list[tuple[int, int]] = []  # (frames, episodes finished) per batch
        self.returns: list[float] = []
        self.successes: list[bool] | None = []  # None: not measured
        self.reached: list[float] = []  # subgoals achieved when the episode ended (a shaped env)
        self.count = 0
        self.window, self.cap, self.reward_scale = window, cap, reward_scale
        self.signal = success if success is not None else SuccessSignal()

    def add(self, data: TensorDictBase) -> None:
        """Add a collected batch (any batch shape)."""
        done = data.get(("next", "done")).reshape(-1)
        finished = int(done.sum())
        self.batches = [*self.batches, (data.numel(), finished)][-self.window :]
        if not finished:
            return
        nxt = data.get("next").reshape(-1)[done]
        returns = nxt.get(EPISODE_RETURN).reshape(-1) / self.reward_scale
        self.returns = (self.returns + returns.tolist())[-4 * self.window :]
        reached = nxt.get(REACHED, None)
        if reached is not None:
            self.reached = (self.reached + reached.reshape(-1).float().tolist())[-4 * self.window :]
        success = self.signal.read(nxt, returns)
        if success is None:
            self.successes = None
        elif self.successes is not None:
            self.successes = (self.successes + success.tolist())[-4 * self.window :]
        self.count += finished

    def mean_length(self) -> float:
        """Frames per finished episode over the window (the cap when none finished)."""
        frames = sum(f for f, _ in self.batches)
        episodes = sum(e for _, e in self.batches)
        return min(self.cap, frames / episodes) if episodes else self.cap

    def mean_return(self) -> float:
        """Mean env return of the recent finished episodes."""
        return float(np.mean(self.returns)) if self.returns else 0.0

    def subgoals_reached(self) -> float:
        """Mean subgoals achieved by the recent finished episodes (NaN before any, or unshaped)."""
        return float(np.mean(self.reached)) if self.reached else math.nan

    def success_rate(self) -> float:
        """Fraction of the recent finished episodes that succeeded (NaN before any, or when not measured)."""
        if not self.successes:  # None (not measured) or none finished yet
            return math.nan
        return float(np.mean(self.successes))


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
        success: how a finished episode's success is read.

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
        potential: nn.Module | torch.Tensor | None = None,
        success: SuccessSignal | None = None,
    ) -> None:
        self.episodes = EpisodeWindow(window, cap, reward_scale, success)
        self.curve = LearningCurve()
        self.logger, self.progress = logger, progress
        table = potential if isinstance(potential, torch.Tensor) else getattr(potential, "table", None)
        small = isinstance(table, torch.Tensor) and table.dim() == 1 and len(table) <= self.LOGGED_ENTRIES
        self.table = table if small else None  # one learner's table (not one per env), small enough to log
        self.start = time.perf_counter()

    def add(self, data: TensorDictBase, frames: int, scalars: dict[str, float]) -> None:
        """Record a batch collected when ``frames`` frames have been; log ``scalars`` (NaN ones are left out)."""
        episodes, curve = self.episodes, self.curve
        episodes.add(data)
        curve.frames.append(frames)
        curve.episode_length.append(episodes.mean_length())
        curve.episode_return.append(episodes.mean_return())
        curve.success.append(episodes.success_rate())
        curve.episodes.append(episodes.count)
        if self.logger is not None:
            logged = {
                "episode_length": curve.episode_length[-1],
                "episode_return": curve.episode_return[-1],
                "success": curve.success[-1],
                "subgoals_reached": episodes.subgoals_reached(),
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

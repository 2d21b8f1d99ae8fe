"""The settings every learner shares, and the one check of every learner's settings.

:class:`Settings` is the base of every learner's config: it holds ``gamma`` and the
``device`` and checks every field against :data:`RULES`, one rule per field *name*,
so a field means and refuses the same thing in whichever config it appears
(``gamma`` must lie in ``(0, 1]`` for A2C as for tabular Q-learning). A config
adds only its own fields, and a rule for each new name.
:class:`LearnerConfig` adds the fields of every collector-based learner (envs,
batches, the shaping potential's training, the records), :class:`NetworkConfig`
the input layers and hidden sizes of the A2C, PPO and DQN networks,
:class:`OffPolicyConfig` the replay and warm-up of DQN and DDPG.

A schedule or a warm-up (DQN's ``exploration_frames``, the off-policy learners'
``learning_starts``) may be given as a fraction of ``total_frames`` (a value
below 1) or as frames (1 or more): :func:`frames_of` resolves it, so the
defaults suit any budget.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Literal

import torch

__all__ = ["RULES", "LearnerConfig", "NetworkConfig", "OffPolicyConfig", "Settings", "frames_of"]

Features = Literal["one_hot", "fourier", "mlp"]


def _at_least(low: int) -> Callable[[Any], str | None]:
    return lambda v: None if v >= low else f"must be >= {low}, got {v}"


def _positive(v: Any) -> str | None:
    return None if v > 0 else f"must be > 0, got {v}"


def _between(low: float, high: float, *, open_low: bool = False) -> Callable[[Any], str | None]:
    left = "(" if open_low else "["

    def rule(v: Any) -> str | None:
        inside = (low < v if open_low else low <= v) and v <= high
        return None if inside else f"must lie in {left}{low:g}, {high:g}], got {v}"

    return rule


def _one_of(*choices: str) -> Callable[[Any], str | None]:
    return lambda v: None if v in choices else f"must be {', '.join(choices[:-1])} or {choices[-1]}, got {v!r}"


def _sizes(v: Any) -> str | None:
    return None if all(int(h) >= 1 for h in v) else f"must be sizes >= 1, got {tuple(v)}"


def _device(v: Any) -> str | None:
    try:
        torch.device(v)
    except (RuntimeError, TypeError):
        return f"must name a torch device (cpu, cuda, cuda:1, ...), got {v!r}"
    return None


def _frames_or_fraction(v: Any) -> str | None:
    return None if v >= 0 and (v < 1 or float(v).is_integer()) else f"must be a fraction in [0, 1) or frames, got {v}"


#: One rule per field name, shared by every config that has the field: ``None`` when the value is
#: fine, else what is wrong (the error is ``"<field> <what>"``).
RULES: dict[str, Callable[[Any], str | None]] = {
    # every learner
    "gamma": _between(0.0, 1.0, open_low=True),
    "lr": _between(0.0, 1.0, open_low=True),
    "value_lr": _between(0.0, 1.0, open_low=True),
    "device": _device,
    # collection and records
    **dict.fromkeys(("num_envs", "frames_per_batch", "total_frames", "record_window", "episodes"), _at_least(1)),
    **dict.fromkeys(("env_workers", "collector_workers", "max_frames", "fourier_order"), _at_least(0)),
    "reward_scale": _positive,
    "value_optimizer": _one_of("adam", "sgd"),
    # networks and losses
    "features": _one_of("one_hot", "fourier", "mlp"),
    "hidden": _sizes,
    "loss_function": _one_of("l2", "smooth_l1", "l1"),
    "loss_critic_type": _one_of("l2", "smooth_l1", "l1"),
    "target_update": _one_of("hard", "soft"),
    "polyak_every": _one_of("update", "batch"),
    "clip_return": lambda v: None if v is None or v > 0 else f"must be > 0 or None, got {v}",
    **dict.fromkeys(
        ("max_grad_norm", "critic_coeff", "entropy_coeff", "noise_eps", "target_noise", "noise_clip", "action_l2"),
        _at_least(0),
    ),
    **dict.fromkeys(("adam_eps", "clip_epsilon", "norm_clip"), _positive),
    **dict.fromkeys(("gae_lambda", "polyak", "random_eps", "epsilon", "eps_init", "eps_end"), _between(0.0, 1.0)),
    "tau": _between(0.0, 1.0, open_low=True),
    # off-policy learners
    **dict.fromkeys(
        ("gradient_steps", "updates_per_batch", "batch_size", "buffer_size", "target_update_interval", "policy_delay"),
        _at_least(1),
    ),
    **dict.fromkeys(("epochs", "minibatch_size"), _at_least(1)),
    "learning_starts": _frames_or_fraction,
    "exploration_frames": lambda v: _frames_or_fraction(v) or (None if v > 0 else f"must be > 0, got {v}"),
}


def frames_of(value: float, total_frames: int) -> int:
    """Frames meant by a schedule setting: ``value`` frames, or ``value × total_frames`` when below 1.

    Examples:
        >>> frames_of(0.2, 120_000), frames_of(1000, 120_000), frames_of(0, 500)
        (24000, 1000, 0)
    """
    return round(value * total_frames) if value < 1 else int(value)


@dataclass
class Settings:
    """What every learner's settings have: the discount, the device, and the check of every field.

    A config refuses a bad value on construction (and on :func:`dataclasses.replace`), one line naming
    the field: each field by its name's rule in :data:`RULES`, then the config's own checks between
    fields (:meth:`check`).

    Examples:
        >>> from torchrl_subgoal.training import A2CConfig, PPOConfig
        >>> A2CConfig(gamma=2.0)
        Traceback (most recent call last):
        ...
        ValueError: gamma must lie in (0, 1], got 2.0
        >>> PPOConfig(value_lr=-1)
        Traceback (most recent call last):
        ...
        ValueError: value_lr must lie in (0, 1], got -1
    """

    gamma: float = 0.99
    """discount, in ``(0, 1]``"""
    device: str = "cpu"
    """where the networks, their optimisers and the replay buffer live (``"cpu"``, ``"cuda"``…); the
    envs step on the CPU"""

    def __post_init__(self) -> None:
        hidden = getattr(self, "hidden", None)
        if isinstance(hidden, list | tuple):
            object.__setattr__(self, "hidden", tuple(int(h) for h in hidden))  # (a list from JSON)
        for f in dataclasses.fields(self):
            rule = RULES.get(f.name)
            if rule is None:
                continue
            why = rule(getattr(self, f.name))
            if why is not None:
                raise ValueError(f"{f.name} {why}")
        self.check()

    def check(self) -> None:
        """The config's checks between fields (after every field passed its rule)."""

    @property
    def torch_device(self) -> torch.device:
        """:attr:`device` as a ``torch.device``."""
        return torch.device(self.device)


@dataclass
class LearnerConfig(Settings):
    """What every collector-based learner's settings have (A2C, PPO, DQN, DDPG); each learner adds its own.

    Examples:
        >>> from torchrl_subgoal.training import DQNConfig
        >>> DQNConfig(num_envs=4, frames_per_batch=30)
        Traceback (most recent call last):
        ...
        ValueError: frames_per_batch (30) must be a multiple of num_envs x collector_workers (4 x 1): ...
    """

    num_envs: int = 1
    """envs per learner per collecting process (the batch one learner steps)"""
    env_workers: int = 0
    """``ParallelEnv`` worker processes holding the envs (0: the batched env in the collecting process)"""
    collector_workers: int = 0
    """0: one ``Collector`` in this process; ``k``: a ``MultiSyncCollector`` of ``k`` processes (one learner only)"""
    frames_per_batch: int = 1000
    """frames per learner per collected batch (over all collector workers): one update's data"""
    total_frames: int = 100_000
    """frames per learner"""
    lr: float = 1e-3
    """Adam learning rate of the learner's networks"""
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
    sees_subgoal: bool | None = False
    """the networks also read the subgoal index ``z`` (one-hot); ``None``: whenever a shaping transform
    keeps it"""

    def check(self) -> None:
        if self.env_workers and self.num_envs % self.env_workers:
            raise ValueError(f"num_envs ({self.num_envs}) must be a multiple of env_workers ({self.env_workers})")
        if self.frames_per_batch % (self.num_envs * max(1, self.collector_workers)):
            raise ValueError(
                f"frames_per_batch ({self.frames_per_batch}) must be a multiple of num_envs x "
                f"collector_workers ({self.num_envs} x {max(1, self.collector_workers)}): each "
                "collecting process steps its num_envs envs an equal number of times"
            )

    @property
    def iterations(self) -> int:
        """Collected batches (updates) per learner."""
        return math.ceil(self.total_frames / self.frames_per_batch)


@dataclass
class NetworkConfig(LearnerConfig):
    """A learner whose networks start with an input layer of its choice (A2C, PPO, DQN).

    Examples:
        >>> from torchrl_subgoal.training import A2CConfig, DQNConfig
        >>> issubclass(A2CConfig, NetworkConfig), issubclass(DQNConfig, NetworkConfig)
        (True, True)
        >>> A2CConfig(features="cnn")
        Traceback (most recent call last):
        ...
        ValueError: features must be one_hot, fourier or mlp, got 'cnn'
    """

    features: Features = "mlp"
    """the networks' input layer: ``"one_hot"`` (a categorical observation), ``"fourier"`` (a Fourier
    basis of a bounded observation) or ``"mlp"`` (the observation vector)"""
    hidden: tuple[int, ...] = (64,)
    """hidden layer sizes (``()``: linear in the features)"""
    fourier_order: int = 3
    """order of the Fourier basis"""
    max_grad_norm: float = 1.0
    """gradient clipping, learner by learner (0: none)"""

    def network_options(self) -> dict[str, Any]:
        """The networks' settings, as the network builders take them (``features``, ``hidden``, ``fourier_order``).

        Examples:
            >>> NetworkConfig(features="one_hot", hidden=()).network_options()
            {'features': 'one_hot', 'hidden': (), 'fourier_order': 3}
        """
        return {"features": self.features, "hidden": self.hidden, "fourier_order": self.fourier_order}


@dataclass
class OffPolicyConfig(LearnerConfig):
    """A learner that learns from a replay buffer (DQN, DDPG), after a warm-up of random actions.

    Examples:
        >>> from torchrl_subgoal.training import DDPGTrainConfig, DQNConfig
        >>> DQNConfig().buffer_size, DDPGTrainConfig().buffer_size  # each learner's own default
        (10000, 1000000)
        >>> DQNConfig(batch_size=0)
        Traceback (most recent call last):
        ...
        ValueError: batch_size must be >= 1, got 0
    """

    learning_starts: float = 0.02
    """frames collected with uniformly random actions before the first gradient step (a value below 1:
    that fraction of ``total_frames``)"""
    batch_size: int = 256
    """transitions per learner per gradient step"""
    buffer_size: int = 1_000_000
    """replay capacity per learner (transitions)"""
    reshape_samples: bool = False
    """re-shape every replay sample with the potential as it is now before the loss (else the loss reads
    the reward shaped at collection)"""

    @property
    def warmup_frames(self) -> int:
        """Frames of random actions before the first gradient step (``learning_starts`` resolved).

        Examples:
            >>> OffPolicyConfig(total_frames=20_000).warmup_frames, OffPolicyConfig(learning_starts=500).warmup_frames
            (400, 500)
        """
        return frames_of(self.learning_starts, self.total_frames)

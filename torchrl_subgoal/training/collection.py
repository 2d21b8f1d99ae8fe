"""Collecting a learner's batches: a TorchRL collector over its env factory, seeded, and closed cleanly."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Protocol

import torch
from tensordict.nn import TensorDictModuleBase
from torchrl.collectors import Collector, MultiSyncCollector
from torchrl.envs import EnvBase

__all__ = ["close_collector", "make_collector", "seed_collector"]


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
    device: torch.device | str | None = None,
) -> Collector | MultiSyncCollector:
    """A ``Collector`` over ``env_factory()`` in this process, or a ``MultiSyncCollector`` of
    ``config.collector_workers`` processes each building its env from ``env_factory``.

    Args:
        env_factory: builds a collecting process's env (picklable for worker processes).
        policy: the acting policy (its weights are sent to the workers).
        config: ``collector_workers``, ``frames_per_batch`` and ``total_frames``.
        init_random_frames: frames collected with random actions first (off-policy learners), rounded
            up to whole batches.
        device: where the policy runs and the batches are delivered (the envs step on the CPU);
            ``None``: the policy's and the env's own.

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
    if device is not None and torch.device(device).type != "cpu":
        extra.update(policy_device=device, storing_device=device, env_device="cpu")
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


def seed_collector(collector: Collector | MultiSyncCollector, seed: int) -> None:
    """Seed the collector's envs and policy noise (a ``MultiSyncCollector``'s workers seed numpy with
    the seed, which takes 32 bits; sweep seeds take 63).

    Examples:
        >>> from torchrl_subgoal.envs import FourRoomsEnv
        >>> collector = Collector(FourRoomsEnv(2), None, frames_per_batch=8, total_frames=8)
        >>> seed_collector(collector, 2**40)
        >>> close_collector(collector)
    """
    collector.set_seed(seed % 2**32 if isinstance(collector, MultiSyncCollector) else seed)

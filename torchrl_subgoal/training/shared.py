"""One potential for envs in worker processes: module arguments passed in shared memory.

When envs run in collector worker processes (a ``MultiSyncCollector``, a
``MultiAsyncCollector``), each worker builds its env from a factory. A
potential captured by that factory would be *copied* into every worker —
TorchRL wraps factories with cloudpickle, which serialises tensors by value —
and each worker would then shape with its own copy that nobody trains.
:class:`EnvFactory` passes its module arguments through shared memory instead:
every worker's potential is a view of the same storage as the main process's,
so the potential trained in the main process is the one every worker shapes
with, and an online update (``value_lr``) in one worker is seen by all.

Staleness: a worker reads ``Φ`` at every step. With a ``MultiSyncCollector``
the workers wait while the main process trains, so each batch is shaped with
the potential as it was after the last update (none stale). With a
``MultiAsyncCollector`` a worker collects its next batch while the main
process trains, so a batch may straddle an update (at most one update stale).
Ray workers on other machines do not share memory with the driver: there,
train the potential online in the workers (``value_lr``) or send its weights
with the collector's weight-sync schemes.
"""

from __future__ import annotations

import io
import pickle
from collections import ChainMap
from collections.abc import Callable
from multiprocessing.reduction import ForkingPickler
from typing import Any, Generic, TypeVar

import cloudpickle
from torch import nn

__all__ = ["EnvFactory"]

E = TypeVar("E")


def _dumps(obj: Any) -> bytes:
    """cloudpickle (lambdas, local functions) with torch.multiprocessing's reductions (shared
    tensors as handles to their storage, as ``ForkingPickler`` sends them)."""
    # the C pickler reads ``dispatch_table`` when it is created: give it as a class attribute
    table = ChainMap(cloudpickle.Pickler.dispatch_table, ForkingPickler(io.BytesIO()).dispatch_table)
    pickler_class = type("_SharedMemoryPickler", (cloudpickle.Pickler,), {"dispatch_table": table})
    buffer = io.BytesIO()
    pickler_class(buffer).dump(obj)
    return buffer.getvalue()


def _rebuild(payload: bytes) -> EnvFactory[Any]:
    fn, kwargs = pickle.loads(payload)
    return EnvFactory(fn, **kwargs)


class EnvFactory(Generic[E]):
    """``fn(**kwargs)`` as a picklable factory whose ``nn.Module`` arguments live in shared memory.

    Args:
        fn: builds the env (a module-level function is cheapest to send).
        **kwargs: its arguments; modules among them (a potential) are moved to
            shared memory (``module.share_memory()``) and reach worker processes
            as views of the same storage.

    Examples:
        >>> import pickle, torch
        >>> from torchrl_subgoal import TabularPotential
        >>> potential = TabularPotential(3)
        >>> factory = EnvFactory(dict, potential=potential)
        >>> potential.table.is_shared()
        True
        >>> factory()["potential"] is potential
        True
    """

    def __init__(self, fn: Callable[..., E], **kwargs: Any) -> None:
        # not ``fn``/``kwargs``: TorchRL's CloudpickleWrapper copies the wrapped object's
        # ``__dict__`` over its own attributes of those names (functools.update_wrapper)
        self.env_fn = fn
        self.env_kwargs = kwargs
        for value in kwargs.values():
            if isinstance(value, nn.Module):
                value.share_memory()

    def __call__(self) -> E:
        return self.env_fn(**self.env_kwargs)

    def __reduce__(self) -> tuple[Any, ...]:
        # shared storages travel as handles; the (cloud)pickler that wraps this factory carries the bytes
        return _rebuild, (_dumps((self.env_fn, self.env_kwargs)),)

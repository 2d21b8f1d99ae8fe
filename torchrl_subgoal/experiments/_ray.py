"""The Ray backend of :class:`~torchrl_subgoal.experiments.sweep.Sweep`: one Ray task per chunk.

On an existing cluster (``RAY_ADDRESS`` or a running local cluster), else on a local Ray
instance started for the sweep. Tasks *return* their table to the driver, which writes it:
the cluster needs no shared filesystem, and the store keeps a single writer. A chunk whose
worker process or node dies runs again, up to
:data:`~torchrl_subgoal.experiments.backend.RAY_RETRIES` times.
"""

from __future__ import annotations

import os
import socket
from collections.abc import Mapping, Sequence
from typing import Any

from torchrl_subgoal.experiments.backend import (
    RAY_RETRIES,
    BackendUnavailableError,
    ChunkFailedError,
    Finished,
    ProgressBar,
    RunChunk,
    ThrottledProgress,
    failure,
    limit_threads,
)
from torchrl_subgoal.experiments.results import Chunk, EpisodeTable


def _execute_chunk_ray(
    run_chunk: RunChunk, chunk: Chunk, config: Mapping[str, Any], progress_queue: Any
) -> EpisodeTable:
    limit_threads()
    progress = ThrottledProgress(chunk.name, progress_queue.put_nowait)
    table = run_chunk(chunk, config, progress)
    progress.flush()
    return table


def check_ray_address(timeout: float = 10.0) -> None:
    """Refuse at once a ``RAY_ADDRESS`` (``host:port``) where nothing answers: Ray itself retries for minutes.

    Raises:
        BackendUnavailableError: naming the address, the reason and what to do.

    Examples:
        >>> from unittest import mock
        >>> with mock.patch.dict(os.environ, {"RAY_ADDRESS": "127.0.0.1:1"}):  # nothing listens on port 1
        ...     check_ray_address()
        Traceback (most recent call last):
        ...
        torchrl_subgoal.experiments.backend.BackendUnavailableError: RAY_ADDRESS=127.0.0.1:1: no Ray cluster answers ...
    """
    address = os.environ.get("RAY_ADDRESS", "")
    if not address or address in ("local", "auto") or "://" in address:
        return
    host, _, port = address.rpartition(":")
    try:
        socket.create_connection((host.strip("[]") or "127.0.0.1", int(port)), timeout=timeout).close()
    except (OSError, ValueError) as exc:
        reason = getattr(exc, "strerror", None) or str(exc) or type(exc).__name__
        raise BackendUnavailableError(
            f"RAY_ADDRESS={address}: no Ray cluster answers there ({reason}); start it (ray start --head) or "
            "set RAY_ADDRESS to its head's HOST:PORT (unset, the sweep uses a cluster running on this machine or "
            "starts one)"
        ) from None


def _connect_ray(workers: int) -> tuple[Any, bool]:
    """Import Ray and connect; returns (ray module, whether we started the instance)."""
    try:
        import ray
    except ImportError as exc:
        raise ImportError("backend='ray' needs Ray: pip install 'torchrl_subgoal[ray]'") from exc
    if ray.is_initialized():
        return ray, False
    if os.environ.get("RAY_ADDRESS") == "local":  # a fresh instance, whatever else runs here
        ray.init(address="local", num_cpus=max(workers, 1), include_dashboard=False)
        return ray, True
    try:
        # RAY_ADDRESS when set, else a cluster already running on this machine.
        ray.init(address="auto")
    except ConnectionError:
        if os.environ.get("RAY_ADDRESS"):
            raise
        ray.init(address="local", num_cpus=max(workers, 1), include_dashboard=False)
        return ray, True
    return ray, False


def run_ray(
    chunks: Sequence[Chunk],
    run_chunk: RunChunk,
    config: Mapping[str, Any],
    bar: ProgressBar,
    workers: int,
) -> Finished:
    """Run ``chunks`` as Ray tasks on ``workers`` CPUs of a local instance (or the cluster's); yields
    ``(chunk, table)`` as they finish; a chunk that failed raises ``ChunkFailedError`` once the others
    are cancelled."""
    ray, started = _connect_ray(workers)
    pending: list[Any] = []
    progress_queue = None
    try:
        from ray.util.queue import Queue

        progress_queue = Queue(actor_options={"num_cpus": 0})  # never waits for a free CPU
        task = ray.remote(num_cpus=1, max_retries=RAY_RETRIES)(_execute_chunk_ray)
        config_ref = ray.put(dict(config))
        refs = {task.remote(run_chunk, chunk, config_ref, progress_queue): chunk for chunk in chunks}
        pending = list(refs)
        error: ChunkFailedError | None = None
        while pending:
            done, pending = ray.wait(pending, num_returns=1, timeout=0.2)
            size = progress_queue.qsize()
            messages = progress_queue.get_nowait_batch(size) if size else []
            for name, k in messages:
                bar.add(name, k)
            for ref in done:
                try:
                    table = ray.get(ref)
                except ray.exceptions.TaskCancelledError:
                    continue
                except ray.exceptions.RayError as exc:
                    if error is None:
                        # a task's own exception, without Ray's wrapping traceback text; else its worker
                        # or node died each time Ray ran it
                        crashed = not isinstance(exc, ray.exceptions.RayTaskError)
                        note = f" (Ray ran it {RAY_RETRIES + 1} times)" if crashed else ""
                        error = failure(refs[ref], getattr(exc, "cause", None) or exc, note)
                        error.__cause__ = exc
                        for other in pending:
                            ray.cancel(other)
                    continue
                yield refs[ref], table
        if error is not None:
            raise error
    finally:
        for other in pending:
            ray.cancel(other, force=True)
        if progress_queue is not None:
            progress_queue.shutdown()
        if started:
            ray.shutdown()

"""Background "Try it" jobs: one thread each, one per pattern at a time, a few at once, cancellable."""

from __future__ import annotations

import logging
import threading
import time
import uuid
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

__all__ = ["Cancelled", "Job", "JobError", "Jobs"]

log = logging.getLogger(__name__)

#: A job's work: called with a progress callback (units done) and returns a JSON-ready result.
Work = Callable[[Callable[[int], None]], dict[str, Any]]


class Cancelled(Exception):
    """Raised inside a job's progress callback once the job was cancelled.

    Examples:
        >>> job = Job("1", "alice", total=10)
        >>> def progress(k):
        ...     if job.cancel.is_set():
        ...         raise Cancelled
        >>> job.cancel.set()
        >>> try:
        ...     progress(1)
        ... except Cancelled:
        ...     print("stopped")
        stopped
    """


class JobError(RuntimeError):
    """A job cannot start (``status`` 409: this pattern is already training; 429: too many jobs).

    Examples:
        >>> error = JobError("pattern 'alice' is already training", status=409)
        >>> error.status
        409
    """

    def __init__(self, message: str, status: int) -> None:
        super().__init__(message)
        self.status = status


@dataclass
class Job:
    """One background learning and what the page polls.

    Examples:
        >>> job = Job("1", "alice", total=10, done=5)
        >>> status = job.status()
        >>> status["state"], status["progress"]
        ('running', 0.5)
    """

    id: str
    key: str
    total: int
    done: int = 0
    state: str = "running"  # running, done, failed, cancelled
    result: dict[str, Any] | None = None
    error: str | None = None
    started: float = field(default_factory=time.time)
    finished: float | None = None
    cancel: threading.Event = field(default_factory=threading.Event, repr=False)

    def status(self) -> dict[str, Any]:
        """The JSON the page polls."""
        return {
            "id": self.id,
            "key": self.key,
            "state": self.state,
            "done": self.done,
            "total": self.total,
            "progress": min(1.0, self.done / self.total) if self.total else 0.0,
            "result": self.result,
            "error": self.error,
            "seconds": (self.finished or time.time()) - self.started,
        }


class Jobs:
    """Runs jobs in daemon threads.

    Args:
        max_running: jobs that may run at once (the machine's cores are few).
        keep: finished jobs remembered for polling; older ones are forgotten.

    Examples:
        >>> jobs = Jobs()
        >>> job = jobs.start("four_rooms/p", 2, lambda progress: (progress(2), {"ok": True})[1])
        >>> jobs.wait(job.id, timeout=30).state
        'done'
    """

    def __init__(self, max_running: int = 2, keep: int = 50) -> None:
        self.max_running = max_running
        self.keep = keep
        self._jobs: OrderedDict[str, Job] = OrderedDict()
        self._threads: dict[str, threading.Thread] = {}
        self._lock = threading.Lock()

    def running(self) -> list[Job]:
        """Jobs still running."""
        with self._lock:
            return [j for j in self._jobs.values() if j.state == "running"]

    def start(self, key: str, total: int, work: Work) -> Job:
        """Start ``work`` unless a job with ``key`` runs or ``max_running`` jobs run (:class:`JobError`)."""
        with self._lock:
            running = [j for j in self._jobs.values() if j.state == "running"]
            for job in running:
                if job.key == key:
                    raise JobError(
                        f"{key}: a learning with this pattern is already running (job {job.id}); "
                        "wait for it or cancel it",
                        409,
                    )
            if len(running) >= self.max_running:
                raise JobError(
                    f"{len(running)} learnings are running, the most this studio runs at once; "
                    "wait for one to finish or cancel it",
                    429,
                )
            job = Job(uuid.uuid4().hex[:12], key, total)
            self._jobs[job.id] = job
            finished = [i for i, j in self._jobs.items() if j.state != "running"]
            for old in finished[: max(0, len(self._jobs) - self.keep)]:
                del self._jobs[old]
            thread = threading.Thread(target=self._run, args=(job, work), name=f"studio-job-{job.id}", daemon=True)
            self._threads[job.id] = thread
        thread.start()
        return job

    def _run(self, job: Job, work: Work) -> None:
        def progress(units: int) -> None:
            if job.cancel.is_set():
                raise Cancelled
            job.done += units

        try:
            result = work(progress)
        except Cancelled:
            job.state = "cancelled"
        except Exception as exc:  # the page shows it; the server goes on
            log.exception("studio job %s (%s) failed", job.id, job.key)
            job.error = f"{type(exc).__name__}: {exc}"
            job.state = "failed"
        else:
            job.result = result
            job.done = job.total
            job.state = "done"
        finally:
            job.finished = time.time()
            with self._lock:
                self._threads.pop(job.id, None)

    def get(self, job_id: str) -> Job | None:
        """The job, or ``None`` if unknown or forgotten."""
        with self._lock:
            return self._jobs.get(job_id)

    def cancel(self, job_id: str) -> Job | None:
        """Ask a job to stop (at its next progress report); returns it, or ``None`` if unknown."""
        job = self.get(job_id)
        if job is not None:
            job.cancel.set()
        return job

    def wait(self, job_id: str, timeout: float | None = None) -> Job:
        """Block until the job's thread has ended (for tests and shutdown)."""
        with self._lock:
            thread = self._threads.get(job_id)
            job = self._jobs[job_id]
        if thread is not None:
            thread.join(timeout)
        return job

    def shutdown(self, timeout: float = 30.0) -> None:
        """Cancel every running job and wait for their threads."""
        for job in self.running():
            self.cancel(job.id)
        for job_id in list(self._threads):
            self.wait(job_id, timeout)

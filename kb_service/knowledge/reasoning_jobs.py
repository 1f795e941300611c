"""Reasoning jobs off the request path: one worker thread runs them in order, each within its own deadline; at most
`capacity` jobs wait or run at once, and one more is refused (`BusyError`) rather than queued without end.

The jobs' results stay in memory (the last `KEPT` finished ones); what a job inferred is handed to `on_done`
(the knowledge service stores it) before the job counts as finished.
"""
from __future__ import annotations

import logging
import queue
import threading
import time
from collections import OrderedDict
from dataclasses import dataclass, field
from typing import Any, Callable

from ..store import KBError, NotFoundError
from .reasoning import ReasoningRequest, ReasoningResult

log = logging.getLogger(__name__)

KEPT = 100  # finished jobs whose answer can still be read


class BusyError(KBError):
    """Too many reasoning jobs are waiting or running; the message says when to try again."""


@dataclass
class Job:
    id: str
    request: ReasoningRequest
    submitted_at: float
    status: str = "queued"  # queued, running, done, failed
    result: ReasoningResult | None = None
    error: str | None = None
    finished: threading.Event = field(default_factory=threading.Event)

    def public(self) -> dict[str, Any]:
        out: dict[str, Any] = {"id": self.id, "status": self.status, "reasoner": self.request.reasoner,
                               "object_id": self.request.object_id, "scope": str(self.request.scope)}
        if self.result is not None:
            out.update(self.result.public())
        if self.error is not None:
            out["error"] = self.error
        return out


class ReasoningJobs:
    """A bounded queue of reasoning jobs and the one thread that runs them."""

    def __init__(self, run: Callable[[ReasoningRequest], ReasoningResult],
                 on_done: Callable[[ReasoningResult], None], capacity: int) -> None:
        self._run = run
        self._on_done = on_done
        self._capacity = capacity
        self._lock = threading.Lock()
        self._jobs: OrderedDict[str, Job] = OrderedDict()
        self._pending = 0  # queued or running
        self._count = 0
        self._queue: queue.Queue[Job | None] = queue.Queue()
        self._closed = False
        self._thread = threading.Thread(target=self._work, name="planhrc-reasoning", daemon=True)
        self._thread.start()

    def submit(self, request: ReasoningRequest) -> Job:
        with self._lock:
            if self._closed:
                raise BusyError("reasoning: the service is stopping; try again when it is back")
            if self._pending >= self._capacity:
                raise BusyError(f"reasoning: {self._pending} job(s) are waiting or running, the most this service "
                                "takes (its reasoning_queue); try again when one has finished")
            self._count += 1
            job = Job(f"job{self._count}", request, time.time())
            self._jobs[job.id] = job
            self._pending += 1
            while len(self._jobs) > KEPT + self._capacity:
                oldest = next(iter(self._jobs.values()))
                if not oldest.finished.is_set():
                    break
                self._jobs.popitem(last=False)
        self._queue.put(job)
        return job

    def get(self, job_id: str) -> Job:
        with self._lock:
            job = self._jobs.get(job_id)
        if job is None:
            raise NotFoundError(f"job_id: no reasoning job {job_id!r} (finished jobs are kept for a while only)")
        return job

    def close(self) -> None:
        """Stop taking jobs; the queued ones fail at once (a request waiting for one answers), the running one is
        waited for a few seconds (its reasoner's JVM ends with its time limit or with the process)."""
        with self._lock:
            self._closed = True
        self._queue.put(None)
        self._thread.join(timeout=5)

    def _work(self) -> None:
        while True:
            job = self._queue.get()
            if job is None:
                return
            if self._closed:
                job.error, job.status = "the service stopped before the job ran", "failed"
                with self._lock:
                    self._pending -= 1
                job.finished.set()
                continue
            job.status = "running"
            try:
                result = self._run(job.request)
                self._on_done(result)
                job.result, job.status = result, "done"
            except KBError as exc:
                job.error, job.status = str(exc), "failed"
            except Exception as exc:  # a job must never stop the worker: it fails, with its reason
                log.exception("reasoning job %s failed", job.id)
                job.error, job.status = f"internal error: {exc}", "failed"
            finally:
                with self._lock:
                    self._pending -= 1
                job.finished.set()

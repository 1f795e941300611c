"""Planning on any host: the planning job queue in PostgreSQL (`store.postgres.jobs`), the service's side of it
(`QueuedPlanning`, the planning pool of a service on PostgreSQL with `planning_queue` set) and the workers' side
(`serve_jobs`, what `planhrc planning-worker` runs, on any host that reaches the database).

* **Which tasks.** As with the service's own pool (`planning_pool`): tasks whose states hold at least `min_atoms`
  atoms; smaller ones are planned in the service's process.
* **The deadline, end to end.** A job goes in with the seconds its request has left; no worker starts it once they
  are gone; a worker plans by them (the pipeline's deadline, on its own clock, from the seconds the database says
  are left); the service stops waiting at the deadline plus `grace_s`, withdraws the row and gets `timeout`, so the
  perception answers 503 and stores nothing. A service that cannot reach the database gets `timeout` too.
* **A worker killed mid-job** stops renewing its lease; when the lease has expired another worker takes the job
  again, from the start, if the deadline leaves time for it. Only the worker holding the row stores an outcome and
  the service takes one outcome per job: one plan, whichever worker made it.
* **VAL** gates dispatch exactly as with the service's own pool: with the early answer the service runs VAL on the
  outcome (`pipeline.replan`), else the worker checks the whole plan before it answers.
* **The garbage collector** of a worker is handled as the pool's workers' (`planning_pool.JobCollector`): off
  during a job, the young generations after it, a full pass every `FULL_COLLECT_JOBS` jobs, so that the grounded
  tasks a worker keeps are not walked after every job.
* **A job on the wire** is pickled, as the service's own pool sends it to its workers, and so is its outcome
  (`planning_pool.pack_outcome`): whoever may write the database may run code in the workers, so the database's
  credentials are the trust boundary (they already guard every plan the robot executes). Service and workers run
  the same planhrc version; each worker reads the TBox from its own file (`--tbox`).
"""
from __future__ import annotations

import logging
import os
import pickle
import socket
import threading
import time
from dataclasses import replace
from pathlib import Path
from typing import Any, Sequence

import psycopg

from planhrc.model import ArticulatedObject
from planhrc.pipeline import PlanOutcome
from planhrc.pipeline.replan import StepsKnown
from planhrc.vocabulary import PlanningStatus

from .metrics import WorkerMetrics
from .planning_pool import JobCollector, PlanningJob, StateSizes, pack_outcome, unpack_outcome
from .store import UnavailableError
from .store.postgres.jobs import (CLAIM, COLLECT, DEPTH, DONE_CHANNEL, FINISH, FORGET, HAND_BACK, JOB_CHANNEL,
                                  JOB_TABLES, MIN_LEFT_S, RENEW, SUBMIT, WITHDRAW, Claimed, claimed)
from .tracing import Tracing
from .store.postgres.schema import SCHEMA_LOCK
from .store.postgres.session import Connection, connect

log = logging.getLogger(__name__)

CHECK_S = 1.0  # how often a waiting job's row is read, should its announcement be lost (the listener reconnecting)
RECONNECT_S = 1.0  # between attempts to reach a database that went away
FORGET_EVERY_S = 60.0  # how often a worker deletes the rows of jobs long past their deadline


def ensure_tables(conn: Connection) -> None:
    """The queue's table, made by whichever process comes first (a worker may start before any service)."""
    with conn.transaction():
        conn.execute("SELECT pg_advisory_xact_lock(%s)", (SCHEMA_LOCK,))
        for sql in JOB_TABLES:
            conn.execute(sql)


class _Link:
    """A connection that is opened again after the server dropped it; `execute` holds it for one statement and turns
    a lost connection into `UnavailableError`."""

    def __init__(self, db: str, password: str | None, what: str) -> None:
        self._db, self._password, self._what = db, password, what
        self._lock = threading.Lock()
        self._conn: Connection | None = None

    def execute(self, sql: str, params: Sequence[Any] | dict[str, Any] = ()) -> list[tuple[Any, ...]]:
        with self._lock:
            try:
                if self._conn is None or self._conn.broken:
                    if self._conn is not None:
                        self._conn.close()
                    self._conn = connect(self._db, self._password, self._what)
                    ensure_tables(self._conn)
                cursor = self._conn.execute(sql, params)
                return cursor.fetchall() if cursor.description is not None else []
            except psycopg.OperationalError as exc:
                reason = " ".join(str(exc).split())[:200]
                raise UnavailableError(f"db: the planning queue lost its connection ({reason})") from None

    def close(self) -> None:
        with self._lock:
            if self._conn is not None:
                self._conn.close()
                self._conn = None


# -- the service's side ---------------------------------------------------------------------------------------
class QueuedPlanning:
    """Large tasks planned by `planhrc planning-worker` processes through the database (`plan(job)` queues the job
    and waits for its outcome, by the job's deadline and `grace_s`). With `tracing` on, a job carries the trace
    context of the request that queued it (the row's `trace`), and the worker's span continues that trace."""

    def __init__(self, db: str, password: str | None, min_atoms: int, grace_s: float = 1.0,
                 tracing: Tracing | None = None) -> None:
        self.min_atoms = min_atoms
        self._tracing = tracing or Tracing.off()
        self.grace_s = grace_s
        self._db, self._password = db, password
        self._link = _Link(db, password, "planhrc-planning")
        self._guard = threading.Lock()
        self._waiting: dict[int, threading.Event] = {}
        self._sizes = StateSizes()
        self._closed = threading.Event()
        self._listener = threading.Thread(target=self._listen, name="planhrc-planning-done", daemon=True)
        self._listener.start()

    def close(self) -> None:
        self._closed.set()
        with self._guard:
            for event in self._waiting.values():
                event.set()
        self._listener.join(timeout=2)
        self._link.close()

    def takes(self, obj: ArticulatedObject) -> bool:
        return not self._closed.is_set() and self._sizes.at_least(obj, self.min_atoms)

    def plan(self, job: PlanningJob, steps_known: StepsKnown | None = None) -> PlanOutcome:
        """The outcome a worker made, or `timeout` when none came by the job's deadline and its grace (the job is
        withdrawn: no worker starts it after that). `steps_known` is not called: a queued job's outcome comes
        whole, in one row."""
        deadline = job.config.deadline_s
        left = job.deadline_at - time.monotonic()
        if left <= MIN_LEFT_S:
            return _outcome(job, PlanningStatus.TIMEOUT, f"planning deadline of {deadline:g} s exceeded before "
                            "the task was queued")
        done = threading.Event()
        job_id: int | None = None
        collected = False
        try:
            trace = self._tracing.carrier().get("traceparent")
            job_id = int(self._link.execute(SUBMIT, (job.obj.ident, pickle.dumps(job, pickle.HIGHEST_PROTOCOL),
                                                     left, trace))[0][0])
            with self._guard:
                self._waiting[job_id] = done
            until = job.deadline_at + self.grace_s
            while not self._closed.is_set():
                rows = self._link.execute(COLLECT, (job_id,))
                if rows:
                    collected = True  # the row went with its outcome
                    frames: list[bytes] = pickle.loads(rows[0][0])
                    return unpack_outcome(iter(frames))
                rest = until - time.monotonic()
                if rest <= 0:
                    return _outcome(job, PlanningStatus.TIMEOUT, f"planning deadline of {deadline:g} s exceeded "
                                    "while the task waited in the planning queue or was planned by a worker")
                done.wait(min(rest, CHECK_S))
                done.clear()
            return _outcome(job, PlanningStatus.ERROR, "the service is stopping: no planning worker")
        except UnavailableError as exc:
            return _outcome(job, PlanningStatus.TIMEOUT, f"the planning queue cannot be reached ({exc})")
        finally:
            if job_id is not None:
                with self._guard:
                    self._waiting.pop(job_id, None)
                if not collected:
                    self._withdraw(job_id)

    def warm(self, job: PlanningJob) -> None:
        """Nothing: the object's next job goes to whichever `planhrc planning-worker` takes it first, on any host,
        so no warm-up can be placed where that job will run."""

    def depth(self) -> dict[str, int]:
        """Jobs queued and running in the database now (every service's, not only this one's)."""
        return {str(state): int(count) for state, count in self._link.execute(DEPTH)}

    def reachable(self) -> bool:
        """Whether the queue's database answers now."""
        try:
            self._link.execute("SELECT 1")
        except UnavailableError:
            return False
        return True

    def _withdraw(self, job_id: int) -> None:
        try:
            self._link.execute(WITHDRAW, (job_id,))
        except UnavailableError as exc:  # its deadline passes anyway: no worker starts it then
            log.warning("planning job %d could not be withdrawn: %s", job_id, exc)

    def _listen(self) -> None:
        """Wake the request waiting for each job whose outcome is stored (`DONE_CHANNEL`)."""
        conn: Connection | None = None
        while not self._closed.is_set():
            try:
                if conn is None:
                    conn = connect(self._db, self._password, "planhrc-planning-done")
                    conn.execute(f"LISTEN {DONE_CHANNEL}")
                for note in conn.notifies(timeout=0.5, stop_after=1):
                    with self._guard:
                        event = self._waiting.get(int(note.payload))
                    if event is not None:
                        event.set()
            except (UnavailableError, psycopg.OperationalError) as exc:
                log.warning("planning queue: %s; listening again", " ".join(str(exc).split())[:200])
                if conn is not None:
                    conn.close()
                conn = None
                self._closed.wait(RECONNECT_S)
        if conn is not None:
            conn.close()


def _outcome(job: PlanningJob, status: PlanningStatus, message: str) -> PlanOutcome:
    return PlanOutcome(status, message, job.config.planner)


# -- the workers' side ----------------------------------------------------------------------------------------
def worker_name() -> str:
    """How a worker names itself on the rows it holds: host and process id."""
    return f"{socket.gethostname()}:{os.getpid()}"


class _Lease(threading.Thread):
    """Renews a job's lease every third of its length, on a connection of its own, until `stop`."""

    def __init__(self, db: str, password: str | None, job_id: int, worker: str, lease_s: float) -> None:
        super().__init__(name="planhrc-job-lease", daemon=True)
        self._link = _Link(db, password, "planhrc-planning-lease")
        self._job_id, self._worker, self._lease_s = job_id, worker, lease_s
        self._ended = threading.Event()

    def run(self) -> None:
        try:
            while not self._ended.wait(self._lease_s / 3):
                try:
                    rows = self._link.execute(RENEW, (self._lease_s, self._job_id, self._worker))
                except UnavailableError as exc:
                    log.warning("job %d: the lease was not renewed (%s)", self._job_id, exc)
                    continue
                if not rows:
                    log.warning("job %d is no longer this worker's (withdrawn, or taken over)", self._job_id)
                    return
        finally:
            self._link.close()

    def stop(self) -> None:
        self._ended.set()
        self.join(timeout=5)


def serve_jobs(db: str, password: str | None, tbox_path: str, lease_s: float, stop: threading.Event,
               worker: str | None = None, metrics: WorkerMetrics | None = None,
               tracing: Tracing | None = None) -> None:
    """Plan queued jobs one at a time until `stop` is set; a database that goes away is reached again. SIGTERM (a
    `BaseException` raised in this thread) hands the running job back to the queue. What it does is counted in
    `metrics` (served by the caller) and traced with `tracing`, each job's span a child of the request that queued
    it."""
    from planhrc import pipeline

    worker = worker or worker_name()
    metrics = metrics or WorkerMetrics()
    tracing = tracing or Tracing.off()
    link = _Link(db, password, "planhrc-planning-worker")
    collector = JobCollector()  # as the pool's workers: the grounded tasks it keeps are not walked after each job
    listener: Connection | None = None
    forgotten_at = 0.0
    try:
        while not stop.is_set():
            try:
                if listener is None:
                    listener = connect(db, password, "planhrc-planning-wake")
                    listener.execute(f"LISTEN {JOB_CHANNEL}")
                    log.info("planning worker %s: serving the job queue", worker)
                if time.monotonic() - forgotten_at > FORGET_EVERY_S:
                    link.execute(FORGET)
                    forgotten_at = time.monotonic()
                got = claimed(next(iter(link.execute(CLAIM, {"worker": worker, "lease": lease_s})), None))
                if got is None:  # until a job is queued, or a lease may have expired
                    for _ in listener.notifies(timeout=min(1.0, lease_s / 2), stop_after=1):
                        pass
                    continue
                if got.taken_over:
                    metrics.taken_over.inc()
                parent = {"traceparent": got.trace} if got.trace else None
                with collector.job(), tracing.span("planning_job", {"object_id": got.object_id, "worker": worker,
                                                                    "attempt": got.attempts, "queue": "postgresql"},
                                                   parent=parent):
                    outcome = _run_job(pipeline.plan, link, db, password, worker, got, tbox_path, lease_s)
                metrics.finished(str(outcome.status), outcome.timings)
                tracing.flush()
            except (UnavailableError, psycopg.OperationalError) as exc:
                log.warning("planning worker %s: %s; trying again", worker, " ".join(str(exc).split())[:200])
                if listener is not None:
                    listener.close()
                listener = None
                stop.wait(RECONNECT_S)
    finally:
        if listener is not None:
            listener.close()
        link.close()


def _run_job(plan: Any, link: _Link, db: str, password: str | None, worker: str, got: Claimed, tbox_path: str,
             lease_s: float) -> PlanOutcome:
    """Plan a claimed job and store its outcome (which it returns)."""
    job_id, object_id, blob, left, attempts = got.id, got.object_id, got.blob, got.left, got.attempts
    lease: _Lease | None = None
    try:
        try:
            job: PlanningJob = pickle.loads(blob)
        except Exception as exc:  # a service of another planhrc version: it gets an error, not silence
            log.error("planning job %d (%s) does not read as a job of this version: %s", job_id, object_id, exc)
            failed = PlanOutcome(PlanningStatus.ERROR, f"the planning worker could not read the job ({exc})",
                                 "none")
            link.execute(FINISH, (pickle.dumps(list(pack_outcome(failed))), job_id, worker))
            return failed
        job = replace(job, config=replace(job.config, tbox_path=Path(tbox_path)),
                      deadline_at=time.monotonic() + left)
        log.info("planning job %d (%s, attempt %d, %.2f s left)", job_id, object_id, attempts, left)
        lease = _Lease(db, password, job_id, worker, lease_s)
        lease.start()
        try:
            outcome: PlanOutcome = plan(job.obj, job.init, job.goal, job.config, placement=job.placement,
                                        deadline_at=job.deadline_at)
        except Exception as exc:  # the service gets an outcome whatever happens
            log.exception("planning failed for %s", object_id)
            outcome = PlanOutcome(PlanningStatus.ERROR, f"{type(exc).__name__}: {exc}", job.config.planner)
        lease.stop()
    except BaseException:  # stopped (SIGTERM, Ctrl-C) while it held the job: another worker may take it at once
        if lease is not None:
            lease.stop()
        try:
            link.execute(HAND_BACK, (job_id, worker))
        except UnavailableError:
            pass  # its lease expires instead
        raise
    frames = pickle.dumps(list(pack_outcome(outcome)), pickle.HIGHEST_PROTOCOL)
    if not link.execute(FINISH, (frames, job_id, worker)):
        log.warning("planning job %d was withdrawn or taken over meanwhile: its outcome is dropped", job_id)
    return outcome

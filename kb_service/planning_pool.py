"""Planning worker processes owned by the service, so a large task's planning does not hold its interpreter. (A
service on PostgreSQL may instead put its large tasks in the database's job queue, for `planhrc planning-worker`
processes on any host: `planning_queue`.)

The pipeline (translate -> plan -> order -> expected states -> VAL, `pipeline.plan`) is mostly Python: while it
runs in the service's process it holds the interpreter lock in turns with every request, and its memoised
grounding stays in the service's heap, which every full garbage collection then walks. `PlanningPool` runs it in
a few worker processes instead: the service hands a worker a value (`PlanningJob`: the object, the states, the
planning configuration, the deadline) and gets back the `PlanOutcome`, checked by VAL (VAL's processes are the
worker's, so they end with it). The store's checks of the plan stay with the caller: they need the store.

* **Which tasks.** Only tasks whose states hold at least `min_atoms` atoms go to a worker (`takes`): a small
  task's pipeline (a relative 20 x 12 re-plan, say) costs less than the trip.
* **The deadline.** A worker runs the pipeline with the job's deadline (`time.monotonic()` is the same clock in
  every process of the machine) and answers by it; one that has not answered `grace_s` after it is stopped
  (SIGTERM, then SIGKILL) and replaced, and the job ends `timeout`. A worker that dies ends its job `error` and is
  replaced too. A job waits for a free worker (or one starting) only until its deadline.
* **What comes back.** The outcome's expected states share most atoms (every state carries the object's static
  facts): a worker sends the first state once and, for each further state, the atoms it lacks and adds against
  the one before it (the replay's own changes), and the service keeps them so (`transition.ExpectedStates`: a
  state is made whole when something reads it, most of them behind the answer). The outcome travels
  in several frames (header, actions, states in chunks) so that no single unpickling holds the service's
  interpreter for long. Asked to (`plan`'s `steps_known`: the service checks the first motion with VAL itself), a
  worker first sends the plan's task and steps (`EarlySteps`), before it replays them.
* **The cyclic garbage collector.** A large task's replay and unpacking make hundreds of thousands of small
  objects (ground conditional effects, atoms), and every few thousand allocations start a collection pass; the
  full passes walk every expected state made so far (each holds all the object's static facts), so on the
  absolute 200 x 12 task those passes, not the work, took most of the replay's and the unpacking's time. The
  unpacking makes no reference cycle, and a whole pipeline run (absolute 60 x 12) about 1,500 cyclic objects:
  a worker runs a job with the collector off and, once the outcome is sent (before it takes the next job), collects
  the young generations, where everything the job made is: its cycles go, for about a millisecond on absolute
  20 x 12. A full collection, which also walks what the worker keeps from job to job (the grounded tasks: about
  45 ms there, more than planning the job), runs every `FULL_COLLECT_JOBS` jobs. The service pauses its collector
  only while it unpacks an outcome that has arrived (`_CollectorPause`), not while it waits for one. A huge outcome
  (`FREEZE_ATOMS` atoms in its expected states: absolute 200 x 12 has about 12 million) is then frozen out of the
  collector's passes (`gc.freeze`, as start-up's objects are): each full pass walked all its states while it held
  the interpreter, half a second or more, and every other object's request and /health waited (`planhrc
  service-bench --parts contention`: another object's slowest perception 1.0-1.1 s -> 0.17 s, the slowest /health
  0.5-1.0 s -> 0.05 s). Its objects are still freed when the plan is dropped (they hold no reference cycle); what
  else was in the collector's generations at that moment is frozen with it until shutdown, which is why only huge
  outcomes are.
* **Priority.** A worker runs at nice 10: on a machine whose cores are all busy, the service's requests come
  first and the large task gets what is left (`planhrc service-bench --parts contention` compares the slowest
  /health and the other object's slowest perception with the workers at the service's priority).
* **Life.** The service makes the pool in its lifespan and closes it at shutdown; a worker starts when a job
  first needs it (it imports the pipeline first, which takes a while), up to `workers`, and stays.
* **Warm-up.** An object's first job would also pay for what a worker memoises per object (the planner's grounding
  of its task: about 1 s of the first 200 x 12 absolute re-plan, on top of the worker's start). When a large
  object's goal is set, the service asks the pool to `warm` a worker up for it: a free worker (or one it may still
  start) runs `pipeline.warm_up` (translate and plan a task towards the goal, no replay, no VAL), off the request's
  thread; the object's next job waits for that worker rather than start another, cold one. Nothing is warmed
  behind another job, nor on a worker that last planned the object. A worker ignores SIGINT
  (the service stops it), stops on SIGTERM with the VAL or planner processes it started, and watches its parent:
  when the parent is gone (SIGKILL included) it stops the same way.
"""
from __future__ import annotations

import gc
import itertools
import logging
import os
import pickle
import signal
import socket
import subprocess
import sys
import threading
import time
from contextlib import contextmanager
from dataclasses import dataclass, replace
from multiprocessing.connection import Connection
from typing import Callable, Iterator, Mapping, Sequence

from planhrc.model import ActionSpec, ArticulatedObject, Atom, State
from planhrc.pipeline import PlanOutcome
from planhrc.pipeline.replan import PlanningJob, StepsKnown
from planhrc.translator.translate import PddlTask
from planhrc.transition import Change, ExpectedStates, changes_of
from planhrc.vocabulary import PlanningStatus

from .tracing import Tracing

__all__ = ["ATOMS_PER_FRAME", "JobCollector", "PlanningJob", "PlanningPool", "pack_outcome", "state_size",
           "unpack_outcome"]

log = logging.getLogger(__name__)

ATOMS_PER_FRAME = 5_000  # one frame's unpickling holds the service's interpreter only briefly
EFFECTS_PER_FRAME = 1_000  # actions' conditional effects per frame (absolute 200 links: about 200 an action)
WORKER_NICE = 10  # below the service's requests when they compete for a core
FULL_COLLECT_JOBS = 100  # a worker collects every generation after this many jobs, the young ones after each
FREEZE_ATOMS = 1_000_000  # an outcome whose expected states hold this many atoms in all is frozen (module's note)
_PARENT_POLL_S = 0.2
_STOP_WAIT_S = 1.0


def state_size(obj: ArticulatedObject) -> int:
    """Atoms in a complete state of the object (its static facts and one orientation per joint): what a
    re-plan's replay, expected states and checks grow with."""
    return len(obj.state([0] * obj.n_joints))


class StateSizes:
    """`state_size` of each object, made once (objects never change): whether a task on it is worth a worker."""

    def __init__(self) -> None:
        self._sizes: dict[str, int] = {}  # object id -> state_size

    def at_least(self, obj: ArticulatedObject, atoms: int) -> bool:
        size = self._sizes.get(obj.ident)
        if size is None:
            size = self._sizes.setdefault(obj.ident, state_size(obj))
        return size >= atoms


# -- the outcome on the wire ----------------------------------------------------------------------------------
def pack_outcome(outcome: PlanOutcome) -> Iterator[bytes]:
    """The outcome as frames: a header (the outcome without actions and states, and how many frames follow),
    the actions in chunks, the first expected state, then each further state as (missing, added) atoms against
    the one before it, in chunks of about `ATOMS_PER_FRAME` atoms. A solved outcome's states are its actions'
    replay (`PlanOutcome`), kept as what each step changes (`transition.ExpectedStates`): those changes are sent as
    they are, and no state is made whole here (`transition.changes_of`; states given whole are compared step by
    step, `changes_along`)."""
    states, actions = outcome.expected_states, outcome.actions
    action_chunks: list[list[ActionSpec]] = []
    weight = EFFECTS_PER_FRAME
    for action in actions:
        if weight >= EFFECTS_PER_FRAME:
            action_chunks.append([])
            weight = 0
        action_chunks[-1].append(action)
        weight += 1 + len(action.cond_eff)
    state_chunks: list[list[tuple[frozenset[Atom], frozenset[Atom]]]] = []
    base_frames: list[list[Atom]] = []
    if states:
        base = states[0]
        chunk: list[tuple[frozenset[Atom], frozenset[Atom]]] = []
        size = 0
        for diff in changes_of(states, actions):
            chunk.append(diff)
            size += len(diff[0]) + len(diff[1]) + 1
            if size >= ATOMS_PER_FRAME:
                state_chunks.append(chunk)
                chunk, size = [], 0
        if chunk:
            state_chunks.append(chunk)
        atoms = list(base)
        base_frames = [atoms[i:i + ATOMS_PER_FRAME] for i in range(0, len(atoms), ATOMS_PER_FRAME)]
    bare = replace(outcome, actions=(), expected_states=())
    header = (bare, len(action_chunks), bool(states), len(base_frames), len(state_chunks))
    yield pickle.dumps(header, pickle.HIGHEST_PROTOCOL)
    for part in (*action_chunks, *base_frames, *state_chunks):
        yield pickle.dumps(part, pickle.HIGHEST_PROTOCOL)


def unpack_outcome(frames: Iterator[bytes], init: State | None = None) -> PlanOutcome:
    """The outcome `pack_outcome` sent, its states as the first one and the changes (`transition.ExpectedStates`: a
    state is made whole when something reads it, not here). With `init` (the job's initial state, which the first
    expected state equals), the states are made on it: their static facts are then the service's own atoms, which
    the store's checks of those states find by identity instead of comparing copies."""
    header: tuple[PlanOutcome, int, bool, int, int] = pickle.loads(next(frames))
    bare, n_actions, has_states, n_base, n_states = header
    actions: list[ActionSpec] = []
    for _ in range(n_actions):
        actions.extend(pickle.loads(next(frames)))
    base_atoms: list[Atom] = []
    for _ in range(n_base):
        base_atoms.extend(pickle.loads(next(frames)))
    changes: list[Change] = []
    for _ in range(n_states):
        changes.extend(pickle.loads(next(frames)))
    if not has_states:
        return replace(bare, actions=tuple(actions), expected_states=())
    first = frozenset(base_atoms)
    if init is not None and first == init:
        first = init if isinstance(init, frozenset) else frozenset(init)
    return replace(bare, actions=tuple(actions), expected_states=ExpectedStates(first, changes))


# -- the pool (in the service) --------------------------------------------------------------------------------
class _Worker:
    def __init__(self, environment: Mapping[str, str]) -> None:
        parent_end, child_end = socket.socketpair()
        code = "from planhrc.kb_service.planning_pool import run_worker; run_worker()"
        self.proc = subprocess.Popen(
            [sys.executable, "-c", code, str(child_end.fileno()), str(os.getpid())],
            pass_fds=(child_end.fileno(),), stdin=subprocess.DEVNULL, start_new_session=True,
            env={**os.environ, **environment})
        child_end.close()
        self.conn = Connection(parent_end.detach())
        self.last_object: str | None = None
        self.warming: str | None = None  # the object whose warm-up it runs (`PlanningPool.warm`)

    @property
    def pid(self) -> int:
        return self.proc.pid

    def stop(self, wait_s: float = _STOP_WAIT_S) -> None:
        """SIGTERM (the worker stops the processes it started), then SIGKILL if it is still there. The connection
        is left to the thread using it, which reads the end of it."""
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(wait_s)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()

    def close(self) -> None:
        try:
            self.conn.close()
        except OSError:
            pass


class PlanningPool:
    """Up to `workers` planning processes, started when a job first needs one and kept until `close`;
    `plan(job)` runs a job on a free one (the one that last planned the same object when it is free: its memoised
    grounding is warm) and returns the outcome by the job's deadline and its grace. With `tracing` on, each job
    carries the current trace context to its worker, whose span continues the request's trace (the workers trace to
    the endpoint `environment` names: PLANHRC_OTLP_ENDPOINT, or OpenTelemetry's variables, which they inherit)."""

    def __init__(self, workers: int, min_atoms: int, grace_s: float = 1.0, tracing: Tracing | None = None,
                 environment: Mapping[str, str] | None = None) -> None:
        self.size = workers
        self._tracing = tracing or Tracing.off()
        self._environment = dict(environment or {})
        self.min_atoms = min_atoms
        self.grace_s = grace_s
        self._idle: list[_Worker] = []
        self._all: set[_Worker] = set()
        self._cond = threading.Condition()
        self._closed = False
        self._sizes = StateSizes()
        self._pause = _CollectorPause()

    def close(self) -> None:
        """Stop every worker (a job still running ends `error`)."""
        with self._cond:
            self._closed = True
            workers, idle = list(self._all), list(self._idle)
            self._all.clear()
            self._idle.clear()
            self._cond.notify_all()
        for worker in workers:
            worker.stop()
        for worker in idle:
            worker.close()

    def __enter__(self) -> "PlanningPool":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def reachable(self) -> bool:
        """Whether the pool takes jobs (open; a pool of no workers plans in the service's process)."""
        return not self._closed

    def pids(self) -> tuple[int, ...]:
        with self._cond:
            return tuple(sorted(w.pid for w in self._all))

    def warming(self) -> tuple[str, ...]:
        """The objects a worker is warming up for now (`warm`)."""
        with self._cond:
            return tuple(sorted(w.warming for w in self._all if w.warming is not None))

    def takes(self, obj: ArticulatedObject) -> bool:
        """Whether a task on `obj` is worth a worker (large enough, and the pool open)."""
        return self.size != 0 and not self._closed and self._sizes.at_least(obj, self.min_atoms)

    def plan(self, job: PlanningJob, steps_known: StepsKnown | None = None) -> PlanOutcome:
        """The job's outcome: the worker's, or `timeout` / `error` when no worker answered in time or it died.
        With `steps_known`, the worker sends the plan's task and steps before it replays them (`EarlySteps`), and
        they are handed to `steps_known` here, on the caller's thread, as soon as they come."""
        worker = self._take(job.obj.ident, job.deadline_at)
        if worker is None:
            if self._closed:
                return _outcome(job, PlanningStatus.ERROR, "the service is stopping: no planning worker")
            return _outcome(job, PlanningStatus.TIMEOUT, f"planning deadline of {job.config.deadline_s:g} s "
                            "exceeded while waiting for a free planning worker")
        return self._run(worker, job, False, steps_known)

    def warm(self, job: PlanningJob) -> None:
        """Warm a worker up for `job`'s object (`pipeline.warm_up`: the worker starts if none is free, imports the
        pipeline and memoises the object's grounding), on a thread of its own, so that the object's next job finds
        it ready. Only on a worker free now or one the pool may still start (never behind another job), and not
        when a worker last planned the object (it is warm). The object's next job waits for that worker while the
        warm-up runs (`_take`): another, cold worker would do the same work again."""
        object_id = job.obj.ident
        with self._cond:
            if self._closed or any(w.last_object == object_id for w in self._all):
                return
            if self._idle:
                worker = self._idle.pop(0)
            elif len(self._all) < self.size:
                worker = self._start()
            else:
                return
            worker.last_object = worker.warming = object_id
        threading.Thread(target=self._run, args=(worker, job, True), name="planhrc-pool-warm", daemon=True).start()

    def _run(self, worker: _Worker, job: PlanningJob, warm_up: bool, steps_known: StepsKnown | None = None
             ) -> PlanOutcome:
        """`job` on `worker` (taken for it): planned, or only warmed up (`warm_up`); the worker given back."""
        healthy = False
        try:
            worker.conn.send((job, self._tracing.carrier(), warm_up, steps_known is not None))
            frames = self._frames(worker, job.deadline_at + self.grace_s)
            header = next(frames)
            if steps_known is not None:
                early = pickle.loads(header)
                if isinstance(early, EarlySteps):  # the replay goes on in the worker meanwhile
                    steps_known(early.task, early.steps)
                    header = next(frames)
            # the worker's answer has come: the rest follows at once
            with self._pause:
                outcome = unpack_outcome(itertools.chain((header,), frames), job.init)
                if _atoms_in(outcome.expected_states) >= FREEZE_ATOMS:
                    gc.freeze()  # see the module's note: kept out of the collector's full passes
            healthy = True
            if warm_up:
                log.info("planning worker %d warmed up for %s: %s", worker.pid, job.obj.ident, outcome.message)
            return outcome
        except _Overrun:
            log.warning("planning worker %d overran the deadline of %s: stopped", worker.pid, job.obj.ident)
            return _outcome(job, PlanningStatus.TIMEOUT, f"planning deadline of {job.config.deadline_s:g} s "
                            "exceeded (the planning worker was stopped)")
        except (EOFError, OSError, pickle.UnpicklingError) as exc:
            code = worker.proc.poll()
            log.error("planning worker %d failed on %s (%s, exit code %s)", worker.pid, job.obj.ident,
                      type(exc).__name__, code)
            return _outcome(job, PlanningStatus.ERROR, f"the planning worker stopped (exit code {code})")
        finally:
            self._give_back(worker, healthy)

    def _frames(self, worker: _Worker, until: float) -> Iterator[bytes]:
        while True:
            if not worker.conn.poll(max(0.0, until - time.monotonic())):
                raise _Overrun()
            yield worker.conn.recv_bytes()

    def _take(self, object_id: str, deadline_at: float) -> _Worker | None:
        """A free worker (the one that last planned the object when it is free; started here while the pool has
        fewer than `size`), waiting for one until the job's deadline; while a worker warms up for the object, that
        one. None when none came or the pool is closed."""
        with self._cond:
            while not self._closed:
                warming = any(w.warming == object_id for w in self._all)
                worker = next((w for w in self._idle if w.last_object == object_id), None)
                if worker is None and self._idle and not warming:
                    worker = self._idle[0]
                if worker is not None:
                    self._idle.remove(worker)
                    break
                if not warming and len(self._all) < self.size:
                    worker = self._start()
                    break
                left = deadline_at - time.monotonic()
                if left <= 0:
                    return None
                self._cond.wait(left)
            else:
                return None
            worker.last_object = object_id
            return worker

    def _start(self) -> _Worker:
        """A new worker, counted in the pool (the caller holds `_cond`)."""
        worker = _Worker(self._environment)
        self._all.add(worker)
        log.info("planning worker %d started", worker.pid)
        return worker

    def _give_back(self, worker: _Worker, healthy: bool) -> None:
        """A worker back to the idle ones; a failed one is stopped (off this thread) and its place freed. Every
        waiting job looks again (one may be waiting for this worker's warm-up)."""
        with self._cond:
            worker.warming = None
            if healthy and not self._closed:
                self._idle.append(worker)
                self._cond.notify_all()
                return
            self._all.discard(worker)
            self._cond.notify_all()
        worker.close()
        threading.Thread(target=worker.stop, name="planhrc-pool-stop", daemon=True).start()


@dataclass(frozen=True)
class EarlySteps:
    """What a worker sends first when asked to (`PlanningPool.plan`'s `steps_known`): the plan's task and steps,
    before it replays them."""

    task: PddlTask
    steps: tuple[str, ...]


class _CollectorPause:
    """The cyclic garbage collector off while any thread of the service is inside (see the module's note), on
    again when the last one leaves (if it was on when the first came in). `gc` has one switch per process: the
    count keeps one thread's leaving from turning it on under another still unpacking."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._inside = 0
        self._was_enabled = False

    def __enter__(self) -> None:
        with self._lock:
            if self._inside == 0:
                self._was_enabled = gc.isenabled()
                gc.disable()
            self._inside += 1

    def __exit__(self, *exc: object) -> None:
        with self._lock:
            self._inside -= 1
            if self._inside == 0 and self._was_enabled:
                gc.enable()


def _atoms_in(states: Sequence[State]) -> int:
    """How many atoms the states hold, about (each holds the first one's static facts), without making them whole."""
    return len(states[0]) * len(states) if states else 0


class _Overrun(Exception):
    """A worker did not answer by the job's deadline and its grace."""


def _outcome(job: PlanningJob, status: PlanningStatus, message: str) -> PlanOutcome:
    return PlanOutcome(status, message, job.config.planner)


# -- the worker (its own process) -----------------------------------------------------------------------------
def run_worker() -> None:
    """A worker's life: `python -c ... FD PARENT_PID`; runs jobs from the connection on FD until it closes or the
    parent is gone."""
    fd, parent = int(sys.argv[1]), int(sys.argv[2])
    logging.basicConfig(level=logging.WARNING, format="planning worker %(process)d: %(levelname)s %(message)s")
    os.nice(WORKER_NICE)
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the service stops its workers itself
    signal.signal(signal.SIGTERM, _stop)
    threading.Thread(target=_watch_parent, args=(parent,), name="planhrc-parent-watch", daemon=True).start()
    from planhrc import pipeline

    conn = Connection(fd)
    collector = JobCollector()
    tracing = Tracing.start("planhrc-planning-pool", os.environ.get("PLANHRC_OTLP_ENDPOINT") or None)
    try:
        while True:
            try:
                job, carrier, warm_up, steps_first = conn.recv()
            except (EOFError, OSError):
                return
            run: Callable[[PlanningJob], PlanOutcome] = (
                pipeline.warm_up if warm_up else (lambda j: _plan_steps_first(conn, j)) if steps_first else _plan)
            with collector.job():
                with tracing.span("planning_warm_up" if warm_up else "planning_job",
                                  {"object_id": job.obj.ident, "worker.pid": os.getpid(), "queue": "pool"},
                                  parent=carrier):
                    sent = _answer(conn, job, run)
            tracing.flush()
            if not sent:
                return
    finally:
        tracing.close()


class JobCollector:
    """The cyclic garbage collector of a process that plans jobs one after another (see the module's note): off
    during a job, the young generations collected after it, every generation after every `FULL_COLLECT_JOBS`."""

    def __init__(self) -> None:
        self.done = 0

    @contextmanager
    def job(self) -> Iterator[None]:
        gc.disable()
        try:
            yield
        finally:
            gc.enable()
            self.done += 1
            gc.collect(2 if self.done % FULL_COLLECT_JOBS == 0 else 1)


def _plan(job: PlanningJob) -> PlanOutcome:
    from planhrc import pipeline

    return pipeline.plan(job.obj, job.init, job.goal, job.config, placement=job.placement, deadline_at=job.deadline_at)


def _plan_steps_first(conn: Connection, job: PlanningJob) -> PlanOutcome:
    """`_plan` for a job VAL does not check here (the early answer: the service does), the plan's task and steps
    sent (`EarlySteps`) before they are replayed."""
    from planhrc import pipeline

    assert not job.config.validate
    found = pipeline.find_plan(job.obj, job.init, job.goal, job.config, placement=job.placement,
                               deadline_at=job.deadline_at)
    if isinstance(found, PlanOutcome):
        return found
    conn.send_bytes(pickle.dumps(EarlySteps(found.task, found.steps), pickle.HIGHEST_PROTOCOL))
    return pipeline.expect(job.obj, job.init, job.goal, found, job.deadline_at)


def _answer(conn: Connection, job: PlanningJob, run: Callable[[PlanningJob], PlanOutcome]) -> bool:
    """Run the job (plan it, or warm up for it) and send its outcome; False when the service's end of the
    connection is gone."""
    try:
        outcome = run(job)
    except Exception as exc:  # the service gets an outcome whatever happens
        log.exception("planning failed for %s", job.obj.ident)
        outcome = PlanOutcome(PlanningStatus.ERROR, f"{type(exc).__name__}: {exc}", job.config.planner)
    try:
        for frame in pack_outcome(outcome):
            conn.send_bytes(frame)
    except OSError:
        return False
    return True


def _stop(signum: int, frame: object) -> None:
    raise SystemExit(0)  # unwinds through `run_limited`, which kills the planner or VAL process group it runs


def _watch_parent(parent: int) -> None:
    while os.getppid() == parent:
        time.sleep(_PARENT_POLL_S)
    os.kill(os.getpid(), signal.SIGTERM)
    time.sleep(_STOP_WAIT_S)
    os._exit(1)


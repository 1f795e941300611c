"""One object's write, serialised across every service process on the store: the unit of work each writing use
case calls (`object_write`), the retry around it (`serialized`), and a re-plan's write overlapping VAL's check of
the new plan (`write_on_verdict`). Every retry of a write and every wait on VAL lives here.

Within one process the object's lock (`locks.ObjectLocks`) makes one object's requests one at a time. Several
processes on one PostgreSQL store (replicas) serialise each object's writes in the database instead:
`object_write` opens the transaction and takes the object's lock across processes first (`store.ObjectLocking`,
an advisory lock its commit or rollback releases, or the death of its process). A use case decides on what it read
before its write (a re-plan takes seconds, and a transaction holds the store's connection for every object), so
under the lock it checks that the object did not move since: every change of an object comes with an event, so the
object's event log says whether another process wrote it after the use case read it (`read_mark`). When it did,
the decision may rest on a state that is no longer stored: `object_write` raises `StaleRead`, which rolls the write
back, and `serialized` runs the use case again on what is stored now. A retry of an idempotent request sent to
another replica thereby gets the answer the first replica committed (the use case recalls it again), and two
replicas taking the same object's next action dispatch it once (the second finds it dispatched and answers it).
VAL's verdicts are events too, but no write rests on their absence (the gate waits for the verdicts it needs), so
they do not count as a move.

A store that one process owns (SQLite) has no such lock and nothing moves under the in-process lock: its writes
are plain transactions, as before.

A re-plan's write rests on VAL's verdict on the new plan, VAL running in its own processes meanwhile
(`pipeline.VerdictHandle`). A plan VAL checks in one short run has its write begun before VAL answered: the write
reads the verdict inside the store's transaction, waiting `OVERLAP_WAIT_S` at most, so that a slow VAL (a loaded
machine) does not hold the store every object writes to: the write is then rolled back, VAL waited for outside the
store, and the write done again. Any other verdict is waited for before the write. A verdict saying the planning
deadline passed raises `DeadlineError` and stores nothing; whatever fails, VAL's runs on the plan are stopped.
"""
from __future__ import annotations

import logging
import time
from contextlib import contextmanager
from typing import Callable, Iterator, TypeVar

from planhrc.pipeline import PlannedTurn, PlanOutcome, deadline_from
from planhrc.vocabulary import PlanningStatus

from ..store import CheckedPlan, DeadlineError, KBError, ObjectLocking
from .context import Context
from .seen import NewPlan

log = logging.getLogger(__name__)
T = TypeVar("T")

# How long a re-plan's write, begun while VAL checks its new plan in one short run, waits for VAL inside the
# store's transaction: on a quiet machine VAL answers within it; a slower run is waited for outside the store.
OVERLAP_WAIT_S = 0.02


class StaleRead(KBError):
    """Another process wrote the object after the use case read it: its write was rolled back, and `serialized`
    runs the use case again."""


def read_mark(context: Context, object_id: str) -> int:
    """Where the object's log stands (the last event that changed the object), read before anything a write will
    rest on; 0 on a store one process owns, where nothing moves under the in-process lock."""
    if not isinstance(context.store, ObjectLocking):
        return 0
    return context.memory.of(context.store, object_id).changed_seq


@contextmanager
def object_write(context: Context, object_id: str, read_at: int | None = None) -> Iterator[None]:
    """One transaction writing `object_id`, holding the object's lock across processes when the store has one;
    with `read_at` (`read_mark` before the use case read), `StaleRead` when another process changed the object
    since."""
    store = context.store
    with store.transaction():
        if isinstance(store, ObjectLocking):
            store.lock_object(object_id)
            if read_at is not None:
                now = context.memory.of(store, object_id).changed_seq  # committed events only: nothing written yet
                if now != read_at:
                    raise StaleRead(f"{object_id} was written by another process while this request decided "
                                    f"(event {read_at} -> {now})")
        yield


def serialized(context: Context, object_id: str, attempt: Callable[[], T], deadline_at: float | None = None) -> T:
    """`attempt()`, again as long as it raises `StaleRead` (another process wrote the object meanwhile), until
    `deadline_at` (`time.monotonic()`; by default the planning deadline from now): then `DeadlineError`."""
    deadline_at = deadline_from(context.planning) if deadline_at is None else deadline_at
    while True:
        try:
            return attempt()
        except StaleRead as exc:
            if time.monotonic() >= deadline_at:
                raise DeadlineError(f"planning: planning deadline of {context.planning.deadline_s:g} s exceeded "
                                    f"while other requests kept changing {object_id}; nothing was stored") from None
            log.info("%s: deciding again on what is stored now", exc)


class _ValStillRunning(Exception):
    """VAL did not answer within OVERLAP_WAIT_S of the write: roll it back and wait outside the store."""


def write_on_verdict(context: Context, object_id: str, planned: PlannedTurn,
                     check: Callable[[], CheckedPlan | None], write: Callable[[Callable[[], NewPlan]], T]) -> T:
    """A re-plan's write (see the module's note): `check()`, the store's checks of the new plan, runs while VAL
    checks it; then `write(new_plan)`, which calls `new_plan()` for the plan as VAL checked it once it has written
    what does not rest on it (inside the store's transaction: the overlap). `write` runs again when VAL was slower
    than `OVERLAP_WAIT_S`; VAL's runs stop when anything fails (no VAL process outlives the request)."""
    verdict = planned.verdict
    try:
        checks = check()
        with context.observer.span("val"):
            if not verdict.read_in_write:  # VAL's verdict before the write: the store is not held meanwhile
                _checked(verdict.outcome(None))

            def new_plan(wait_s: float | None) -> Callable[[], NewPlan]:
                return lambda: NewPlan(outcome=_checked(verdict.outcome(wait_s)), checks=checks,
                                       early=verdict.early_answer())

            try:
                return write(new_plan(OVERLAP_WAIT_S if verdict.read_in_write else None))
            except _ValStillRunning:
                log.info("VAL was slower than %.0f ms on %s's plan: the write waited for it outside the store",
                         OVERLAP_WAIT_S * 1000, object_id)
                _checked(verdict.outcome(None))
                return write(new_plan(None))
    except BaseException:
        verdict.cancel()
        raise


def _checked(outcome: PlanOutcome | None) -> PlanOutcome:
    """The plan as VAL checked it; `_ValStillRunning` while VAL runs, `DeadlineError` when the deadline passed
    (while planning or while VAL checked: the one place a re-plan's deadline is read)."""
    if outcome is None:
        raise _ValStillRunning()
    if outcome.status is PlanningStatus.TIMEOUT:
        raise DeadlineError(f"planning: {outcome.message}")
    return outcome

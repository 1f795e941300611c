"""What the service asks of its knowledge base, as protocols a backend implements (the SQLite/owlready2 store,
`knowledge_base.SqliteStore`, and the PostgreSQL store, `postgres.PostgresStore`), split by responsibility:

| protocol | what it offers |
|---|---|
| `Writes` | new ids, objects, states and perceptions, problems, plans, events, the execution cursor, idempotent responses; `transaction()`, the one unit of work |
| `Reads` | one record by id (cached), the latest problem and plan of an object, objects and events, counts |
| `PlanChecks` | a plan checked against its object ahead of its write (`check_plan` -> `CheckedPlan`) |
| `PlanJournal` | plans stored as one journal row each, written out as facts when they are read as facts (`settle`, `plans_to_write`) |
| `Export` | the TBox with the ABox as RDF: N-Triples lines, or bytes in a format |
| `Retention` | compaction of each object's history |
| `Inferences` | what a DL reasoner inferred, kept apart from the asserted facts |
| `KnowledgeStore` | all of them, and closing: what a backend must offer |
| `ObjectLocking`, `EventFeeding` | what a store shared by several service processes adds (PostgreSQL): an object's lock across processes, a feed of the events every process commits |

Records are the frozen dataclasses of `records`; ids are the readable IRI fragments of `names`, whatever the
backend. Nothing here names a backend's internals (worlds, storids, connections): a backend that keeps the facts
as rows or triples elsewhere implements the same protocols, and the store's tests run on every backend.

Guarantees every backend keeps:
- A write checks its whole input first: a refused one raises `ValidationError` naming the field, and nothing is
  written. Unknown ids read raise `NotFoundError`; every error is a `KBError`.
- Inside `transaction()` every write commits together at its end, or none does (an exception rolls back all).
- Records are immutable; a record once handed out reads back equal, across restarts too.
- A plan is answered at once by `add_plan`; its facts may be written out later (`plans_to_write`: when a reader
  of the facts needs them), but it is never lost once its transaction committed, and readers of the facts
  (`export_lines`, the reasoners' copy) see it.
- Every method is safe to call from several threads.
"""
from __future__ import annotations

from contextlib import AbstractContextManager
from typing import Any, Iterator, Protocol, Self, Sequence, runtime_checkable

from planhrc.model import ArticulatedObject, Atom, Perception

from .records import (ActionSpec, CheckedPlan, Compaction, Execution, StoredAction, StoredEvent, StoredPlan,
                      StoredProblem, StoredState)

MAX_SEQ = 2**63 - 1  # the largest event seq a caller may name (the largest SQLite or PostgreSQL bigint)
MAX_EVENTS_PAGE = 1000  # the most events one read of the log returns over HTTP (a page, or one poll of a stream)
FORMATS = ("xml", "turtle", "nt")  # RDF/XML, Turtle, N-Triples
HISTORY = ("current", "all")  # an export of each object's current ABox, or of every fact ever stored


@runtime_checkable
class Writes(Protocol):
    def transaction(self) -> AbstractContextManager[None]:
        """Every write inside the block is one transaction (nested blocks join the outermost one)."""
        ...

    def new_object_id(self) -> str:
        """A fresh object id `objN`; N is never handed out twice, even across restarts."""
        ...

    def create_object(self, obj: ArticulatedObject) -> None: ...

    def add_state(self, object_id: str, kind: str, atoms: frozenset[Atom],
                  link_orientations_deg: Sequence[float] | None = None) -> StoredState: ...

    def add_perception(self, perception: Perception) -> StoredState:
        """A perceived state from a perception validated and snapped where it entered (`model.perceive`)."""
        ...

    def add_problem(self, object_id: str, init_state_id: str, goal_state_id: str) -> StoredProblem: ...

    def add_plan(self, problem_id: str, planner: str, actions: Sequence[ActionSpec],
                 expected_states: Sequence[frozenset[Atom]], checked: CheckedPlan | None = None) -> StoredPlan:
        """Store a plan (checked again unless `checked` is the check of these very tuples)."""
        ...

    def add_event(self, object_id: str, kind: str, reason: str, data: dict[str, Any]) -> StoredEvent: ...

    def set_execution(self, object_id: str, execution: Execution) -> None: ...

    def remember_response(self, object_id: str, key: str, response: dict[str, Any]) -> None:
        """Remember the response to an idempotent request; the first response stored under a key wins."""
        ...


@runtime_checkable
class Reads(Protocol):
    def get_object(self, object_id: str) -> ArticulatedObject: ...

    def list_objects(self) -> tuple[ArticulatedObject, ...]:
        """Every object, in natural order of their ids."""
        ...

    def get_state(self, state_id: str) -> StoredState: ...

    def get_problem(self, problem_id: str) -> StoredProblem: ...

    def get_plan(self, plan_id: str) -> StoredPlan: ...

    def get_action(self, action_id: str) -> StoredAction: ...

    def latest_problem(self, object_id: str) -> StoredProblem | None: ...

    def latest_plan(self, object_id: str) -> StoredPlan | None: ...

    def list_events(self, object_id: str, after_seq: int = 0, limit: int | None = None) -> tuple[StoredEvent, ...]:
        """The object's events after `after_seq`, oldest first, at most `limit` (None: all)."""
        ...

    def get_execution(self, object_id: str) -> Execution: ...

    def recall_response(self, object_id: str, key: str) -> dict[str, Any] | None:
        """The response remembered under an idempotency key, or None (the object need not exist)."""
        ...

    def triple_count(self) -> int:
        """Facts stored (kept by every commit: no scan, no lock)."""
        ...

    def object_count(self) -> int:
        """Objects stored (kept by every commit: no scan, no lock)."""
        ...

    def revision(self) -> int:
        """A number that changes with every committed write, by any process the store is shared with (no scan:
        cheap enough to ask before every query): a reader that keeps something built from the store (the SPARQL
        graph) builds it again only when this changed."""
        ...


@runtime_checkable
class PlanChecks(Protocol):
    def check_plan(self, object_id: str, actions: Sequence[ActionSpec], expected_states: Sequence[frozenset[Atom]],
                   deadline_at: float | None = None, first_steps: int | None = None) -> CheckedPlan:
        """Every check `add_plan` makes, without the store's lock and without writing: a caller runs it beside
        other work (the service: while VAL checks the plan). Past `deadline_at` (`time.monotonic()`) it raises
        `DeadlineError`. With `first_steps`, only the checks of the first steps (`checks.check_plan`): the caller
        checks every later step with `check_steps` before it uses it."""
        ...

    def check_steps(self, object_id: str, actions: Sequence[ActionSpec], expected_states: Sequence[frozenset[Atom]],
                    first: int, last: int) -> None:
        """The checks of steps a_first .. a_last of a plan checked with `first_steps` (their actions and the expected
        states after them): `ValidationError` naming the field when one fails."""
        ...


@runtime_checkable
class PlanJournal(Protocol):
    def settle(self) -> None:
        """Write out every journalled plan's facts now (inside an open transaction: nothing, its plans are not
        committed yet)."""
        ...

    def plans_to_write(self) -> int:
        """Committed plans whose facts are not written yet (kept as their journal rows)."""
        ...


@runtime_checkable
class Export(Protocol):
    def export_lines(self, history: str = "current", object_ids: Sequence[str] | None = None) -> Iterator[str]:
        """TBox + ABox as N-Triples lines (`HISTORY`): the current ABox of `object_ids` (None: of every object),
        or every fact. Unknown objects are a `NotFoundError` before the first line."""
        ...

    def export(self, fmt: str = "xml", history: str = "current", object_ids: Sequence[str] | None = None) -> bytes:
        """The same as RDF in one of `FORMATS`."""
        ...

    def export_stream(self, fmt: str = "xml", history: str = "current",
                      object_ids: Sequence[str] | None = None) -> Iterator[str]:
        """The same in pieces, each written as the lines are read (what a response streams); the arguments are
        checked before the first piece."""
        ...

    def current_roots(self, object_id: str) -> tuple[str, ...]:
        """The ids the object's current ABox starts from: the object, its goal, its latest perceived state, the
        plan its execution follows (else its latest plan) and its latest problem. The current export is every
        fact reachable from them; records are immutable, so while these ids stay the same so does that export.
        An unknown object is a `NotFoundError`."""
        ...


@runtime_checkable
class Retention(Protocol):
    def compact(self, keep_perceived: int) -> Compaction:
        """Keep each object's current records and its last `keep_perceived` perceived states, delete the rest of
        its history, in one transaction."""
        ...


@runtime_checkable
class Inferences(Protocol):
    """Facts a DL reasoner inferred, as N-Triples lines under a scope (`"all"`, or an object's id): kept apart
    from the asserted facts, so that no export, read or reasoner mistakes them for what was stored."""

    def replace_inferred(self, scope: str, lines: Sequence[str]) -> int:
        """Replace every line kept under `scope` by `lines` in one transaction; how many are kept now."""
        ...

    def inferred_lines(self) -> Iterator[str]:
        """Every inferred line of every scope (a line kept under two scopes comes twice)."""
        ...


@runtime_checkable
class KnowledgeStore(Writes, Reads, PlanChecks, PlanJournal, Export, Retention, Inferences, Protocol):
    """What a backend must offer: every protocol above, and closing (the store is also its own context manager)."""

    def close(self) -> None: ...

    def __enter__(self) -> Self: ...

    def __exit__(self, *exc: object) -> None: ...


# -- what a store several service processes share adds (`postgres.replicas`) ---------------------------------
@runtime_checkable
class ObjectLocking(Protocol):
    def lock_object(self, object_id: str) -> None:
        """Hold the object's lock, across every process on the store, until the open transaction ends (inside
        `transaction()` only): the object's writes are one at a time, as the service's in-process locks make them
        within one process."""
        ...


class EventFeed(Protocol):
    def wait(self, timeout_s: float) -> list[tuple[str, int]]:
        """(object id, seq) of every event committed (by any process) since the last call, waiting up to
        `timeout_s` for one; `UnavailableError` when the feed lost its connection."""
        ...

    def close(self) -> None: ...


@runtime_checkable
class EventFeeding(Protocol):
    def event_feed(self) -> EventFeed:
        """A feed of the events every process commits; the caller closes it (one per process is enough)."""
        ...

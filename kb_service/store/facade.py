"""The store's core (`StoreCore`): what a store does, the same on every engine. Its life cycle (`close`,
`transaction()` over the engine's unit of work, `work.UnitOfWork`); each write handed to the shared writes
(`writes.RecordWriter`) and each read of a record to its cache, under the store's guard; the side tables' rows
checked (`checks`) and written in the unit of work; compaction's steps (the roots read, the kept plans written out,
each object compacted in one transaction, the caches dropped); the export in every format from the engine's
N-Triples lines.

An engine's store class (`knowledge_base.SqliteStore`, `postgres.PostgresStore`) subclasses it and gives it its
unit of work, records, writes, plan journal and side tables (each the engine's SQL), and adds what only it has:
how an object's history is compacted and exported, its journal's settling, and its own extras.
"""
from __future__ import annotations

from abc import ABC, abstractmethod
from contextlib import AbstractContextManager, contextmanager
from dataclasses import replace
from typing import Any, Iterable, Iterator, Protocol, Self, Sequence

from planhrc.model import ArticulatedObject, Atom, Perception
from planhrc.transition import frozen_states

from .acting import acting_client
from .cache import R, RecordCache
from .checks import (check_event, check_events_page, check_execution, check_export, check_inferred, check_keep_perceived,
                     check_plan, check_response, check_steps)
from .errors import NotFoundError, ValidationError
from .export import export_pieces
from .journal import encode_body
from .names import ABOX_IRI, TBOX_IRI
from .records import (ActionSpec, CheckedPlan, Compaction, Execution, StoredAction, StoredEvent, StoredPlan, StoredProblem,
                      StoredState)
from .unit import RecordsOfWrites
from .work import UnitOfWork
from .writes import RecordWriter

PREFIXES = {"planhrc": TBOX_IRI, "abox": ABOX_IRI, "owl": "http://www.w3.org/2002/07/owl#"}


class RecordsOfStore(RecordsOfWrites, Protocol):
    """A backend's records, as the store reads them."""

    plans: RecordCache[StoredPlan]
    actions: RecordCache[StoredAction]

    def object_ids(self) -> list[str]: ...

    def clear(self) -> None: ...


class JournalOfStore(Protocol):
    """A backend's plan journal, as the core uses it (`backlog.PlanBacklog`, `postgres.journal.PgJournal`)."""

    def settle(self, plan_ids: Iterable[str] | None = None) -> None: ...

    def drop(self, object_id: str, keep: Iterable[str]) -> int: ...


class EventTable(Protocol):
    """The event log's rows (`events.EventLog`, `postgres.tables.PgEventLog`)."""

    def append(self, object_id: str, kind: str, reason: str, text: str, client: str | None) -> StoredEvent: ...

    def after(self, object_id: str, after_seq: int = 0, limit: int | None = None) -> tuple[StoredEvent, ...]: ...


class ExecutionTable(Protocol):
    """The execution cursor's rows (`execution.ExecutionCursor`, `postgres.tables.PgExecutionCursor`)."""

    def read(self, object_id: str) -> Execution: ...

    def write(self, object_id: str, execution: Execution) -> None: ...


class ResponseTable(Protocol):
    """Idempotent responses' rows (`responses.ResponseMemory`, `postgres.tables.PgResponseMemory`)."""

    def recall(self, object_id: str, key: str) -> dict[str, Any] | None: ...

    def remember(self, object_id: str, key: str, text: str) -> None: ...


class InferredTable(Protocol):
    """What a reasoner inferred (`inferred.InferredFacts`, `postgres.inferred.PgInferred`)."""

    def replace(self, scope: str, lines: Sequence[str]) -> int: ...

    def lines(self) -> Iterable[str]: ...


class StoreCore(ABC):
    """What a store does on every engine (see the module's docstring)."""

    _unit: UnitOfWork
    _guard: AbstractContextManager[None]
    _records: RecordsOfStore
    _writes: RecordWriter
    _journal: JournalOfStore
    _events: EventTable
    _execution: ExecutionTable
    _responses: ResponseTable
    _inferred: InferredTable

    # -- life cycle -------------------------------------------------------------------------------------------
    def close(self) -> None:
        with self._unit.lock:  # the journalled plans stay rows: they are the plans, in the store's database
            if not self._unit.closed:
                self._unit.close()

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @contextmanager
    def transaction(self) -> Iterator[None]:
        with self._guard, self._unit.transaction():
            yield

    def triple_count(self) -> int:
        self._unit.check_open()
        return self._unit.triples

    def object_count(self) -> int:
        self._unit.check_open()
        return self._unit.objects

    # -- what an engine supplies ------------------------------------------------------------------------------

    @abstractmethod
    def _latest_id(self, object_id: str, noun: str) -> str | None:
        """The newest record of a kind of the object (its counter), or None: the backend's."""

    @abstractmethod
    def _roots(self, object_id: str) -> list[str]:
        """`roots.current_roots` of the object on the backend's connection, the guard held: the backend's."""

    @abstractmethod
    def export_lines(self, history: str = "current", object_ids: Sequence[str] | None = None) -> Iterator[str]:
        """The export's lines (`history`, `object_ids`: as `_export_ids` checks them): the backend's."""

    def current_roots(self, object_id: str) -> tuple[str, ...]:
        with self._guard:
            self._records.info(object_id)
            return tuple(self._roots(object_id))

    def _current_names(self, object_ids: Sequence[str]) -> list[str]:
        """The roots of these objects' current ABoxes, one list (the plans an export of them shows among them)."""
        with self._guard:
            return [name for oid in object_ids for name in self._roots(oid)]

    def _export_ids(self, history: str, object_ids: Sequence[str] | None) -> list[str] | None:
        """The export's arguments checked; the objects a current export shows (each known), None for the whole
        history."""
        check_export(history, object_ids)
        if history != "current":
            return None
        with self._guard:
            ids = self._records.object_ids() if object_ids is None else list(object_ids)
            for oid in ids:
                self._records.info(oid)
        return ids

    # -- writes -----------------------------------------------------------------------------------------------
    def new_object_id(self) -> str:
        with self._guard:
            return self._writes.new_object_id()

    def create_object(self, obj: ArticulatedObject) -> None:
        with self._guard:
            self._writes.create_object(obj)

    def add_state(self, object_id: str, kind: str, atoms: frozenset[Atom],
                  link_orientations_deg: Sequence[float] | None = None) -> StoredState:
        with self._guard:
            return self._writes.add_state(object_id, kind, atoms, link_orientations_deg)

    def add_perception(self, perception: Perception) -> StoredState:
        with self._guard:
            return self._writes.add_perception(perception)

    def add_problem(self, object_id: str, init_state_id: str, goal_state_id: str) -> StoredProblem:
        with self._guard:
            return self._writes.add_problem(object_id, init_state_id, goal_state_id)

    def add_plan(self, problem_id: str, planner: str, actions: Sequence[ActionSpec],
                 expected_states: Sequence[frozenset[Atom]], checked: CheckedPlan | None = None) -> StoredPlan:
        with self._guard:
            return self._writes.add_plan(problem_id, planner, actions, expected_states, checked)

    def check_plan(self, object_id: str, actions: Sequence[ActionSpec], expected_states: Sequence[frozenset[Atom]],
                   deadline_at: float | None = None, first_steps: int | None = None) -> CheckedPlan:
        with self._guard:  # only to look the object up: the checks read nothing else
            info = self._records.info(object_id, "object_id")
        checked = check_plan(info, tuple(actions), frozen_states(expected_states), deadline_at, first_steps)
        # the journal row's body too, here, outside the store's lock: for a large plan the write would hold the
        # lock every object's write needs for most of a second making it (`journal.encode_body`)
        return replace(checked, journal_body=encode_body(checked.actions, checked.expected_states))

    def check_steps(self, object_id: str, actions: Sequence[ActionSpec], expected_states: Sequence[frozenset[Atom]],
                    first: int, last: int) -> None:
        with self._guard:
            info = self._records.info(object_id, "object_id")
        check_steps(info, tuple(actions), frozen_states(expected_states), first, last)

    def _checked_execution(self, object_id: str, execution: Execution) -> str:
        """Check a new execution of an object (with the store's guard held); the object's id."""
        ident = self._records.info(object_id, "object_id").obj.ident
        if not isinstance(execution, Execution):
            raise ValidationError(f"execution: expected an Execution, got {type(execution).__name__}")
        plan = None
        if execution.plan_id is not None:
            try:
                plan = self._records.plans.get(execution.plan_id)
            except NotFoundError:
                raise ValidationError(f"execution.plan_id: no plan {execution.plan_id!r}") from None
        check_execution(ident, execution, plan)
        return ident

    # -- the side tables --------------------------------------------------------------------------------------
    def add_event(self, object_id: str, kind: str, reason: str, data: dict[str, Any]) -> StoredEvent:
        with self._guard:
            ident = self._records.info(object_id, "object_id").obj.ident
            text = check_event(kind, reason, data)
            client = acting_client()
            return self._unit.write(lambda: self._events.append(ident, kind, reason, text, client))

    def list_events(self, object_id: str, after_seq: int = 0, limit: int | None = None) -> tuple[StoredEvent, ...]:
        check_events_page(after_seq, limit)
        with self._guard:
            return self._events.after(self._records.info(object_id).obj.ident, after_seq, limit)

    def set_execution(self, object_id: str, execution: Execution) -> None:
        with self._guard:
            ident = self._checked_execution(object_id, execution)
            self._unit.write(lambda: self._execution.write(ident, execution))

    def get_execution(self, object_id: str) -> Execution:
        with self._guard:
            return self._execution.read(self._records.info(object_id).obj.ident)

    def remember_response(self, object_id: str, key: str, response: dict[str, Any]) -> None:
        with self._guard:
            text = check_response(key, response)
            self._unit.write(lambda: self._responses.remember(object_id, key, text))

    def recall_response(self, object_id: str, key: str) -> dict[str, Any] | None:
        with self._guard:
            return self._responses.recall(object_id, key)

    def replace_inferred(self, scope: str, lines: Sequence[str]) -> int:
        checked = check_inferred(scope, lines)
        with self._guard:
            return self._unit.write(lambda: self._inferred.replace(scope, checked))

    def inferred_lines(self) -> Iterator[str]:
        with self._guard:
            return iter(list(self._inferred.lines()))

    # -- retention --------------------------------------------------------------------------------------------
    def compact(self, keep_perceived: int) -> Compaction:
        keep = check_keep_perceived(keep_perceived)
        with self._guard:
            objects = self._records.object_ids()
            shared = {oid: sorted(self._records.info(oid).shared_atom_name.values()) for oid in objects}
            roots = {oid: self._roots(oid) for oid in objects}
            # the plans kept are written out (the walk below reads their triples); the others' rows are dropped
            self._journal.settle([name for names in roots.values() for name in names])

            def fill() -> Compaction:
                if not self._may_compact():
                    return Compaction(0, 0, 0)
                individuals = triples = 0
                for oid in objects:
                    i, t = self._compact_object(oid, roots[oid], shared[oid], keep)
                    individuals, triples = individuals + i, triples + t
                self._unit.pending_triples -= triples
                return Compaction(len(objects), individuals, triples)

            result = self._unit.write(fill)
            self._records.clear()  # records of deleted individuals must not be served from memory
            return result

    def _may_compact(self) -> bool:
        """Whether this process compacts now (inside compaction's transaction): the engine's, yes by default."""
        return True

    @abstractmethod
    def _compact_object(self, object_id: str, roots: list[str], shared: list[str], keep: int) -> tuple[int, int]:
        """Drop what retention does not keep of one object, its journalled plans but `roots` included (inside
        compaction's transaction); (records, triples) deleted: the engine's."""

    # -- reads ------------------------------------------------------------------------------------------------
    def get_object(self, object_id: str) -> ArticulatedObject:
        with self._guard:
            return self._records.info(object_id).obj

    def list_objects(self) -> tuple[ArticulatedObject, ...]:
        with self._guard:
            return tuple(self._records.info(ident).obj for ident in self._records.object_ids())

    def get_state(self, state_id: str) -> StoredState:
        return self._get(self._records.states, state_id)

    def get_problem(self, problem_id: str) -> StoredProblem:
        return self._get(self._records.problems, problem_id)

    def get_plan(self, plan_id: str) -> StoredPlan:
        return self._get(self._records.plans, plan_id)

    def get_action(self, action_id: str) -> StoredAction:
        return self._get(self._records.actions, action_id)

    def _get(self, records: RecordCache[R], ident: str) -> R:
        with self._guard:
            return records.get(ident)

    def latest_problem(self, object_id: str) -> StoredProblem | None:
        return self._latest(self._records.problems, object_id)

    def latest_plan(self, object_id: str) -> StoredPlan | None:
        return self._latest(self._records.plans, object_id)

    def _latest(self, records: RecordCache[R], object_id: str) -> R | None:
        with self._guard:
            ident = self._latest_id(self._records.info(object_id).obj.ident, records.noun)
            return records.get(ident) if ident else None

    # -- export -----------------------------------------------------------------------------------------------
    def export(self, fmt: str = "xml", history: str = "current", object_ids: Sequence[str] | None = None) -> bytes:
        return "".join(self.export_stream(fmt, history, object_ids)).encode("utf-8")

    def export_stream(self, fmt: str = "xml", history: str = "current",
                      object_ids: Sequence[str] | None = None) -> Iterator[str]:
        """The export in pieces, each written as the store's lines are read: what a response streams."""
        check_export(history, object_ids, fmt)
        return export_pieces(self.export_lines(history, object_ids), fmt, PREFIXES)

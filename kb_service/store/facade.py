"""What every backend's store class does the same way (`StoreFacade`): each write handed to the shared writes
(`writes.RecordWriter`) and each read of a record to its cache, under the store's guard; the checks of a new execution;
the export in every format from the backend's N-Triples lines.

A backend's class (`knowledge_base.SqliteStore`, `postgres.PostgresStore`) subclasses it, gives it its guard, records
and writes, and adds what differs: its transactions, side tables, plan journal, retention and export lines.
"""
from __future__ import annotations

from contextlib import AbstractContextManager
from dataclasses import replace
from typing import Iterator, Protocol, Sequence

from planhrc.model import ArticulatedObject, Atom, Perception
from planhrc.transition import frozen_states

from .cache import R, RecordCache
from .checks import check_export, check_plan, check_steps
from .errors import NotFoundError, ValidationError
from .execution import ExecutionCursor
from .export import export_pieces
from .journal import encode_body
from .names import ABOX_IRI, TBOX_IRI
from .records import ActionSpec, CheckedPlan, Execution, StoredAction, StoredPlan, StoredProblem, StoredState
from .unit import RecordsOfWrites
from .writes import RecordWriter

PREFIXES = {"planhrc": TBOX_IRI, "abox": ABOX_IRI, "owl": "http://www.w3.org/2002/07/owl#"}


class RecordsOfStore(RecordsOfWrites, Protocol):
    """A backend's records, as the store reads them."""

    plans: RecordCache[StoredPlan]
    actions: RecordCache[StoredAction]

    def object_ids(self) -> list[str]: ...


class StoreFacade:
    """The writes and reads of records common to every backend (see the module's docstring)."""

    _guard: AbstractContextManager[None]
    _records: RecordsOfStore
    _writes: RecordWriter

    def _latest_id(self, object_id: str, noun: str) -> str | None:
        """The newest record of a kind of the object (its counter), or None: the backend's."""
        raise NotImplementedError

    def _roots(self, object_id: str) -> list[str]:
        """`roots.current_roots` of the object on the backend's connection, the guard held: the backend's."""
        raise NotImplementedError

    def export_lines(self, history: str = "current", object_ids: Sequence[str] | None = None) -> Iterator[str]:
        raise NotImplementedError

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
        ExecutionCursor.check(ident, execution, plan)
        return ident

    # -- reads ------------------------------------------------------------------------------------------------
    def get_object(self, object_id: str) -> ArticulatedObject:
        with self._guard:
            return self._records.info(object_id).obj

    def list_objects(self) -> tuple[ArticulatedObject, ...]:
        with self._guard:
            return tuple(self._records.info(ident).obj for ident in self._records.object_ids())

    def get_state(self, state_id: str) -> StoredState:
        with self._guard:
            return self._records.states.get(state_id)

    def get_problem(self, problem_id: str) -> StoredProblem:
        with self._guard:
            return self._records.problems.get(problem_id)

    def get_plan(self, plan_id: str) -> StoredPlan:
        with self._guard:
            return self._records.plans.get(plan_id)

    def get_action(self, action_id: str) -> StoredAction:
        with self._guard:
            return self._records.actions.get(action_id)

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

"""The store's identity map (`IdentityMap`), written once for every engine: the objects' infos and one cache per kind
of record (`cache.RecordCache`), dropped after a rollback or when they grow past `CACHE_LIMIT`, and the order a
record is looked for in: a plan whose triples are not written yet is read from its journal row, which is looked up
first (a row turns into triples in one transaction, so one or the other is found), else from the triples.

An engine (`reads.SqliteRecords`, `postgres.records.PgRecords`) supplies only the reads: its journal rows, the
triples of each kind, what it caches besides the records. The map is a `TransactionListener` of the engine's unit
of work; every method is called with the store's lock held.
"""
from __future__ import annotations

from abc import ABC, abstractmethod

from planhrc.model import ArticulatedObject

from .cache import RecordCache
from .checks import ObjectInfo
from .errors import NotFoundError, ValidationError
from .journal import JournalEntry
from .records import StoredAction, StoredPlan, StoredProblem, StoredState

# Records (and an engine's own lookups) cached past this many entries are dropped after a commit (they are read
# again on demand), so the service's memory stays flat as the history grows.
CACHE_LIMIT = 5_000


class IdentityMap(ABC):
    """The records of one store read or written so far, cached (see the module's docstring)."""

    def __init__(self) -> None:
        self.objects: dict[str, ObjectInfo] = {}
        self.states = RecordCache("state", StoredState, self._load_state)
        self.problems = RecordCache("problem", StoredProblem, self._read_problem)
        self.plans = RecordCache("plan", StoredPlan, self._load_plan)
        self.actions = RecordCache("action", StoredAction, self._load_action)

    # -- the map's life -------------------------------------------------------------------------------------
    def clear(self) -> None:
        """Forget every cached record (and what the engine caches besides)."""
        self._forget()
        self.objects.clear()
        for cache in (self.states, self.problems, self.plans, self.actions):
            cache.clear()

    def committed(self) -> None:
        if self._cached() > CACHE_LIMIT:
            self.clear()

    def rolled_back(self) -> None:
        self.clear()  # records cached during a rolled-back transaction were never stored

    def put_entry(self, entry: JournalEntry) -> StoredPlan:
        """Cache a journalled plan's records (its actions and expected states); the plan's."""
        return entry.cache(self.plans, self.actions, self.states)

    # -- objects --------------------------------------------------------------------------------------------
    def info(self, object_id: str, field: str | None = None) -> ObjectInfo:
        """The object's info, cached; unknown -> ValidationError naming `field` (writes) or NotFoundError
        (reads)."""
        info = self.objects.get(object_id) if isinstance(object_id, str) else None
        if info is None and isinstance(object_id, str):
            obj = self._read_object(object_id)
            if obj is not None:
                info = self.objects[object_id] = ObjectInfo(obj)
        if info is None:
            if field is None:
                raise NotFoundError(f"object_id: no object {object_id!r}")
            raise ValidationError(f"{field}: no object {object_id!r}")
        return info

    # -- loaders of the cached kinds: the journal first, then the triples -----------------------------------
    def _load_state(self, state_id: str) -> StoredState | None:
        object_id, _, number = state_id.rpartition("_state_")
        if number.isdigit():
            entry = self._entry_of_state(object_id, int(number))
            if entry is not None:
                self.put_entry(entry)
                return self.states.get(state_id)
        return self._read_state(state_id)

    def _load_action(self, action_id: str) -> StoredAction | None:
        plan_id, _, step = action_id.rpartition("_a")
        if step.isdigit():
            entry = self._entry(plan_id)
            if entry is not None:
                self.put_entry(entry)
                return self.actions.get(action_id)
        return self._read_action(action_id)

    def _load_plan(self, plan_id: str) -> StoredPlan | None:
        entry = self._entry(plan_id)
        if entry is not None:
            return self.put_entry(entry)
        return self._read_plan(plan_id)

    # -- what an engine supplies ------------------------------------------------------------------------------
    @abstractmethod
    def object_ids(self) -> list[str]:
        """Every stored object's id, in natural order."""

    @abstractmethod
    def _cached(self) -> int:
        """How many entries the map holds, as the engine counts them (compared with `CACHE_LIMIT`)."""

    @abstractmethod
    def _forget(self) -> None:
        """Forget what the engine caches besides the records."""

    @abstractmethod
    def _entry(self, plan_id: str) -> JournalEntry | None:
        """The journal row of a plan, if the plan is in the journal."""

    @abstractmethod
    def _entry_of_state(self, object_id: str, number: int) -> JournalEntry | None:
        """The journal row of the plan whose expected states include the object's state `number`, if one is."""

    @abstractmethod
    def _read_object(self, ident: str) -> ArticulatedObject | None: ...

    @abstractmethod
    def _read_state(self, state_id: str) -> StoredState | None: ...

    @abstractmethod
    def _read_problem(self, problem_id: str) -> StoredProblem | None: ...

    @abstractmethod
    def _read_action(self, action_id: str) -> StoredAction | None: ...

    @abstractmethod
    def _read_plan(self, plan_id: str) -> StoredPlan | None: ...

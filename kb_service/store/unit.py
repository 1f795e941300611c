"""What the backend-neutral writes (`writes`, `triples`) ask of a backend: its unit of work over the ABox's
triples (`AboxWriter`), a batch of triples it flushes (`TripleBatch`), its records (`RecordsOfWrites`) and what
stores a new plan (`PlanAdopter`).

The SQLite ABox (`abox.Abox`, triples in owlready2's quad tables) and the PostgreSQL one
(`postgres.session.Session`, triples as rows) implement them, so an object, a state, a problem and a plan are the
same triples under the same names on every backend, written by the same code.
"""
from __future__ import annotations

from typing import Any, Callable, Protocol, Sequence, TypeVar

from .cache import RecordCache
from .checks import ObjectInfo
from .journal import JournalEntry
from .records import StoredPlan, StoredProblem, StoredState

T = TypeVar("T")
BatchT = TypeVar("BatchT", bound="TripleBatch")


class TripleBatch(Protocol):
    """Triples collected during a write, individuals by their IRI fragment and properties by their TBox name."""

    shared: set[str]  # object-level predicate individuals this batch creates

    def individual(self, name: str, *classes: str) -> str: ...

    def rel(self, s: str, prop: str, o: str) -> None: ...

    def data(self, s: str, prop: str, value: Any) -> None: ...


class AboxNames(Protocol):
    """Which individuals exist, and the store's counters (what `triples` reads while it builds a batch)."""

    def existing(self, names: Sequence[str]) -> list[str]:
        """Those of `names` that are stored individuals, in order."""
        ...

    def has_class(self, name: str, cls: str) -> bool:
        """Whether the individual `name` is stored with the TBox class `cls`."""
        ...

    def next_counter(self, name: str) -> int: ...

    def reserve_counter(self, name: str, count: int) -> int:
        """Take `count` consecutive values of a counter at once; the first."""
        ...


class AboxWriter(AboxNames, Protocol[BatchT]):
    """A backend's unit of work over the ABox."""

    def batch(self) -> BatchT: ...

    def flush(self, batch: BatchT) -> None:
        """Write the batch's triples inside the open transaction."""
        ...

    def note_object(self) -> None:
        """The open transaction creates one more object (the store's count follows its commit)."""
        ...

    def write(self, fill: Callable[[], T]) -> T:
        """Run `fill()` in one transaction (or inside the open one); roll back on any error."""
        ...


class RecordsOfWrites(Protocol):
    """The records a write checks against and caches."""

    objects: dict[str, ObjectInfo]
    states: RecordCache[StoredState]
    problems: RecordCache[StoredProblem]

    def info(self, object_id: str, field: str | None = None) -> ObjectInfo: ...


class PlanAdopter(Protocol):
    """Stores a new plan inside the open transaction (a journal row, written out as triples when they are read)."""

    def adopt(self, entry: JournalEntry, body: bytes | None = None) -> StoredPlan:
        """`body`: the row's body made before the write (`journal.encode_body`), else made here."""
        ...

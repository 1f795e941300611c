"""The SQLite backend of the knowledge base (`SqliteStore`): the ABox (`abox`,
`reads`, `writes`, `backlog`) with the event log (`events`), the execution cursor (`execution`) and idempotent
responses (`responses`) in the same SQLite database, retention (`retention`) and the RDF export (`export`). It
implements `interface.KnowledgeStore`; what every backend does alike (the writes and reads of records) is
the core's (`facade.StoreCore`): this engine gives it the parts above.

Every public method takes the store's lock (one RLock) and refuses a closed store; the parts it puts together
are called with that lock held. Each write checks its input completely before anything is written; every write
is one transaction, and `transaction()` makes several writes one (all of them commit, or none does).
"""
from __future__ import annotations

import logging
import os
import sqlite3
import threading
from pathlib import Path
from typing import Iterator, Sequence

from .abox import Abox
from .backlog import PlanBacklog
from .errors import KBError
from .events import EventLog
from .execution import ExecutionCursor
from .facade import StoreCore
from .export import ntriples
from .inferred import InferredFacts
from .interface import MAX_EVENTS_PAGE, MAX_SEQ
from .journal import JournalTable
from .names import ABOX_IRI
from .owl import World
from .reads import SqliteRecords
from .responses import ResponseMemory
from .retention import compact_object
from .roots import SQLITE, current_roots
from .writes import RecordWriter

__all__ = ["MAX_EVENTS_PAGE", "MAX_SEQ", "SqliteStore"]

log = logging.getLogger(__name__)


class SqliteStore(StoreCore):
    """TBox + ABox in one owlready2 World on SQLite (a file, or memory when `path` is None), with the service's
    side tables; thread safe."""

    _records: SqliteRecords
    _journal: PlanBacklog

    def __init__(self, path: str | None, tbox_path: Path | str) -> None:
        abox = self._unit = self._abox = Abox(path, tbox_path)
        self._guard = abox.guard
        try:
            journal = JournalTable(abox.q)
            self._records = SqliteRecords(abox, journal)
            self._journal = PlanBacklog(abox, self._records, journal)
            abox.listen(self._journal, self._records)
            self._writes = RecordWriter(abox, self._records, self._journal)
            self._events = EventLog(abox.q)
            self._execution = ExecutionCursor(abox.q)
            self._responses = ResponseMemory(abox.q)
            self._inferred = InferredFacts(abox.q)
            abox.q.commit()
        except Exception:
            abox.q.abandon()
            raise

    # -- what only this backend has (the reasoners, `planhrc compact --vacuum`) ---------------------------------
    @property
    def lock(self) -> threading.RLock:
        return self._abox.lock

    @property
    def tbox_path(self) -> Path:
        return self._abox.tbox_path

    @property
    def world(self) -> World:
        """The owlready2 world (read it under `lock`; reasoners work on copies), with every plan written out."""
        self._journal.settle()
        return self._abox.world

    def ntriples(self) -> bytes:
        """TBox + ABox as owlready2 serialises the world in N-Triples."""
        self._journal.settle()
        with self._guard:
            self._journal.settle()  # a plan adopted meanwhile
            return self._abox.q.ntriples()

    def rewrite(self) -> tuple[int, int]:
        """Rewrite the store's file (`QuadStore.rewrite`): the space compaction freed goes back to the file system,
        and a file made with 32 KiB pages gets 4 KiB ones. Only on a store no other process has open. The file's
        size in bytes (log included) before and after."""
        with self._guard:
            path = self._abox.path
            if not path:
                raise KBError("store: an in-memory store has no file to rewrite")
            before = _file_bytes(path)
            self._abox.q.rewrite()
            return before, _file_bytes(path)

    # -- reads (the rest: `facade.StoreCore`) ---------------------------------------------------------------
    def _latest_id(self, object_id: str, noun: str) -> str | None:
        return self._abox.latest(object_id, noun)

    # -- the plan journal -------------------------------------------------------------------------------------
    def settle(self) -> None:
        self._journal.settle()
        with self._guard:
            self._journal.settle()  # a plan adopted meanwhile

    def plans_to_write(self) -> int:
        self._abox.check_open()
        return len(self._journal)

    # -- retention (the steps: `facade.StoreCore.compact`) ---------------------------------------------------
    def _compact_object(self, object_id: str, roots: list[str], shared: list[str], keep: int) -> tuple[int, int]:
        abox = self._abox
        dropped = self._journal.drop(object_id, roots)
        individuals, triples = compact_object(abox.q.db, ABOX_IRI, abox.c, abox.t, object_id, shared, keep)
        return dropped + individuals, triples

    # -- export -----------------------------------------------------------------------------------------------
    def export_lines(self, history: str = "current", object_ids: Sequence[str] | None = None) -> Iterator[str]:
        """A file store is read on a connection of the export's own, without the store's lock."""
        ids = self._export_ids(history, object_ids)
        # the export reads triples: the journalled plans it shows are written out first (each object's current
        # plan, or with the history every one)
        self._journal.settle(None if ids is None else self._current_names(ids))
        with self._guard:
            self._journal.settle(None if ids is None else self._current_names(ids))  # adopted meanwhile
            abox = self._abox
            reader = abox.q.reader()
            if reader is None:  # an in-memory store: read on its connection, under its lock, at once
                return iter(list(ntriples(abox.q.db, ABOX_IRI, abox.c, abox.t["staticFactOf"], ids)))
        return self._read_lines(reader, ids)

    def _read_lines(self, reader: sqlite3.Connection, ids: list[str] | None) -> Iterator[str]:
        try:
            yield from ntriples(reader, ABOX_IRI, self._abox.c, self._abox.t["staticFactOf"], ids)
        finally:
            reader.close()

    def revision(self) -> int:
        self._abox.check_open()
        return self._abox.revision

    def _roots(self, object_id: str) -> list[str]:
        return current_roots(self._abox.q.db, SQLITE, object_id)


def _file_bytes(path: str) -> int:
    return sum(os.path.getsize(p) for p in (path, path + "-wal") if os.path.exists(p))

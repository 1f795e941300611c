"""The SQLite backend of the knowledge base (`SqliteStore`): the ABox (`abox`,
`reads`, `writes`, `backlog`) with the event log (`events`), the execution cursor (`execution`) and idempotent
responses (`responses`) in the same SQLite database, retention (`retention`) and the RDF export (`export`). It
implements `interface.KnowledgeStore`; what every backend does alike (the writes and reads of records) is
`facade.StoreFacade`'s.

Every public method takes the store's lock (one RLock) and refuses a closed store; the parts it puts together
are called with that lock held. Each write checks its input completely before anything is written; every write
is one transaction, and `transaction()` makes several writes one (all of them commit, or none does).
"""
from __future__ import annotations

import logging
import os
import sqlite3
import threading
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Iterator, Self, Sequence

from .abox import Abox
from .acting import acting_client
from .backlog import PlanBacklog
from .checks import check_events_page, check_keep_perceived
from .errors import KBError
from .events import EventLog
from .execution import ExecutionCursor
from .facade import StoreFacade
from .export import ntriples
from .inferred import InferredFacts
from .interface import MAX_EVENTS_PAGE, MAX_SEQ
from .journal import JournalTable
from .names import ABOX_IRI
from .owl import World
from .reads import SqliteRecords
from .records import Compaction, Execution, StoredEvent
from .responses import ResponseMemory
from .retention import compact_object
from .roots import SQLITE, current_roots
from .writes import RecordWriter

__all__ = ["MAX_EVENTS_PAGE", "MAX_SEQ", "SqliteStore"]

log = logging.getLogger(__name__)


class SqliteStore(StoreFacade):
    """TBox + ABox in one owlready2 World on SQLite (a file, or memory when `path` is None), with the service's
    side tables; thread safe."""

    _records: SqliteRecords

    def __init__(self, path: str | None, tbox_path: Path | str) -> None:
        abox = self._abox = Abox(path, tbox_path)
        self._guard = abox.guard
        try:
            journal = JournalTable(abox.q)
            self._records = SqliteRecords(abox, journal)
            self._backlog = PlanBacklog(abox, self._records, journal)
            abox.listen(self._backlog, self._records)
            self._writes = RecordWriter(abox, self._records, self._backlog)
            self._events = EventLog(abox.q)
            self._execution = ExecutionCursor(abox.q)
            self._responses = ResponseMemory(abox.q)
            self._inferred = InferredFacts(abox.q)
            abox.q.commit()
        except Exception:
            abox.q.abandon()
            raise

    # -- life cycle -------------------------------------------------------------------------------------------
    def close(self) -> None:
        with self._abox.lock:  # the journalled plans stay rows: they are the plans, in the file
            if not self._abox.closed:
                self._abox.close()

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @contextmanager
    def transaction(self) -> Iterator[None]:
        with self._guard, self._abox.transaction():
            yield

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
        self._backlog.settle()
        return self._abox.world

    def ntriples(self) -> bytes:
        """TBox + ABox as owlready2 serialises the world in N-Triples."""
        self._backlog.settle()
        with self._guard:
            self._backlog.settle()  # a plan adopted meanwhile
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

    # -- writes (the rest: `facade.StoreFacade`) ------------------------------------------------------------
    def add_event(self, object_id: str, kind: str, reason: str, data: dict[str, Any]) -> StoredEvent:
        with self._guard:
            ident = self._records.info(object_id, "object_id").obj.ident
            text = self._events.check(kind, reason, data)
            client = acting_client()
            return self._abox.write(lambda: self._events.append(ident, kind, reason, text, client))

    def set_execution(self, object_id: str, execution: Execution) -> None:
        with self._guard:
            ident = self._checked_execution(object_id, execution)
            self._abox.write(lambda: self._execution.write(ident, execution))

    def remember_response(self, object_id: str, key: str, response: dict[str, Any]) -> None:
        with self._guard:
            text = self._responses.check(key, response)
            self._abox.write(lambda: self._responses.remember(object_id, key, text))

    # -- reads (the rest: `facade.StoreFacade`) -------------------------------------------------------------
    def _latest_id(self, object_id: str, noun: str) -> str | None:
        return self._abox.latest(object_id, noun)

    def list_events(self, object_id: str, after_seq: int = 0, limit: int | None = None) -> tuple[StoredEvent, ...]:
        check_events_page(after_seq, limit)
        with self._guard:
            return self._events.after(self._records.info(object_id).obj.ident, after_seq, limit)

    def get_execution(self, object_id: str) -> Execution:
        with self._guard:
            return self._execution.read(self._records.info(object_id).obj.ident)

    def recall_response(self, object_id: str, key: str) -> dict[str, Any] | None:
        with self._guard:
            return self._responses.recall(object_id, key)

    def triple_count(self) -> int:
        self._abox.check_open()
        return self._abox.triples

    def object_count(self) -> int:
        self._abox.check_open()
        return self._abox.objects

    # -- the plan journal -------------------------------------------------------------------------------------
    def settle(self) -> None:
        self._backlog.settle()
        with self._guard:
            self._backlog.settle()  # a plan adopted meanwhile

    def plans_to_write(self) -> int:
        self._abox.check_open()
        return len(self._backlog)

    # -- retention --------------------------------------------------------------------------------------------
    def compact(self, keep_perceived: int) -> Compaction:
        keep = check_keep_perceived(keep_perceived)
        with self._guard:
            abox = self._abox
            objects = self._records.object_ids()
            shared = {oid: sorted(self._records.info(oid).shared_atom_name.values()) for oid in objects}
            roots = {oid: self._roots(oid) for oid in objects}
            # the plans kept are written out (the walk below reads their triples); the others' rows are dropped
            self._backlog.settle(name for names in roots.values() for name in names)

            def fill() -> Compaction:
                individuals = triples = 0
                for oid in objects:
                    individuals += self._backlog.drop(oid, roots[oid])
                    i, t = compact_object(abox.q.db, ABOX_IRI, abox.c, abox.t, oid, shared[oid], keep)
                    individuals, triples = individuals + i, triples + t
                abox.pending_triples -= triples
                return Compaction(len(objects), individuals, triples)

            result = abox.write(fill)
            self._records.clear()  # records of deleted individuals must not be served from memory
            return result

    # -- export -----------------------------------------------------------------------------------------------
    def export_lines(self, history: str = "current", object_ids: Sequence[str] | None = None) -> Iterator[str]:
        """A file store is read on a connection of the export's own, without the store's lock."""
        ids = self._export_ids(history, object_ids)
        # the export reads triples: the journalled plans it shows are written out first (each object's current
        # plan, or with the history every one)
        self._backlog.settle(None if ids is None else self._current_names(ids))
        with self._guard:
            self._backlog.settle(None if ids is None else self._current_names(ids))  # adopted meanwhile
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

    # -- inferences -------------------------------------------------------------------------------------------
    def replace_inferred(self, scope: str, lines: Sequence[str]) -> int:
        checked = InferredFacts.check(scope, lines)
        with self._guard:
            return self._abox.write(lambda: self._inferred.replace(scope, checked))

    def inferred_lines(self) -> Iterator[str]:
        with self._guard:
            return iter(list(self._inferred.lines()))


def _file_bytes(path: str) -> int:
    return sum(os.path.getsize(p) for p in (path, path + "-wal") if os.path.exists(p))

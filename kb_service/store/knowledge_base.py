"""The knowledge base the service owns: the ABox (`abox`) with the event log (`events`), the execution cursor
(`execution`) and idempotent responses (`responses`) in the same SQLite database, and the RDF export (`export`).

Each part validates its input completely before anything is written; every write is one transaction, and
`transaction()` makes several writes one (all of them commit, or none does).
"""
from __future__ import annotations

import os
from typing import Any, Iterator, Sequence

from .abox import ABOX_IRI, TBOX_IRI, Abox
from .errors import KBError, NotFoundError, ValidationError
from .events import EventLog
from .execution import ExecutionCursor
from .export import FORMATS, HISTORY, export_rdf, ntriples
from .records import Execution, StoredEvent
from .responses import ResponseMemory
from .retention import DEFAULT_KEEP_PERCEIVED, Compaction, compact_object

MAX_SEQ = 2**63 - 1  # the largest event seq a caller may name (the largest SQLite INTEGER)
MAX_EVENTS_PAGE = 1000  # the most events one read of the log returns over HTTP (a page, or one poll of a stream)


class KnowledgeBase(Abox):
    """TBox + ABox in one owlready2 World on SQLite, with the service's side tables; thread safe (one RLock)."""

    def __init__(self, path: str | None, tbox_path: Any) -> None:
        super().__init__(path, tbox_path)
        try:
            self._events = EventLog(self._q)
            self._execution = ExecutionCursor(self._q)
            self._responses = ResponseMemory(self._q)
            self._q.commit()
        except Exception:
            self.close()
            raise

    # -- events -------------------------------------------------------------------------------------------
    def add_event(self, object_id: str, kind: str, reason: str, data: dict[str, Any]) -> StoredEvent:
        with self._lock:
            self._check_open()
            ident = self._info(object_id, "object_id").obj.ident
            text = self._events.check(kind, reason, data)
            return self._write(lambda: self._events.append(ident, kind, reason, text))

    def list_events(self, object_id: str, after_seq: int = 0, limit: int | None = None) -> tuple[StoredEvent, ...]:
        """The object's events after `after_seq`, oldest first, at most `limit` (None: all)."""
        if isinstance(after_seq, bool) or not isinstance(after_seq, int) or not 0 <= after_seq <= MAX_SEQ:
            raise ValidationError(f"after_seq: must be an integer from 0 to {MAX_SEQ}, got {after_seq!r}")
        if limit is not None and (isinstance(limit, bool) or not isinstance(limit, int) or limit < 1):
            raise ValidationError(f"limit: must be a positive integer, got {limit!r}")
        with self._lock:
            self._check_open()
            return self._events.after(self._info(object_id).obj.ident, after_seq, limit)

    # -- execution ----------------------------------------------------------------------------------------
    def get_execution(self, object_id: str) -> Execution:
        with self._lock:
            self._check_open()
            return self._execution.read(self._info(object_id).obj.ident)

    def set_execution(self, object_id: str, execution: Execution) -> None:
        with self._lock:
            self._check_open()
            ident = self._info(object_id, "object_id").obj.ident
            if not isinstance(execution, Execution):
                raise ValidationError(f"execution: expected an Execution, got {type(execution).__name__}")
            plan = None
            if execution.plan_id is not None:
                try:
                    plan = self.get_plan(execution.plan_id)
                except NotFoundError:
                    raise ValidationError(f"execution.plan_id: no plan {execution.plan_id!r}") from None
            self._execution.check(ident, execution, plan)
            self._write(lambda: self._execution.write(ident, execution))

    # -- idempotent responses -----------------------------------------------------------------------------
    def recall_response(self, object_id: str, key: str) -> dict[str, Any] | None:
        """The response remembered under an idempotency key, or None (the object need not exist)."""
        with self._lock:
            self._check_open()
            return self._responses.recall(object_id, key)

    def remember_response(self, object_id: str, key: str, response: dict[str, Any]) -> None:
        """Remember the response to an idempotent request; the first response stored under a key wins."""
        with self._lock:
            self._check_open()
            text = self._responses.check(key, response)
            self._write(lambda: self._responses.remember(object_id, key, text))

    # -- retention ------------------------------------------------------------------------------------------
    def compact(self, keep_perceived: int = DEFAULT_KEEP_PERCEIVED) -> Compaction:
        """Apply the retention policy (`retention`) to every object in one transaction: keep each object's current
        records and its last `keep_perceived` perceived states, delete the rest of its history."""
        if isinstance(keep_perceived, bool) or not isinstance(keep_perceived, int) or keep_perceived < 1:
            raise ValidationError(f"keep_perceived: must be a positive integer, got {keep_perceived!r}")
        with self._lock:
            self._check_open()
            self.settle()  # a plan still in the journal is history like any other
            objects = [o.ident for o in self.list_objects()]
            shared = {oid: sorted(self._info(oid).orientation_atom_name.values()) for oid in objects}

            def fill() -> Compaction:
                individuals = triples = 0
                for oid in objects:
                    i, t = compact_object(self._q.db, ABOX_IRI, self._c, self._t, oid, shared[oid], keep_perceived)
                    individuals, triples = individuals + i, triples + t
                self._pending[0] -= triples
                return Compaction(len(objects), individuals, triples)

            result = self._write(fill)
            self._drop_caches()  # records of deleted individuals must not be served from memory
            return result

    def rewrite(self) -> tuple[int, int]:
        """Rewrite the store's file (`QuadStore.rewrite`): the space compaction freed goes back to the file system,
        and a file made with 32 KiB pages gets 4 KiB ones. Only on a store no other process has open. The file's
        size in bytes (log included) before and after."""
        with self._lock:
            self._check_open()
            if not self._path:
                raise KBError("store: an in-memory store has no file to rewrite")
            self.settle()
            before = _file_bytes(self._path)
            self._q.rewrite()
            return before, _file_bytes(self._path)

    # -- whole-ontology views -----------------------------------------------------------------------------
    def ntriples(self) -> bytes:
        """TBox + ABox as N-Triples (what the reasoners and `export` read)."""
        with self._lock:
            self._check_open()
            self.settle()
            return self._q.ntriples()

    def export_lines(self, history: str = "current", object_ids: Sequence[str] | None = None) -> Iterator[str]:
        """TBox + ABox as N-Triples lines: the current ABox of `object_ids` (None: of every object) when
        `history` is 'current', every triple when it is 'all' (see `export`). Unknown objects are a NotFoundError
        before the first line. A file store is read on a connection of the export's own, without the store's lock."""
        if history not in HISTORY:
            raise ValidationError(f"history: must be one of {', '.join(HISTORY)}, got {history!r}")
        ids = None
        if history == "current":
            ids = [o.ident for o in self.list_objects()] if object_ids is None else list(object_ids)
            for oid in ids:
                self.get_object(oid)
        elif object_ids is not None:
            raise ValidationError("object: the whole history is exported for every object (history=all)")
        with self._lock:
            self._check_open()
            self.settle()  # the export reads triples: every journalled plan's are written first
            reader = self._q.reader()
            if reader is None:  # an in-memory store: read on its connection, under its lock, at once
                return iter(list(ntriples(self._q.db, ABOX_IRI, self._c, self._t["staticFactOf"], ids)))
        return self._read_lines(reader, ids)

    def _read_lines(self, reader: Any, ids: list[str] | None) -> Iterator[str]:
        try:
            yield from ntriples(reader, ABOX_IRI, self._c, self._t["staticFactOf"], ids)
        finally:
            reader.close()

    def export(self, fmt: str = "xml", history: str = "current", object_ids: Sequence[str] | None = None) -> bytes:
        """TBox + ABox (see `export_lines`) as RDF/XML (`xml`), Turtle (`turtle`) or N-Triples (`nt`)."""
        if fmt not in FORMATS:
            raise ValidationError(f"fmt: must be one of {', '.join(FORMATS)}, got {fmt!r}")
        text = "".join(self.export_lines(history, object_ids)).encode("utf-8")
        return export_rdf(text, fmt, {"planhrc": TBOX_IRI, "abox": ABOX_IRI,
                                      "owl": "http://www.w3.org/2002/07/owl#"})


def _file_bytes(path: str) -> int:
    return sum(os.path.getsize(p) for p in (path, path + "-wal") if os.path.exists(p))

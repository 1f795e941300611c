"""The PostgreSQL backend of the knowledge base (`PostgresStore`): the ABox as rows of triples (`schema`, `rows`),
written by the backend-neutral writes (`writes`, `triples`) through this backend's unit of work (`session`) and read
back by `records`, with the event log, the execution cursor and idempotent responses as tables beside it, retention
and the RDF export (`history`), and what a reasoner inferred beside them (`inferred`). It implements
`interface.KnowledgeStore` through the store's core (`..facade.StoreCore`), giving it the parts above and the side
tables (`tables`), and adds what replicas need (`replicas.ObjectLocking`, `event_feed`).

Every public method takes the store's lock and refuses a closed store. Each write checks its input completely
before anything is written; every write is one transaction, and `transaction()` makes several writes one. A plan is
stored as a journal row and its triples are written when a reader of the triples needs them (`journal`), as in the
SQLite store; every process reads it from its row until then.

The TBox is read by each process from its file (an in-memory owlready2 world, for the TBox's lines of the export);
its digest is kept in the database, and a process whose TBox differs from the one the store was written with says
so in its log.
"""
from __future__ import annotations

import hashlib
import logging
from pathlib import Path
from typing import Any, Iterator, Sequence

from ..errors import DamagedStoreError, KBError, UnavailableError
from ..facade import StoreCore
from ..location import shown_location
from ..names import TBOX_IRI
from ..owl import QuadStore, ntriple_lines
from ..roots import POSTGRESQL, current_roots
from ..writes import RecordWriter
from .history import abox_lines, compact_object
from .inferred import PgInferred
from .journal import PgJournal
from .records import PgRecords
from .replicas import LOCK_NAMESPACE, LOCK_OBJECT, PgEventFeed
from .schema import ABOX_ONTOLOGY, OWL, RDF_TYPE, SCHEMA_LOCK, SCHEMA_VERSION, TABLES
from .session import Session
from .tables import PgEventLog, PgExecutionCursor, PgResponseMemory

log = logging.getLogger(__name__)


COMPACT_LOCK = 0x706C616E68726302  # "planhrc\x02": held by the one process compacting the store


class PostgresStore(StoreCore):
    """TBox (from its file) + ABox and the service's tables in one PostgreSQL database; thread safe."""

    _records: PgRecords
    _journal: PgJournal

    def __init__(self, db: str | None, tbox_path: Path | str, password: str | None = None) -> None:
        if not db:
            raise KBError("db: a PostgreSQL store needs a URL (postgresql://user@host:port/database)")
        self.tbox_path = Path(tbox_path)
        if not self.tbox_path.is_file():
            raise KBError(f"tbox_path: no such file {self.tbox_path}")
        self._password = password
        self._tbox_lines = _tbox_lines(self.tbox_path)
        session = self._unit = self._session = Session(db, password)
        self._guard = session.guard
        self._plans_to_write = 0  # the last count read, what /health shows while the database is away
        try:
            self._prepare(hashlib.sha256(self.tbox_path.read_bytes()).hexdigest())
            self._records = PgRecords(session)
            self._journal = PgJournal(session, self._records)
            session.listen(self._records)
            self._writes = RecordWriter(session, self._records, self._journal)
            self._inferred = PgInferred(session)
            self._events = PgEventLog(session)
            self._execution = PgExecutionCursor(session)
            self._responses = PgResponseMemory(session)
            self._journal.check()  # before anything is served
        except BaseException:
            session.close()
            raise
        log.info("store: PostgreSQL at %s", shown_location(db))

    def _prepare(self, tbox_digest: str) -> None:
        """Create the tables of a new database (one process at a time), refuse one of another schema, count."""
        s = self._session
        with s.transaction():
            s.execute("SELECT pg_advisory_xact_lock(%s)", (SCHEMA_LOCK,))
            for sql in TABLES:
                s.execute(sql)
            meta = dict(s.execute("SELECT key, value FROM planhrc_meta").fetchall())
            if meta.get("schema", SCHEMA_VERSION) != SCHEMA_VERSION:
                raise DamagedStoreError(f"db: the database holds a store of schema {meta['schema']}, this version "
                                        f"reads schema {SCHEMA_VERSION}")
            if not meta:
                s.execute("INSERT INTO planhrc_meta VALUES ('schema', %s)", (SCHEMA_VERSION,))
                s.execute("INSERT INTO planhrc_triple (s, p, o) VALUES (%s, %s, %s)",
                          (ABOX_ONTOLOGY, RDF_TYPE, OWL + "Ontology"))
            if meta.get("tbox_sha256") != tbox_digest:
                if "tbox_sha256" in meta:
                    log.warning("TBox %s differs from the one this database was written with", self.tbox_path)
                s.execute("INSERT INTO planhrc_meta VALUES ('tbox_sha256', %s) ON CONFLICT (key) "
                          "DO UPDATE SET value = EXCLUDED.value", (tbox_digest,))
            row = s.execute("SELECT count(*) FROM planhrc_triple").fetchone()
            s.triples = len(self._tbox_lines) + int(row[0] if row else 0)
            row = s.execute("SELECT count(*) FROM planhrc_triple WHERE o = %s AND p = %s",
                            (TBOX_IRI + "ArticulatedObject", RDF_TYPE)).fetchone()
            s.objects = int(row[0] if row else 0)

    # -- what only this backend has: replicas -------------------------------------------------------------------
    def lock_object(self, object_id: str) -> None:
        with self._guard:
            if not self._session.depth:
                raise KBError("internal: lock_object outside a transaction() (it would be released at once)")
            self._session.execute(LOCK_OBJECT, (LOCK_NAMESPACE + object_id,))

    def event_feed(self) -> PgEventFeed:
        """A feed of the events every process commits (`replicas.PgEventFeed`); the caller closes it."""
        self._session.check_open()
        return PgEventFeed(self._session.db, self._password)

    # -- reads (the rest: `facade.StoreCore`) ---------------------------------------------------------------
    def _latest_id(self, object_id: str, noun: str) -> str | None:
        return self._session.latest(object_id, noun)

    def revision(self) -> int:
        """Changes with every commit that wrote, by any process on the database: one query of a few rows."""
        with self._guard:
            return self._session.revision()

    # -- the plan journal -------------------------------------------------------------------------------------
    def settle(self) -> None:
        with self._guard:
            self._journal.settle()

    def plans_to_write(self) -> int:
        try:
            with self._guard:
                self._plans_to_write = len(self._journal)
        except UnavailableError:
            pass  # /health answers from memory while the database takes no connections, as its other counts do
        return self._plans_to_write

    # -- retention (the steps: `facade.StoreCore.compact`) ---------------------------------------------------
    def _may_compact(self) -> bool:
        # one process compacts at a time (every replica compacts on its schedule), and each object's writes wait
        # for it as for any other write of the object (its lock, until the commit)
        row = self._session.execute("SELECT pg_try_advisory_xact_lock(%s)", (COMPACT_LOCK,)).fetchone()
        if not (row and row[0]):
            log.info("store: another process is compacting the store; this one leaves it to it")
            return False
        return True

    def _compact_object(self, object_id: str, roots: list[str], shared: list[str], keep: int) -> tuple[int, int]:
        s = self._session
        s.execute(LOCK_OBJECT, (LOCK_NAMESPACE + object_id,))
        # a plan another replica adopted since the roots were read is current too: its row stays
        dropped = self._journal.drop(object_id, {*roots, *self._roots(object_id)})
        individuals, triples = compact_object(s.conn, object_id, shared, keep)
        return dropped + individuals, triples

    # -- export -----------------------------------------------------------------------------------------------
    def export_lines(self, history: str = "current", object_ids: Sequence[str] | None = None) -> Iterator[str]:
        """Read on a connection of the export's own, in one snapshot, without the store's lock."""
        ids = self._export_ids(history, object_ids)
        with self._guard:
            # the export reads triples: the journalled plans it shows are written out first (each object's
            # current plan, or with the history every one)
            self._journal.settle(None if ids is None else self._current_names(ids))
            reader = self._session.reader()
        return self._read_lines(reader, ids)

    def _read_lines(self, reader: Any, ids: list[str] | None) -> Iterator[str]:
        try:
            yield from self._tbox_lines
            yield from abox_lines(reader, ids)
        finally:
            reader.close()

    def _roots(self, object_id: str) -> list[str]:
        return current_roots(self._session.conn, POSTGRESQL, object_id)


def _tbox_lines(tbox_path: Path) -> tuple[str, ...]:
    """The TBox as N-Triples lines, as the SQLite store exports it (owlready2 reads the file into memory)."""
    quads = QuadStore(None)
    try:
        try:
            quads.load_ontology(TBOX_IRI, tbox_path.read_bytes(), reload=False)
        except Exception as exc:  # owlready2 raises several kinds for a file that is no ontology
            raise KBError(f"tbox_path: {tbox_path} does not read as an ontology ({exc})") from None
        return tuple(ntriple_lines(quads.db, "1"))
    finally:
        quads.abandon()

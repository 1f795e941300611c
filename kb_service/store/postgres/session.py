"""The PostgreSQL ABox's unit of work (`unit.AboxWriter`): one connection, its transactions, the store's counters
and which individuals are stored.

The connection runs in autocommit mode, so a read outside a transaction holds no snapshot open; a write, or a
`transaction()` block, is one `BEGIN ... COMMIT`, and nested blocks join the outermost one; each commit that wrote is
counted in the database (`revision`). The nesting, the counts and the listeners are the unit of work's
(`..work.UnitOfWork`); this engine supplies the connection. Every method here is called with `lock` held; the store
takes it (`guard`), which also reconnects a connection the server dropped (`ready`: between transactions only, a
transaction cut off is rolled back, never replayed) and turns a lost connection into `UnavailableError` (`lost`).
"""
from __future__ import annotations

import logging
from contextlib import contextmanager
from typing import Any, Iterator, Sequence

import psycopg

from ..errors import KBError, UnavailableError
from ..names import ABOX_IRI, TBOX_IRI, counter_name, record_name
from .rows import RowBatch
from ..location import shown_location
from .schema import RDF_TYPE
from ..work import UnitOfWork

log = logging.getLogger(__name__)
Connection = psycopg.Connection[tuple[Any, ...]]
CONNECT_TIMEOUT_S = 10
# Each statement planned with the sizes of now, not with a plan cached when the statement was first prepared: the
# store's tables grow from nothing, and a plan made for an empty triple table (a sequential scan) stays cached on
# the connection after the table holds thousands of rows (a lookup of individuals then read the whole table).
CONNECTION_OPTIONS = "-c plan_cache_mode=force_custom_plan"
# `Reads.revision`, which must change with every commit that wrote, by any process on the database. A transaction
# that wrote (it has a transaction id; one that only read has none) adds one to its connection's row just before it
# commits, so the sum changes exactly when its writes become visible: a sequence would change at `nextval`, before
# the commit, and a reader that saw the new number with the old data would keep that data as current. Rows spread
# by connection rather than one counter: a row is locked until its transaction's commit is flushed, and one row
# would queue every writer of every process behind each other's flush.
REVISION_SHARDS = 16
COUNT_COMMIT = ("INSERT INTO planhrc_revision AS r (shard, value) SELECT mod(pg_backend_pid(), %s), 1 "
                "WHERE pg_current_xact_id_if_assigned() IS NOT NULL "
                "ON CONFLICT (shard) DO UPDATE SET value = r.value + 1")


def connect(db: str, password: str | None, what: str = "planhrc") -> Connection:
    """A connection in autocommit mode; a server that cannot be reached is a one-line `UnavailableError` naming
    the location (without its password)."""
    try:
        return psycopg.connect(db, password=password, autocommit=True, connect_timeout=CONNECT_TIMEOUT_S,
                               application_name=what, options=CONNECTION_OPTIONS)
    except psycopg.OperationalError as exc:
        reason = str(exc).strip().splitlines()[-1] if str(exc).strip() else type(exc).__name__
        raise UnavailableError(f"db: cannot connect to {shown_location(db)} ({reason})") from None
    except psycopg.ProgrammingError as exc:  # a URL libpq does not parse
        raise KBError(f"db: {shown_location(db)} is no PostgreSQL location ({exc})") from None


class Session(UnitOfWork):
    """One connection to the store's database, in one transaction at a time."""

    def __init__(self, db: str, password: str | None) -> None:
        super().__init__()
        self.db = db
        self._password = password
        self.conn = connect(db, password)
        self.known: set[str] = set()  # individuals known to be stored (never deleted: objects, their parts)

    def ready(self) -> None:
        if not self.depth and self.conn.broken:
            self.reconnect()

    def lost(self, exc: BaseException) -> BaseException | None:
        if not isinstance(exc, psycopg.OperationalError):
            return None
        reason = " ".join(str(exc).split())[:200]  # libpq's messages may run over several lines
        return UnavailableError(f"db: the connection to the database was lost ({reason}); "
                                "nothing of this request was written")

    def reconnect(self) -> None:
        log.warning("store: the connection to %s was lost; connecting again", shown_location(self.db))
        self.conn.close()
        self.conn = connect(self.db, self._password)

    def reader(self) -> Connection:
        """A connection of its own in one read-only snapshot (an export reads it without the store's lock);
        the caller closes it."""
        conn = connect(self.db, self._password, "planhrc-export")
        conn.execute("BEGIN ISOLATION LEVEL REPEATABLE READ READ ONLY")
        return conn

    def _close_connection(self) -> None:
        self.conn.close()

    def execute(self, sql: str, params: Sequence[Any] = ()) -> psycopg.Cursor[tuple[Any, ...]]:
        return self.conn.execute(sql, params)

    def revision(self) -> int:
        """Commits that wrote, by every process, since the database was made (`COUNT_COMMIT`)."""
        row = self.execute("SELECT coalesce(sum(value), 0)::bigint FROM planhrc_revision").fetchone()
        return int(row[0]) if row else 0

    # -- what the backend-neutral writes ask (`unit.AboxWriter`) ------------------------------------------
    def existing(self, names: Sequence[str]) -> list[str]:
        unknown = [ABOX_IRI + name for name in names if name not in self.known]
        if unknown:
            rows = self.execute("SELECT DISTINCT s FROM planhrc_triple WHERE s = ANY(%s)", (unknown,))
            self.known.update(s[len(ABOX_IRI):] for (s,) in rows)
        return [name for name in names if name in self.known]

    def has_class(self, name: str, cls: str) -> bool:
        return self.execute("SELECT 1 FROM planhrc_triple WHERE s = %s AND p = %s AND o = %s LIMIT 1",
                            (ABOX_IRI + name, RDF_TYPE, TBOX_IRI + cls)).fetchone() is not None

    def next_counter(self, name: str) -> int:
        return self.reserve_counter(name, 1)

    def reserve_counter(self, name: str, count: int) -> int:
        row = self.execute("INSERT INTO planhrc_counter AS c (name, value) VALUES (%s, %s) ON CONFLICT (name) "
                           "DO UPDATE SET value = c.value + EXCLUDED.value RETURNING value", (name, count)).fetchone()
        assert row is not None
        return int(row[0]) - count + 1

    def latest(self, object_id: str, kind: str) -> str | None:
        """The newest record `<object>_<kind>_<n>`: n is the object's counter."""
        row = self.execute("SELECT value FROM planhrc_counter WHERE name = %s",
                           (counter_name(object_id, kind),)).fetchone()
        return record_name(object_id, kind, row[0]) if row and row[0] else None

    def batch(self) -> RowBatch:
        return RowBatch()

    def flush(self, batch: RowBatch) -> None:
        """Every row of the batch in one COPY (inside the open transaction)."""
        if batch.rows:
            with self.conn.cursor().copy("COPY planhrc_triple (s, p, o, lit, dt) FROM STDIN") as copy:
                for row in batch.rows:
                    copy.write_row(row)
        self.known.update(batch.new)
        self.pending_triples += len(batch.rows)

    # -- transactions (`..work.UnitOfWork.transaction`) -----------------------------------------------------
    @contextmanager
    def _one_transaction(self) -> Iterator[None]:
        try:
            with self.conn.transaction():
                yield
                self.execute(COUNT_COMMIT, (REVISION_SHARDS,))
        except BaseException:
            self.known.clear()  # names created by the rolled-back transaction are not stored
            raise

"""The SQLite ABox's unit of work: the owlready2 world that holds the TBox and the ABox, the names of its
individuals, the store's counters, and its transactions.

The ontology lives in an owlready2 `World` backed by SQLite. The TBox file is loaded into the world once; the
ABox is written straight into owlready2's quad tables (`objs`, `datas`) through the adapter (`owl.QuadStore`), a
`Batch` of triples at a time, after the whole input has been checked (`checks`): a write either commits completely
or not at all. Nothing loads ABox individuals as owlready2 Python objects, so owlready2's entity cache never goes
stale. Its transactions, counts and listeners (the record caches of `reads`, the count of journalled plans of
`backlog`) are the unit of work's (`work.UnitOfWork`); this engine supplies the SQLite connection's commit and
rollback.

Every method here is called with `lock` held; the store (`knowledge_base.SqliteStore`) takes it.
"""
from __future__ import annotations

import hashlib
import logging
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Iterable, Iterator, Sequence

from .errors import DamagedStoreError, KBError
from .names import ABOX_IRI, TBOX_IRI, TBOX_TERMS, counter_name, record_name
from .owl import NAMED_INDIVIDUAL, RDF_TYPE, QuadStore, World
from .work import UnitOfWork

log = logging.getLogger(__name__)

_TABLES = (
    "CREATE TABLE IF NOT EXISTS planhrc_meta (key TEXT PRIMARY KEY, value TEXT)",
    "CREATE TABLE IF NOT EXISTS planhrc_counter (name TEXT PRIMARY KEY, value INTEGER)",
)


class Batch:
    """Triples collected during a write, subjects and objects by name, flushed in one go (`Abox.flush`)."""

    def __init__(self, terms: dict[str, int]) -> None:
        self.terms = terms
        self.new_iris: list[str] = []
        self.objs: list[tuple[str | int, int, str | int]] = []
        self.datas: list[tuple[str | int, int, Any]] = []
        self.shared: set[str] = set()  # object-level predicate individuals this batch creates

    def individual(self, name: str, *classes: str) -> str:
        self.new_iris.append(name)
        self.objs.append((name, RDF_TYPE, NAMED_INDIVIDUAL))
        for cls in classes:
            self.objs.append((name, RDF_TYPE, self.terms[cls]))
        return name

    def rel(self, s: str, prop: str, o: str | int) -> None:
        self.objs.append((s, self.terms[prop], o))

    def data(self, s: str, prop: str, value: Any) -> None:
        self.datas.append((s, self.terms[prop], value))


class Abox(UnitOfWork):
    """TBox + ABox in one owlready2 World on SQLite, with the store's counters, in one transaction at a time."""

    def __init__(self, path: str | None, tbox_path: Path | str) -> None:
        super().__init__()
        self.path = path
        self.tbox_path = Path(tbox_path)
        if not self.tbox_path.is_file():
            raise KBError(f"tbox_path: no such file {self.tbox_path}")
        self.q = QuadStore(path)
        try:
            if path:
                self.q.use_wal()
            for sql in _TABLES:
                self.q.execute(sql)
            self._load_tbox()
            self.c = self.q.context(ABOX_IRI)
            self.t = {term: self.q.storid(TBOX_IRI + term) for term in TBOX_TERMS}
            self.q.commit()
        except Exception:
            self.q.abandon()
            raise
        self.triples = self.q.count()
        self.objects = len(self.q.subjects(RDF_TYPE, self.t["ArticulatedObject"], self.c))
        self.revision = 0  # commits since the store was opened (`Reads.revision`)
        self.iri_sid: dict[str, int] = {}
        self.sid_name: dict[int, str] = {}

    def _load_tbox(self) -> None:
        data = self.tbox_path.read_bytes()
        digest = hashlib.sha256(data).hexdigest()
        row = self.q.execute("SELECT value FROM planhrc_meta WHERE key='tbox_sha256'").fetchone()
        if row is None or row[0] != digest:
            if row is not None:
                log.warning("TBox %s changed since this database was written: reloading it", self.tbox_path)
            self.q.load_ontology(TBOX_IRI, data, reload=row is not None)
            self.q.execute("INSERT OR REPLACE INTO planhrc_meta VALUES ('tbox_sha256', ?)", (digest,))

    @property
    def world(self) -> World:
        return self.q.world

    def _close_connection(self) -> None:
        self.q.close()

    # -- names of individuals -----------------------------------------------------------------------------
    def sid(self, name: str) -> int | None:
        """Storid of an existing ABox individual, or None."""
        sid = self.iri_sid.get(name)
        if sid is None:
            sid = self.q.storid(ABOX_IRI + name, False) or None
            if sid is not None:
                self.iri_sid[name] = sid
                self.sid_name[sid] = name
        return sid

    def names(self, sids: Iterable[int]) -> None:
        """Fill the storid -> name cache for these storids in one query."""
        missing = [s for s in set(sids) if s not in self.sid_name]
        for sid, iri in self.q.iris(missing).items():
            name = iri[len(ABOX_IRI):] if iri.startswith(ABOX_IRI) else iri
            self.sid_name[sid] = name
            self.iri_sid.setdefault(name, sid)

    def forget_names(self) -> None:
        self.iri_sid.clear()
        self.sid_name.clear()

    # -- what the backend-neutral writes ask (`unit.AboxWriter`) ------------------------------------------
    def existing(self, names: Sequence[str]) -> list[str]:
        return [name for name in names if self.sid(name) is not None]

    def has_class(self, name: str, cls: str) -> bool:
        sid = self.sid(name)
        return sid is not None and self.is_a(sid, cls)

    def batch(self) -> Batch:
        return Batch(self.t)

    # -- triples of one individual ------------------------------------------------------------------------
    def is_a(self, sid: int, cls: str) -> bool:
        return self.q.has(sid, RDF_TYPE, self.t[cls])

    def types(self, sid: int) -> set[int]:
        return set(self.q.objects(sid, RDF_TYPE))

    def ref(self, sid: int, prop: str) -> int:
        """The one object of a property every record of its kind has; a missing one is a damaged store."""
        found = self.q.object(sid, self.t[prop])
        if found is None:
            raise DamagedStoreError(f"store: record {self.sid_name.get(sid, sid)} has no {prop}")
        return found

    def objn(self, sid: int, prop: str) -> list[int]:
        return self.q.objects(sid, self.t[prop])

    def data1(self, sid: int, prop: str) -> Any:
        return self.q.data(sid, self.t[prop])

    # -- counters -------------------------------------------------------------------------------------------
    def next_counter(self, name: str) -> int:
        return self.reserve_counter(name, 1)

    def reserve_counter(self, name: str, count: int) -> int:
        """Take `count` consecutive values of a counter at once (two statements, whatever `count`); the first."""
        row = self.q.execute("SELECT value FROM planhrc_counter WHERE name=?", (name,)).fetchone()
        first = (row[0] if row else 0) + 1
        self.q.execute("INSERT OR REPLACE INTO planhrc_counter VALUES (?, ?)", (name, first + count - 1))
        return int(first)

    def latest(self, object_id: str, kind: str) -> str | None:
        """The newest record `<object>_<kind>_<n>`: n is the object's counter (one row read, whatever the
        history)."""
        row = self.q.execute("SELECT value FROM planhrc_counter WHERE name=?",
                             (counter_name(object_id, kind),)).fetchone()
        return record_name(object_id, kind, row[0]) if row and row[0] else None

    # -- writes ---------------------------------------------------------------------------------------------
    def flush(self, batch: Batch) -> None:
        """Allocate storids for the new individuals and insert every triple (inside the open transaction)."""
        names = batch.new_iris
        if names:
            for sid, name in zip(self.q.allocate([ABOX_IRI + name for name in names]), names):
                self.iri_sid[name] = sid
                self.sid_name[sid] = name

        known = self.iri_sid

        def resolve(x: str | int) -> int:
            if isinstance(x, int):
                return x
            sid = known.get(x)
            if sid is not None:
                return sid
            sid = self.sid(x)
            if sid is None:
                raise KBError(f"internal: individual {x!r} was neither stored nor created")
            return sid

        self.q.insert_objs(self.c, [(resolve(s), p, resolve(o)) for s, p, o in batch.objs])
        self.q.insert_datas(self.c, [(resolve(s), p, value) for s, p, value in batch.datas])
        self.pending_triples += len(batch.objs) + len(batch.datas)

    # -- transactions (`work.UnitOfWork.transaction`) -------------------------------------------------------
    @contextmanager
    def _one_transaction(self) -> Iterator[None]:
        try:
            yield
            self.q.commit()
        except BaseException:
            self.q.rollback()
            # Storids handed out in a rolled-back transaction are invalid: forget every name (they are read again).
            self.forget_names()
            raise
        self.revision += 1

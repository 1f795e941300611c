"""The one module that touches owlready2's internals.

The knowledge base writes owlready2's quad tables directly (one SQLite transaction per write, no Python object
per individual), and the reasoners pass a time limit through owlready2's subprocess settings. Everything that
relies on how owlready2 works inside — its SQLite connection, the tables `resources`, `objs`, `datas` and
`store`, storids (`_abbreviate`), literal encoding (`_to_rdf`, `_to_python`), the graph context of an ontology
(`graph.c`) and the reasoners' `_subprocess_kargs` and class paths (`_PELLET_CLASSPATH`, `_HERMIT_CLASSPATH`) — is here, behind plain methods.
`check_internals()` verifies each of these assumptions against the installed owlready2 and raises
`OwlInternalsError` naming the one that broke; a test runs it, so an owlready2 upgrade that changes them fails
loudly instead of corrupting a store.
"""
from __future__ import annotations

import io
import logging
import os
import sqlite3
import threading
from typing import Any, Iterable, Sequence

import owlready2
from owlready2 import World as World  # the world type the store and the reasoners pass around
from owlready2.base import owl_named_individual, owl_ontology, rdf_type

from .errors import KBError

log = logging.getLogger(__name__)

RDF_TYPE: int = rdf_type
NAMED_INDIVIDUAL: int = owl_named_individual
ONTOLOGY: int = owl_ontology

# The columns of owlready2's tables this adapter writes positionally (`INSERT ... VALUES`), exactly and in order.
TABLES: dict[str, tuple[str, ...]] = {
    "resources": ("storid", "iri"),
    "objs": ("c", "s", "p", "o"),
    "datas": ("c", "s", "p", "o", "d"),
}
PAGE_CACHE_KIB = 16_384  # SQLite page cache of the store's connection
# The page size of a store this adapter creates. owlready2 makes 32 KiB pages, and a re-planning perception
# dirties a page at the end of each index group it adds to (one per predicate individual, class and argument its
# triples point at), and every dirty page goes whole to the WAL and, at a checkpoint, into the file: smaller pages
# write less for the same triples, and what the process writes grows less with the history (README, "The store's
# pages", has the figures; tests/test_kb_owl_adapter.py bounds one perception's log).
PAGE_SIZE = 4096
# The WAL is copied into the file by a thread of its own (`Checkpointer`), not inside a commit. Past this many
# pages the writer copies its last commits itself so that the log restarts, and a log file longer than
# WAL_FILE_LIMIT is cut back when it restarts.
WAL_RESTART_PAGES = 16_384
CATCH_UP_COMMITS = 64  # ... and at least every this many commits
# The thread copies the log once this many commits have gathered since its last copy, or GATHER_S after the first
# of them, whichever comes first: one copy of the pages they share, and fewer wake-ups of the thread.
GATHER_COMMITS = 16
GATHER_S = 4.0
RETRY_S = 1.0  # a checkpoint that could not copy the whole log (a reader held it) is tried again this long after
WAL_FILE_LIMIT = 64 * 1024 * 1024
STORE_COUNTER = "current_resource"  # column of the one-row table `store`: the last storid handed out
# owlready2's indexes on subject and on object. Queries that ask for the rows of a few individuals of the ABox
# name them (`INDEXED BY`): left to itself, SQLite's planner (no statistics) reads such a query through the index
# on the context `c`, or scans the table once the `IN` list is long, and the ABox's context holds every row of the
# history, so a read of a few individuals would grow with the history (tests/test_kb_owl_adapter.py checks it
# does not).
BY_SUBJECT = {"objs": "index_objs_sp", "datas": "index_datas_sp"}
BY_OBJECT = {"objs": "index_objs_op", "datas": "index_datas_op"}


class OwlInternalsError(KBError):
    """The installed owlready2 no longer works the way this adapter relies on (the message says what changed)."""


class Checkpointer:
    """Copies a WAL store's log into its file from a connection and thread of its own, woken by the commits.

    A passive checkpoint never blocks the writer or the readers, and once it has copied every frame before the
    next write begins, that write restarts the log from its start, so the log stays short while writes leave gaps
    between them. Under writes with no gap the thread is always a commit behind and the log grows: past
    `WAL_RESTART_PAGES` pages, or `CATCH_UP_COMMITS` commits, the writer copies what is left itself
    (`QuadStore.commit`; the thread has done most of it), so its next write finds the log copied and restarts
    it.

    The thread sleeps until a commit wakes it, then lets `GATHER_COMMITS` commits gather (or `GATHER_S` pass) and
    copies them at once: a page several commits dirtied (the last page of an index group a perception adds to,
    usually the same from one perception to the next) is copied once, and the thread wakes twice per gathering
    instead of for every commit. Each wake-up of a service's thread costs its process some CPU whatever it then
    does (more after a pause than back to back), at a robot's pace a visible part of a re-plan's; an idle service
    copies nothing and its thread does not wake. Only a checkpoint that could not copy the whole log (a reader held
    frames) is tried again `RETRY_S` later, commit or not, so that a log a reader held is still copied while
    nothing is written."""

    def __init__(self, path: str) -> None:
        self._conn = sqlite3.connect(path, isolation_level=None, check_same_thread=False, timeout=10)
        self._wake = threading.Event()
        self._stop = threading.Event()
        self._one = threading.Lock()
        self.log_pages = 0  # the log's length at the last checkpoint (pages)
        self.commits = 0  # commits since the writer last copied the log itself
        self.checkpoints = 0  # checkpoints the thread has run
        self.gathered = 0  # commits since the thread's last copy (a lost count only makes a copy come earlier)
        self.left_behind = False  # the last one could not copy the whole log: tried again after RETRY_S
        self._thread = threading.Thread(target=self._run, name="planhrc-checkpoint", daemon=True)
        self._thread.start()

    def poke(self) -> None:
        """A commit: the first one after a copy wakes the thread (it starts gathering), the `GATHER_COMMITS`th makes
        it copy."""
        self.gathered += 1
        if self.gathered == 1 or self.gathered >= GATHER_COMMITS:
            self._wake.set()

    def checkpoint(self, conn: sqlite3.Connection | None = None) -> tuple[int, int, int]:
        """One passive checkpoint, on the thread's connection or the writer's: (busy, pages in the log, pages
        copied). One at a time: two at once would refuse each other."""
        with self._one:
            row = (conn or self._conn).execute("PRAGMA wal_checkpoint(PASSIVE)").fetchall()[0]
        return int(row[0]), int(row[1]), int(row[2])

    def _run(self) -> None:
        while not self._stop.is_set():
            self._wake.wait(RETRY_S if self.left_behind else None)  # None: until a commit wakes the thread
            self._wake.clear()
            if 0 < self.gathered < GATHER_COMMITS:
                self._wake.wait(GATHER_S)  # the last commit to gather, the time limit, or close()
                self._wake.clear()
            if self._stop.is_set():
                return
            self.gathered = 0
            try:
                busy, self.log_pages, copied = self.checkpoint()
                self.checkpoints += 1
                self.left_behind = bool(busy) or copied < self.log_pages
            except sqlite3.Error as exc:  # tried again later; the log is only longer meanwhile
                log.warning("store: checkpoint of the WAL failed: %s", exc)
                self.left_behind = True

    def close(self) -> None:
        self._stop.set()
        self._wake.set()
        self._thread.join(30)
        self._conn.close()


class QuadStore:
    """An owlready2 World on SQLite (or in memory), read and written through its quad tables."""

    def __init__(self, path: str | None) -> None:
        new = bool(path) and not (os.path.exists(str(path)) and os.path.getsize(str(path)))
        # Not owlready2's default exclusive locking: readers on connections of their own (`reader`) must be able
        # to read the file while this connection writes.
        # owlready2 leaves a half-built graph behind when SQLite cannot open the file at all, whose clean-up then
        # fails noisily: a path no file can be made at is refused before.
        if path and os.path.isdir(path):
            raise KBError(f"db: {path} cannot be opened as a store (it is a folder)")
        if path and not os.path.isdir(os.path.dirname(os.path.abspath(path))):
            raise KBError(f"db: {path} cannot be opened as a store (no folder {os.path.dirname(path)})")
        try:
            self.world = World(filename=str(path), exclusive=False) if path else World()
        except sqlite3.Error as exc:  # not a database, or not readable: the caller's mistake
            raise KBError(f"db: {path} cannot be opened as a store ({exc})") from None
        self.db: sqlite3.Connection = self.world.graph.db
        self._checkpointer: Checkpointer | None = None
        if new:
            self._use_page_size(PAGE_SIZE)

    def _use_page_size(self, size: int) -> None:
        """Rewrite a new (still nearly empty) file with pages of `size` bytes: owlready2 has just created its tables
        with 32 KiB pages, and the page size of a file is fixed once it is in WAL mode."""
        self.db.commit()
        self.db.execute(f"PRAGMA page_size = {int(size)}")
        self.db.execute("VACUUM")

    def page_size(self) -> int:
        return int(self.db.execute("PRAGMA page_size").fetchone()[0])

    def rewrite(self, page_size: int = PAGE_SIZE) -> None:
        """Rewrite a WAL file store (VACUUM) with pages of `page_size` bytes: the pages deletions freed go back to
        the file system, and a file made with owlready2's 32 KiB pages gets this adapter's. The file must have no
        other connection (the checkpointer's is closed here and opened again after)."""
        if self._checkpointer is not None:
            self._checkpointer.close()
            self._checkpointer = None
        self.db.commit()
        try:
            try:
                mode = self.db.execute("PRAGMA journal_mode=DELETE").fetchone()[0]
            except sqlite3.OperationalError:
                mode = None
            if str(mode).lower() != "delete":
                raise KBError("store: another process has the file open (a running service?); stop it before "
                              "rewriting the file")
            self.db.execute(f"PRAGMA page_size = {int(page_size)}")
            try:
                self.db.execute("VACUUM")
            except sqlite3.Error as exc:
                raise KBError(f"store: the file could not be rewritten ({exc}); it is unchanged") from None
        finally:
            self.use_wal()

    # -- SQL on the same connection (the store's own side tables live in this database too) ------------------
    def execute(self, sql: str, params: Sequence[Any] = ()) -> sqlite3.Cursor:
        return self.db.execute(sql, params)

    def use_wal(self) -> None:
        """WAL + synchronous=NORMAL: a commit does not wait for fsync (durable across process crashes, the last
        commits may be lost on power loss); with the plain rollback journal every write would wait for the disk."""
        self.db.commit()
        self.db.execute("PRAGMA journal_mode=WAL")
        self.db.execute("PRAGMA synchronous=NORMAL")
        # owlready2 asks for a 200 MB page cache and a 30 GB memory map, both of which fill as the file grows:
        # bounded here so the service's memory does not follow its history (reads stay in the OS page cache).
        self.db.execute(f"PRAGMA cache_size = -{PAGE_CACHE_KIB}")
        self.db.execute("PRAGMA mmap_size = 0")
        # A checkpoint inside a commit copies the last ~1,000 pages into the file on the writer's time (every few
        # perceptions, and more of them as the file grows): the copy is done beside the writes instead.
        self.db.execute("PRAGMA wal_autocheckpoint = 0")
        self.db.execute(f"PRAGMA journal_size_limit = {WAL_FILE_LIMIT}")
        path = self.db.execute("PRAGMA database_list").fetchone()[2]
        self._checkpointer = Checkpointer(path)

    def commit(self) -> None:
        self.world.save()
        ckpt = self._checkpointer
        if ckpt is not None:
            ckpt.commits += 1
            if ckpt.log_pages > WAL_RESTART_PAGES or ckpt.commits >= CATCH_UP_COMMITS:
                # the thread has copied all but the last commits: copy these too, before the next write begins
                busy, pages, copied = ckpt.checkpoint(self.db)
                if not busy and copied == pages:
                    ckpt.log_pages = ckpt.commits = 0
            ckpt.poke()

    def rollback(self) -> None:
        self.db.rollback()

    def close(self) -> None:
        self._stop_checkpoints()
        self.world.save()
        self.world.close()

    def abandon(self) -> None:
        """Close without committing what the open transaction wrote (a store that failed to open)."""
        self._stop_checkpoints()
        self.world.close()

    def _stop_checkpoints(self) -> None:
        if self._checkpointer is not None:
            self._checkpointer.close()
            self._checkpointer = None

    # -- ontologies --------------------------------------------------------------------------------------------
    def load_ontology(self, iri: str, data: bytes, reload: bool) -> None:
        self.world.get_ontology(iri).load(fileobj=io.BytesIO(data), reload=reload)

    def context(self, ontology_iri: str) -> int:
        """The graph context (`c` column) of an ontology, which is declared as an owl:Ontology if it is new."""
        onto = self.world.get_ontology(ontology_iri)
        c: int = onto.graph.c
        sid = self.storid(ontology_iri.rstrip("#"))
        if not self.has(sid, RDF_TYPE, ONTOLOGY):
            self.db.execute("INSERT INTO objs VALUES (?,?,?,?)", (c, sid, RDF_TYPE, ONTOLOGY))
        return c

    def ntriples(self) -> bytes:
        buf = io.BytesIO()
        self.world.save(buf, format="ntriples")
        return buf.getvalue()

    def reader(self) -> sqlite3.Connection | None:
        """A read-only connection of its own on the database file (WAL: it reads the last commit while writers
        go on, and holds no lock of the store), or None for an in-memory store. The caller closes it."""
        row = self.db.execute("PRAGMA database_list").fetchone()
        path = row[2] if row else ""
        if not path:
            return None
        conn = sqlite3.connect(f"file:{path}?mode=ro", uri=True, check_same_thread=False)
        conn.execute("BEGIN")  # one snapshot for every query of the export, taken now
        conn.execute("SELECT COUNT(*) FROM store").fetchone()
        return conn

    # -- storids -----------------------------------------------------------------------------------------------
    def storid(self, iri: str, create: bool = True) -> int:
        """The storid of an IRI, created when `create` (else 0 when the IRI is unknown)."""
        sid = self.world.graph._abbreviate(iri, create)
        return int(sid) if sid else 0

    def iris(self, storids: Iterable[int]) -> dict[int, str]:
        """storid -> IRI for these storids, read in a few queries."""
        out: dict[int, str] = {}
        sids = list(storids)
        for i in range(0, len(sids), 500):
            chunk = sids[i:i + 500]
            q = "SELECT storid, iri FROM resources WHERE storid IN (%s)" % ",".join("?" * len(chunk))
            out.update(self.db.execute(q, chunk))
        return out

    def allocate(self, iris: Sequence[str]) -> list[int]:
        """New storids for new IRIs, in order (inside the open transaction)."""
        if not iris:
            return []
        n = len(iris)
        self.db.execute("UPDATE store SET current_resource=current_resource+?", (n,))
        last = self.db.execute("SELECT current_resource FROM store").fetchone()[0]
        first = last - n + 1
        rows = [(first + i, iri) for i, iri in enumerate(iris)]
        self.db.executemany("INSERT INTO resources VALUES (?,?)", rows)
        return [sid for sid, _ in rows]

    # -- triples -----------------------------------------------------------------------------------------------
    def insert_objs(self, c: int, rows: Iterable[tuple[int, int, int]]) -> None:
        self.db.executemany("INSERT INTO objs VALUES (?,?,?,?)", [(c, s, p, o) for s, p, o in rows])

    def insert_datas(self, c: int, rows: Iterable[tuple[int, int, Any]]) -> None:
        encoded = []
        for s, p, value in rows:
            o, d = self.world._to_rdf(value)
            encoded.append((c, s, p, o, d))
        self.db.executemany("INSERT INTO datas VALUES (?,?,?,?,?)", encoded)

    def has(self, s: int, p: int, o: int) -> bool:
        return self.db.execute("SELECT 1 FROM objs WHERE s=? AND p=? AND o=? LIMIT 1", (s, p, o)).fetchone() is not None

    def objects(self, s: int, p: int) -> list[int]:
        return [o for (o,) in self.db.execute("SELECT o FROM objs WHERE s=? AND p=?", (s, p))]

    def object(self, s: int, p: int) -> int | None:
        row = self.db.execute("SELECT o FROM objs WHERE s=? AND p=? LIMIT 1", (s, p)).fetchone()
        return row[0] if row else None

    def subjects(self, p: int, o: int, c: int | None = None) -> list[int]:
        if c is None:
            return [s for (s,) in self.db.execute("SELECT s FROM objs WHERE p=? AND o=?", (p, o))]
        return [s for (s,) in self.db.execute("SELECT s FROM objs WHERE c=? AND p=? AND o=?", (c, p, o))]

    def subjects_typed(self, p: int, o: int, cls: int) -> list[int]:
        """Subjects s with (s p o) and (s rdf:type cls)."""
        q = "SELECT a.s FROM objs a JOIN objs t ON t.s = a.s WHERE a.p=? AND a.o=? AND t.p=? AND t.o=?"
        return [s for (s,) in self.db.execute(q, (p, o, RDF_TYPE, cls))]

    def triples_of(self, subjects: Sequence[int], predicates: Sequence[int]) -> list[tuple[int, int, int]]:
        """(s, p, o) of the given subjects and predicates, in a few queries."""
        out: list[tuple[int, int, int]] = []
        preds = list(predicates)
        for i in range(0, len(subjects), 400):
            chunk = list(subjects[i:i + 400])
            q = (f"SELECT s, p, o FROM objs WHERE s IN ({','.join('?' * len(chunk))}) "
                 f"AND p IN ({','.join('?' * len(preds))})")
            out.extend(self.db.execute(q, chunk + preds))
        return out

    def data(self, s: int, p: int) -> Any:
        row = self.db.execute("SELECT o, d FROM datas WHERE s=? AND p=? LIMIT 1", (s, p)).fetchone()
        if row is None:
            return None
        return self.world._to_python(row[0], row[1])

    def count(self) -> int:
        a = self.db.execute("SELECT COUNT(*) FROM objs").fetchone()[0]
        b = self.db.execute("SELECT COUNT(*) FROM datas").fetchone()[0]
        return int(a + b)


# -- N-Triples straight from the tables ---------------------------------------------------------------------------
def escape_literal(text: str) -> str:
    """A literal's lexical form as N-Triples writes it between quotes."""
    return text.replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n").replace("\r", "\\r")


def ntriple_lines(db: sqlite3.Connection, where: str, params: Sequence[Any] = (),
                   by_subject: bool = False) -> Iterable[str]:
    """The triples of `objs` and `datas` rows matching `where` (on columns of `t`) as N-Triples lines, read
    row by row (nothing is loaded into owlready2), literals encoded as owlready2 encodes them. `by_subject`: read
    through the subject index (`where` names the subjects)."""
    def node(iri: str | None, sid: int) -> str:
        return f"_:b{-sid}" if sid < 0 or iri is None else f"<{iri}>"

    def table(name: str) -> str:
        return f"{name} t INDEXED BY {BY_SUBJECT[name]}" if by_subject else f"{name} t"

    q = (f"SELECT rs.iri, t.s, rp.iri, ro.iri, t.o FROM {table('objs')} LEFT JOIN resources rs ON rs.storid = t.s "
         "JOIN resources rp ON rp.storid = t.p LEFT JOIN resources ro ON ro.storid = t.o WHERE " + where)
    for s_iri, s, p_iri, o_iri, o in db.execute(q, params):
        yield f"{node(s_iri, s)} <{p_iri}> {node(o_iri, o)} .\n"
    q = (f"SELECT rs.iri, t.s, rp.iri, t.o, t.d, rd.iri FROM {table('datas')} LEFT JOIN resources rs ON rs.storid = t.s "
         "JOIN resources rp ON rp.storid = t.p LEFT JOIN resources rd ON rd.storid = t.d WHERE " + where)
    for s_iri, s, p_iri, o, d, d_iri in db.execute(q, params):
        text = f'"{escape_literal(str(o))}"'
        if isinstance(d, str) and d.startswith("@"):
            text += d
        elif d_iri:
            text += f"^^<{d_iri}>"
        yield f"{node(s_iri, s)} <{p_iri}> {text} .\n"


def other_contexts(db: sqlite3.Connection, c: int) -> list[int]:
    """The graph contexts of every ontology of the world but `c` (the TBox, for the ABox's context)."""
    return [int(x) for (x,) in db.execute("SELECT c FROM ontologies WHERE c <> ?", (c,))]


def storids_of(db: sqlite3.Connection, iris: Sequence[str]) -> list[int]:
    """The storids of those of `iris` that are stored (on any connection to the database)."""
    out: list[int] = []
    for i in range(0, len(iris), 500):
        chunk = list(iris[i:i + 500])
        out.extend(s for (s,) in db.execute(
            f"SELECT storid FROM resources WHERE iri IN ({','.join('?' * len(chunk))})", chunk))
    return out


def subjects_to(db: sqlite3.Connection, c: int, p: int, objects: Sequence[int]) -> list[int]:
    """Subjects s of context `c` with (s p o) for some o of `objects`."""
    return [s for o in objects for (s,) in db.execute("SELECT s FROM objs WHERE o = ? AND p = ? AND c = ?", (o, p, c))]


def reachable(db: sqlite3.Connection, c: int, roots: Iterable[int]) -> set[int]:
    """Every individual of context `c` reachable from `roots` by object properties (rdf:type excluded)."""
    seen = set(roots)
    frontier = list(seen)
    while frontier:
        found: set[int] = set()
        for i in range(0, len(frontier), 500):
            chunk = frontier[i:i + 500]
            q = (f"SELECT DISTINCT o FROM objs INDEXED BY {BY_SUBJECT['objs']} "
                 f"WHERE s IN ({','.join('?' * len(chunk))}) AND c = ? AND p <> ? AND o > 0")
            found.update(o for (o,) in db.execute(q, chunk + [c, RDF_TYPE]))
        frontier = list(found - seen)
        seen |= found
    return seen


def delete_individuals(db: sqlite3.Connection, c: int, sids: Sequence[int]) -> int:
    """Delete individuals of context `c`: their triples (as subject or object) and their IRIs, inside the open
    transaction; the number of triples deleted."""
    deleted = 0
    for i in range(0, len(sids), 500):
        chunk = list(sids[i:i + 500])
        marks = ",".join("?" * len(chunk))
        for table, index, column in (("objs", BY_SUBJECT, "s"), ("objs", BY_OBJECT, "o"), ("datas", BY_SUBJECT, "s")):
            deleted += db.execute(f"DELETE FROM {table} INDEXED BY {index[table]} WHERE {column} IN ({marks}) "
                                  "AND c = ?", chunk + [c]).rowcount
        db.execute(f"DELETE FROM resources WHERE storid IN ({marks})", chunk)
    return deleted


# -- reasoners ---------------------------------------------------------------------------------------------------
def reasoner_subprocess_kwargs() -> dict[str, Any]:
    """The dict owlready2 passes to `subprocess` for every reasoner call (a time limit is set there)."""
    kwargs: dict[str, Any] = owlready2.reasoning._subprocess_kargs
    return kwargs


def reasoner_classpath(reasoner: str) -> str:
    """The Java class path of owlready2's bundled HermiT or Pellet."""
    if reasoner == "hermit":
        return str(owlready2.reasoning._HERMIT_CLASSPATH)
    return str(owlready2.reasoning._PELLET_CLASSPATH)


def pellet_command(java: str) -> list[str]:
    """`java -Xmx… -cp <owlready2's Pellet> pellet.Pellet`: Pellet as owlready2 ships it."""
    return [java, f"-Xmx{owlready2.reasoning.JAVA_MEMORY}M", "-cp", owlready2.reasoning._PELLET_CLASSPATH,
            "pellet.Pellet"]


def facts_in(world: World, ontology_iri: str) -> int:
    """How many triples the ontology `ontology_iri` of `world` holds (what a reasoner inferred, e.g.)."""
    c = world.get_ontology(ontology_iri).graph.c
    db = world.graph.db
    return int(db.execute("SELECT COUNT(*) FROM objs WHERE c=?", (c,)).fetchone()[0]
               + db.execute("SELECT COUNT(*) FROM datas WHERE c=?", (c,)).fetchone()[0])


def ntriples_in(world: World, ontology_iri: str) -> list[str]:
    """The triples of the ontology `ontology_iri` of `world` as N-Triples lines (what a reasoner inferred, e.g.)."""
    c = world.get_ontology(ontology_iri).graph.c
    return list(ntriple_lines(world.graph.db, "t.c = ?", [c]))


def load_ntriples(world: World, ontology_iri: str, lines: Sequence[str]) -> None:
    """Load N-Triples lines into the ontology `ontology_iri` of `world`."""
    data = "".join(lines).encode("utf-8")
    if data.strip():
        world.get_ontology(ontology_iri).load(fileobj=io.BytesIO(data), format="ntriples", reload=True)


# -- what the adapter relies on ----------------------------------------------------------------------------------
def check_internals() -> None:
    """Verify every owlready2 internal this module relies on; raise OwlInternalsError naming what changed."""
    def need(ok: bool, what: str) -> None:
        if not ok:
            raise OwlInternalsError(f"owlready2 {getattr(owlready2, 'VERSION', '?')}: {what}")

    for name, value in (("rdf_type", rdf_type), ("owl_named_individual", owl_named_individual),
                        ("owl_ontology", owl_ontology)):
        need(isinstance(value, int), f"owlready2.base.{name} is no longer an integer storid")
    world = World()
    try:
        need(isinstance(getattr(world.graph, "db", None), sqlite3.Connection),
             "World.graph.db is no longer the sqlite3 connection")
        for table, columns in TABLES.items():
            got = tuple(row[1] for row in world.graph.db.execute(f"PRAGMA table_info({table})"))
            need(got == columns, f"table {table} has columns {got}, expected exactly {columns}")
        indexes = {name for (name,) in world.graph.db.execute("SELECT name FROM sqlite_master WHERE type='index'")}
        for index in (*BY_SUBJECT.values(), *BY_OBJECT.values()):
            need(index in indexes, f"the index {index} is gone (queries name it)")
        got = tuple(row[1] for row in world.graph.db.execute("PRAGMA table_info(store)"))
        need(STORE_COUNTER in got, f"table store has no column {STORE_COUNTER} (columns {got})")
        need(callable(getattr(world.graph, "_abbreviate", None)), "World.graph._abbreviate is gone")
        need(callable(getattr(world, "_to_rdf", None)) and callable(getattr(world, "_to_python", None)),
             "World._to_rdf / World._to_python are gone")
        for value in (7, 0.25, "text", True):
            o, d = world._to_rdf(value)
            back = world._to_python(o, d)
            need(back == value and type(back) is type(value), f"_to_rdf/_to_python no longer round-trip {value!r}")
        need(isinstance(getattr(owlready2.reasoning, "_subprocess_kargs", None), dict),
             "owlready2.reasoning._subprocess_kargs is no longer a dict")
        need(isinstance(getattr(owlready2.reasoning, "_PELLET_CLASSPATH", None), str),
             "owlready2.reasoning._PELLET_CLASSPATH is gone")
        need(isinstance(getattr(owlready2.reasoning, "_HERMIT_CLASSPATH", None), str),
             "owlready2.reasoning._HERMIT_CLASSPATH is gone")
        # Individuals written through the tables are what owlready2's own API then reads.
        store = QuadStore.__new__(QuadStore)
        store.world, store.db = world, world.graph.db
        onto_iri = "http://planhrc.org/check#"
        c = store.context(onto_iri)
        cls_sid = store.storid("http://www.w3.org/2002/07/owl#Thing")
        prop = store.storid(onto_iri + "value")
        (sid,) = store.allocate([onto_iri + "probe"])
        store.insert_objs(c, [(sid, RDF_TYPE, NAMED_INDIVIDUAL), (sid, RDF_TYPE, cls_sid)])
        store.insert_datas(c, [(sid, prop, 42)])
        need(store.storid(onto_iri + "probe", create=False) == sid, "_abbreviate does not find an allocated IRI")
        need(store.data(sid, prop) == 42, "a literal written to datas does not read back")
        entity = world[onto_iri + "probe"]
        need(entity is not None and entity.storid == sid, "owlready2 does not see an individual written to objs")
    finally:
        world.close()


def iri_pairs(world: World, property_iri: str) -> list[tuple[str, str]]:
    """(subject IRI, object IRI) of every triple of `world` with the property `property_iri`, told or inferred."""
    p = world.graph._abbreviate(property_iri, False)
    if not p:
        return []
    q = ("SELECT rs.iri, ro.iri FROM objs t JOIN resources rs ON rs.storid = t.s "
         "JOIN resources ro ON ro.storid = t.o WHERE t.p = ?")
    return [(s, o) for s, o in world.graph.db.execute(q, (p,))]

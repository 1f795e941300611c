"""The owlready2 adapter: what the store relies on in owlready2 still holds, and nothing else relies on it."""
import os
import re
import sqlite3
from pathlib import Path

import pytest

from planhrc.kb_service.store import owl
from planhrc.kb_service.store.owl import OwlInternalsError, check_internals

ROOT = Path(__file__).resolve().parents[1]
# Markers of owlready2 internals: its tables, storids, literal encoding, private modules and attributes.
INTERNALS = re.compile(r"_abbreviate|_to_rdf|_to_python|_subprocess_kargs|_PELLET_CLASSPATH|graph\.db\b|graph\.c\b"
                       r"|owlready2\.base|\bFROM (objs|datas|resources)\b|\bINTO (objs|datas|resources)\b|current_resource")


def test_owlready2_still_works_the_way_the_store_relies_on():
    """Fails loudly, naming the assumption, if an owlready2 upgrade changes a table, a storid or an encoding."""
    check_internals()


def test_a_changed_internal_is_reported_by_name(monkeypatch):
    monkeypatch.setattr(owl.owlready2.reasoning, "_PELLET_CLASSPATH", None)
    with pytest.raises(OwlInternalsError, match="_PELLET_CLASSPATH"):
        check_internals()


def test_only_the_adapter_touches_owlready2_internals():
    sources = [p for folder in ("planhrc", "kb_service", "translator", "planner", "robot_sim")
               for p in (ROOT / folder).rglob("*.py")]
    offenders = sorted(str(p.relative_to(ROOT)) for p in sources
                       if p != Path(owl.__file__).resolve() and INTERNALS.search(p.read_text()))
    assert offenders == []


def _vm_steps(db, read) -> int:
    """SQLite virtual-machine steps (in hundreds) that `read()` takes on `db`."""
    steps = [0]

    def count() -> int:
        steps[0] += 1
        return 0

    db.set_progress_handler(count, 100)
    try:
        read()
    finally:
        db.set_progress_handler(None, 0)
    return steps[0]


@pytest.mark.parametrize("read", ["reachable", "ntriple_lines", "delete_individuals"])
def test_reads_of_a_few_individuals_cost_the_same_however_full_their_context(read):
    """The export's walk from an object's current individuals, its N-Triples of them and the compaction's deletes
    read through the subject/object indexes: their cost does not grow with the rest of the context (SQLite's
    planner, left alone, read these through the index on `c`, i.e. the whole ABox history)."""
    iri = "http://planhrc.org/probe#"

    def cost(history: int) -> int:
        store = owl.QuadStore(None)
        try:
            c = store.context(iri)
            p = store.storid(iri + "p")
            mine = store.allocate([f"{iri}mine{n}" for n in range(120)])
            store.insert_objs(c, [(a, p, b) for a, b in zip(mine, mine[1:])])  # a chain: several rounds
            past = store.allocate([f"{iri}past{n}" for n in range(2 * history)])
            store.insert_objs(c, [(past[n], p, past[n + history]) for n in range(history)])
            store.insert_datas(c, [(s, p, 1) for s in past[:history]])
            db = store.db
            reads = {"reachable": lambda: owl.reachable(db, c, mine[:1]),
                     "ntriple_lines": lambda: list(owl.ntriple_lines(
                         db, f"t.c = ? AND t.s IN ({','.join('?' * len(mine))})", [c, *mine], by_subject=True)),
                     "delete_individuals": lambda: owl.delete_individuals(db, c, mine)}
            return _vm_steps(db, reads[read])
        finally:
            store.world.close()

    small, large = cost(1_000), cost(30_000)
    assert large < 1.3 * small + 20, (small, large)


def test_a_new_store_file_gets_small_pages_and_an_old_one_keeps_its_own(tmp_path):
    """A store this adapter creates has `PAGE_SIZE` pages (owlready2 makes 32 KiB ones); a file made before with
    owlready2's pages opens as it is (its page size is fixed once it is in WAL mode) and still works."""
    from planhrc.kb_service.store import SqliteStore
    from planhrc.paths import default_tbox_path

    with SqliteStore(str(tmp_path / "new.sqlite3"), default_tbox_path()) as kb:
        assert kb._abox.q.page_size() == owl.PAGE_SIZE == 4096
        kb.create_object(_object(kb))
    old = tmp_path / "old.sqlite3"
    world = owl.World(filename=str(old), exclusive=False)
    world.save()
    world.close()
    with SqliteStore(str(old), default_tbox_path()) as kb:
        assert kb._abox.q.page_size() == 32768
        kb.create_object(_object(kb))
        assert [o.ident for o in kb.list_objects()] == ["obj1"]


def _object(kb):
    from planhrc.model import make_object

    return make_object(kb.new_object_id(), "relative", 4, 12)


def test_a_replanning_perception_writes_little_to_the_log_however_long_the_history(tmp_path):
    """What one re-planning perception of an 8-link object writes to SQLite's log (pages x page size): each insert
    dirties the last page of every index group it adds to, so the page size decides. With owlready2's 32 KiB
    pages it was 1.3 MB here (after 20 perceptions; the file's writes, checkpoints included, grew from 3.9 to
    10 MB per perception over 3,000); with 4 KiB pages it is about 0.5 MB."""
    import random

    from planhrc.kb_service import usecases
    from planhrc.kb_service.store import SqliteStore
    from planhrc.paths import default_tbox_path
    from planhrc.settings import make_settings

    tbox = default_tbox_path()
    rng = random.Random(3)
    with SqliteStore(str(tmp_path / "kb.sqlite3"), tbox) as kb:
        context = usecases.open_context(kb, make_settings(tbox_path=str(tbox), planner="inproc"))
        ident = usecases.create_object(context, usecases.NewObject("bar", 8, 12, "relative")).id
        usecases.set_goal(context, usecases.GoalRequest(ident, tuple(rng.randrange(12) * 30 for _ in range(8))))

        def perceive(n: int) -> None:
            for _ in range(n):  # random configurations: nearly every one is off the plan and re-plans
                links = tuple(rng.randrange(12) * 30 for _ in range(8))
                usecases.perceive(context, usecases.PerceptionRequest(ident, links))

        perceive(20)
        kb.settle()  # the plans' triples too, as a reader of the triples has them written
        quads = kb._abox.q
        db = quads.db
        quads._checkpointer.close()  # its copies would race the count (a refused TRUNCATE leaves old frames)
        quads._checkpointer = None
        assert db.execute("PRAGMA wal_checkpoint(TRUNCATE)").fetchall()[0][0] == 0
        db.execute("PRAGMA wal_autocheckpoint = 0")  # the log keeps every page written from here on
        perceive(10)
        kb.settle()
        frames = db.execute("PRAGMA wal_checkpoint(PASSIVE)").fetchall()[0][1]
        per_perception = frames * quads.page_size() / 10
        usecases.close_context(context)
    assert per_perception < 800_000, per_perception


def _write_rows(store, writes: int) -> int:
    """`writes` back-to-back commits of 100 new individuals each on a WAL store; the longest its log file got."""
    iri = "http://planhrc.org/probe#"
    c = store.context(iri)
    p = store.storid(iri + "p")
    longest = 0
    for n in range(writes):
        sids = store.allocate([f"{iri}n{n}_{k}" for k in range(100)])
        store.insert_objs(c, [(a, p, b) for a, b in zip(sids, sids[1:])])
        store.commit()
        longest = max(longest, os.path.getsize(store.db.execute("PRAGMA database_list").fetchone()[2] + "-wal"))
    return longest


def test_the_log_is_copied_beside_the_writes_and_stays_short(tmp_path, monkeypatch):
    """A file store's writer never checkpoints inside a commit (`wal_autocheckpoint` 0): a thread of its own
    copies the log into the file after each commit. Under back-to-back writes it is always a commit behind, and
    past `WAL_RESTART_PAGES` pages or `CATCH_UP_COMMITS` commits the writer copies the rest, so the log restarts instead of growing with the writes
    (measured against the same writes with nothing copying the log). Closing the store stops the thread, and
    everything written is in the file."""
    import threading

    monkeypatch.setattr(owl, "WAL_RESTART_PAGES", 64)
    monkeypatch.setattr(owl, "CATCH_UP_COMMITS", 16)
    monkeypatch.setattr(owl, "WAL_FILE_LIMIT", 64 * owl.PAGE_SIZE)
    unchecked = owl.QuadStore(str(tmp_path / "unchecked.sqlite3"))
    unchecked.use_wal()
    unchecked._checkpointer.close()
    unchecked._checkpointer = None  # nothing copies its log
    grown = _write_rows(unchecked, 400)
    unchecked.close()

    path = tmp_path / "q.sqlite3"
    store = owl.QuadStore(str(path))
    store.use_wal()
    assert store.db.execute("PRAGMA wal_autocheckpoint").fetchone()[0] == 0
    longest = _write_rows(store, 400)
    assert any(t.name == "planhrc-checkpoint" for t in threading.enumerate())
    store.close()
    assert not any(t.name == "planhrc-checkpoint" for t in threading.enumerate())
    assert longest < grown / 3, (longest, grown)
    check = sqlite3.connect(str(path))
    assert check.execute("SELECT COUNT(*) FROM objs").fetchone()[0] >= 400 * 99
    check.close()


def _wait_for(condition, timeout_s: float = 10.0) -> bool:
    import time

    end = time.monotonic() + timeout_s
    while not condition():
        if time.monotonic() > end:
            return False
        time.sleep(0.01)
    return True


def test_the_checkpoint_thread_wakes_for_commits_only(tmp_path, monkeypatch):
    """The log is copied after a commit (`GATHER_S` after a lone one; `GATHER_COMMITS` commits in a row are copied
    at once); an idle store's thread sleeps (no checkpoint while nothing is written), except that a checkpoint a
    reader kept from copying the whole log is tried again `RETRY_S` later, and the log is copied once the reader
    is gone, with no further commit."""
    import time

    monkeypatch.setattr(owl, "RETRY_S", 0.2)
    monkeypatch.setattr(owl, "GATHER_S", 1.0)  # a lone commit's wait, shortened for the test
    path = tmp_path / "q.sqlite3"
    store = owl.QuadStore(str(path))
    store.use_wal()
    ckpt = store._checkpointer
    assert ckpt is not None
    iri = "http://planhrc.org/probe#"
    c = store.context(iri)

    def write(name: str) -> None:
        sid = store.allocate([iri + name])[0]
        store.insert_objs(c, [(sid, sid, sid)])
        store.commit()

    write("first")
    assert _wait_for(lambda: ckpt.checkpoints >= 1)
    done = ckpt.checkpoints
    time.sleep(1.5)  # longer than the thread used to sleep between wake-ups
    assert ckpt.checkpoints == done  # idle: nothing copied, nothing tried
    write("second")
    assert _wait_for(lambda: ckpt.checkpoints > done)
    time.sleep(0.3)
    done = ckpt.checkpoints
    for k in range(owl.GATHER_COMMITS):
        write(f"burst{k}")
    assert _wait_for(lambda: ckpt.checkpoints > done)
    time.sleep(owl.GATHER_S + 0.3)
    assert ckpt.checkpoints == done + 1  # the burst was copied once
    busy, pages, copied = ckpt.checkpoint()
    assert not busy and copied == pages

    reader = sqlite3.connect(str(path))
    reader.execute("BEGIN")
    reader.execute("SELECT COUNT(*) FROM objs").fetchone()  # holds a snapshot: frames after it stay in the log
    write("late")
    tried = ckpt.checkpoints
    assert _wait_for(lambda: ckpt.checkpoints >= tried + 2)  # tried again without a commit, while it is held
    assert ckpt.left_behind
    reader.execute("COMMIT")
    reader.close()
    assert _wait_for(lambda: not ckpt.left_behind)  # a retry copied the rest, with no commit
    busy, pages, copied = ckpt.checkpoint()
    assert not busy and copied == pages
    done = ckpt.checkpoints
    time.sleep(0.6)
    assert ckpt.checkpoints == done  # and the thread sleeps again
    store.close()

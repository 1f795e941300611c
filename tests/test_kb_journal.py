"""A plan is stored as one journal row in the transaction that adopts it and written out as triples by the store's
writer thread soon after (`kb_service/store/journal.py`, `backlog.py`): answered at once, never lost, the same
triples in the end."""
from __future__ import annotations

import subprocess
import sys
import textwrap
import threading
import time

import pytest

from planhrc.kb_service.store import ABOX_IRI, KnowledgeBase, KnowledgeStore
from planhrc.kb_service.store.abox import Abox
from planhrc.kb_service.store.errors import DamagedStoreError, NotFoundError
from planhrc.kb_service.store import journal
from planhrc.kb_service.store.journal import JournalEntry, decode, encode
from planhrc.model import make_object
from planhrc.paths import default_tbox_path
from tests.store_backends import journal_rows, place  # noqa: F401 (fixtures)
from tests.test_kb_scenarios import plan_for

TBOX = default_tbox_path()


def _object_with_problem(kb: KnowledgeStore, formulation: str = "absolute"):
    obj = make_object("obj1", formulation, 4, 8)
    kb.create_object(obj)
    start = kb.add_state("obj1", "perceived", obj.state([0] * (4 if formulation == "absolute" else 3)))
    actions, states = plan_for(obj, start.atoms, [(1, True), (3, False), (2, True)])
    goal = kb.add_state("obj1", "goal", states[-1])
    return obj, kb.add_problem("obj1", start.id, goal.id), actions, states


def test_a_row_holds_every_part_of_the_plan():
    obj = make_object("obj1", "absolute", 4, 8)
    actions, states = plan_for(obj, obj.state([0, 0, 0, 0]), [(1, True), (3, False)])
    entry = JournalEntry("obj1_plan_3", "obj1", "obj1_problem_2", "inproc", 12.5, 7, tuple(actions), tuple(states))
    assert any(a.cond_eff for a in actions)
    assert decode(encode(entry)) == entry


def test_a_plan_is_answered_at_once_and_its_triples_follow(place, monkeypatch):
    monkeypatch.setattr(journal, "WRITE_DELAY_S", 1.0)  # the checks right after the commit come first, under any load
    with place.open() as kb:
        _, problem, actions, states = _object_with_problem(kb)
        before = kb.triple_count()
        plan = kb.add_plan(problem.id, "inproc", actions, states)
        assert kb.get_plan(plan.id) == plan
        assert kb.get_state(plan.expected_state_ids[-1]).atoms == frozenset(states[-1])
        assert kb.get_action(plan.actions[0].id) == plan.actions[0]
        assert place.journal_rows() == kb.plans_to_write() == 1  # answered from the journal ...
        assert kb.triple_count() == before
        deadline = time.monotonic() + 10
        while place.journal_rows() and time.monotonic() < deadline:  # ... written by the writer thread, not a reader
            time.sleep(0.02)
        assert place.journal_rows() == kb.plans_to_write() == 0
        assert kb.triple_count() > before + 100
    with place.open() as again:  # read back from the triples alone
        assert again.get_plan(plan.id) == plan


def test_a_process_killed_before_the_write_out_keeps_its_plan(place):
    child = textwrap.dedent(f"""
        import os, sys
        from planhrc.kb_service.store import journal
        journal.WRITE_DELAY_S = 600.0  # the writer never gets to it: the process dies first
        from planhrc.kb_service.store import open_store
        from planhrc.paths import default_tbox_path
        from tests.test_kb_journal import _object_with_problem
        kb = open_store({place.db!r}, default_tbox_path())
        _, problem, actions, states = _object_with_problem(kb)
        plan = kb.add_plan(problem.id, "inproc", actions, states)
        print(plan.id, flush=True)
        os._exit(0)
    """)
    done = subprocess.run([sys.executable, "-c", child], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    plan_id = done.stdout.split()[-1]
    assert place.journal_rows() == 1
    with place.open() as kb:  # opening writes the row out before anything is served
        assert place.journal_rows() == kb.plans_to_write() == 0
        plan = kb.get_plan(plan_id)
    with place.open() as again:
        assert again.get_plan(plan_id) == plan
        assert len(plan.actions) == 3
        text = again.export("nt").decode()
        assert f"<{ABOX_IRI}{plan.actions[2].id}>" in text


def test_a_failed_write_out_keeps_the_row_and_the_plan(tmp_path, monkeypatch):
    """The SQLite backend's writer fails to write a plan's triples (the disk full): the row stays, the plan is
    still answered, and the next write-out writes it."""
    path = str(tmp_path / "kb.sqlite3")
    with KnowledgeBase(path, TBOX) as kb:
        _, problem, actions, states = _object_with_problem(kb, "relative")
        original = Abox.flush
        monkeypatch.setattr(Abox, "flush", lambda self, batch: (_ for _ in ()).throw(OSError("disk full")))
        with kb.transaction():  # inside a transaction the writer waits: nothing is written before the patch
            plan = kb.add_plan(problem.id, "inproc", actions, states)
        with pytest.raises(OSError):
            kb.settle()
        assert journal_rows("sqlite", path) == 1
        assert kb.get_plan(plan.id) == plan  # still answered
        monkeypatch.setattr(Abox, "flush", original)
        kb.settle()
        assert journal_rows("sqlite", path) == 0
        assert kb.get_plan(plan.id) == plan


def test_a_rolled_back_plan_leaves_nothing(place):
    with place.open() as kb:
        _, problem, actions, states = _object_with_problem(kb)
        with pytest.raises(RuntimeError):
            with kb.transaction():
                plan = kb.add_plan(problem.id, "inproc", actions, states)
                raise RuntimeError("the decision's write failed")
        with pytest.raises(NotFoundError):
            kb.get_plan(plan.id)
        with pytest.raises(NotFoundError):
            kb.get_state(plan.expected_state_ids[0])
        assert place.journal_rows() == kb.plans_to_write() == 0
        assert kb.add_plan(problem.id, "inproc", actions, states).id == plan.id  # no id was used up


def test_readers_of_the_triples_see_a_plan_just_adopted(place):
    for make in (place.open, lambda: KnowledgeBase(None, TBOX)):  # every backend, and the SQLite store in memory
        with make() as kb:
            _, problem, actions, states = _object_with_problem(kb)
            plan = kb.add_plan(problem.id, "inproc", actions, states)
            assert f"<{ABOX_IRI}{plan.actions[0].id}>" in kb.export("nt").decode()


def test_a_row_holds_the_expected_states_as_changes_and_rows_of_the_layout_before_are_read():
    """The row keeps the first expected state and each next one's dropped and added atoms (a few atoms a step),
    and decodes to the same plan; a row written whole by the layout before is still read."""
    import pickle

    obj = make_object("obj1", "relative", 20, 12)
    start = obj.state([0] * 19)
    actions, states = plan_for(obj, start, [(k, k % 2 == 0) for k in range(1, 19)] * 2)
    entry = JournalEntry("obj1_plan_3", "obj1", "obj1_problem_2", "inproc", 12.5, 7, tuple(actions), tuple(states))
    row = encode(entry)
    assert decode(row) == entry
    whole = pickle.dumps((journal.WHOLE_STATES, *pickle.loads(row)[1:8], tuple(states)), protocol=5)
    assert decode(whole) == entry
    assert len(row) < len(whole) / 2, (len(row), len(whole))
    with pytest.raises(DamagedStoreError, match="unknown layout"):
        decode(pickle.dumps((99, "x")))
    with pytest.raises(DamagedStoreError, match="does not read back"):
        decode(row[: len(row) // 2])


def test_a_request_waiting_for_the_store_gets_it_between_two_plans_written_out(monkeypatch):
    """The writer takes the store's lock once per plan; a thread waiting for that lock must get it after the plan
    being written, not after every plan left (a lock released and taken again at once is not handed over)."""
    monkeypatch.setattr(journal, "WRITE_DELAY_S", 0.0)
    lock = threading.RLock()
    left = [20]
    writing = threading.Event()

    def write_one() -> bool:  # one plan: 5 ms with the store's lock held
        with lock:
            writing.set()
            time.sleep(0.005)
            left[0] -= 1
            return left[0] > 0

    writer = journal.PlanWriter(write_one)
    try:
        writer.poke()
        assert writing.wait(5)
        with lock:
            behind = left[0]  # plans still to write when the waiting thread got the store
    finally:
        writer.close()
    assert behind >= 15, f"the waiting thread got the store only with {behind} of 20 plans left"


def test_a_damaged_journal_row_refuses_the_store_and_leaves_no_thread_behind(tmp_path):
    """A row this version cannot read (damaged, or written by a newer layout) stops the SQLite store from opening
    with a DamagedStoreError, before it serves anything, and the threads it had started are stopped."""
    import sqlite3

    path = str(tmp_path / "kb.sqlite3")
    with KnowledgeBase(path, TBOX) as kb:
        _object_with_problem(kb)
    with sqlite3.connect(path) as conn:
        conn.execute("INSERT INTO planhrc_plan_journal VALUES ('obj1_plan_1', ?)", (b"\x80\x05not a pickle",))
    before = {t.name for t in threading.enumerate()}
    with pytest.raises(DamagedStoreError, match="^plan journal: a row that does not read back"):
        KnowledgeBase(path, TBOX)
    deadline = time.monotonic() + 10
    while {t.name for t in threading.enumerate()} - before and time.monotonic() < deadline:
        time.sleep(0.02)
    assert {t.name for t in threading.enumerate()} - before == set()

"""A plan is stored as one journal row in the transaction that adopts it, read from that row, and written out as
triples only when a reader of the triples needs them (`kb_service/store/journal.py`, `backlog.py`): answered at once,
never lost, the same triples whenever they are written."""
from __future__ import annotations

import subprocess
import sys
import textwrap
import threading
import time

import pytest

from planhrc.kb_service.store import ABOX_IRI, KnowledgeStore, SqliteStore
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


def test_a_plan_is_answered_from_its_row_and_written_out_when_the_triples_are_read(place):
    with place.open() as kb:
        _, problem, actions, states = _object_with_problem(kb)
        before = kb.triple_count()
        plan = kb.add_plan(problem.id, "inproc", actions, states)
        assert kb.get_plan(plan.id) == plan
        assert kb.get_state(plan.expected_state_ids[-1]).atoms == frozenset(states[-1])
        assert kb.get_action(plan.actions[0].id) == plan.actions[0]
        time.sleep(0.3)  # nothing writes the plan out behind the answer
        assert place.journal_rows() == kb.plans_to_write() == 1
        assert kb.triple_count() == before
    with place.open() as again:  # another process: read from the row, which opening leaves as it is
        assert again.get_plan(plan.id) == plan
        assert [again.get_state(s).atoms for s in plan.expected_state_ids] == [frozenset(s) for s in states]
        assert again.get_action(plan.actions[2].id) == plan.actions[2]
        assert place.journal_rows() == again.plans_to_write() == 1
        assert f"<{ABOX_IRI}{plan.actions[2].id}>" in again.export("nt").decode()  # a reader of the triples ...
        assert place.journal_rows() == again.plans_to_write() == 0  # ... has it written out first
        assert again.triple_count() > before + 100
    with place.open() as third:  # read back from the triples alone
        assert third.get_plan(plan.id) == plan
        assert [third.get_state(s).atoms for s in plan.expected_state_ids] == [frozenset(s) for s in states]


def test_a_process_killed_right_after_its_commit_keeps_its_plan(place):
    child = textwrap.dedent(f"""
        import os, sys
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
    with place.open() as kb:  # the row is the plan
        plan = kb.get_plan(plan_id)
        assert len(plan.actions) == 3
        text = kb.export("nt").decode()
        assert f"<{ABOX_IRI}{plan.actions[2].id}>" in text
        assert place.journal_rows() == 0
    with place.open() as again:
        assert again.get_plan(plan_id) == plan


def test_a_failed_write_out_keeps_the_row_and_the_plan(tmp_path, monkeypatch):
    """The SQLite backend's writer fails to write a plan's triples (the disk full): the row stays, the plan is
    still answered, and the next write-out writes it."""
    path = str(tmp_path / "kb.sqlite3")
    with SqliteStore(path, TBOX) as kb:
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
    for make in (place.open, lambda: SqliteStore(None, TBOX)):  # every backend, and the SQLite store in memory
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
    header = pickle.loads(row)[1:7]  # plan, object, problem, planner, time, first state's counter
    action_pieces, count, first_pieces, change_pieces = pickle.loads(pickle.loads(row)[7])  # the body, in pieces
    actions_rows = tuple(row for piece in action_pieces for row in pickle.loads(piece))
    first = frozenset(atom for piece in first_pieces for atom in pickle.loads(piece))
    as_changes = (count, first, tuple(c for piece in change_pieces for c in pickle.loads(piece)))
    whole = pickle.dumps((journal.WHOLE_STATES, *header, actions_rows, tuple(states)), protocol=5)
    assert decode(whole) == entry
    inline = pickle.dumps((journal.AS_CHANGES, *header, actions_rows, as_changes), protocol=5)
    assert decode(inline) == entry  # the layout before the body was pickled apart
    assert len(row) < len(whole) / 2, (len(row), len(whole))
    # the body made before the write (outside the store's lock) is the body the row would have made itself
    assert encode(entry, journal.encode_body(entry.actions, entry.expected_states)) == row


def test_a_large_plans_row_is_pickled_in_pieces_that_each_hold_the_interpreter_briefly(monkeypatch):
    """No single pickling of a large plan's row holds the interpreter (and every other request) for long: the
    body is pickled in pieces of at most ATOMS_PER_PIECE atoms (one item larger alone: its own piece), and reads
    back the same whatever the pieces' size."""
    import pickle

    obj = make_object("obj1", "absolute", 12, 8)
    start = obj.state([0] * obj.n_joints)
    actions, states = plan_for(obj, start, [(k, k % 3 == 0) for k in range(1, obj.n_joints + 1)] * 3)
    entry = JournalEntry("obj1_plan_3", "obj1", "obj1_problem_2", "inproc", 12.5, 7, tuple(actions), tuple(states))
    whole = decode(encode(entry))
    monkeypatch.setattr(journal, "ATOMS_PER_PIECE", 40)
    row = encode(entry)
    assert decode(row) == entry == whole
    action_pieces, _, first_pieces, change_pieces = pickle.loads(pickle.loads(row)[7])
    assert len(action_pieces) > 10 and len(first_pieces) > 2 and len(change_pieces) > 1
    for piece in action_pieces:
        rows = pickle.loads(piece)
        assert len(rows) == 1 or sum(journal._action_atoms(r) for r in rows) <= 40
    with pytest.raises(DamagedStoreError, match="unknown layout"):
        decode(pickle.dumps((99, "x")))
    with pytest.raises(DamagedStoreError, match="does not read back"):
        decode(row[: len(row) // 2])


def test_a_request_waiting_for_the_store_gets_it_between_two_plans_written_out(tmp_path):
    """An export of the whole history writes out every journalled plan, taking the store's lock once per plan; a
    request waiting for that lock gets it after the plan being written, not after every plan left (a lock released
    and taken again at once is not handed over)."""
    with SqliteStore(str(tmp_path / "kb.sqlite3"), TBOX) as kb:
        _, problem, actions, states = _object_with_problem(kb, "relative")
        plans = [kb.add_plan(problem.id, "inproc", actions, states) for _ in range(20)]
        exporting = threading.Thread(target=lambda: kb.export("nt", "all"))
        exporting.start()
        deadline = time.monotonic() + 10
        while kb.plans_to_write() == 20 and time.monotonic() < deadline:
            time.sleep(0.001)
        kb.get_object("obj1")  # takes the store's lock
        behind = kb.plans_to_write()
        exporting.join(60)
        assert kb.plans_to_write() == 0 and all(kb.get_plan(p.id) == p for p in plans)
    assert behind >= 15, f"the waiting request got the store only with {behind} of 20 plans left"


def test_a_damaged_journal_row_refuses_the_store_and_leaves_no_thread_behind(tmp_path):
    """A row this version cannot read (damaged, or written by a newer layout) stops the SQLite store from opening
    with a DamagedStoreError, before it serves anything, and the threads it had started are stopped."""
    import sqlite3

    path = str(tmp_path / "kb.sqlite3")
    with SqliteStore(path, TBOX) as kb:
        _object_with_problem(kb)
    with sqlite3.connect(path) as conn:
        conn.execute("INSERT INTO planhrc_plan_journal VALUES ('obj1_plan_1', ?, 'obj1', 9, 12)",
                     (b"\x80\x05not a pickle",))
    before = {t.name for t in threading.enumerate()}
    with pytest.raises(DamagedStoreError, match="^plan journal: a row that does not read back"):
        SqliteStore(path, TBOX)
    deadline = time.monotonic() + 10
    while {t.name for t in threading.enumerate()} - before and time.monotonic() < deadline:
        time.sleep(0.02)
    assert {t.name for t in threading.enumerate()} - before == set()


def test_a_journal_table_written_before_rows_named_their_states_is_read(tmp_path):
    """A store whose journal rows hold only the plan's id and payload (the layout before a row named its object
    and states): opening it adds the columns, filled from the payloads, and every state is read from its row."""
    import sqlite3

    path = str(tmp_path / "kb.sqlite3")
    with SqliteStore(path, TBOX) as kb:
        _, problem, actions, states = _object_with_problem(kb)
        plan = kb.add_plan(problem.id, "inproc", actions, states)
    with sqlite3.connect(path) as conn:
        payload = conn.execute("SELECT payload FROM planhrc_plan_journal").fetchone()[0]
        conn.execute("DROP TABLE planhrc_plan_journal")
        conn.execute("CREATE TABLE planhrc_plan_journal (plan_id TEXT PRIMARY KEY, payload BLOB NOT NULL)")
        conn.execute("INSERT INTO planhrc_plan_journal VALUES (?, ?)", (plan.id, payload))
    with SqliteStore(path, TBOX) as kb:
        assert kb.plans_to_write() == 1
        assert [kb.get_state(s).atoms for s in plan.expected_state_ids] == [frozenset(s) for s in states]
        assert kb.get_plan(plan.id) == plan


def _history_of_plans(kb: KnowledgeStore, write_out: bool) -> None:
    """An object with two re-plans: with `write_out` every plan's triples are written at once (as the store did
    behind every answer), else they stay journal rows until a reader needs them."""
    obj = make_object("obj1", "absolute", 4, 8)
    kb.create_object(obj)
    goal = kb.add_state("obj1", "goal", obj.configuration_atoms([90, 0, 45, 0]))
    for values, moves in (([0, 0, 0, 0], [(1, True), (3, False), (2, True)]), ([45, 0, 0, 90], [(4, False)])):
        start = kb.add_state("obj1", "perceived", obj.state(values), [float(v) for v in values])
        actions, states = plan_for(obj, start.atoms, moves)
        kb.add_plan(kb.add_problem("obj1", start.id, goal.id).id, "inproc", actions, states)
        if write_out:
            kb.settle()


def _lines(kb: KnowledgeStore, history: str) -> set[str]:
    return set(kb.export("nt", history).decode().splitlines())


def test_plans_written_out_when_read_give_the_facts_written_at_once(place, tmp_path, monkeypatch):
    """The export of a store whose plans stayed journal rows until it was read is the export of the same writes
    with every plan written out at once: the current ABox and the whole history, fact for fact."""
    monkeypatch.setattr(time, "time", lambda: 1_700_000_000.0)  # the records' createdAt: the same in both
    other = place.another(tmp_path / "eager")
    with place.open() as lazy, other.open() as eager:
        _history_of_plans(lazy, write_out=False)
        _history_of_plans(eager, write_out=True)
        assert (lazy.plans_to_write(), eager.plans_to_write()) == (2, 0)
        current = _lines(lazy, "current")
        assert lazy.plans_to_write() == 1  # the current export wrote out the current plan only
        assert current == _lines(eager, "current")
        assert _lines(lazy, "all") == _lines(eager, "all")
        assert lazy.plans_to_write() == 0 and lazy.triple_count() == eager.triple_count()


@pytest.mark.reasoner
def test_plans_written_out_when_read_give_the_inferences_of_plans_written_at_once(monkeypatch):
    """Pellet infers the same facts from the world of a store whose plans stayed journal rows (written out when the
    reasoner's copy is made) as from one whose plans were written at once, and finds both consistent."""
    from planhrc.kb_service.reasoner import INFERENCES_IRI, copy_world, reason_in_place
    from planhrc.kb_service.store.owl import ntriples_in

    monkeypatch.setattr(time, "time", lambda: 1_700_000_000.0)
    inferred = []
    for write_out in (False, True):
        with SqliteStore(None, TBOX) as kb:
            _history_of_plans(kb, write_out)
            world = copy_world(kb)
            assert kb.plans_to_write() == 0
        try:
            consistent, _ = reason_in_place(world, "pellet", 120.0)
            assert consistent
            inferred.append(set(ntriples_in(world, INFERENCES_IRI)))
        finally:
            world.close()
    assert inferred[0] and inferred[0] == inferred[1]


@pytest.mark.reasoner
def test_the_reasoning_service_infers_the_same_from_plans_written_out_when_read(place, tmp_path, monkeypatch):
    """The knowledge service's DL check (`knowledge.reasoning.reason`, on the store's export) of the whole current
    ABox, the plan with its actions and expected states too, finds the same inferences, consistent, in a store whose
    plans stayed journal rows as in one whose plans were written at once, on each backend."""
    from rdflib import Graph

    from planhrc.kb_service.knowledge.reasoning import ReasoningRequest, reason
    from planhrc.kb_service.knowledge.entailment import Vocabulary
    from planhrc.vocabulary import ReasoningScope

    tbox = Graph()
    tbox.parse(str(TBOX), format="xml")
    vocabulary = Vocabulary.of(tbox)
    monkeypatch.setattr(time, "time", lambda: 1_700_000_000.0)
    other = place.another(tmp_path / "eager")
    request = ReasoningRequest("pellet", "obj1", ReasoningScope.CURRENT)
    with place.open() as lazy, other.open() as eager:
        _history_of_plans(lazy, write_out=False)
        _history_of_plans(eager, write_out=True)
        plan = lazy.latest_plan("obj1")
        assert plan is not None and lazy.plans_to_write() == 2  # the plans are rows until the reasoner reads them
        results = [reason(kb, request, 120.0, vocabulary, tmp_path) for kb in (lazy, eager)]
    assert all(result.consistent for result in results)
    assert results[0].inferred and set(results[0].inferred) == set(results[1].inferred)
    # the current plan's expected states were among what the reasoner read
    assert any(f"#{state}>" in line for state in plan.expected_state_ids for line in results[0].inferred)


def test_a_plan_whose_states_are_kept_as_changes_is_stored_without_making_them_and_reads_the_same(place,
                                                                                                  monkeypatch):
    """A plan given with the replay's `ExpectedStates` and checked on its first steps: its write makes no state
    whole past those (its row is the first state and the changes; each state's record is made when it is read), and
    every state reads back as the replayed one, in this process and in another."""
    from planhrc.transition import ExpectedStates, replay
    from planhrc.translator.domain import read_domain_model

    made: list[int] = []
    real_make = ExpectedStates._make

    def counted(self, k):
        made.append(k)
        return real_make(self, k)

    monkeypatch.setattr(ExpectedStates, "_make", counted)
    obj = make_object("obj1", "absolute", 8, 8)
    domain = read_domain_model(TBOX, "absolute")
    with place.open() as kb:
        kb.create_object(obj)
        start = kb.add_state("obj1", "perceived", obj.state([0] * 8))
        plan_steps = [f"(rotateclockwise obj1_l{k} obj1_l{k - 1} obj1_j{k} deg_{45 * i} deg_{45 * (i + 1)})"
                      for k in (8, 6, 4, 2) for i in range(3)]
        actions, states = replay(domain, start.atoms, plan_steps)
        whole = [frozenset(s) for s in states]
        goal = kb.add_state("obj1", "goal", states[-1])
        problem = kb.add_problem("obj1", start.id, goal.id)
        made.clear()
        checked = kb.check_plan("obj1", actions, states, first_steps=3)
        plan = kb.add_plan(problem.id, "inproc", actions, states, checked)
        assert sorted(set(made)) == [1, 2, 3]  # s^e_2 .. s^e_4 for the check of a_1 .. a_3, nothing for the write
        assert [kb.get_state(s).atoms for s in plan.expected_state_ids] == whole
    with place.open() as again:
        assert [again.get_state(s).atoms for s in plan.expected_state_ids[::-1]] == whole[::-1]


def test_a_record_put_to_be_made_later_is_made_once_when_first_got():
    from planhrc.kb_service.store.cache import RecordCache
    from planhrc.kb_service.store.records import StoredState

    calls: list[str] = []
    cache = RecordCache("state", StoredState, lambda ident: None)

    def make(ident):
        def build():
            calls.append(ident)
            return StoredState(ident, "o", "expected", frozenset({("p",)}), 1.0)
        return build

    cache.put_later("o_state_1", make("o_state_1"))
    cache.put_later("o_state_2", make("o_state_2"))
    assert len(cache) == 2 and calls == []
    assert cache.get("o_state_2").id == "o_state_2" and cache.get("o_state_2").id == "o_state_2"
    assert calls == ["o_state_2"] and len(cache) == 2
    cache.clear()
    with pytest.raises(NotFoundError):
        cache.get("o_state_1")
    assert calls == ["o_state_2"]

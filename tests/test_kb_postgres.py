"""The PostgreSQL store beside the SQLite one: the same history gives the same RDF export and the same reasoning,
acknowledged writes survive a process killed mid-transaction, and what replicas need (two stores on one database,
the per-object lock, the event feed) works. The rest of the store suite runs on both backends
(`tests/store_backends.py`)."""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
import textwrap
import threading
import time
from collections.abc import Iterator

import pytest
import rdflib
from rdflib.compare import isomorphic

from planhrc.kb_service.store import TBOX_IRI, KBError, KnowledgeStore, SqliteStore, open_store
from planhrc.kb_service.store.records import Execution
from planhrc.model import make_object, snap_angle
from planhrc.paths import default_tbox_path
from tests.store_backends import journal_rows
from tests.test_kb_scenarios import plan_for
from tests.processes import alive

TBOX = default_tbox_path()
CREATED_AT = rdflib.URIRef(TBOX_IRI + "createdAt")


@pytest.fixture
def pg_url(pg_cluster) -> Iterator[str]:
    url = pg_cluster.database()
    yield url
    pg_cluster.drop(url)


def _history(kb: KnowledgeStore) -> None:
    """Objects, goals, perceptions, re-plans with their events and execution: what the service writes."""
    a = make_object("obj1", "absolute", [0.1, 0.2, 0.15], 4, name="arm")
    r = make_object("obj2", "relative", 4, 8)
    for obj in (a, r):
        kb.create_object(obj)
    goal = kb.add_state("obj1", "goal", a.configuration_atoms([90, 90, 90]))
    kb.add_event("obj1", "goal_set", "", {"goal_state_id": goal.id})
    for k, raw in enumerate(([1.0, 92.0, 178.5], [0.0, 0.0, 0.0], [91.0, 0.0, 180.0], [0.0, 90.0, 90.0])):
        with kb.transaction():  # one perception, one transaction
            perceived = kb.add_state("obj1", "perceived", a.state([snap_angle(x, 4) for x in raw]), raw)
            problem = kb.add_problem("obj1", perceived.id, goal.id)
            actions, states = plan_for(a, perceived.atoms, [(1 + k % 3, True), (3, False)])
            plan = kb.add_plan(problem.id, "inproc", actions, states)
            kb.add_event("obj1", "replan", "perceived", {"perceived_state_id": perceived.id, "plan_id": plan.id})
            kb.set_execution("obj1", Execution(plan.id, 1, "ready"))
    initial = kb.add_state("obj2", "initial", r.state([0, 45, 315]))
    rel_actions, rel_states = plan_for(r, initial.atoms, [(1, False), (2, True)])
    problem = kb.add_problem("obj2", initial.id, kb.add_state("obj2", "goal", rel_states[-1]).id)
    kb.add_plan(problem.id, "inproc", rel_actions, rel_states)
    kb.remember_response("obj1", "key-1", {"state_id": goal.id})


def _graph(kb: KnowledgeStore, history: str) -> tuple[rdflib.Graph, int]:
    """The export as a graph without the creation times (the two stores wrote at other moments), and how many
    creation times there were."""
    graph = rdflib.Graph()
    graph.parse(data="".join(kb.export_lines(history)), format="nt")
    times = list(graph.triples((None, CREATED_AT, None)))
    for triple in times:
        graph.remove(triple)
    return graph, len(times)


def test_the_literals_take_owlready2s_forms():
    """A PostgreSQL row's literal is what owlready2 writes for the same value in the SQLite store."""
    from owlready2 import World

    from planhrc.kb_service.store.postgres.rows import literal, value_of

    world = World()
    try:
        for value in (7, -3, 0.25, 0.1, 1775000000.123456, 1e-07, 90.0, "text", "", True, False):
            o, d = world._to_rdf(value)
            assert literal(value) == (str(o), world._unabbreviate(d)), value
            back = value_of(*literal(value))
            assert back == value and type(back) is type(value)
    finally:
        world.close()


def test_the_same_history_gives_the_same_export_on_both_backends(pg_url, tmp_path):
    with SqliteStore(str(tmp_path / "kb.sqlite3"), TBOX) as sqlite, open_store(pg_url, TBOX) as pg:
        for kb in (sqlite, pg):
            _history(kb)
        for history in ("current", "all"):
            (g_sqlite, t_sqlite), (g_pg, t_pg) = _graph(sqlite, history), _graph(pg, history)
            assert t_sqlite == t_pg > 0, history
            assert len(g_sqlite) == len(g_pg) > 2000, history
            assert isomorphic(g_sqlite, g_pg), history
        assert _graph(pg, "current")[0] != _graph(pg, "all")[0]  # the current ABox is not the history
        sqlite.settle()
        assert pg.triple_count() == sqlite.triple_count()
        assert pg.compact(1) == sqlite.compact(1)  # the same retention
        assert pg.compact(1).individuals == 0
        for history in ("current", "all"):
            assert isomorphic(_graph(sqlite, history)[0], _graph(pg, history)[0]), history
        assert pg.triple_count() == sqlite.triple_count()
        count = pg.triple_count()
    with open_store(pg_url, TBOX) as again:  # counted anew when opened
        assert again.triple_count() == count and again.object_count() == 2


@pytest.mark.reasoner
def test_the_reasoners_read_the_postgresql_store_as_owl(pg_url):
    """Pellet finds the same facts in the PostgreSQL store (read back from its export) as in the SQLite store,
    and the SWRL derivations work on it."""
    from planhrc.kb_service.reasoner import derive_chain_facts, derive_relative_orientations, run_reasoner

    with SqliteStore(None, TBOX) as sqlite, open_store(pg_url, TBOX) as pg:
        reports = []
        for kb in (sqlite, pg):
            obj = make_object("obj1", "absolute", 4, 4)
            kb.create_object(obj)
            kb.add_state("obj1", "perceived", obj.state([0, 90, 180, 270]), [0.0, 91.0, 180.0, 269.0])
            reports.append(run_reasoner(kb, "pellet", timeout_s=120))
        same = ("consistent", "classes", "inferred_facts", "notes")
        assert [getattr(reports[0], f) for f in same] == [getattr(reports[1], f) for f in same]
        assert reports[1].consistent and reports[1].inferred_facts > 0
        assert derive_chain_facts(pg, "obj1") == obj.affected_atoms()
        rel = make_object("obj2", "relative", 3, 4)
        pg.create_object(rel)
        state = pg.add_state("obj2", "perceived", rel.state([90, 0]), [0.0, 90.0, 90.0])
        assert derive_relative_orientations(pg, state.id) == (90, 0)
    from planhrc.kb_service.check import check_ontology

    checked = check_ontology(TBOX, pg_url, "pellet", timeout_s=120)  # `planhrc ontology check --db postgresql://`
    assert checked.consistent and checked.report.inferred_facts >= reports[1].inferred_facts


def test_acknowledged_writes_survive_a_process_killed_mid_transaction(pg_url):
    """A process acknowledges each perception after its transaction committed, then dies (SIGKILL) inside the next
    one: every acknowledged perception reads back whole, nothing of the killed one is there, its object is not
    left locked, and writes go on with fresh ids."""
    child = textwrap.dedent(f"""
        import os, signal
        from planhrc.kb_service.store import open_store
        from planhrc.paths import default_tbox_path
        from planhrc.model import make_object
        kb = open_store({pg_url!r}, default_tbox_path())
        obj = make_object("obj1", "relative", 4, 4)
        kb.create_object(obj)
        for k in range(5):
            with kb.transaction():
                kb.lock_object("obj1")
                state = kb.add_state("obj1", "perceived", obj.state([90 * (k % 4), 0, 0]))
                kb.add_event("obj1", "perception", "", {{"perceived_state_id": state.id}})
            print("ack", state.id, flush=True)
        with kb.transaction():
            kb.lock_object("obj1")
            state = kb.add_state("obj1", "perceived", obj.state([0, 90, 90]))
            kb.add_event("obj1", "perception", "", {{"perceived_state_id": state.id}})
            print("unacknowledged", state.id, flush=True)
            os.kill(os.getpid(), signal.SIGKILL)
    """)
    env = {**os.environ, "PYTHONPATH": os.getcwd()}
    done = subprocess.run([sys.executable, "-c", child], capture_output=True, text=True, timeout=120, env=env)
    assert done.returncode == -9, done.stderr
    acked = [line.split()[1] for line in done.stdout.splitlines() if line.startswith("ack")]
    (lost,) = [line.split()[1] for line in done.stdout.splitlines() if line.startswith("unacknowledged")]
    assert len(acked) == 5
    with open_store(pg_url, TBOX) as kb:
        obj = kb.get_object("obj1")
        for k, state_id in enumerate(acked):
            assert kb.get_state(state_id).atoms == obj.state([90 * (k % 4), 0, 0])
        assert [e.data["perceived_state_id"] for e in kb.list_events("obj1")] == acked
        with pytest.raises(KBError):
            kb.get_state(lost)
        started = time.monotonic()
        with kb.transaction():
            kb.lock_object("obj1")  # the dead process's lock went with its connection
            again = kb.add_state("obj1", "perceived", obj.state([0, 0, 0]))
            event = kb.add_event("obj1", "perception", "", {})
        assert time.monotonic() - started < 5
        assert again.id not in acked and event.seq == 6


def test_two_stores_on_one_database_see_each_others_writes(pg_url):
    """What replicas rely on: a write committed by one process is read by another at once, a plan included."""
    with open_store(pg_url, TBOX) as one, open_store(pg_url, TBOX) as two:
        obj = make_object(one.new_object_id(), "absolute", 3, 4)
        one.create_object(obj)
        assert two.new_object_id() != obj.ident  # ids are never handed out twice, across processes too
        start = one.add_state(obj.ident, "perceived", obj.state([0, 0, 0]))
        actions, states = plan_for(obj, start.atoms, [(1, True), (2, False)])
        goal = one.add_state(obj.ident, "goal", states[-1])
        plan = one.add_plan(one.add_problem(obj.ident, start.id, goal.id).id, "inproc", actions, states)
        assert two.get_plan(plan.id) == plan
        assert two.latest_plan(obj.ident) == plan
        assert [two.get_state(s).atoms for s in plan.expected_state_ids] == list(states)
        assert two.list_objects() == (obj,)
        one.add_event(obj.ident, "k", "", {})
        assert two.add_event(obj.ident, "k", "", {}).seq == 2  # one order of events per object


def test_a_plan_journalled_by_one_process_is_read_and_written_out_by_another(pg_url):
    """A plan's journal row is the plan for every process until its triples are written, and any process writes
    it out (`kb_service/store/postgres/journal.py`)."""
    with open_store(pg_url, TBOX) as one, open_store(pg_url, TBOX) as two:
        obj = make_object("obj1", "absolute", 4, 8)
        one.create_object(obj)
        start = one.add_state("obj1", "perceived", obj.state([0, 0, 0, 0]))
        actions, states = plan_for(obj, start.atoms, [(1, True), (3, False), (2, True)])
        goal = one.add_state("obj1", "goal", states[-1])
        plan = one.add_plan(one.add_problem("obj1", start.id, goal.id).id, "inproc", actions, states)
        assert journal_rows("postgresql", pg_url) == one.plans_to_write() == 1
        assert two.get_action(plan.actions[2].id) == plan.actions[2]  # from the row, in another process
        assert two.get_state(plan.expected_state_ids[1]).atoms == frozenset(states[1])
        assert two.get_plan(plan.id) == plan
        before = two.triple_count()
        assert f"{plan.actions[0].id}>" in two.export("nt").decode()  # the export writes it out first
        assert journal_rows("postgresql", pg_url) == 0 and two.triple_count() > before + 100
        one.settle()
        assert one.plans_to_write() == 0 and one.get_plan(plan.id) == plan
    with open_store(pg_url, TBOX) as three:  # from the triples alone
        assert three.get_plan(plan.id) == plan
        assert [three.get_state(s).atoms for s in plan.expected_state_ids] == [frozenset(s) for s in states]


def test_the_object_lock_holds_a_second_process_until_the_commit(pg_url):
    with open_store(pg_url, TBOX) as one, open_store(pg_url, TBOX) as two:
        one.create_object(make_object("obj1", "relative", 3, 4))
        with pytest.raises(KBError, match="outside a transaction"):
            one.lock_object("obj1")
        locked, order = threading.Event(), []

        def first() -> None:
            with one.transaction():
                one.lock_object("obj1")
                locked.set()
                time.sleep(0.5)
                order.append(("first", one.add_event("obj1", "k", "first", {}).seq))

        thread = threading.Thread(target=first)
        thread.start()
        assert locked.wait(10)
        with two.transaction():
            two.lock_object("obj1")  # waits for the first transaction to commit
            order.append(("second", two.add_event("obj1", "k", "second", {}).seq))
        thread.join(10)
        assert order == [("first", 1), ("second", 2)]
        with two.transaction():
            two.lock_object("obj2")  # another object's lock is another lock: no wait


def test_the_event_feed_announces_each_event_once_it_commits(pg_url):
    with open_store(pg_url, TBOX) as one, open_store(pg_url, TBOX) as two, two.event_feed() as feed:
        one.create_object(make_object("obj1", "relative", 3, 4))
        with one.transaction():
            one.add_event("obj1", "k", "", {})
            assert feed.wait(0.3) == []  # not before the commit
        assert feed.wait(10) == [("obj1", 1)]
        one.add_event("obj1", "k", "", {})
        two.add_event("obj1", "k", "", {})
        seen: list[tuple[str, int]] = []
        deadline = time.monotonic() + 10
        while len(seen) < 2 and time.monotonic() < deadline:
            seen += feed.wait(1)
        assert seen == [("obj1", 2), ("obj1", 3)]
        with pytest.raises(KBError):
            one.add_event("obj1", "k", "", {"x": object()})
        assert feed.wait(0.3) == []  # a refused event is not announced


def test_a_connection_the_server_dropped_fails_one_request_and_is_opened_again(pg_url, pg_cluster):
    """The server ends the store's connection (a restart, an administrator): the request that finds it lost fails
    with UnavailableError, nothing of it written, and the next request connects again."""
    import psycopg

    from planhrc.kb_service.store.errors import UnavailableError

    with open_store(pg_url, TBOX) as kb:
        obj = make_object("obj1", "relative", 3, 4)
        kb.create_object(obj)
        with psycopg.connect(pg_cluster.url, autocommit=True) as admin:
            admin.execute("SELECT pg_terminate_backend(pid) FROM pg_stat_activity WHERE datname = %s "
                          "AND application_name = 'planhrc'", (pg_url.rsplit("/", 1)[1],))
        with pytest.raises(UnavailableError, match="^db: the connection to the database was lost"):
            kb.add_state("obj1", "perceived", obj.state([0, 90]))
        state = kb.add_state("obj1", "perceived", obj.state([0, 90]))
        assert kb.get_state(state.id).atoms == obj.state([0, 90])
        assert state.id == "obj1_state_1"  # the failed request used up nothing


def test_a_test_process_killed_leaves_no_server_behind(pg_cluster):
    """The throwaway cluster's server dies with the process that started it, even one killed with SIGKILL."""
    child = textwrap.dedent("""
        import os, signal
        from tests.pg_cluster import Cluster
        cluster = Cluster()
        print(cluster.server_pid(), cluster.folder, flush=True)
        os.kill(os.getpid(), signal.SIGKILL)
    """)
    env = {**os.environ, "PYTHONPATH": os.getcwd()}
    done = subprocess.run([sys.executable, "-c", child], capture_output=True, text=True, timeout=120, env=env)
    pid, folder = done.stdout.split()
    try:
        deadline = time.monotonic() + 30
        while alive(int(pid)) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert not alive(int(pid)), f"postgres {pid} outlived the process that started it"
    finally:
        shutil.rmtree(folder, ignore_errors=True)  # what a killed run leaves: its folder in the temporary folder



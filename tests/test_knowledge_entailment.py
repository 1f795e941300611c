"""The entailed graph of the SPARQL endpoint, computed in process, is what Pellet derives from the same current
ABox: the named types of every ABox individual (a perceived state is a State) and the SWRL rules' facts (the chain,
the affected joints, the madeof links to static facts, the relative angles)."""
from __future__ import annotations

import pytest
from owlready2 import World
from rdflib import RDF, Graph, URIRef

from planhrc.kb_service.knowledge.entailment import DERIVED, Vocabulary, entail
from planhrc.ontology.rules import SWRL_RULES
from planhrc.kb_service.knowledge.graph import parse_lines
from planhrc.kb_service.knowledge.reasoning import ReasoningRequest, reason
from planhrc.kb_service.store import ABOX_IRI, TBOX_IRI, SqliteStore
from owlready2.base import rdfs_subclassof as SUBCLASS_OF

from planhrc.kb_service.store.owl import RDF_TYPE as RDF_TYPE_SID
from planhrc.kb_service.store.owl import iri_pairs, load_ntriples
from planhrc.kb_service.reasoner import reason_in_place
from planhrc.model import make_object, relative_from_absolute, snap_angle
from planhrc.paths import default_tbox_path

TBOX = default_tbox_path()
T = TBOX_IRI


@pytest.fixture(scope="module")
def vocab() -> Vocabulary:
    g = Graph()
    g.parse(str(TBOX), format="xml")
    return Vocabulary.of(g)


def store_with(formulation: str, links: int, raw: list[float] | None, orientations: int = 4) -> SqliteStore:
    kb = SqliteStore(None, TBOX)
    obj = make_object("obj1", formulation, links, orientations)
    kb.create_object(obj)
    if raw is not None:
        snapped = [snap_angle(x, orientations) for x in raw]
        state = kb.add_state("obj1", "perceived", obj.state(obj.joint_values_from_links(snapped)), raw)
        kb.add_event("obj1", "replan", "test", {"perceived_state_id": state.id})
    return kb


def abox_triples(kb: SqliteStore) -> set:
    return parse_lines(line for line in kb.export_lines("current", ["obj1"]) if line.startswith("<" + ABOX_IRI))


def test_the_rules_are_the_tboxs():
    world = World()
    with open(TBOX, "rb") as f:
        world.get_ontology(T).load(fileobj=f)
    assert sorted(str(rule) for rule in world.rules()) == sorted(SWRL_RULES)


def test_a_perceived_state_is_a_state_and_the_chain_is_derived(vocab):
    with store_with("absolute", 3, [0.0, 90.0, 180.0]) as kb:
        facts = abox_triples(kb) | entail(abox_triples(kb), vocab)
    state = URIRef(ABOX_IRI + "obj1_state_1")
    assert (state, RDF.type, URIRef(T + "State")) in facts
    assert (URIRef(ABOX_IRI + "obj1_l1"), RDF.type, URIRef(T + "Type")) in facts
    affects = {(str(s)[len(ABOX_IRI):], str(o)[len(ABOX_IRI):]) for s, p, o in facts if p == URIRef(T + "affectsJoint")}
    assert affects == {("obj1_j1", "obj1_j1"), ("obj1_j1", "obj1_j2"), ("obj1_j1", "obj1_j3"), ("obj1_j2", "obj1_j2"),
                       ("obj1_j2", "obj1_j3"), ("obj1_j3", "obj1_j3")}


def test_relative_angles_follow_the_observations(vocab):
    raw = [10.0, 95.0, 200.0, 359.0, 44.0]
    with store_with("relative", 5, raw, orientations=12) as kb:
        facts = entail(abox_triples(kb), vocab)
    rel = {str(s).rsplit("_lo_l", 1)[1]: int(str(o).split("_")[-1]) for s, p, o in facts
           if p == URIRef(T + "relativeOrientation")}
    snapped = [snap_angle(x, 12) for x in raw]
    assert [rel[str(k)] for k in range(2, 6)] == list(relative_from_absolute(snapped))


def pellet_view(kb: SqliteStore) -> tuple[set, set]:
    """(individual, named class) and (s, p, o) of the derived properties that Pellet finds in the current ABox."""
    world = World()
    try:
        lines = list(kb.export_lines("current", ["obj1"]))
        load_ntriples(world, T.rstrip("#"), [x for x in lines if not x.startswith("<" + ABOX_IRI)])
        load_ntriples(world, ABOX_IRI.rstrip("#"), [x for x in lines if x.startswith("<" + ABOX_IRI)])
        consistent, _ = reason_in_place(world, "pellet", 120)
        assert consistent
        # told and inferred types, closed over the class hierarchy as it stands after the run (owlready2 writes
        # the subclass axioms a classification finds into the world too)
        q = ("WITH RECURSIVE up(s, c) AS (SELECT s, o FROM objs WHERE p = ? UNION "
             "SELECT up.s, x.o FROM up JOIN objs x ON x.s = up.c AND x.p = ?) "
             "SELECT DISTINCT rs.iri, rc.iri FROM up JOIN resources rs ON rs.storid = up.s "
             "JOIN resources rc ON rc.storid = up.c")
        types = {(s, c) for s, c in world.graph.db.execute(q, (RDF_TYPE_SID, SUBCLASS_OF))
                 if s.startswith(ABOX_IRI) and c.startswith(T)}
        props = {(s, str(prop), o) for prop in DERIVED for s, o in iri_pairs(world, str(prop))
                 if s.startswith(ABOX_IRI)}
        return types, props
    finally:
        world.close()


def our_view(kb: SqliteStore, vocab: Vocabulary) -> tuple[set, set]:
    asserted = abox_triples(kb)
    facts = asserted | entail(asserted, vocab)
    types = {(str(s), str(o)) for s, p, o in facts if p == RDF.type and str(s).startswith(ABOX_IRI)
             and str(o).startswith(T)}
    props = {(str(s), str(p), str(o)) for s, p, o in facts if p in DERIVED}
    return types, props


@pytest.mark.reasoner
@pytest.mark.parametrize("formulation,links,raw", [
    ("absolute", 4, [0.0, 91.0, 180.0, 269.0]),
    ("relative", 4, [10.0, 95.0, 200.0, 359.0]),
    ("relative", 3, None),
])
def test_entailment_is_what_pellet_derives(vocab, formulation, links, raw):
    with store_with(formulation, links, raw) as kb:
        ours = our_view(kb, vocab)
        pellets = pellet_view(kb)
    assert ours[0] == pellets[0], (ours[0] ^ pellets[0])
    assert ours[1] == pellets[1], (ours[1] ^ pellets[1])
    assert ours[1]  # the rules fired


@pytest.mark.reasoner
def test_reasoning_names_the_individuals_of_an_inconsistency(vocab):
    with store_with("relative", 3, [0.0, 90.0, 90.0]) as kb:
        abox = kb._abox  # the SQLite store's internals: a fact no write of the store would accept
        with kb.lock:
            abox.q.insert_objs(abox.c, [(abox.sid("obj1_l2"), RDF_TYPE_SID, abox.t["Joint"])])
            abox.q.commit()
        for name in ("pellet", "hermit"):
            result = reason(kb, ReasoningRequest(name, "obj1"), 120, vocab)
            assert not result.consistent
            assert result.individuals == ("obj1_l2",)
            assert any("Joint" in axiom for axiom in result.axioms)


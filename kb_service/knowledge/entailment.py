"""The facts the TBox entails from an object's current ABox, computed in process (no JVM): the `entailed` graph
of the SPARQL endpoint.

Two parts, run to a fixed point:

* the TBox's RDFS-style axioms, read from the TBox itself (`Vocabulary`): every named superclass of a type
  (a perceived state is a `State`), the domain and range of each property (whatever `stateOf` points from is a
  `State`), every superproperty of a property (`nextJoint` is a `downstreamJoint`) and the closure of each
  transitive property (`downstreamJoint`);
* the TBox's six SWRL rules (`RULES`, the rule texts as the TBox states them; a test checks that the TBox still
  holds exactly these): which link turns about each joint, the joints downstream of it, which joints each turn
  affects (the chain and the `Affected` facts), the `madeof` links of a state that includes its object's static
  facts, and the relative angle of each observed link of a perceived state.

What Pellet derives from the same ABox and TBox, restricted to named classes and these properties, is exactly this
(tests/test_knowledge_entailment.py, `reasoner`-marked). Individuals are entailed only from facts of their own
object, so each object's entailment is computed alone and kept until its current ABox changes.
"""
from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass
from typing import Iterable

from rdflib import OWL, RDF, RDFS, XSD, Graph, Literal, URIRef
from rdflib.term import Node

from ..store import TBOX_IRI

Triple = tuple[Node, Node, Node]

RULES = (
    "Connected(?c), arg1(?c, ?j), arg2(?c, ?l), Connected(?d), arg1(?d, ?j), arg2(?d, ?u), nextLink(?u, ?l)"
    " -> turns(?j, ?l)",
    "turns(?j, ?l), nextLink(?l, ?m), turns(?k, ?m) -> nextJoint(?j, ?k)",
    "turns(?j, ?l), downstreamJoint(?j, ?k) -> affectsJoint(?j, ?k)",
    "turns(?j, ?l) -> affectsJoint(?j, ?j)",
    "State(?s), includesStaticFacts(?s, true), stateOf(?s, ?x), staticFactOf(?p, ?x) -> madeof(?s, ?p)",
    "PerceivedState(?s), observes(?s, ?p), observes(?s, ?q), arg1(?p, ?a), arg1(?q, ?b), nextLink(?a, ?b),"
    " arg2(?p, ?oa), arg2(?q, ?ob), degrees(?oa, ?x), degrees(?ob, ?y), subtract(?d, ?y, ?x),"
    " add(?e, ?d, 360), mod(?r, ?e, 360), Orientation(?o), degrees(?o, ?r) -> relativeOrientation(?q, ?o)",
)


def _t(name: str) -> URIRef:
    return URIRef(TBOX_IRI + name)


CONNECTED, STATE, PERCEIVED, ORIENTATION = _t("Connected"), _t("State"), _t("PerceivedState"), _t("Orientation")
ARG1, ARG2, NEXT_LINK, TURNS, NEXT_JOINT = _t("arg1"), _t("arg2"), _t("nextLink"), _t("turns"), _t("nextJoint")
DOWNSTREAM, AFFECTS, MADEOF, STATE_OF = _t("downstreamJoint"), _t("affectsJoint"), _t("madeof"), _t("stateOf")
STATIC_FACT_OF, INCLUDES_STATIC, OBSERVES = _t("staticFactOf"), _t("includesStaticFacts"), _t("observes")
DEGREES, RELATIVE = _t("degrees"), _t("relativeOrientation")
# The properties the rules derive: what the agreement test with Pellet compares, besides the types.
DERIVED = (TURNS, NEXT_JOINT, DOWNSTREAM, AFFECTS, MADEOF, RELATIVE)


@dataclass(frozen=True)
class Vocabulary:
    """What the TBox says about its names, as lookups: superclasses (reflexive, transitive, named classes only),
    superproperties (reflexive, transitive), domains and class ranges, and the transitive properties."""

    superclasses: dict[Node, frozenset[Node]]
    superproperties: dict[Node, frozenset[Node]]
    domains: dict[Node, frozenset[Node]]
    ranges: dict[Node, frozenset[Node]]
    transitive: frozenset[Node]

    @classmethod
    def of(cls, tbox: Graph) -> Vocabulary:
        named = {s for s in tbox.subjects(RDF.type, OWL.Class) if isinstance(s, URIRef)}
        supers = _closure({c: {o for o in tbox.objects(c, RDFS.subClassOf) if o in named} for c in named})
        props = {s for s, o in tbox.subject_objects(RDFS.subPropertyOf)} | {
            s for kind in (OWL.ObjectProperty, OWL.DatatypeProperty) for s in tbox.subjects(RDF.type, kind)}
        super_props = _closure({p: set(tbox.objects(p, RDFS.subPropertyOf)) for p in props})

        def classes(p: Node, axiom: URIRef) -> frozenset[Node]:
            # a property inherits the domain and range of its superproperties
            return frozenset(c for q in super_props.get(p, {p}) for c in tbox.objects(q, axiom) if c in named)

        return cls(
            superclasses={c: frozenset(v) for c, v in supers.items()},
            superproperties={p: frozenset(v) for p, v in super_props.items()},
            domains={p: d for p in props if (d := classes(p, RDFS.domain))},
            ranges={p: r for p in props if (r := classes(p, RDFS.range))},
            transitive=frozenset(tbox.subjects(RDF.type, OWL.TransitiveProperty)),
        )


def _closure(edges: dict[Node, set[Node]]) -> dict[Node, set[Node]]:
    """Reflexive-transitive closure of a small relation."""
    out: dict[Node, set[Node]] = {}
    for start in edges:
        seen = {start}
        todo = [start]
        while todo:
            for nxt in edges.get(todo.pop(), ()):
                if nxt not in seen:
                    seen.add(nxt)
                    todo.append(nxt)
        out[start] = seen
    return out


class _Facts:
    """A set of triples with the lookups the rules join on."""

    def __init__(self, triples: Iterable[Triple]) -> None:
        self.all: set[Triple] = set()
        self.by_p: dict[Node, set[tuple[Node, Node]]] = defaultdict(set)
        for t in triples:
            self.add(t)

    def add(self, t: Triple) -> bool:
        if t in self.all:
            return False
        self.all.add(t)
        self.by_p[t[1]].add((t[0], t[2]))
        return True

    def pairs(self, p: Node) -> set[tuple[Node, Node]]:
        return self.by_p.get(p, set())

    def of(self, p: Node) -> dict[Node, set[Node]]:
        out: dict[Node, set[Node]] = defaultdict(set)
        for s, o in self.pairs(p):
            out[s].add(o)
        return out

    def typed(self, cls: Node) -> set[Node]:
        return {s for s, o in self.pairs(RDF.type) if o == cls}


def entail(asserted: Iterable[Triple], vocab: Vocabulary) -> set[Triple]:
    """The triples the TBox entails from `asserted` (an object's current ABox) that `asserted` does not hold."""
    facts = _Facts(asserted)
    given = set(facts.all)
    todo = list(given)
    while todo:
        _rdfs(facts, vocab, todo)
        todo = _rules(facts)
    return facts.all - given


def _rdfs(facts: _Facts, vocab: Vocabulary, todo: list[Triple]) -> None:
    """Add what the axioms entail from the triples of `todo` (and from what that adds), until nothing is new."""
    while todo:
        while todo:
            s, p, o = todo.pop()
            new = [(s, q, o) for q in vocab.superproperties.get(p, ()) if q != p]
            new += [(s, RDF.type, c) for c in vocab.domains.get(p, ())]
            if isinstance(o, URIRef):
                new += [(o, RDF.type, c) for c in vocab.ranges.get(p, ())]
            if p == RDF.type:
                new += [(s, RDF.type, c) for c in vocab.superclasses.get(o, ()) if c != o]
            todo += [t for t in new if facts.add(t)]
        for p in vocab.transitive:
            succ = facts.of(p)
            reach = _closure({k: set(v) for k, v in succ.items()})
            todo += [t for s, objs in reach.items() for o in objs - {s} if facts.add(t := (s, p, o))]


def _rules(facts: _Facts) -> list[Triple]:
    """Apply the six rules once; the triples that are new."""
    new: list[Triple] = []
    connected = facts.typed(CONNECTED)
    arg1, arg2 = facts.of(ARG1), facts.of(ARG2)
    links_at: dict[Node, set[Node]] = defaultdict(set)  # joint -> links Connected to it
    for c in connected:
        for j in arg1.get(c, ()):
            links_at[j] |= arg2.get(c, set())
    next_link = facts.pairs(NEXT_LINK)
    for j, links in links_at.items():  # rule 1: the downstream one of the two links at a joint turns
        new += [(j, TURNS, link) for u, link in next_link if u in links and link in links]
    turns = facts.pairs(TURNS)
    turned_by: dict[Node, set[Node]] = defaultdict(set)
    for j, link in turns:
        turned_by[link].add(j)
    for j, link in turns:
        new.append((j, AFFECTS, j))  # rule 4
        new += [(j, NEXT_JOINT, k) for l0, m in next_link if l0 == link for k in turned_by.get(m, ())]  # rule 2
    downstream = facts.of(DOWNSTREAM)
    new += [(j, AFFECTS, k) for j, _ in turns for k in downstream.get(j, ())]  # rule 3
    state_of, static_of = facts.of(STATE_OF), facts.of(STATIC_FACT_OF)
    statics: dict[Node, set[Node]] = defaultdict(set)
    for p, objs in static_of.items():
        for x in objs:
            statics[x].add(p)
    for s in facts.typed(STATE):  # rule 5
        if any(_is_true(v) for v in facts.of(INCLUDES_STATIC).get(s, ())):
            new += [(s, MADEOF, p) for x in state_of.get(s, ()) for p in statics.get(x, ())]
    new += _relative_orientations(facts, arg1, arg2)  # rule 6
    return [t for t in new if facts.add(t)]


def _relative_orientations(facts: _Facts, arg1: dict[Node, set[Node]], arg2: dict[Node, set[Node]]) -> list[Triple]:
    degrees = {s: _int(v) for s, vs in facts.of(DEGREES).items() for v in vs}
    at_degrees: dict[int, set[Node]] = defaultdict(set)
    for o in facts.typed(ORIENTATION):
        d = degrees.get(o)
        if d is not None:
            at_degrees[d].add(o)
    next_link = facts.pairs(NEXT_LINK)
    observes = facts.of(OBSERVES)
    out: list[Triple] = []
    for s in facts.typed(PERCEIVED):
        seen = observes.get(s, set())
        for p in seen:
            for q in seen:
                if not any((a, b) in next_link for a in arg1.get(p, ()) for b in arg1.get(q, ())):
                    continue
                for oa in arg2.get(p, ()):
                    for ob in arg2.get(q, ()):
                        x, y = degrees.get(oa), degrees.get(ob)
                        if x is None or y is None:
                            continue
                        out += [(q, RELATIVE, o) for o in at_degrees.get((y - x + 360) % 360, ())]
    return out


def _int(value: Node) -> int | None:
    number = value.toPython() if isinstance(value, Literal) else None
    if isinstance(number, bool) or not isinstance(number, (int, float)):
        return None
    return int(number) if float(number).is_integer() else None


def _is_true(value: Node) -> bool:
    return isinstance(value, Literal) and value.datatype in (XSD.boolean, None) and value.toPython() is True

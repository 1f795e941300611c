"""The facts the TBox entails from an object's current ABox, computed in process (no JVM): the `entailed` graph
of the SPARQL endpoint.

Two parts, run to a fixed point:

* the TBox's RDFS-style axioms, read from the TBox itself (`Vocabulary`): every named superclass of a type
  (a perceived state is a `State`), the domain and range of each property (whatever `stateOf` points from is a
  `State`), every superproperty of a property (`nextJoint` is a `downstreamJoint`) and the closure of each
  transitive property (`downstreamJoint`);
* the TBox's six SWRL rules, read from their texts (`ontology.rules.SWRL_RULES`, which the TBox builder states;
  `read_rule`), each joined over the facts atom by atom: which link turns about each joint, the joints downstream
  of it, which joints each turn affects (the chain and the `Affected` facts), the `madeof` links of a state that
  includes its object's static facts, and the relative angle of each observed link of a perceived state.

What Pellet derives from the same ABox and TBox, restricted to named classes and these properties, is exactly this
(tests/test_knowledge_entailment.py, `reasoner`-marked). Individuals are entailed only from facts of their own
object, so each object's entailment is computed alone and kept until its current ABox changes.
"""
from __future__ import annotations

import re
from collections import defaultdict
from dataclasses import dataclass
from functools import lru_cache
from typing import Any, Callable, Iterable

from rdflib import OWL, RDF, RDFS, Graph, Literal, URIRef
from rdflib.term import Node

from planhrc.ontology.rules import SWRL_RULES

from ..store import TBOX_IRI

Triple = tuple[Node, Node, Node]


def _t(name: str) -> URIRef:
    return URIRef(TBOX_IRI + name)


TYPE = RDF.type
DOWNSTREAM = _t("downstreamJoint")  # transitive: what the rules' `nextJoint` facts add up to
# The properties the rules derive: what the agreement test with Pellet compares, besides the types.
DERIVED = tuple(_t(name) for name in ("turns", "nextJoint", "affectsJoint", "madeof", "relativeOrientation")) + (
    DOWNSTREAM,)


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
        # made when a rule first looks a property up, and again after the property gained a triple
        self._by_subject: dict[Node, dict[Node, set[Node]]] = {}  # p -> s -> objects
        self._by_value: dict[Node, dict[Any, set[Node]]] = {}  # p -> `_value` of an object -> subjects
        for t in triples:
            self.add(t)

    def add(self, t: Triple) -> bool:
        if t in self.all:
            return False
        p = t[1]
        self.all.add(t)
        self.by_p[p].add((t[0], t[2]))
        if p in self._by_subject:
            del self._by_subject[p]
        if p in self._by_value:
            del self._by_value[p]
        return True

    def pairs(self, p: Node) -> set[tuple[Node, Node]]:
        return self.by_p.get(p, set())

    def objects(self, p: Node, s: Node) -> set[Node]:
        index = self._by_subject.get(p)
        if index is None:
            index = self._by_subject[p] = defaultdict(set)
            for subject, o in self.pairs(p):
                index[subject].add(o)
        return index.get(s, set())

    def subjects(self, p: Node, value: Any) -> set[Node]:
        """The subjects of `p` whose object is `value` (a node, or a literal's `_value`)."""
        index = self._by_value.get(p)
        if index is None:
            index = self._by_value[p] = defaultdict(set)
            for subject, o in self.pairs(p):
                index[_value(o) if isinstance(o, Literal) else o].add(subject)
        return index.get(value, set())

    def of(self, p: Node) -> dict[Node, set[Node]]:
        out: dict[Node, set[Node]] = defaultdict(set)
        for s, o in self.pairs(p):
            out[s].add(o)
        return out

    def typed(self, cls: Node) -> set[Node]:
        return self.subjects(TYPE, cls)


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
            new += [(s, TYPE, c) for c in vocab.domains.get(p, ())]
            if isinstance(o, URIRef):
                new += [(o, TYPE, c) for c in vocab.ranges.get(p, ())]
            if p == TYPE:
                new += [(s, TYPE, c) for c in vocab.superclasses.get(o, ()) if c != o]
            todo += [t for t in new if facts.add(t)]
        for p in vocab.transitive:
            succ = facts.of(p)
            reach = _closure({k: set(v) for k, v in succ.items()})
            todo += [t for s, objs in reach.items() for o in objs - {s} if facts.add(t := (s, p, o))]


# -- the SWRL rules, read from their text ---------------------------------------------------------------------
Term = str | int | bool  # in a rule: a variable ("?x"), or a constant (`true`, a whole number)
BUILTINS: dict[str, Callable[[Any, Any], Any]] = {  # swrlb:name(?result, ?a, ?b): result = a op b
    "subtract": lambda a, b: a - b, "add": lambda a, b: a + b, "mod": lambda a, b: a % b}


@dataclass(frozen=True)
class RuleAtom:
    """One atom of a rule: a class (one term), a property (two) or a built-in (`BUILTINS`: three)."""

    name: str
    terms: tuple[Term, ...]

    @property
    def iri(self) -> URIRef:
        return _t(self.name)


@dataclass(frozen=True)
class Rule:
    """A rule's body, in the order it is joined (the atoms with the most terms known first), and its head."""

    body: tuple[RuleAtom, ...]
    head: RuleAtom


def read_rule(text: str) -> Rule:
    """A rule as `ontology.rules` writes it: `A(?x), p(?x, ?y), subtract(?d, ?y, ?x) -> q(?x, ?d)`."""
    body_text, head_text = text.split("->")
    body = [_atom(m) for m in re.finditer(r"(\w+)\(([^)]*)\)", body_text)]
    head = [_atom(m) for m in re.finditer(r"(\w+)\(([^)]*)\)", head_text)]
    if len(head) != 1 or not body:
        raise ValueError(f"a rule with one head atom and a body expected: {text!r}")
    return Rule(_join_order(body), head[0])


def _atom(match: re.Match[str]) -> RuleAtom:
    def term(word: str) -> Term:
        word = word.strip()
        if word.startswith("?"):
            return word
        if word in ("true", "false"):
            return word == "true"
        return int(word)

    return RuleAtom(match.group(1), tuple(term(w) for w in match.group(2).split(",")))


def _join_order(atoms: list[RuleAtom]) -> tuple[RuleAtom, ...]:
    """The atoms in the order a join reads them cheaply: each time the one whose terms are most known already (a
    check before a lookup before a scan; a built-in once its inputs are known, a class scan before a property's)."""
    known: set[Term] = set()
    order: list[RuleAtom] = []
    left = list(atoms)

    def cost(atom: RuleAtom) -> float:
        bound = [not isinstance(t, str) or t in known for t in atom.terms]
        if atom.name in BUILTINS:
            return 0.0 if all(bound[1:]) else 9.0
        if len(atom.terms) == 1:
            return 1.0 if bound[0] else 4.0
        return {(True, True): 1.0, (True, False): 2.0, (False, True): 3.0}.get((bound[0], bound[1]), 5.0)

    while left:
        atom = min(left, key=cost)
        left.remove(atom)
        order.append(atom)
        known.update(t for t in atom.terms if isinstance(t, str))
    return tuple(order)


@lru_cache(maxsize=1)
def tbox_rules() -> tuple[Rule, ...]:
    return tuple(read_rule(text) for text in SWRL_RULES)


def _rules(facts: _Facts) -> list[Triple]:
    """Apply the TBox's rules once; the triples that are new."""
    new: list[Triple] = []
    for rule in tbox_rules():
        new += _matches(rule, facts)
    return [t for t in new if facts.add(t)]


def _matches(rule: Rule, facts: _Facts) -> list[Triple]:
    """The head of `rule` for every way its body holds in `facts` (a nested-loop join in the rule's order)."""
    out: list[Triple] = []
    body = rule.body
    iris = [atom.iri for atom in body]
    head = rule.head.iri

    def known(term: Term, binding: dict[str, Any]) -> Any:
        return binding.get(term) if isinstance(term, str) else term

    def join(i: int, binding: dict[str, Any]) -> None:
        if i == len(body):
            s, o = (binding[t] if isinstance(t, str) else Literal(t) for t in rule.head.terms)
            out.append((s, head, o))
            return
        atom = body[i]
        if atom.name in BUILTINS:
            result, a, b = (known(t, binding) for t in atom.terms)
            a, b = _value(a), _value(b)
            if not isinstance(a, (int, float)) or not isinstance(b, (int, float)):
                return
            value = BUILTINS[atom.name](a, b)
            if result is None:
                join(i + 1, {**binding, str(atom.terms[0]): value})
            elif _value(result) == value:
                join(i + 1, binding)
            return
        if len(atom.terms) == 1:
            var, cls = atom.terms[0], iris[i]
            subject = known(var, binding)
            if subject is not None:
                if (subject, TYPE, cls) in facts.all:
                    join(i + 1, binding)
                return
            for node in facts.typed(cls):
                join(i + 1, {**binding, str(var): node})
            return
        prop = iris[i]
        s_term, o_term = atom.terms
        subject, obj = known(s_term, binding), known(o_term, binding)
        if subject is not None:
            pairs: Iterable[tuple[Node, Node]] = ((subject, o) for o in facts.objects(prop, subject))
        elif obj is not None:
            pairs = ((s, obj) for s in facts.subjects(prop, _value(obj)))
        else:
            pairs = facts.pairs(prop)
        for s_node, o_node in pairs:
            if obj is not None and _value(o_node) != _value(obj):
                continue
            grown = binding
            if subject is None or obj is None:
                grown = dict(binding)
                if subject is None:
                    grown[str(s_term)] = s_node
                if obj is None:
                    grown[str(o_term)] = o_node
            join(i + 1, grown)

    join(0, {})
    return out


def _value(node: Any) -> Any:
    """What a rule compares: a literal's number (whole numbers as int) or boolean, a variable's computed number, or
    the node itself. A boolean is kept apart from the numbers 0 and 1."""
    if isinstance(node, Literal):
        value = node.toPython()
        if isinstance(value, bool):
            return ("boolean", value)
        if isinstance(value, (int, float)):
            return int(value) if float(value).is_integer() else float(value)
        return node
    if isinstance(node, bool):
        return ("boolean", node)
    if isinstance(node, float) and node.is_integer():
        return int(node)
    return node

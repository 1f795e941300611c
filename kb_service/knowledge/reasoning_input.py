"""What a reasoning job gives the DL reasoner: the TBox, the part of the current ABox the question needs, and the
transitive closures the service has already computed.

* **Scope** (`ReasoningScope`). `states` (the default): each object with its goal and its latest perceived state,
  i.e. everything reachable from them (links, joints, orientations, static facts, the states' predicates), which is
  what consistency, the types of the states and the SWRL rules' facts are about. `current`: the whole current ABox
  as `GET /ontology` exports it, the latest problem and the plan with its actions and expected states included
  (on a 20-link object four times as many facts, and the expected states' predicates make most of the reasoner's
  work).
* **Closures.** The TBox's rule `turns(j, l), downstreamJoint(j, k) -> affectsJoint(j, k)` joins on a transitive
  property, and Pellet spent most of a job (about four fifths on 20 links) finding that property's instances for
  it. Those instances are facts the TBox entails (`entailment.entail`, shown equal to Pellet's by
  tests/test_knowledge_entailment.py), so they go to the reasoner as facts: adding entailed facts changes no model,
  so neither consistency nor any other entailment. They are counted among what the job inferred, as the reasoner
  would have.
"""
from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Iterable, Sequence

from planhrc.vocabulary import ReasoningScope

from ..store import ABOX_IRI, TBOX_IRI, NotFoundError
from .entailment import DOWNSTREAM, Vocabulary, entail
from .graph import KnowledgeSource, parse_lines

_ABOX_LINE = "<" + ABOX_IRI
_RDF_TYPE = "http://www.w3.org/1999/02/22-rdf-syntax-ns#type"
_STATIC_FACT_OF = TBOX_IRI + "staticFactOf"
_TRIPLE = re.compile(r"<([^>]*)> <([^>]*)> (?:<([^>]*)>)?")
SEEDED = (DOWNSTREAM,)  # the transitive properties whose entailed instances the reasoner is given


@dataclass(frozen=True)
class ReasonerInput:
    tbox: tuple[str, ...]  # N-Triples lines, the ontology's header included
    abox: tuple[str, ...]
    seeded: tuple[str, ...]  # entailed facts given as facts (counted as inferred)


def reasoner_input(store: KnowledgeSource, object_ids: Sequence[str] | None, scope: ReasoningScope,
                   vocabulary: Vocabulary) -> ReasonerInput:
    """The lines of the objects `object_ids` (None: every object) for a job of `scope`."""
    ids = [obj.ident for obj in store.list_objects()] if object_ids is None else list(object_ids)
    lines = list(store.export_lines("current", ids))
    tbox = tuple(line for line in lines if not line.startswith(_ABOX_LINE))
    abox = [line for line in lines if line.startswith(_ABOX_LINE)]
    if scope is ReasoningScope.STATES:
        abox = reachable_lines(abox, [ABOX_IRI + name for oid in ids for name in state_roots(store, oid)])
    facts = parse_lines(abox)
    seeded = sorted(f"<{s}> <{p}> <{o}> .\n" for s, p, o in entail(facts, vocabulary) if p in SEEDED)
    return ReasonerInput(tbox, tuple(abox), tuple(seeded))


def state_roots(store: KnowledgeSource, object_id: str) -> list[str]:
    """The object and those of its current roots that are states (its goal and its latest perceived state)."""
    roots = store.current_roots(object_id)
    out = [roots[0]]
    for name in roots[1:]:
        try:
            store.get_state(name)
        except NotFoundError:
            continue
        out.append(name)
    return out


def reachable_lines(abox: Iterable[str], roots: Iterable[str]) -> list[str]:
    """The ABox lines about the individuals reachable from `roots` by object properties (not rdf:type), and about
    the static facts of a root (they point to their object), as the current export gathers them."""
    about: dict[str, list[str]] = {}
    edges: dict[str, set[str]] = {}
    start = set(roots)
    statics = set()
    for line in abox:
        m = _TRIPLE.match(line)
        if m is None:
            continue
        s, p, o = m.groups()
        about.setdefault(s, []).append(line)
        if o is not None and o.startswith(ABOX_IRI) and p != _RDF_TYPE:
            edges.setdefault(s, set()).add(o)
            if p == _STATIC_FACT_OF and o in start:
                statics.add(s)
    seen = start | statics
    todo = list(seen)
    while todo:
        for o in edges.get(todo.pop(), ()):
            if o not in seen:
                seen.add(o)
                todo.append(o)
    return [line for s in sorted(seen) for line in about.get(s, ())]

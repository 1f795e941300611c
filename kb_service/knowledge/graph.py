"""The graphs the SPARQL endpoint answers from: the TBox, each object's current ABox, what the TBox entails from it
and what a reasoner inferred, as four named graphs, plus their `default` union (TBox, ABox, entailed), kept up to
date from the store through its interface (`Reads.revision`, `Export.current_roots`, `Export.export_lines`,
`Inferences`).

They stay small however long the history: an object's current ABox is what the cooperation model works with now
(its object, goal, latest perceived state, latest problem, current plan), and it is read again only when its roots
changed (records are immutable), as a difference: a perception adds its state's triples and drops the previous
one's. `refresh()` returns what changed, graph by graph (`Change`), for the query engine that holds a copy
(`engines`); `contents()` gives everything, for an engine that starts afresh. Nothing here depends on a backend
or on an engine.

The caller holds `lock` around `refresh()` and the queries that follow it.
"""
from __future__ import annotations

import re
import threading
from collections import Counter
from dataclasses import dataclass
from pathlib import Path
from typing import Iterable, Protocol

from rdflib import Graph, Literal, URIRef
from rdflib.term import Node

from ..store import ABOX_IRI
from ..store.interface import Export, Inferences, Reads
from .entailment import Triple, Vocabulary, entail

GRAPH_IRI = "http://planhrc.org/graph/"
NAMED = ("tbox", "abox", "entailed", "inferred")
GRAPHS = {name: URIRef(GRAPH_IRI + name) for name in NAMED}
DEFAULT = "default"  # the union of DEFAULT_NAMES, the default graph of a query that names none
DEFAULT_NAMES = ("tbox", "abox", "entailed")  # asserted and entailed, not inferred
DEFAULT_GRAPHS = tuple(GRAPHS[name] for name in DEFAULT_NAMES)
_ABOX_LINE = "<" + ABOX_IRI


class KnowledgeSource(Reads, Export, Inferences, Protocol):
    """The parts of the store the knowledge service reads."""


@dataclass(frozen=True)
class Change:
    """Triples that left and entered one graph (a name of NAMED, or DEFAULT)."""

    graph: str
    removed: frozenset[Triple]
    added: frozenset[Triple]


class _Layer:
    """One named graph whose triples come from several keys (objects): a triple shared by two keys stays until
    neither holds it."""

    def __init__(self) -> None:
        self.count: Counter[Triple] = Counter()
        self.by_key: dict[str, frozenset[Triple]] = {}

    def replace(self, key: str, triples: Iterable[Triple]) -> tuple[set[Triple], set[Triple]]:
        """Give `key` these triples; the triples that left the graph and those that entered it."""
        new = frozenset(triples)
        old = self.by_key.pop(key, frozenset())
        removed, added = set(), set()
        for t in old - new:
            self.count[t] -= 1
            if not self.count[t]:
                del self.count[t]
                removed.add(t)
        for t in new - old:
            self.count[t] += 1
            if self.count[t] == 1:
                added.add(t)
        if new:
            self.by_key[key] = new
        return removed, added


class _Union:
    """The default graph: each triple once while any of the graphs it unites holds it."""

    def __init__(self) -> None:
        self.count: Counter[Triple] = Counter()

    def apply(self, removed: Iterable[Triple], added: Iterable[Triple]) -> tuple[set[Triple], set[Triple]]:
        gone, new = set(), set()
        for t in removed:
            self.count[t] -= 1
            if not self.count[t]:
                del self.count[t]
                gone.add(t)
        for t in added:
            self.count[t] += 1
            if self.count[t] == 1:
                new.add(t)
        return gone, new


# The lines the store writes (`store.owl.ntriple_lines`): IRIs, and literals with a datatype or a language. Read
# here several times faster than rdflib's general parser, which still reads any other line (blank nodes).
_LINE = re.compile(r'<([^<>"{}|^`\\ ]*)> <([^<>"{}|^`\\ ]*)> (?:<([^<>"{}|^`\\ ]*)>|"((?:[^"\\]|\\.)*)"'
                   r'(?:\^\^<([^<>"{}|^`\\ ]*)>|@([A-Za-z0-9-]+))?) \.\s*$')
_UNESCAPE = re.compile(r"\\(.)")
_ESCAPES = {"n": "\n", "r": "\r", "t": "\t", '"': '"', "\\": "\\"}


def parse_lines(lines: Iterable[str]) -> set[Triple]:
    """N-Triples lines as rdflib triples."""
    out: set[Triple] = set()
    other: list[str] = []
    for line in lines:
        m = _LINE.match(line)
        if m is None or (m.group(4) is not None and "\\u" in m.group(4).lower()):
            other.append(line)
            continue
        s, p, o, text, datatype, lang = m.groups()
        obj: Node
        if o is not None:
            obj = URIRef(o)
        else:
            value = _UNESCAPE.sub(lambda e: _ESCAPES.get(e.group(1), e.group(0)), text)
            obj = Literal(value, datatype=URIRef(datatype) if datatype else None, lang=lang)
        out.add((URIRef(s), URIRef(p), obj))
    if other:
        graph = Graph()
        graph.parse(data="".join(other), format="nt")
        out.update(graph)
    return out


class KnowledgeGraph:
    """The graphs of the endpoint over one store; `refresh()` (under `lock`) brings them up to date."""

    def __init__(self, store: KnowledgeSource, tbox_path: Path | str) -> None:
        self.store = store
        self.lock = threading.Lock()
        tbox = Graph()
        tbox.parse(str(tbox_path), format="xml")
        self.vocabulary = Vocabulary.of(tbox)
        self._layers = {name: _Layer() for name in NAMED}
        self._default = _Union()
        self._pending: list[Change] = []
        self._replace("tbox", "tbox", set(tbox))
        self._replace("entailed", "tbox", entail(tbox, self.vocabulary))  # the TBox's own individuals
        self._revision: int | None = None
        self._inferred_stale = True  # read at the first refresh, then after each reasoning job stored its facts
        self._roots: dict[str, tuple[str, ...]] = {}
        self.version = 0  # grows whenever a refresh changed something
        self.objects_read = 0  # objects whose current ABox was read again (tests and the benchmark look)

    def refresh(self) -> tuple[Change, ...]:
        """Read again what changed since the last refresh (nothing when the store's revision is the same); what
        changed since the last call, graph by graph."""
        revision = self.store.revision()
        if revision != self._revision:
            self.version += 1
            ids = [obj.ident for obj in self.store.list_objects()]
            for gone in set(self._roots) - set(ids):
                for name in ("abox", "entailed"):
                    self._replace(name, gone, ())
                self._roots.pop(gone, None)
            for oid in ids:
                roots = self.store.current_roots(oid)
                if roots == self._roots.get(oid):
                    continue
                lines = self.store.export_lines("current", [oid])
                abox = parse_lines(line for line in lines if line.startswith(_ABOX_LINE))
                self._replace("abox", oid, abox)
                self._replace("entailed", oid, entail(abox, self.vocabulary))
                self._roots[oid] = roots
                self.objects_read += 1
            if self._inferred_stale:
                self._replace("inferred", "all", parse_lines(self.store.inferred_lines()))
                self._inferred_stale = False
            self._revision = revision
        changes, self._pending = tuple(c for c in self._pending if c.removed or c.added), []
        return changes

    def inferred_changed(self) -> None:
        """The store's inferred facts were replaced: read them again at the next refresh."""
        self._inferred_stale = True
        self._revision = None

    def contents(self) -> dict[str, frozenset[Triple]]:
        """Every graph's triples now (NAMED and DEFAULT), for an engine that starts afresh."""
        out = {name: frozenset(layer.count) for name, layer in self._layers.items()}
        out[DEFAULT] = frozenset(self._default.count)
        return out

    def sizes(self) -> dict[str, int]:
        return {name: len(layer.count) for name, layer in self._layers.items()}

    def _replace(self, name: str, key: str, triples: Iterable[Triple]) -> None:
        removed, added = self._layers[name].replace(key, triples)
        self._pending.append(Change(name, frozenset(removed), frozenset(added)))
        if name in DEFAULT_NAMES:
            gone, new = self._default.apply(removed, added)
            self._pending.append(Change(DEFAULT, frozenset(gone), frozenset(new)))

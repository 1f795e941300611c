"""The graph the SPARQL endpoint answers from: the TBox, each object's current ABox, what the TBox entails from it
and what a reasoner inferred, as four named graphs of one in-memory rdflib dataset, kept up to date from the store
through its interface (`Reads.revision`, `Export.current_roots`, `Export.export_lines`, `Inferences`).

It stays small however long the history: an object's current ABox is what the cooperation model works with now
(its object, goal, latest perceived state, latest problem, current plan), and it is read again only when its roots
changed (records are immutable), as a difference: a perception adds its state's triples and drops the previous
one's. Nothing here depends on a backend.

Every read and write of the dataset happens under `lock` (rdflib's memory store is not safe to read while it
changes); the store the dataset lives in stops a query past its deadline as it reads triples.
"""
from __future__ import annotations

import re
import threading
import time
from collections import Counter
from pathlib import Path
from typing import Any, Iterable, Iterator, Protocol

from rdflib import Dataset, Graph, Literal, URIRef
from rdflib.plugins.stores.memory import Memory
from rdflib.term import Node

from ..store import ABOX_IRI, DeadlineError
from ..store.interface import Export, Inferences, Reads
from .entailment import Triple, Vocabulary, entail

GRAPH_IRI = "http://planhrc.org/graph/"
GRAPHS = {name: URIRef(GRAPH_IRI + name) for name in ("tbox", "abox", "entailed", "inferred")}
DEFAULT_GRAPHS = (GRAPHS["tbox"], GRAPHS["abox"], GRAPHS["entailed"])  # asserted and entailed, not inferred
_ABOX_LINE = "<" + ABOX_IRI


class KnowledgeSource(Reads, Export, Inferences, Protocol):
    """The parts of the store the knowledge service reads."""


class BoundedMemory(Memory):
    """rdflib's memory store that raises `DeadlineError` when a query reads triples past `deadline`
    (`time.monotonic()`; None: no limit). Queries run one at a time (`KnowledgeGraph.lock`)."""

    CHECK_EVERY = 256

    def __init__(self) -> None:
        super().__init__()
        self.deadline: float | None = None
        self.limit_s = 0.0

    def _check(self) -> None:
        if self.deadline is not None and time.monotonic() > self.deadline:
            raise DeadlineError(f"query: no answer within {self.limit_s:g} s (the service's sparql_timeout_s); "
                                "ask for less, e.g. with more specific patterns or a LIMIT")

    def triples(self, triple_pattern: Any, context: Any = None) -> Iterator[Any]:  # type: ignore[override]
        self._check()
        for n, item in enumerate(super().triples(triple_pattern, context)):
            if not n % self.CHECK_EVERY:
                self._check()
            yield item


class _Layer:
    """One named graph whose triples come from several keys (objects): a triple shared by two keys stays until
    neither holds it."""

    def __init__(self, graph: Graph) -> None:
        self.graph = graph
        self.count: Counter[Triple] = Counter()
        self.by_key: dict[str, frozenset[Triple]] = {}

    def replace(self, key: str, triples: Iterable[Triple]) -> None:
        new = frozenset(triples)
        old = self.by_key.pop(key, frozenset())
        for t in old - new:
            self.count[t] -= 1
            if not self.count[t]:
                del self.count[t]
                self.graph.remove(t)
        for t in new - old:
            self.count[t] += 1
            if self.count[t] == 1:
                self.graph.add(t)
        if new:
            self.by_key[key] = new

    def keys(self) -> set[str]:
        return set(self.by_key)


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
    """The four graphs of the endpoint over one store; `refresh()` (under `lock`) brings them up to date."""

    def __init__(self, store: KnowledgeSource, tbox_path: Path | str) -> None:
        self.store = store
        self.lock = threading.Lock()
        self.memory = BoundedMemory()
        self.dataset = Dataset(store=self.memory, default_union=True)
        tbox = self.dataset.graph(GRAPHS["tbox"])
        tbox.parse(str(tbox_path), format="xml")
        self.vocabulary = Vocabulary.of(tbox)
        self._abox = _Layer(self.dataset.graph(GRAPHS["abox"]))
        self._entailed = _Layer(self.dataset.graph(GRAPHS["entailed"]))
        self._inferred = _Layer(self.dataset.graph(GRAPHS["inferred"]))
        self._entailed.replace("tbox", entail(tbox, self.vocabulary))  # the TBox's own individuals
        self._revision: int | None = None
        self._inferred_stale = True  # read at the first refresh, then after each reasoning job stored its facts
        self._roots: dict[str, tuple[str, ...]] = {}
        self.version = 0  # grows whenever a refresh changed something
        self.objects_read = 0  # objects whose current ABox was read again (tests and the benchmark look)

    def graph(self, iri: URIRef) -> Graph:
        return self.dataset.graph(iri)

    def refresh(self) -> None:
        """Read again what changed since the last refresh (nothing when the store's revision is the same)."""
        revision = self.store.revision()
        if revision == self._revision:
            return
        self.version += 1
        ids = [obj.ident for obj in self.store.list_objects()]
        for gone in set(self._roots) - set(ids):
            self._drop(gone)
        for oid in ids:
            roots = self.store.current_roots(oid)
            if roots == self._roots.get(oid):
                continue
            lines = self.store.export_lines("current", [oid])
            abox = parse_lines(line for line in lines if line.startswith(_ABOX_LINE))
            self._abox.replace(oid, abox)
            self._entailed.replace(oid, entail(abox, self.vocabulary))
            self._roots[oid] = roots
            self.objects_read += 1
        if self._inferred_stale:
            self._inferred.replace("all", parse_lines(self.store.inferred_lines()))
            self._inferred_stale = False
        self._revision = revision

    def inferred_changed(self) -> None:
        """The store's inferred facts were replaced: read them again at the next refresh."""
        self._inferred_stale = True
        self._revision = None

    def _drop(self, oid: str) -> None:
        for layer in (self._abox, self._entailed):
            layer.replace(oid, ())
        self._roots.pop(oid, None)

    def sizes(self) -> dict[str, int]:
        return {name: len(self.dataset.graph(iri)) for name, iri in GRAPHS.items()}

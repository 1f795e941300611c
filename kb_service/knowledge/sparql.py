"""SPARQL 1.1 queries over the knowledge graph (`graph.KnowledgeGraph`), read-only, with a time and a result-size
limit, answered in the format the client accepts.

This module decides what a query may read; an engine (`ENGINES`, each a `query_engine.QueryEngine`) evaluates it on
its copy of the graphs. The default graph is the union of the graphs the request names (`default-graph-uri`, or
`FROM` in the query), else of the TBox, the current ABox and the entailed facts; the four graphs are also named graphs
(`GRAPH <http://planhrc.org/graph/inferred> {…}`). Nothing is ever fetched from elsewhere: `FROM` may name only
these graphs and `SERVICE` is refused (`query_text`), so a query can make the service open no connection and read
no file. Updates (`INSERT`, `DELETE`, `LOAD`, `CLEAR`, …) are refused with a message that says the endpoint is
read-only.
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Callable, Mapping, Sequence

from rdflib import Graph

from planhrc.vocabulary import SparqlEngineName

from ..store import DeadlineError
from .graph import DEFAULT, DEFAULT_NAMES, GRAPHS, KnowledgeGraph
from .query_engine import CheckedQuery, QueryEngine, QueryError
from .query_text import read_query_text

# Media types of the answers: SELECT and ASK (SPARQL results), CONSTRUCT and DESCRIBE (RDF); the first is the
# default when the client accepts anything. The values are the formats' names the engines know.
RESULT_TYPES = {"application/sparql-results+json": "json", "application/json": "json",
                "application/sparql-results+xml": "xml", "application/xml": "xml", "text/xml": "xml",
                "text/csv": "csv", "text/tab-separated-values": "tsv"}
GRAPH_TYPES = {"text/turtle": "turtle", "application/n-triples": "nt", "application/rdf+xml": "xml",
               "application/ld+json": "json-ld"}
PREFIXES = {"planhrc": "http://planhrc.org/ontology/planhrc.owl#", "abox": "http://planhrc.org/abox#",
            "graph": "http://planhrc.org/graph/"}
READ_ONLY = ("query: this endpoint is read-only; SPARQL Update (INSERT, DELETE, LOAD, CLEAR, CREATE, DROP, ...) is "
             "refused")


@dataclass(frozen=True)
class SparqlRequest:
    """A query as the SPARQL protocol carries it."""

    query: str
    accept: str | None = None
    default_graphs: tuple[str, ...] = ()
    named_graphs: tuple[str, ...] = ()


@dataclass(frozen=True)
class SparqlAnswer:
    body: bytes
    media_type: str
    rows: int  # solutions, triples of a graph, or 1 for ASK
    seconds: float


def _oxigraph(limit_s: float) -> QueryEngine:
    from .engine_oxigraph import OxigraphEngine

    return OxigraphEngine(limit_s)


def _rdflib(limit_s: float) -> QueryEngine:
    from .engine_rdflib import RdflibEngine

    return RdflibEngine(limit_s)


ENGINES: dict[SparqlEngineName, Callable[[float], QueryEngine]] = {
    SparqlEngineName.OXIGRAPH: _oxigraph, SparqlEngineName.RDFLIB: _rdflib}


def known_prefixes() -> dict[str, str]:
    """The prefixes a query may use without declaring them: the endpoint's own and rdflib's usual ones (`owl:`,
    `rdfs:`, `xsd:`, ...), the same whichever engine answers."""
    out = {prefix: str(iri) for prefix, iri in Graph().namespace_manager.namespaces() if prefix}
    out.update(PREFIXES)
    return out


class SparqlEndpoint:
    """Runs one query at a time on a `KnowledgeGraph` within `timeout_s` and `max_results`, with an engine."""

    def __init__(self, graph: KnowledgeGraph, engine: QueryEngine, timeout_s: float, max_results: int) -> None:
        self.graph = graph
        self.engine = engine
        self.timeout_s = timeout_s
        self.max_results = max_results
        self.prefixes = known_prefixes()

    def close(self) -> None:
        self.engine.close()

    def run(self, request: SparqlRequest) -> SparqlAnswer:
        started = time.monotonic()
        query, media = self.check(request)
        self.engine.parse(query)
        graph = self.graph
        if not graph.lock.acquire(timeout=self.timeout_s):
            raise DeadlineError(f"query: the endpoint stayed busy for {self.timeout_s:g} s; try again")
        try:
            changes = graph.refresh()
            if not self.engine.loaded():
                self.engine.load(graph.contents())  # a new engine, or one stopped after an overrun
            elif changes:
                self.engine.apply(changes)
            # the limit counts from here: reading the store and (re)starting the engine are the service's work
            body, rows = self.engine.run(query, time.monotonic() + self.timeout_s, self.max_results)
        finally:
            graph.lock.release()
        return SparqlAnswer(body, media, rows, time.monotonic() - started)

    def check(self, request: SparqlRequest) -> tuple[CheckedQuery, str]:
        """The query as an engine gets it, and the answer's media type; QueryError for what is refused."""
        text = request.query
        if not isinstance(text, str) or not text.strip():
            raise QueryError("query: empty; send a SPARQL query (GET ?query=..., or POST)")
        read = read_query_text(text, self.prefixes)
        if read.is_update:
            raise QueryError(READ_ONLY)
        if read.service:
            raise QueryError("query: SERVICE is refused; this endpoint queries no other endpoint")
        _names(read.from_named, "FROM NAMED")  # every graph is a named graph already
        _names(request.named_graphs, "named-graph-uri")
        defaults = _names(request.default_graphs, "default-graph-uri") or _names(read.from_graphs, "FROM")
        if not defaults or set(defaults) == set(DEFAULT_NAMES):
            defaults = (DEFAULT,)
        graph_form = read.form in ("CONSTRUCT", "DESCRIBE")
        media, fmt = _media(request.accept, GRAPH_TYPES if graph_form else RESULT_TYPES)
        return CheckedQuery(text, tuple(sorted(set(defaults))), fmt, self.prefixes), media


def _names(iris: Sequence[str], field: str) -> tuple[str, ...]:
    """The names (of NAMED) of the graphs `iris`; QueryError naming `field` for any other."""
    by_iri = {str(iri): name for name, iri in GRAPHS.items()}
    unknown = [str(iri) for iri in iris if str(iri) not in by_iri]
    if unknown:
        raise QueryError(f"{field}: no graph {', '.join(unknown)} here; the graphs are "
                         f"{', '.join(sorted(by_iri))}")
    return tuple(by_iri[str(iri)] for iri in iris)


def _media(accept: str | None, types: Mapping[str, str]) -> tuple[str, str]:
    """The media type the client prefers among `types` (Accept's q-values honoured), else the first of them."""
    choices: list[tuple[float, int, str]] = []
    for i, part in enumerate((accept or "").split(",")):
        media, _, params = part.strip().partition(";")
        q = 1.0
        for param in params.split(";"):
            name, _, value = param.strip().partition("=")
            if name == "q":
                try:
                    q = float(value)
                except ValueError:
                    q = 0.0
        choices.append((-q, i, media.strip().lower()))
    for q, _, media in sorted(choices):
        if q < 0 and media in types:
            return media, types[media]
    first = next(iter(types))
    return first, types[first]

"""SPARQL 1.1 queries over the knowledge graph (`graph.KnowledgeGraph`), read-only, with a time and a result-size
limit, answered in the format the client accepts.

rdflib parses and evaluates the query; this module decides what it may read. The default graph is the union of
the graphs the request names (`default-graph-uri`, or `FROM` in the query), else of the TBox, the current ABox and
the entailed facts; the four graphs are also named graphs (`GRAPH <http://planhrc.org/graph/inferred> {…}`).
Nothing is ever fetched from elsewhere: `FROM` may name only these graphs and `SERVICE` is refused, so a query can
make the service open no connection and read no file. Updates (`INSERT`, `DELETE`, `LOAD`, `CLEAR`, …) are
refused with a message that says the endpoint is read-only.
"""
from __future__ import annotations

import time
from collections import OrderedDict
from dataclasses import dataclass
from itertools import islice
from typing import Any, Mapping, Sequence

from pyparsing import ParseException
from rdflib import RDF, BNode, URIRef, Variable
from rdflib.graph import Graph, ReadOnlyGraphAggregate
from rdflib.plugins.sparql.algebra import translateQuery
from rdflib.plugins.sparql.evaluate import evalPart
from rdflib.plugins.sparql.parser import parseQuery, parseUpdate
from rdflib.plugins.sparql.parserutils import CompValue
from rdflib.plugins.sparql.processor import SPARQLResult
from rdflib.plugins.sparql.sparql import Query, QueryContext, SPARQLError

from ..store import DeadlineError, KBError
from .graph import DEFAULT_GRAPHS, GRAPHS, KnowledgeGraph

# Media types of the answers: SELECT and ASK (SPARQL results), CONSTRUCT and DESCRIBE (RDF); the first is the
# default when the client accepts anything.
RESULT_TYPES = {"application/sparql-results+json": "json", "application/json": "json",
                "application/sparql-results+xml": "xml", "application/xml": "xml", "text/xml": "xml",
                "text/csv": "csv", "text/tab-separated-values": "tsv"}
GRAPH_TYPES = {"text/turtle": "turtle", "application/n-triples": "nt", "application/rdf+xml": "xml",
               "application/ld+json": "json-ld"}
PREPARED_KEPT = 256  # parsed queries kept (a console or a client sends the same few again and again)
PREFIXES = {"planhrc": "http://planhrc.org/ontology/planhrc.owl#", "abox": "http://planhrc.org/abox#",
            "graph": "http://planhrc.org/graph/"}


class QueryError(KBError):
    """The request is not a query this endpoint answers: malformed, an update, a SERVICE call, a graph it does not
    have, or an answer over the result-size limit (the message says which and what to do)."""


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


class SparqlEngine:
    """Runs one query at a time on a `KnowledgeGraph` within `timeout_s` and `max_results`."""

    def __init__(self, graph: KnowledgeGraph, timeout_s: float, max_results: int) -> None:
        self.graph = graph
        self.timeout_s = timeout_s
        self.max_results = max_results
        self._prepared: OrderedDict[str, Query] = OrderedDict()
        self._counts: tuple[int, Graph, _Counts] | None = None  # kept while the graph's version is the same

    def run(self, request: SparqlRequest) -> SparqlAnswer:
        started = time.monotonic()
        deadline = started + self.timeout_s
        query = self._prepare(request.query)
        defaults = _graphs(request.default_graphs, "default-graph-uri") or _from_clause(query) or DEFAULT_GRAPHS
        _graphs(request.named_graphs, "named-graph-uri")  # every graph is a named graph; others are refused
        kind = query.algebra.name
        media, fmt = _media(request.accept, GRAPH_TYPES if kind in ("ConstructQuery", "DescribeQuery")
                            else RESULT_TYPES)
        graph = self.graph
        if not graph.lock.acquire(timeout=self.timeout_s):
            raise DeadlineError(f"query: the endpoint stayed busy for {self.timeout_s:g} s; try again")
        try:
            graph.refresh()
            graph.memory.deadline, graph.memory.limit_s = deadline, self.timeout_s
            result, rows = self._evaluate(query, defaults)
            body = _serialize(result, fmt)
        finally:
            graph.memory.deadline = None
            graph.lock.release()
        return SparqlAnswer(body, media, rows, time.monotonic() - started)

    def _prepare(self, text: str) -> Query:
        if not isinstance(text, str) or not text.strip():
            raise QueryError("query: empty; send a SPARQL query (GET ?query=..., or POST)")
        query = self._prepared.get(text)
        if query is not None:
            self._prepared.move_to_end(text)
            return query
        query = prepare(text)
        self._prepared[text] = query
        if len(self._prepared) > PREPARED_KEPT:
            self._prepared.popitem(last=False)
        return query

    def _evaluate(self, query: Query, defaults: Sequence[URIRef]) -> tuple[SPARQLResult, int]:
        ctx = QueryContext(self.graph.dataset)  # no dataset clause: rdflib would copy (or fetch) graphs
        filled = {iri for iri in GRAPHS.values() if len(self.graph.graph(iri))}
        # the dataset's own union when it is the default graph (one index lookup a pattern, not one a graph)
        ctx.graph = self.graph.dataset if filled <= set(defaults) else _union([self.graph.graph(i) for i in defaults])
        ctx.prologue = query.prologue
        _order_patterns(query.algebra, self._counts_of(ctx.graph))
        try:
            res: dict[str, Any] = dict(evalPart(ctx, query.algebra))
            if res["type_"] == "SELECT":
                res["bindings"] = list(islice(res["bindings"], self.max_results + 1))
                rows = len(res["bindings"])
            elif res["type_"] == "ASK":
                rows = 1
            else:
                rows = len(res["graph"])
        except (SPARQLError, TypeError, ValueError, ZeroDivisionError) as exc:
            raise QueryError(f"query: cannot be evaluated ({exc})") from None
        if rows > self.max_results:
            raise QueryError(f"query: the answer has more than {self.max_results} results (the service's "
                             "sparql_max_results); ask for fewer, e.g. with LIMIT and OFFSET")
        return SPARQLResult(res), rows


    def _counts_of(self, graph: Graph) -> _Counts:
        kept = self._counts
        if kept is None or kept[0] != self.graph.version or kept[1] is not graph:
            kept = self._counts = (self.graph.version, graph, _Counts(graph))
        return kept[2]


def prepare(text: str) -> Query:
    """Parse a query and check that it only reads this endpoint's graphs; QueryError naming what is wrong."""
    try:
        query = translateQuery(parseQuery(text), None, PREFIXES)
    except ParseException as exc:
        if _is_update(text):
            raise QueryError("query: this endpoint is read-only; SPARQL Update (INSERT, DELETE, LOAD, CLEAR, "
                             "CREATE, DROP, ...) is refused") from None
        raise QueryError(f"query: not SPARQL 1.1 ({exc.msg} at line {exc.lineno}, column {exc.col})") from None
    except Exception as exc:  # rdflib's translation raises plain exceptions for unknown prefixes and the like
        raise QueryError(f"query: {exc}") from None
    if _has_service(query.algebra):
        raise QueryError("query: SERVICE is refused; this endpoint queries no other endpoint")
    _from_clause(query)
    return query


def _is_update(text: str) -> bool:
    try:
        parseUpdate(text)
    except Exception:
        return False
    return True


def _has_service(node: object) -> bool:
    if isinstance(node, CompValue):
        return node.name == "ServiceGraphPattern" or any(_has_service(v) for v in node.values())
    if isinstance(node, (list, tuple)):
        return any(_has_service(v) for v in node)
    return False


def _graphs(iris: Sequence[str], field: str) -> tuple[URIRef, ...]:
    known = set(GRAPHS.values())
    out = tuple(URIRef(str(iri)) for iri in iris)
    unknown = [str(iri) for iri in out if iri not in known]
    if unknown:
        raise QueryError(f"{field}: no graph {', '.join(unknown)} here; the graphs are "
                         f"{', '.join(sorted(str(g) for g in known))}")
    return out


def _from_clause(query: Query) -> tuple[URIRef, ...]:
    """The graphs `FROM` names (FROM NAMED is accepted: every graph is a named graph already)."""
    clause = query.algebra.get("datasetClause") or ()
    # (a CompValue's `get` answers a missing key with the key's name: ask with `in`)
    defaults = [d["default"] for d in clause if "default" in d]
    _graphs([d["named"] for d in clause if "named" in d], "FROM NAMED")
    return _graphs(defaults, "FROM")


class _Counts:
    """How many triples of a graph match a pattern's constant terms (up to `CAP`), counted once a query."""

    CAP = 2_000

    def __init__(self, graph: Graph) -> None:
        self.graph = graph
        self.known: dict[tuple[Any, Any, Any], int] = {}

    def __call__(self, pattern: tuple[Any, Any, Any]) -> int:
        found = self.known.get(pattern)
        if found is None:
            found = self.known[pattern] = sum(1 for _ in islice(self.graph.triples(pattern), self.CAP))
        return found


def _order_patterns(node: object, counts: _Counts, bound: frozenset[Any] = frozenset()) -> None:
    """Order the triple patterns of every basic graph pattern so that each one joins what came before and the
    fewest matches come first. rdflib's own order puts every pattern with two constant terms first, and two
    `?x a C` patterns on unrelated variables then make a product (every perceived state times every
    predicate individual)."""
    if isinstance(node, CompValue):
        if node.name == "BGP" and "triples" in node and len(node["triples"]) > 1:
            node["triples"] = _greedy(list(node["triples"]), counts, bound)
        if node.name == "Join" and "lazy" in node and node["lazy"]:
            # rdflib evaluates p2 once per solution of p1: p1's variables are bound in p2
            _order_patterns(node["p1"], counts, bound)
            _order_patterns(node["p2"], counts, bound | frozenset(node["p1"]["_vars"]))
            return
        for value in node.values():
            _order_patterns(value, counts, bound)
    elif isinstance(node, (list, tuple)):
        for value in node:
            _order_patterns(value, counts, bound)


def _greedy(patterns: list[tuple[Any, Any, Any]], counts: _Counts, given: frozenset[Any]) -> list[tuple[Any, Any, Any]]:
    def variable(term: Any) -> bool:
        return isinstance(term, (Variable, BNode))

    bound: set[Any] = set(given)
    out = []
    while patterns:
        def cost(t: tuple[Any, Any, Any]) -> tuple[bool, int, bool, int]:
            joins = any(variable(x) and x in bound for x in t)
            known = sum(1 for x in t if not variable(x) or x in bound)
            # a known value (not a class) picks out few subjects; a known subject, few values
            value_known = t[1] != RDF.type and (not variable(t[2]) or t[2] in bound)
            return (bool(bound) and not joins, -known, not value_known,
                    counts((None if variable(t[0]) else t[0], None if variable(t[1]) else t[1],
                            None if variable(t[2]) else t[2])))

        best = min(patterns, key=cost)
        patterns.remove(best)
        out.append(best)
        bound.update(x for x in best if variable(x))
    return out


class _Union(ReadOnlyGraphAggregate):
    """The default graph: several graphs of the dataset read as one, each triple once."""

    def triples(self, triple: Any) -> Any:  # type: ignore[override]
        if len(self.graphs) == 1:
            yield from self.graphs[0].triples(triple)
            return
        seen: set[Any] = set()
        for graph in self.graphs:
            for t in graph.triples(triple):
                if t not in seen:
                    seen.add(t)
                    yield t


def _union(graphs: list[Graph]) -> Graph:
    return graphs[0] if len(graphs) == 1 else _Union(graphs)


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


def _serialize(result: SPARQLResult, fmt: str) -> bytes:
    out: bytes | str | None
    if result.type in ("CONSTRUCT", "DESCRIBE"):
        assert result.graph is not None
        out = result.graph.serialize(format=fmt, encoding="utf-8")
    else:
        out = result.serialize(format=fmt, encoding="utf-8")
    return out if isinstance(out, bytes) else str(out or "").encode("utf-8")

"""The rdflib engine: the graphs in an rdflib dataset in the service's process, queries evaluated by rdflib.

The endpoint's first engine, kept to compare (`PLANHRC_SPARQL_ENGINE=rdflib`, the benchmark's side-by-side run,
the engines' agreement test). Its memory store checks the query's deadline as it reads triples; triple patterns
are ordered so that each joins the ones before it, fewest matches first.
"""
from __future__ import annotations

import time
from collections import OrderedDict
from itertools import islice
from typing import Any, Iterator, Mapping, Sequence

from pyparsing import ParseException
from rdflib import RDF, BNode, Dataset, Variable
from rdflib.graph import Graph, ReadOnlyGraphAggregate
from rdflib.plugins.sparql.algebra import translateQuery
from rdflib.plugins.sparql.evaluate import evalPart
from rdflib.plugins.sparql.parser import parseQuery
from rdflib.plugins.sparql.parserutils import CompValue
from rdflib.plugins.sparql.processor import SPARQLResult
from rdflib.plugins.sparql.sparql import Query, QueryContext, SPARQLError
from rdflib.plugins.stores.memory import Memory

from .entailment import Triple
from .graph import DEFAULT, DEFAULT_NAMES, GRAPHS, NAMED, Change
from .query_engine import CheckedQuery, QueryError, timed_out

PREPARED_KEPT = 256  # parsed queries kept (a console or a client sends the same few again and again)


class BoundedMemory(Memory):
    """rdflib's memory store that raises `DeadlineError` when a query reads triples past `deadline`
    (`time.monotonic()`; None: no limit). Queries run one at a time (the endpoint's lock)."""

    CHECK_EVERY = 256

    def __init__(self) -> None:
        super().__init__()
        self.deadline: float | None = None
        self.limit_s = 0.0

    def _check(self) -> None:
        if self.deadline is not None and time.monotonic() > self.deadline:
            raise timed_out(self.limit_s)

    def triples(self, triple_pattern: Any, context: Any = None) -> Iterator[Any]:  # type: ignore[override]
        self._check()
        for n, item in enumerate(super().triples(triple_pattern, context)):
            if not n % self.CHECK_EVERY:
                self._check()
            yield item


class RdflibEngine:
    def __init__(self, limit_s: float) -> None:
        self.memory = BoundedMemory()
        self.memory.limit_s = limit_s
        self.dataset = Dataset(store=self.memory, default_union=True)
        self._loaded = False
        self._version = 0
        self._prepared: OrderedDict[str, Query] = OrderedDict()
        self._counts: tuple[int, Graph, _Counts] | None = None  # kept while the graphs are the same

    def loaded(self) -> bool:
        return self._loaded

    def load(self, contents: Mapping[str, frozenset[Triple]]) -> None:
        for name in NAMED:
            graph = self.dataset.graph(GRAPHS[name])
            for t in contents[name]:
                graph.add(t)
        self._loaded = True
        self._version += 1

    def apply(self, changes: Sequence[Change]) -> None:
        for change in changes:
            if change.graph == DEFAULT:
                continue  # the dataset's own union
            graph = self.dataset.graph(GRAPHS[change.graph])
            for t in change.removed:
                graph.remove(t)
            for t in change.added:
                graph.add(t)
        self._version += 1

    def close(self) -> None:
        pass

    def parse(self, query: CheckedQuery) -> None:
        self._prepare(query)  # kept for the run that follows

    def run(self, query: CheckedQuery, deadline: float, max_results: int) -> tuple[bytes, int]:
        prepared = self._prepare(query)
        self.memory.deadline = deadline
        try:
            result, rows = self._evaluate(prepared, query.defaults, max_results)
            return _serialize(result, query.fmt), rows
        finally:
            self.memory.deadline = None

    def _prepare(self, query: CheckedQuery) -> Query:
        prepared = self._prepared.get(query.text)
        if prepared is not None:
            self._prepared.move_to_end(query.text)
            return prepared
        try:
            prepared = translateQuery(parseQuery(query.text), None, dict(query.prefixes))
        except ParseException as exc:
            raise QueryError(f"query: not SPARQL 1.1 ({exc.msg} at line {exc.lineno}, column {exc.col})") from None
        except Exception as exc:  # rdflib's translation raises plain exceptions for unknown prefixes and the like
            raise QueryError(f"query: {exc}") from None
        self._prepared[query.text] = prepared
        if len(self._prepared) > PREPARED_KEPT:
            self._prepared.popitem(last=False)
        return prepared

    def _evaluate(self, query: Query, defaults: Sequence[str], max_results: int) -> tuple[SPARQLResult, int]:
        ctx = QueryContext(self.dataset)  # no dataset clause: rdflib would copy (or fetch) graphs
        names = DEFAULT_NAMES if tuple(defaults) == (DEFAULT,) else defaults
        filled = {name for name in NAMED if len(self.dataset.graph(GRAPHS[name]))}
        # the dataset's own union when it is the default graph (one index lookup a pattern, not one a graph)
        ctx.graph = self.dataset if filled <= set(names) else _union([self.dataset.graph(GRAPHS[n]) for n in names])
        ctx.prologue = query.prologue
        _order_patterns(query.algebra, self._counts_of(ctx.graph))
        try:
            res: dict[str, Any] = dict(evalPart(ctx, query.algebra))
            if res["type_"] == "SELECT":
                res["bindings"] = list(islice(res["bindings"], max_results + 1))
                rows = len(res["bindings"])
            elif res["type_"] == "ASK":
                rows = 1
            else:
                rows = len(res["graph"])
        except (SPARQLError, TypeError, ValueError, ZeroDivisionError) as exc:
            raise QueryError(f"query: cannot be evaluated ({exc})") from None
        if rows > max_results:
            raise QueryError(f"query: the answer has more than {max_results} results (the service's "
                             "sparql_max_results); ask for fewer, e.g. with LIMIT and OFFSET")
        return SPARQLResult(res), rows

    def _counts_of(self, graph: Graph) -> _Counts:
        kept = self._counts
        if kept is None or kept[0] != self._version or kept[1] is not graph:
            kept = self._counts = (self._version, graph, _Counts(graph))
        return kept[2]


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


def _serialize(result: SPARQLResult, fmt: str) -> bytes:
    out: bytes | str | None
    if result.type in ("CONSTRUCT", "DESCRIBE"):
        assert result.graph is not None
        out = result.graph.serialize(format=fmt, encoding="utf-8")
    else:
        out = result.serialize(format=fmt, encoding="utf-8")
    return out if isinstance(out, bytes) else str(out or "").encode("utf-8")

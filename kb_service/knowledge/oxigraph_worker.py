"""The Oxigraph query process: a copy of the endpoint's graphs in an in-memory Oxigraph store, queries evaluated
there (`engine_oxigraph` starts it and talks to it).

Messages (pickled over the connection the parent hands over), each answered with one message:

* `("load", nquads, named)`: the graphs as N-Quads (the default graph's triples without a graph name) and the
  IRIs of the named graphs a query may see;
* `("apply", removed, added)`: N-Quads that left and entered the graphs;
* `("query", text, defaults, fmt, max_results, prefixes)`: the answer's bytes and rows, or an error.

The answer is `("ok", value)` or `("error", message)`. Oxigraph releases no memory of a query it abandons and
offers no way to stop one, so the parent stops this process instead; it also stops by itself when its parent is
gone.
"""
from __future__ import annotations

import io
import os
import signal
import sys
import threading
import time
from multiprocessing.connection import Connection
from typing import Any

import pyoxigraph as ox

RESULT_FORMATS = {"json": ox.QueryResultsFormat.JSON, "xml": ox.QueryResultsFormat.XML,
                  "csv": ox.QueryResultsFormat.CSV, "tsv": ox.QueryResultsFormat.TSV}
GRAPH_FORMATS = {"turtle": ox.RdfFormat.TURTLE, "nt": ox.RdfFormat.N_TRIPLES, "xml": ox.RdfFormat.RDF_XML,
                 "json-ld": ox.RdfFormat.JSON_LD}
_PARENT_POLL_S = 0.5


class _QueryFailed(Exception):
    """A query this process cannot answer; the message is the client's."""


class Replica:
    """The store and what a query needs besides it."""

    def __init__(self) -> None:
        self.store = ox.Store()
        self.named: list[ox.NamedNode | ox.BlankNode] = []
        self._unions: dict[tuple[str, ...], ox.NamedNode] = {}  # other default graphs, made when first asked

    def load(self, nquads: bytes, named: list[str]) -> None:
        self.store.clear()
        self._unions.clear()
        self.store.extend(ox.parse(nquads, format=ox.RdfFormat.N_QUADS))  # blank node labels kept
        self.named = [ox.NamedNode(iri) for iri in named]

    def apply(self, removed: bytes, added: bytes) -> None:
        for quad in ox.parse(removed, format=ox.RdfFormat.N_QUADS):
            self.store.remove(quad)
        self.store.extend(ox.parse(added, format=ox.RdfFormat.N_QUADS))
        for graph in self._unions.values():
            self.store.remove_graph(graph)
        self._unions.clear()

    def default_graph(self, defaults: list[str] | None) -> Any:
        """The default graph of a query: the store's (None), one graph, or a graph made as the union of several
        (Oxigraph reads a list of graphs as a bag: a triple in two of them would be seen twice)."""
        if defaults is None:
            return ox.DefaultGraph()
        if len(defaults) == 1:
            return ox.NamedNode(defaults[0])
        key = tuple(sorted(defaults))
        union = self._unions.get(key)
        if union is None:
            union = ox.NamedNode(f"urn:planhrc:union:{len(self._unions)}")
            values = " ".join(f"<{iri}>" for iri in key)
            self.store.update(f"INSERT {{ GRAPH <{union.value}> {{ ?s ?p ?o }} }} "
                              f"WHERE {{ VALUES ?g {{ {values} }} GRAPH ?g {{ ?s ?p ?o }} }}")
            self._unions[key] = union
        return union

    def query(self, text: str, defaults: list[str] | None, fmt: str, max_results: int,
              prefixes: dict[str, str]) -> tuple[bytes, int]:
        graph = self.default_graph(defaults)
        try:
            result = self.store.query(text, prefixes=prefixes, default_graph=graph, named_graphs=self.named)
        except SyntaxError as exc:
            raise _QueryFailed(f"query: not SPARQL 1.1 ({_one_line(exc)})") from None
        try:
            if isinstance(result, ox.QueryBoolean):
                return _bytes(result.serialize(format=RESULT_FORMATS.get(fmt, ox.QueryResultsFormat.JSON))), 1
            if isinstance(result, ox.QueryTriples):
                triples = list(dict.fromkeys(_first(result, max_results + 1)))  # a graph holds each triple once
                _check_size(len(triples), max_results)
                return _bytes(ox.serialize(triples, format=GRAPH_FORMATS.get(fmt, ox.RdfFormat.TURTLE),
                                           prefixes=prefixes)), len(triples)
            # the solutions as TSV (one line each, written by Oxigraph as it evaluates: the lines are counted, and
            # the writing stops past the limit), then in the client's format, all without a Python object a term
            rows = _Rows(max_results)
            result.serialize(rows, format=ox.QueryResultsFormat.TSV)
        except _TooMany:
            raise _QueryFailed(_too_many(max_results)) from None
        except (OSError, ValueError, TypeError) as exc:
            raise _QueryFailed(f"query: cannot be evaluated ({_one_line(exc)})") from None
        tsv = rows.getvalue()
        if fmt == "tsv":
            return tsv, rows.count
        parsed = ox.parse_query_results(tsv, format=ox.QueryResultsFormat.TSV)
        return _bytes(parsed.serialize(format=RESULT_FORMATS.get(fmt, ox.QueryResultsFormat.JSON))), rows.count


class _TooMany(Exception):
    """More solutions than the answer may hold."""


class _Rows(io.BytesIO):
    """What Oxigraph writes as TSV, with its solutions counted (a line each, after the line of the variables);
    past `limit` it stops the writing."""

    def __init__(self, limit: int) -> None:
        super().__init__()
        self.limit = limit
        self.lines = 0

    @property
    def count(self) -> int:
        return max(0, self.lines - 1)

    def write(self, data: Any) -> int:
        self.lines += bytes(data).count(b"\n")
        if self.count > self.limit:
            raise _TooMany()
        return super().write(data)


def _first(items: Any, n: int) -> Any:
    for i, item in enumerate(items):
        if i == n:
            return
        yield item


def _too_many(max_results: int) -> str:
    return (f"query: the answer has more than {max_results} results (the service's sparql_max_results); ask for "
            "fewer, e.g. with LIMIT and OFFSET")


def _check_size(rows: int, max_results: int) -> None:
    if rows > max_results:
        raise _QueryFailed(_too_many(max_results))


def _one_line(exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    return text if len(text) <= 300 else text[:297] + "..."


def _bytes(out: bytes | None) -> bytes:
    """What Oxigraph's serialisers return without an output file."""
    assert out is not None
    return out


def serve(conn: Connection) -> None:
    """Answer the parent's messages until the connection closes."""
    replica = Replica()
    while True:
        try:
            message = conn.recv()
        except (EOFError, OSError):
            return
        kind, args = message[0], message[1:]
        try:
            if kind == "load":
                replica.load(*args)
                answer: tuple[Any, ...] = ("ok", None)
            elif kind == "apply":
                replica.apply(*args)
                answer = ("ok", None)
            else:
                answer = ("ok", replica.query(*args))
        except _QueryFailed as exc:
            answer = ("error", str(exc))
        except Exception as exc:  # the parent gets an answer whatever happens
            answer = ("error", f"query: cannot be evaluated ({_one_line(exc)})")
        try:
            conn.send(answer)
        except OSError:
            return


def _watch_parent(parent: int) -> None:
    while os.getppid() == parent:
        time.sleep(_PARENT_POLL_S)
    os._exit(1)  # the parent is gone (SIGKILL included): nothing here is worth keeping


def main() -> None:
    """`python -c ... FD PARENT_PID`."""
    fd, parent = int(sys.argv[1]), int(sys.argv[2])
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the service stops this process itself
    threading.Thread(target=_watch_parent, args=(parent,), name="planhrc-parent-watch", daemon=True).start()
    serve(Connection(fd))

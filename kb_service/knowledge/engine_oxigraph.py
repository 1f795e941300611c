"""The Oxigraph engine: the graphs copied into an Oxigraph store in a process of its own (`oxigraph_worker`),
queries evaluated there.

Oxigraph (Rust) answers the endpoint's queries in a few milliseconds where rdflib took tens to hundreds
(docs/knowledge.md, "Measured"), but it can neither be told to stop a query nor be interrupted: a query that runs
past its time limit keeps a core busy until it ends, which for a product of large patterns is never. So it runs
in a child process that the service stops (SIGKILL: it holds nothing but a copy) when a query overruns, and
starts again with the graphs at the next query. Its answer is the query's bytes, already in the client's format.
"""
from __future__ import annotations

import logging
import os
import socket
import subprocess
import sys
import time
from multiprocessing.connection import Connection
from typing import Any, Iterable, Mapping, Sequence

import pyoxigraph
from rdflib import BNode, Literal, URIRef

from .entailment import Triple
from .graph import DEFAULT, GRAPHS, NAMED, Change
from .oxigraph_worker import one_line
from .query_engine import CheckedQuery, EngineError, QueryError, timed_out

log = logging.getLogger(__name__)

START_TIMEOUT_S = 60.0  # starting the process and loading the graphs: not a query's time
_ESCAPES = str.maketrans({"\\": "\\\\", '"': '\\"', "\n": "\\n", "\r": "\\r"})


def nquad(t: Triple, graph: str) -> str:
    """One triple of graph `graph` (a name of NAMED, or DEFAULT) as an N-Quads line."""
    name = "" if graph == DEFAULT else f" <{GRAPHS[graph]}>"
    return f"{_term(t[0])} {_term(t[1])} {_term(t[2])}{name} .\n"


def _term(term: Any) -> str:
    if isinstance(term, URIRef):
        return f"<{term}>"
    if isinstance(term, BNode):
        return f"_:{term}"
    if isinstance(term, Literal):
        text = f'"{str(term).translate(_ESCAPES)}"'
        if term.language:
            return f"{text}@{term.language}"
        return f"{text}^^<{term.datatype}>" if term.datatype else text
    raise TypeError(f"not an RDF term: {term!r}")


def _nquads(items: Iterable[tuple[str, Iterable[Triple]]]) -> bytes:
    return "".join(nquad(t, graph) for graph, triples in items for t in triples).encode("utf-8")


class OxigraphEngine:
    def __init__(self, limit_s: float) -> None:
        self.limit_s = limit_s
        self._proc: subprocess.Popen[bytes] | None = None
        self._conn: Connection | None = None
        self.starts = 0  # processes started (the tests look)
        self._empty = pyoxigraph.Store()  # in memory, never written: where queries are read (`parse`)

    def loaded(self) -> bool:
        return self._conn is not None and self._proc is not None and self._proc.poll() is None

    def load(self, contents: Mapping[str, frozenset[Triple]]) -> None:
        self.close()
        parent_end, child_end = socket.socketpair()
        code = "from planhrc.kb_service.knowledge.oxigraph_worker import main; main()"
        try:
            self._proc = subprocess.Popen([sys.executable, "-c", code, str(child_end.fileno()), str(os.getpid())],
                                          pass_fds=(child_end.fileno(),), stdin=subprocess.DEVNULL,
                                          start_new_session=True)
        except OSError as exc:
            raise EngineError(f"sparql: cannot start the query process: {exc}") from None
        finally:
            child_end.close()
        self._conn = Connection(parent_end.detach())
        self.starts += 1
        start_by = time.monotonic() + START_TIMEOUT_S
        self._ask(("load", _nquads(contents.items()), [str(GRAPHS[n]) for n in NAMED]), start_by)
        # a first query pays for what the process has not touched yet (pages of its code, the parser's tables):
        # here, not within a client's time limit
        self._ask(("query", "ASK { ?s ?p ?o }", None, "json", 1, {}), start_by)
        log.info("sparql: query process %d holds %d triples", self._proc.pid, len(contents[DEFAULT]))

    def parse(self, query: CheckedQuery) -> None:
        """Oxigraph reads the query here, on an empty store of this process: nothing to evaluate, so the answer is
        at once, where the query process may be stopped (after an overrun) and take seconds to load again."""
        try:
            self._empty.query(query.text, prefixes=dict(query.prefixes))
        except SyntaxError as exc:
            raise QueryError(f"query: not SPARQL 1.1 ({one_line(exc)})") from None
        except (OSError, ValueError, RuntimeError) as exc:  # how pyoxigraph reports a query it cannot evaluate
            raise QueryError(f"query: cannot be evaluated ({one_line(exc)})") from None

    def apply(self, changes: Sequence[Change]) -> None:
        removed = _nquads((c.graph, c.removed) for c in changes)
        added = _nquads((c.graph, c.added) for c in changes)
        self._ask(("apply", removed, added), time.monotonic() + START_TIMEOUT_S)

    def run(self, query: CheckedQuery, deadline: float, max_results: int) -> tuple[bytes, int]:
        defaults = None if query.defaults == (DEFAULT,) else [str(GRAPHS[n]) for n in query.defaults]
        body, rows = self._ask(("query", query.text, defaults, query.fmt, max_results, dict(query.prefixes)),
                               deadline)
        return body, rows

    def close(self) -> None:
        """Stop the query process (SIGKILL: it holds only a copy); the next `load` starts another."""
        proc, conn = self._proc, self._conn
        self._proc = self._conn = None
        if conn is not None:
            conn.close()
        if proc is not None and proc.poll() is None:
            proc.kill()
            proc.wait()

    def pid(self) -> int | None:
        return self._proc.pid if self._proc is not None else None

    def _ask(self, message: tuple[Any, ...], deadline: float) -> Any:
        conn = self._conn
        if conn is None:
            raise EngineError("sparql: the query process is not running")
        try:
            conn.send(message)
            if not conn.poll(max(0.0, deadline - time.monotonic())):
                log.warning("sparql: a query overran %g s: query process %s stopped", self.limit_s, self.pid())
                self.close()
                raise timed_out(self.limit_s)
            status, value = conn.recv()
        except (EOFError, OSError) as exc:
            code = self._proc.poll() if self._proc is not None else None
            self.close()
            raise EngineError(f"sparql: the query process stopped ({type(exc).__name__}, exit code {code}); "
                              "the next query starts another") from None
        if status == "error":
            raise QueryError(value)
        return value


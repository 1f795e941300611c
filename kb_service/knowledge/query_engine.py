"""What a SPARQL engine is given and answers (`sparql.ENGINES` names the engines): a checked query, the errors it
raises, and the protocol every engine follows."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping, Protocol, Sequence

from ..store import DeadlineError, KBError
from .entailment import Triple
from .graph import Change


class QueryError(KBError):
    """The request is not a query this endpoint answers: malformed, an update, a SERVICE call, a graph it does not
    have, or an answer over the result-size limit (the message says which and what to do)."""


class EngineError(KBError):
    """The engine failed other than by the query's fault (its process could not start, or it died); the next
    query tries again."""


@dataclass(frozen=True)
class CheckedQuery:
    """A query the endpoint answers, as an engine gets it."""

    text: str
    defaults: tuple[str, ...]  # the default graph: DEFAULT, or names of NAMED to unite
    fmt: str  # a value of RESULT_TYPES or GRAPH_TYPES
    prefixes: Mapping[str, str]  # known without a PREFIX line


class QueryEngine(Protocol):
    """Evaluates checked queries on its own copy of the graphs."""

    def loaded(self) -> bool:
        """Whether the engine holds the graphs (else `load` them before a query)."""

    def load(self, contents: Mapping[str, frozenset[Triple]]) -> None: ...

    def parse(self, query: CheckedQuery) -> None:
        """QueryError for a query the engine cannot read, without the graphs: a syntax error is answered at once,
        also while the graphs are being (re)loaded."""

    def apply(self, changes: Sequence[Change]) -> None: ...

    def run(self, query: CheckedQuery, deadline: float, max_results: int) -> tuple[bytes, int]:
        """The answer's bytes and its rows; DeadlineError past `deadline` (`time.monotonic()`), QueryError for a
        query it cannot evaluate or an answer over `max_results`."""

    def close(self) -> None: ...


def timed_out(limit_s: float) -> DeadlineError:
    return DeadlineError(f"query: no answer within {limit_s:g} s (the service's sparql_timeout_s); ask for less, "
                         "e.g. with more specific patterns or a LIMIT")

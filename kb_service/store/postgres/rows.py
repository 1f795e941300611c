"""Triples as rows of `planhrc_triple`: a batch of rows (`RowBatch`, the PostgreSQL `unit.TripleBatch`), the
literals' lexical forms and datatypes, the rows of individuals read back (`Individual`), and rows as N-Triples.

Literals take the forms owlready2 gives the same Python values (a test compares them), so a PostgreSQL export is
the SQLite store's, line for line.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Iterable

from ..errors import DamagedStoreError, KBError
from ..names import ABOX_IRI, TBOX_IRI
from ..owl import escape_literal
from .schema import NAMED_INDIVIDUAL, RDF_TYPE

XSD = "http://www.w3.org/2001/XMLSchema#"
BOOLEAN, INTEGER, DECIMAL, STRING = XSD + "boolean", XSD + "integer", XSD + "decimal", XSD + "string"
_ABOX = len(ABOX_IRI)
_TBOX = len(TBOX_IRI)

Row = tuple[str, str, str | None, str | None, str | None]  # (s, p, o, lit, dt)


def literal(value: Any) -> tuple[str, str]:
    """(lexical form, datatype IRI) of a value the store writes."""
    if isinstance(value, bool):
        return ("true" if value else "false"), BOOLEAN
    if isinstance(value, int):
        return str(value), INTEGER
    if isinstance(value, float):
        return repr(value), DECIMAL
    if isinstance(value, str):
        return value, STRING
    raise KBError(f"internal: no literal form for a {type(value).__name__}")


def value_of(lit: str, dt: str | None) -> Any:
    """The Python value of a stored literal."""
    if dt == INTEGER:
        return int(lit)
    if dt == DECIMAL:
        return float(lit)
    if dt == BOOLEAN:
        return lit == "true"
    return lit


class RowBatch:
    """Rows collected during a write, flushed in one COPY (`Session.flush`)."""

    __slots__ = ("rows", "new", "shared")

    def __init__(self) -> None:
        self.rows: list[Row] = []
        self.new: list[str] = []  # individuals this batch creates
        self.shared: set[str] = set()

    def individual(self, name: str, *classes: str) -> str:
        s = ABOX_IRI + name
        self.new.append(name)
        self.rows.append((s, RDF_TYPE, NAMED_INDIVIDUAL, None, None))
        for cls in classes:
            self.rows.append((s, RDF_TYPE, TBOX_IRI + cls, None, None))
        return name

    def rel(self, s: str, prop: str, o: str) -> None:
        self.rows.append((ABOX_IRI + s, TBOX_IRI + prop, ABOX_IRI + o, None, None))

    def data(self, s: str, prop: str, value: Any) -> None:
        lit, dt = literal(value)
        self.rows.append((ABOX_IRI + s, TBOX_IRI + prop, None, lit, dt))


@dataclass
class Individual:
    """One ABox individual read back: its TBox classes, its object properties (names of individuals) and its data
    properties (values), by TBox name."""

    name: str
    types: set[str] = field(default_factory=set)
    rels: dict[str, list[str]] = field(default_factory=dict)
    data: dict[str, Any] = field(default_factory=dict)

    def one(self, prop: str) -> str:
        """The one object of a property every record of its kind has; a missing one is a damaged store."""
        found = self.rels.get(prop)
        if not found:
            raise DamagedStoreError(f"store: record {self.name} has no {prop}")
        return found[0]

    def value(self, prop: str) -> Any:
        if prop not in self.data:
            raise DamagedStoreError(f"store: record {self.name} has no {prop}")
        return self.data[prop]


def individuals(rows: Iterable[tuple[str, str, str | None, str | None, str | None]]) -> dict[str, Individual]:
    """Rows of ABox subjects, by name."""
    out: dict[str, Individual] = {}
    for s, p, o, lit, dt in rows:
        name = s[_ABOX:]
        ind = out.get(name)
        if ind is None:
            ind = out[name] = Individual(name)
        if p == RDF_TYPE:
            if o is not None and o.startswith(TBOX_IRI):
                ind.types.add(o[_TBOX:])
        elif o is not None:
            ind.rels.setdefault(p[_TBOX:], []).append(o[_ABOX:])
        elif lit is not None:
            ind.data[p[_TBOX:]] = value_of(lit, dt)
    return out


def ntriple(s: str, p: str, o: str | None, lit: str | None, dt: str | None) -> str:
    """A row as an N-Triples line, as `owl.ntriple_lines` writes the SQLite store's."""
    if o is not None:
        return f"<{s}> <{p}> <{o}> .\n"
    text = f'"{escape_literal(str(lit))}"'
    if dt and dt.startswith("@"):
        text += dt
    elif dt:
        text += f"^^<{dt}>"
    return f"<{s}> <{p}> {text} .\n"


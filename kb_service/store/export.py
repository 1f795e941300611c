"""RDF export of the ontology: the TBox with the *current* ABox (default) or with the whole history.

The current ABox of an object is what the cooperation model works with now: the object (links, joints,
orientations, static facts), its goal, its latest perceived state, its latest problem and its current plan with
the plan's actions and expected states — every individual reachable from these by object properties. It costs
what it returns, however long the history. The whole history (`history=all`) is every triple.

N-Triples are written row by row from SQLite on a read-only connection of their own (a snapshot of the last
commit), so an export neither holds the store's lock nor loads individuals into owlready2; RDF/XML and Turtle
are written from those lines as they come (`rdf_stream`), so an export in any format holds one subject at a time.
"""
from __future__ import annotations

import sqlite3
from typing import Any, Iterable, Iterator, Mapping, Sequence

from .errors import ValidationError
from .interface import FORMATS
from .owl import ntriple_lines, other_contexts, reachable, storids_of, subjects_to
from .rdf_stream import WRITERS
from .roots import SQLITE, current_roots

_CHUNK = 500


def export_pieces(lines: Iterable[str], fmt: str, prefixes: Mapping[str, str]) -> Iterator[str]:
    """N-Triples lines as N-Triples (`nt`), RDF/XML (`xml`) or Turtle (`turtle`) with readable prefixes, in
    pieces written as the lines are read."""
    if fmt not in FORMATS:
        raise ValidationError(f"fmt: must be one of {', '.join(FORMATS)}, got {fmt!r}")
    if fmt == "nt":
        return iter(lines)
    return WRITERS[fmt](lines, prefixes)


def ntriples(db: sqlite3.Connection, abox_iri: str, abox_c: int, static_fact_of: int,
             object_ids: Sequence[str] | None) -> Iterator[str]:
    """TBox + ABox as N-Triples lines: every triple (`object_ids` None), else the TBox and the current ABox of
    these objects."""
    if object_ids is None:
        yield from ntriple_lines(db, "1")
        return
    others = other_contexts(db, abox_c)  # read through the index on c: the ABox's rows are never scanned
    if others:
        yield from ntriple_lines(db, f"t.c IN ({','.join('?' * len(others))})", others)
    roots = storids_of(db, [abox_iri + name for oid in object_ids for name in current_roots(db, SQLITE, oid)])
    statics = subjects_to(db, abox_c, static_fact_of, roots)  # an object's static facts point to it
    ontology = storids_of(db, [abox_iri.rstrip("#")])
    subjects = sorted(reachable(db, abox_c, roots + statics) | set(ontology))
    for i in range(0, len(subjects), _CHUNK):
        chunk: list[Any] = subjects[i:i + _CHUNK]
        yield from ntriple_lines(db, f"t.c = ? AND t.s IN ({','.join('?' * len(chunk))})", [abox_c] + chunk,
                                 by_subject=True)

"""What of an object's history its current ABox is, in the PostgreSQL store: the N-Triples export (current or
every fact) and compaction, with the policy of the SQLite store's `export` and `retention` modules.

The current ABox of an object is every individual reachable by object properties from its roots (the object, its
goal and last perceived state as its event log names them, the plan its execution follows, its latest plan and
problem) and its static facts; a recursive query walks it, so it costs what it returns.
"""
from __future__ import annotations

from typing import Any, Iterator, Sequence

from ..names import ABOX_IRI, TBOX_IRI
from ..roots import POSTGRESQL, current_roots
from .rows import ntriple
from .schema import ABOX_ONTOLOGY, RDF_TYPE
from .session import Connection

_CHUNK = 1000
_REACHABLE = (
    "WITH RECURSIVE r(n) AS (SELECT unnest(%s::text[]) UNION "
    "SELECT t.o FROM planhrc_triple t JOIN r ON t.s = r.n WHERE t.o IS NOT NULL AND t.p <> %s) SELECT n FROM r"
)


def reachable(conn: Connection, roots: Sequence[str]) -> set[str]:
    """IRIs of every individual reachable from `roots` (IRIs) by object properties (rdf:type excluded)."""
    return {n for (n,) in conn.execute(_REACHABLE, (list(roots), RDF_TYPE))}


def subjects_to(conn: Connection, prop: str, objects: Sequence[str]) -> list[str]:
    """IRIs of subjects s with (s prop o) for some o of `objects` (IRIs)."""
    return [s for (s,) in conn.execute("SELECT s FROM planhrc_triple WHERE o = ANY(%s) AND p = %s",
                                       (list(objects), TBOX_IRI + prop))]


def abox_lines(conn: Connection, object_ids: Sequence[str] | None) -> Iterator[str]:
    """The ABox as N-Triples lines: every row (`object_ids` None), else the current ABox of these objects."""
    if object_ids is None:
        with conn.cursor(name="planhrc_export") as cursor:  # on the server, a batch at a time
            cursor.itersize = 5000
            cursor.execute("SELECT s, p, o, lit, dt FROM planhrc_triple")
            for row in cursor:
                yield ntriple(*row)
        return
    roots = [ABOX_IRI + name for oid in object_ids for name in current_roots(conn, POSTGRESQL, oid)]
    statics = subjects_to(conn, "staticFactOf", roots)  # an object's static facts point to it
    subjects = sorted(reachable(conn, roots + statics) | {ABOX_ONTOLOGY})
    for i in range(0, len(subjects), _CHUNK):
        rows = conn.execute("SELECT s, p, o, lit, dt FROM planhrc_triple WHERE s = ANY(%s)", (subjects[i:i + _CHUNK],))
        for row in rows:
            yield ntriple(*row)


def perceived_to_keep(conn: Connection, object_id: str, keep: int) -> list[str]:
    """Names of the object's last `keep` perceived states (from the decisions its event log records)."""
    rows = conn.execute(
        "SELECT state FROM (SELECT data->>'perceived_state_id' AS state, MAX(seq) AS last FROM planhrc_event "
        "WHERE object_id = %s AND data->>'perceived_state_id' IS NOT NULL GROUP BY 1) q ORDER BY last DESC LIMIT %s",
        (object_id, keep))
    return [str(name) for (name,) in rows]


def compact_object(conn: Connection, object_id: str, shared: Sequence[str], keep_perceived: int) -> tuple[int, int]:
    """Drop what the retention policy does not keep of one object (inside the caller's transaction), as
    `retention.compact_object` does on SQLite; (individuals, triples) deleted."""
    obj = ABOX_IRI + object_id
    keep_names = (current_roots(conn, POSTGRESQL, object_id) + perceived_to_keep(conn, object_id, keep_perceived)
                  + list(shared))
    kept = reachable(conn, [ABOX_IRI + name for name in keep_names] + subjects_to(conn, "staticFactOf", [obj]))
    records = subjects_to(conn, "stateOf", [obj]) + subjects_to(conn, "aboutObject", [obj])
    old = [s for s in records if s not in kept]
    if not old:
        return 0, 0
    doomed: list[Any] = sorted(reachable(conn, old) - kept)
    deleted = 0
    for i in range(0, len(doomed), _CHUNK):
        chunk = doomed[i:i + _CHUNK]
        cursor = conn.execute("DELETE FROM planhrc_triple WHERE s = ANY(%s) OR o = ANY(%s)", (chunk, chunk))
        deleted += cursor.rowcount
    return len(doomed), deleted

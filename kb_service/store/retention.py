"""Retention: what of an object's history the store keeps, and compaction, which drops the rest.

Kept, for every object: the object itself (links, joints, orientations, static facts and the predicate
individuals its states share), its goal, its latest problem, its current plan (or its latest) with the plan's
actions and expected states and the problem and states the plan refers to, and its last `keep_perceived`
perceived states. Every other perceived state, goal, problem and plan of the object is compacted: its triples
and its IRI are deleted. The event log is kept whole; an event may then name a record that is gone (reading
it answers 404).
"""
from __future__ import annotations

import sqlite3

from .owl import delete_individuals, reachable, storids_of, subjects_to
from .roots import SQLITE, current_roots


def perceived_to_keep(db: sqlite3.Connection, object_id: str, keep: int) -> list[str]:
    """Names of the object's last `keep` perceived states (from the decisions its event log records)."""
    rows = db.execute(
        "SELECT DISTINCT json_extract(data, '$.perceived_state_id') FROM planhrc_event WHERE object_id = ? "
        "AND json_extract(data, '$.perceived_state_id') IS NOT NULL ORDER BY seq DESC LIMIT ?", (object_id, keep))
    return [str(name) for (name,) in rows]


def compact_object(db: sqlite3.Connection, abox_iri: str, c: int, terms: dict[str, int], object_id: str,
                   shared: list[str], keep_perceived: int) -> tuple[int, int]:
    """Drop what the retention policy does not keep of one object (inside the caller's transaction);
    (individuals, triples) deleted."""
    (obj,) = storids_of(db, [abox_iri + object_id]) or (None,)
    if obj is None:
        return 0, 0
    keep_names = current_roots(db, SQLITE, object_id) + perceived_to_keep(db, object_id, keep_perceived) + shared
    roots = storids_of(db, [abox_iri + name for name in keep_names])
    kept = reachable(db, c, roots + subjects_to(db, c, terms["staticFactOf"], [obj]))
    records = subjects_to(db, c, terms["stateOf"], [obj]) + subjects_to(db, c, terms["aboutObject"], [obj])
    old = [sid for sid in records if sid not in kept]
    if not old:
        return 0, 0
    doomed = sorted(reachable(db, c, old) - kept)
    return len(doomed), delete_individuals(db, c, doomed)

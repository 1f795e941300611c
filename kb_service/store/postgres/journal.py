"""The PostgreSQL store's plan journal, as the SQLite store's (`..journal`, `..backlog`): a new plan is one row in
the transaction that stores it (the perception's answer waits for nothing more), and its triples are written when a
reader of the triples needs them (the export, compaction), in a transaction that also deletes the row.

On one database several processes share the journal: any process writes out any row (it claims the oldest one
with `FOR UPDATE SKIP LOCKED`, so two writers never take the same), every process reads a plan whose triples are not
written yet from its row (`records`: the row is looked up before the triples, and a row turns into triples in one
transaction, so a reader finds one or the other).
"""
from __future__ import annotations

import logging
from typing import Any, Iterable

from ..journal import JournalEntry, decode, encode
from ..records import StoredPlan
from ..triples import plan_triples
from .records import PgRecords
from .replicas import LOCK_NAMESPACE, LOCK_OBJECT
from .session import Session

log = logging.getLogger(__name__)

LAST = 2**63 - 1
_CLAIM = ("DELETE FROM planhrc_plan_journal WHERE seq = (SELECT seq FROM planhrc_plan_journal WHERE seq <= %s "
          "AND (%s::text[] IS NULL OR plan_id = ANY(%s::text[])) ORDER BY seq LIMIT 1 FOR UPDATE SKIP LOCKED) "
          "RETURNING payload")


class PgJournal:
    """The journalled plans of one PostgreSQL store: a `unit.PlanAdopter`."""

    def __init__(self, session: Session, records: PgRecords) -> None:
        self._session = session
        self._records = records

    def check(self) -> None:
        """Read every row once: a store opened on a row this version cannot read is refused before it serves
        anything (`DamagedStoreError`)."""
        for (payload,) in self._session.execute("SELECT payload FROM planhrc_plan_journal").fetchall():
            decode(bytes(payload))

    def __len__(self) -> int:
        """Plans in the journal, journalled by any process (call with the store's lock held)."""
        row = self._session.execute("SELECT count(*) FROM planhrc_plan_journal").fetchone()
        return int(row[0]) if row else 0

    # -- adopting a plan (inside the write that stores it) -------------------------------------------------
    def adopt(self, entry: JournalEntry, body: bytes | None = None) -> StoredPlan:
        self._session.execute("INSERT INTO planhrc_plan_journal (plan_id, object_id, first_state, last_state, "
                              "payload) VALUES (%s, %s, %s, %s, %s)",
                              (entry.plan_id, entry.object_id, entry.first_state, entry.last_state,
                               encode(entry, body)))
        return self._records.put_entry(entry)

    # -- writing plans out (for readers of the triples) -----------------------------------------------------
    def settle(self, plan_ids: Iterable[str] | None = None) -> None:
        """Write out these journalled plans (None: every one journalled before now), by any process (inside an
        open transaction: nothing, its plans are not committed yet)."""
        s = self._session
        wanted = None if plan_ids is None else list(plan_ids)
        with s.lock:
            if s.depth:
                return
            row = s.execute("SELECT max(seq) FROM planhrc_plan_journal").fetchone()
            last = row[0] if row else None
            while last is not None:
                if self._write_out(int(last), wanted):
                    continue
                # What is left is being written out by another process: wait until it commits.
                with s.transaction():
                    left = s.execute("SELECT seq FROM planhrc_plan_journal WHERE seq <= %s AND "
                                     "(%s::text[] IS NULL OR plan_id = ANY(%s::text[])) FOR UPDATE",
                                     (last, wanted, wanted)).fetchall()
                if not left:
                    break

    def _write_out(self, last: int, wanted: list[str] | None) -> bool:
        """Claim the oldest row up to `last` (of the `wanted` plans), write its plan's triples and delete it, in one
        transaction; whether there was one to claim."""
        s = self._session

        def fill() -> Any:
            row = s.execute(_CLAIM, (last, wanted, wanted)).fetchone()
            if row is None:
                return None
            entry = decode(bytes(row[0]))
            # a write of the object like any other: its shared individuals (orientation atoms) are created once,
            # whichever process writes them, since each write sees what the one before it committed
            s.execute(LOCK_OBJECT, (LOCK_NAMESPACE + entry.object_id,))
            batch = s.batch()
            plan_triples(s, batch, self._records.info(entry.object_id), entry)
            s.flush(batch)
            return entry

        return s.write(fill) is not None

    # -- retention ---------------------------------------------------------------------------------------------
    def drop(self, object_id: str, keep: Iterable[str]) -> int:
        """Delete the rows of the object's journalled plans but those in `keep`, never written (inside the caller's
        transaction); how many records (plans, actions, expected states) they held."""
        rows = self._session.execute(
            "DELETE FROM planhrc_plan_journal WHERE object_id = %s AND NOT plan_id = ANY(%s::text[]) "
            "RETURNING last_state - first_state + 1", (object_id, list(keep))).fetchall()
        return sum(2 * int(n) for (n,) in rows)  # the plan, its n - 1 actions and its n expected states

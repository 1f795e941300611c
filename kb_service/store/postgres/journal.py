"""The PostgreSQL store's plan journal, as the SQLite store's (`..journal`, `..backlog`): a new plan is one row in
the transaction that stores it (the perception's answer waits for nothing more), and its triples are written behind
the answer by a thread of the store's own, in a transaction that also deletes the row.

On one database several processes share the journal: any process writes out any row (it claims the oldest one
with `FOR UPDATE SKIP LOCKED`, so two writers never take the same), every process reads a plan whose triples are not
written yet from its row (`records`: the row is looked up before the triples, and a row turns into triples in one
transaction, so a reader finds one or the other), and a process that opens the store writes out
every row it finds, whoever left it.
"""
from __future__ import annotations

import logging
from typing import Any

from ..journal import JournalEntry, PlanWriter, decode, encode
from ..records import StoredPlan
from ..triples import plan_triples
from .records import PgRecords
from .replicas import LOCK_NAMESPACE, LOCK_OBJECT
from .session import Session

log = logging.getLogger(__name__)

LAST = 2**63 - 1
_CLAIM = ("DELETE FROM planhrc_plan_journal WHERE seq = (SELECT seq FROM planhrc_plan_journal WHERE seq <= %s "
          "ORDER BY seq LIMIT 1 FOR UPDATE SKIP LOCKED) RETURNING payload")


class PgJournal:
    """The journalled plans of one PostgreSQL store: a `unit.PlanAdopter` and a `TransactionListener`."""

    def __init__(self, session: Session, records: PgRecords) -> None:
        self._session = session
        self._records = records
        self._adopted: list[str] = []  # journalled by the open transaction
        self._unwritten: set[str] = set()  # journalled by this process, maybe not written out yet
        self._writer: PlanWriter | None = None

    def __len__(self) -> int:
        """Plans this process journalled whose triples it has not seen written (read without the lock)."""
        return len(self._unwritten)

    def start(self) -> None:
        self._writer = PlanWriter(self._write_one)

    def stop(self) -> None:
        """Stop the writer thread (before taking the store's lock: the thread may be waiting for it)."""
        if self._writer is not None:
            self._writer.close()
            self._writer = None

    # -- adopting a plan (inside the write that stores it) -------------------------------------------------
    def adopt(self, entry: JournalEntry) -> StoredPlan:
        last_state = entry.first_state + len(entry.expected_states) - 1
        self._session.execute("INSERT INTO planhrc_plan_journal (plan_id, object_id, first_state, last_state, "
                              "payload) VALUES (%s, %s, %s, %s, %s)",
                              (entry.plan_id, entry.object_id, entry.first_state, last_state, encode(entry)))
        self._adopted.append(entry.plan_id)
        return self._records.put_entry(entry)

    def committed(self) -> None:
        if self._adopted:
            self._unwritten.update(self._adopted)
            self._adopted = []
            if self._writer is not None:
                self._writer.poke()

    def rolled_back(self) -> None:
        self._adopted = []

    # -- writing plans out ------------------------------------------------------------------------------------
    def settle(self) -> None:
        """Write out every plan journalled before now, by any process (inside an open transaction: nothing, its
        plans are written after it commits)."""
        s = self._session
        with s.lock:
            if s.depth:
                return
            row = s.execute("SELECT max(seq) FROM planhrc_plan_journal").fetchone()
            last = row[0] if row else None
            while last is not None:
                if self._write_out(int(last)):
                    continue
                # What is left is being written out by another process: wait until it commits.
                with s.transaction():
                    left = s.execute("SELECT seq FROM planhrc_plan_journal WHERE seq <= %s FOR UPDATE",
                                     (last,)).fetchall()
                if not left:
                    break
            self._unwritten.clear()

    def recover(self) -> None:
        """Write out the rows that processes which stopped before writing them left, before serving anything."""
        row = self._session.execute("SELECT count(*) FROM planhrc_plan_journal").fetchone()
        if row and row[0]:
            log.info("store: writing out %d journalled plan(s) left in the journal", row[0])
            self.settle()

    def _write_one(self) -> bool:
        """The writer thread's step: write out the oldest row no other process is writing; whether it wrote one."""
        s = self._session
        with s.lock:
            if s.closed or s.depth or s.conn.broken:
                return False
            if self._write_out(LAST):
                return True
            self._unwritten.clear()  # nothing left to claim: every plan of ours is written, or being written
            return False

    def _write_out(self, last: int) -> bool:
        """Claim the oldest row up to `last`, write its plan's triples and delete it, in one transaction; whether
        there was one to claim."""
        s = self._session

        def fill() -> Any:
            row = s.execute(_CLAIM, (last,)).fetchone()
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

        entry = s.write(fill)
        if entry is None:
            return False
        self._unwritten.discard(entry.plan_id)
        return True

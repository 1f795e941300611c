"""Plans stored as journal rows (`journal`) whose triples are not written yet: answered from memory, written out
by the writer thread behind the answer, and settled (written out at once) before anything reads the triples.

A plan is *adopted* by the transaction that journals it; once that commits it is *unwritten* until the writer
thread (`journal.PlanWriter`) writes its triples and deletes its row in one transaction of their own. A rolled
back transaction takes its adopted plans with it. Opening a store writes out the rows a stopped process left.
"""
from __future__ import annotations

import logging

from .abox import Abox
from .journal import JournalEntry, JournalTable, PlanWriter
from .reads import Held, Records
from .records import StoredPlan
from .triples import plan_triples

log = logging.getLogger(__name__)


class PlanBacklog:
    """The journalled plans of one SQLite ABox; a `TransactionListener` of its `Abox`."""

    def __init__(self, abox: Abox, records: Records) -> None:
        self._abox = abox
        self._records = records
        self._table = JournalTable(abox.q)
        self._unwritten: dict[str, JournalEntry] = {}  # committed, oldest first
        self._adopted: list[JournalEntry] = []  # journalled by the open transaction
        self._writer: PlanWriter | None = None

    def recover(self) -> None:
        """Write out the rows a process that stopped before writing them left, before the store serves anything."""
        for entry in self._table.entries():
            self._hold(entry)
            self._unwritten[entry.plan_id] = entry
        if self._unwritten:
            log.info("store: writing out %d journalled plan(s) left by the last run", len(self._unwritten))
            self.settle()

    def start(self) -> None:
        """Start the writer thread."""
        self._writer = PlanWriter(self._write_one)

    def stop(self) -> None:
        """Stop the writer thread (before taking the store's lock: the thread may be waiting for it)."""
        if self._writer is not None:
            self._writer.close()
            self._writer = None

    def __len__(self) -> int:
        """Committed plans whose triples are not written yet (read without the lock)."""
        return len(self._unwritten)

    # -- adopting a plan (inside the write that stores it) ---------------------------------------------------
    def adopt(self, entry: JournalEntry) -> StoredPlan:
        """Journal a plan in the open transaction; its records, answered from memory until it is written."""
        self._table.append(entry)  # the triples follow (`_write_one`); the row is the plan meanwhile
        self._adopted.append(entry)
        return self._hold(entry)

    def committed(self) -> None:
        if self._adopted:
            for entry in self._adopted:
                self._unwritten[entry.plan_id] = entry
            self._adopted = []
            if self._writer is not None:
                self._writer.poke()

    def rolled_back(self) -> None:
        for entry in self._adopted:
            self._release(entry)
        self._adopted = []

    def _hold(self, entry: JournalEntry) -> StoredPlan:
        record, states = entry.records()
        held = self._records.held
        for state in states:
            held[state.id] = state
        for a in record.actions:
            held[a.id] = a
        held[entry.plan_id] = record
        return record

    def _release(self, entry: JournalEntry) -> list[Held]:
        """Stop answering for a plan from memory (its triples are written, or its transaction rolled back)."""
        held = self._records.held
        plan = held.pop(entry.plan_id, None)
        if not isinstance(plan, StoredPlan):  # never held: its transaction failed before `_hold`
            return []
        ids = [*(a.id for a in plan.actions), *plan.expected_state_ids]  # the names `_hold` gave them
        return [plan, *(r for r in (held.pop(i, None) for i in ids) if r is not None)]

    # -- writing plans out ------------------------------------------------------------------------------------
    def settle(self) -> None:
        """Write out every journalled plan's triples now (readers of the triples themselves call this first).
        Inside an open transaction it does nothing: the plans it adopted are written after it commits."""
        with self._abox.lock:
            if self._abox.depth:
                return
            while self._unwritten:
                self._write_out(next(iter(self._unwritten.values())))

    def _write_one(self) -> bool:
        """The writer thread's step: write out the oldest journalled plan; whether more are left."""
        with self._abox.lock:
            if self._abox.closed or self._abox.depth or not self._unwritten:
                return False
            self._write_out(next(iter(self._unwritten.values())))
            return bool(self._unwritten)

    def _write_out(self, entry: JournalEntry) -> None:
        """A journalled plan's triples, and its journal row deleted, in one transaction. The plan was checked
        when it was adopted; here its atoms are only put in writing order."""
        info = self._records.info(entry.object_id)

        def fill() -> None:
            b = self._abox.batch()
            plan_triples(self._abox, b, info, entry)
            self._abox.flush(b)
            self._table.remove(entry.plan_id)

        self._abox.write(fill)
        del self._unwritten[entry.plan_id]
        for record in self._release(entry):  # now cached like any record read back
            self._records.put(record)

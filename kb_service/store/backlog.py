"""Plans stored as journal rows (`journal`) whose triples are not written yet: read from their rows (`reads`),
written out by a reader of the triples when it needs them (`write_out`, `settle`), dropped by retention without
being written (`drop`).

A plan is *adopted* by the transaction that journals it; it stays a row until a reader of the triples writes its
triples and deletes its row, in one transaction of their own, one plan at a time (another request may take the
store's lock between two). A rolled back transaction takes its adopted rows with it.
"""
from __future__ import annotations

import logging
import time
from typing import Iterable

from .abox import Abox
from .journal import JournalEntry, JournalTable
from .reads import SqliteRecords
from .records import StoredPlan
from .triples import plan_triples

log = logging.getLogger(__name__)

# Between two plans written out the store's lock is left free this long: a lock released and taken again at once
# by the same thread is not handed to a thread waiting for it, so without the pause a request arriving behind an
# export of many journalled plans would wait for all of them.
YIELD_S = 0.002


class PlanBacklog:
    """The journalled plans of one SQLite ABox; a `TransactionListener` of its `Abox`."""

    def __init__(self, abox: Abox, records: SqliteRecords, table: JournalTable) -> None:
        self._abox = abox
        self._records = records
        self._table = table
        self._rows = table.check()  # committed rows, kept by the commits (read without the lock)
        self._pending = 0  # rows the open transaction added (adopted) or deleted (dropped)

    def __len__(self) -> int:
        """Committed plans whose triples are not written yet (read without the lock)."""
        return self._rows

    # -- adopting a plan (inside the write that stores it) ---------------------------------------------------
    def adopt(self, entry: JournalEntry, body: bytes | None = None) -> StoredPlan:
        """Journal a plan in the open transaction; its records, cached (the row is the plan from now on)."""
        self._table.append(entry, body)
        self._pending += 1
        return self._records.put_entry(entry)

    def committed(self) -> None:
        self._rows += self._pending
        self._pending = 0

    def rolled_back(self) -> None:
        self._pending = 0

    # -- writing plans out (for readers of the triples) ------------------------------------------------------
    def settle(self, plan_ids: Iterable[str] | None = None) -> None:
        """Write out the triples of these journalled plans (None: of every one), one plan per hold of the store's
        lock (called without it held, other requests go on between two plans). Inside an open transaction it
        does nothing: the plans it adopted are not committed yet."""
        wanted = None if plan_ids is None else set(plan_ids)
        with self._abox.lock:
            if self._abox.depth or self._abox.closed or not self._rows:
                return
            left = [p for p in self._table.plan_ids() if wanted is None or p in wanted]
        for i, plan_id in enumerate(left):
            if i:  # a request waiting for the store gets it between two plans (see YIELD_S)
                time.sleep(YIELD_S)
            with self._abox.lock:
                if self._abox.depth or self._abox.closed:
                    return
                self._write_out(plan_id)

    def _write_out(self, plan_id: str) -> None:
        """A journalled plan's triples, and its row deleted, in one transaction. The plan was checked when it was
        adopted; here its atoms are only put in writing order."""
        entry = self._table.entry(plan_id)
        if entry is None:  # written out meanwhile
            return
        info = self._records.info(entry.object_id)

        def fill() -> None:
            b = self._abox.batch()
            plan_triples(self._abox, b, info, entry)
            self._abox.flush(b)
            self._table.remove(entry.plan_id)

        self._abox.write(fill)
        self._rows -= 1

    # -- retention ---------------------------------------------------------------------------------------------
    def drop(self, object_id: str, keep: Iterable[str]) -> int:
        """Delete the rows of the object's journalled plans but those in `keep`, never written (inside the
        caller's transaction, under the store's lock); how many records (plans, actions, expected states) they
        held. The caller writes out the kept ones first."""
        kept = set(keep)
        doomed = [(p, n) for p, n in self._table.states_of(object_id) if p not in kept]
        for plan_id, _ in doomed:
            self._table.remove(plan_id)
        self._pending -= len(doomed)
        return sum(2 * n for _, n in doomed)  # the plan, its n - 1 actions and its n expected states

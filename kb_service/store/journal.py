"""The plan journal: a new plan is stored first as one row, in the transaction that adopts it, and written out as
ABox triples (its actions, expected states and their links, thousands of triples for a 20-link plan) by a thread
of the store's own soon after (`backlog`).

Why: those triples are SQLite index inserts that the answer to a re-planning perception would otherwise wait
for, while the robot needs only the plan's first action and the guarantee that the plan is stored (the README's
re-planning section has the figures). The row is that guarantee: it commits with the perception, the problem and
the execution (all or nothing), and a store opened after a crash writes out every row it finds before it serves
anything. Until its triples are written, the store answers for the plan from memory, and every reader of the
triples themselves (export, reasoners, retention, the file's rewrite) waits for the writer first (`settle`).

A row holds only Python builtins (tuples, strings, numbers, frozensets), pickled: no class of this package is
named in it, so a newer version reads an older row; only this store writes and reads the table.
"""
from __future__ import annotations

import logging
import pickle
import threading
from dataclasses import dataclass
from typing import Any, Callable

from planhrc.model import Atom

from .errors import DamagedStoreError
from .names import action_name, record_name
from .owl import QuadStore
from .records import ActionSpec, CondEffect, StoredAction, StoredPlan, StoredState

log = logging.getLogger(__name__)

SCHEMA = "CREATE TABLE IF NOT EXISTS planhrc_plan_journal (plan_id TEXT PRIMARY KEY, payload BLOB NOT NULL)"
FORMAT = 2  # the payload's layout (2: expected states as changes); a row of another layout is refused when read
WHOLE_STATES = 1  # the layout before: every expected state whole (still read, from a store written by it)

# The writer waits this long after a commit before writing out the plans it adopted: the answer to the
# perception that made the plan is on its way meanwhile (the writer would compete with it for the interpreter),
# and a robot's next perception follows its action seconds later.
WRITE_DELAY_S = 0.05
# Between two plans the writer pauses this long, so that a request waiting for the store's lock gets it: a lock
# released and taken again at once by the same thread is not handed to the thread waiting for it, so without the
# pause a request arriving behind many unwritten plans would wait for all of them.
YIELD_S = 0.002


@dataclass(frozen=True)
class JournalEntry:
    """A stored plan as its journal row holds it (what `add_plan` was given, with its names)."""

    plan_id: str
    object_id: str
    problem_id: str
    planner: str
    created_at: float
    first_state: int  # the counter of its first expected state: state i is <object>_state_<first_state + i - 1>
    actions: tuple[ActionSpec, ...]
    expected_states: tuple[frozenset[Atom], ...]

    def state_id(self, step: int) -> str:
        """The name of expected state `step` (1-based)."""
        return record_name(self.object_id, "state", self.first_state + step - 1)

    def records(self) -> tuple[StoredPlan, tuple[StoredState, ...]]:
        """The plan's record (with its actions) and its expected states', as the store hands them out."""
        actions = tuple(StoredAction(action_name(self.plan_id, step), step, spec)
                        for step, spec in enumerate(self.actions, start=1))
        states = tuple(StoredState(self.state_id(step), self.object_id, "expected", frozenset(atoms), self.created_at)
                       for step, atoms in enumerate(self.expected_states, start=1))
        plan = StoredPlan(self.plan_id, self.object_id, self.problem_id, self.planner, actions,
                          tuple(s.id for s in states), self.created_at)
        return plan, states


def encode(entry: JournalEntry) -> bytes:
    """The row: the actions, and the expected states as the first one and, for each next one, the atoms it drops
    and adds. An action changes a few atoms of a state, so the row is a fraction of the plan's states written
    whole, and it is written inside the re-plan's transaction, before the answer."""
    actions = tuple((a.name, tuple(a.params), a.pre, a.eff_neg, a.eff_pos,
                     tuple((c.when, c.eff_neg, c.eff_pos) for c in a.cond_eff)) for a in entry.actions)
    states = entry.expected_states
    first = frozenset(states[0]) if states else frozenset()
    changes = tuple((before - after, after - before) for before, after in zip(states, states[1:]))
    return pickle.dumps((FORMAT, entry.plan_id, entry.object_id, entry.problem_id, entry.planner,
                         float(entry.created_at), int(entry.first_state), actions, (len(states), first, changes)),
                        protocol=5)


def decode(payload: bytes) -> JournalEntry:
    try:
        data: Any = pickle.loads(payload)
    except (pickle.UnpicklingError, EOFError, ValueError, TypeError) as exc:
        raise DamagedStoreError(f"plan journal: a row that does not read back ({exc})") from None
    if not isinstance(data, tuple) or not data or data[0] not in (WHOLE_STATES, FORMAT):
        found = data[0] if isinstance(data, tuple) and data else "?"
        raise DamagedStoreError(f"plan journal: a row of an unknown layout ({found})")
    layout, plan_id, object_id, problem_id, planner, created, first_state, actions, states = data
    specs = tuple(ActionSpec(name=n, params=tuple(p), pre=frozenset(pre), eff_neg=frozenset(neg),
                             eff_pos=frozenset(pos),
                             cond_eff=tuple(CondEffect(frozenset(w), frozenset(cn), frozenset(cp)) for w, cn, cp in ces))
                  for n, p, pre, neg, pos, ces in actions)
    expected = (tuple(frozenset(s) for s in states) if layout == WHOLE_STATES else _replayed(*states))
    return JournalEntry(plan_id, object_id, problem_id, planner, float(created), int(first_state), specs, expected)


def _replayed(count: int, first: frozenset[Atom], changes: tuple[tuple[frozenset[Atom], frozenset[Atom]], ...]
              ) -> tuple[frozenset[Atom], ...]:
    """The expected states from the first one and each next one's dropped and added atoms."""
    if count == 0:
        return ()
    states = [frozenset(first)]
    for dropped, added in changes:
        states.append((states[-1] - dropped) | added)
    if len(states) != count:
        raise DamagedStoreError(f"plan journal: a row holds {len(states)} expected states, its header says {count}")
    return tuple(states)


class JournalTable:
    """The journal's side table (inside the store's transactions)."""

    def __init__(self, quads: QuadStore) -> None:
        self.quads = quads
        quads.execute(SCHEMA)

    def append(self, entry: JournalEntry) -> None:
        self.quads.execute("INSERT INTO planhrc_plan_journal VALUES (?, ?)", (entry.plan_id, encode(entry)))

    def remove(self, plan_id: str) -> None:
        self.quads.execute("DELETE FROM planhrc_plan_journal WHERE plan_id=?", (plan_id,))

    def entries(self) -> list[JournalEntry]:
        """Every row, oldest first."""
        rows = self.quads.execute("SELECT payload FROM planhrc_plan_journal ORDER BY rowid").fetchall()
        return [decode(row[0]) for row in rows]


class PlanWriter:
    """A thread that writes journalled plans out as triples, woken by each commit that adopted one: it calls
    `write_one()` (one plan per call, pausing `YIELD_S` between two, so other writers get the store) until that
    returns False (nothing left, or the store busy in a transaction: the next commit wakes the thread again)."""

    def __init__(self, write_one: Callable[[], bool]) -> None:
        self._write_one = write_one
        self._wake = threading.Event()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="planhrc-plan-writer", daemon=True)
        self._thread.start()

    def poke(self) -> None:
        self._wake.set()

    def _run(self) -> None:
        while not self._stop.is_set():
            self._wake.wait(1.0)
            if not self._wake.is_set():
                continue
            if self._stop.wait(WRITE_DELAY_S):
                return
            self._wake.clear()
            try:
                while self._write_one():
                    if self._stop.wait(YIELD_S):
                        return
            except Exception:  # the rows stay in the journal: written at the next wake, or when the store opens
                log.exception("store: writing a journalled plan's triples failed")

    def close(self) -> None:
        self._stop.set()
        self._wake.set()
        self._thread.join(60)

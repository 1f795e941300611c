"""The plan journal: a new plan is stored as one row, in the transaction that adopts it, and its triples (its
actions, expected states and their links, thousands of triples for a 20-link plan) are written only when something
reads the triples themselves (`backlog`).

Why: a robot re-plans far more often than anything reads a plan's triples, and most plans are replaced before that
happens. Written behind every answer, those triples (SQLite index inserts, the pages they dirty copied into the
file) were most of a relative re-plan's CPU. The row is the plan: it commits with the perception, the problem and
the execution (all or nothing), the store reads the plan, its actions and expected states from it, and a reader of
the triples (the export, the reasoners' copy of the world, retention) writes out the rows it needs first, by the
same code that would have written them behind the answer (`triples.plan_triples`), so every reader sees the same
facts. Retention drops the rows of plans it does not keep without writing them.

A row holds only Python builtins (tuples, strings, numbers, frozensets), pickled: no class of this package is
named in it, so a newer version reads an older row; only this store writes and reads the table. Beside the
payload a row names the plan's object and the counters of its first and last expected states, so that a state is
found in its plan's row by its name.
"""
from __future__ import annotations

import logging
import pickle
from dataclasses import dataclass
from functools import partial
from typing import Any, Sequence

from planhrc.model import Atom
from planhrc.transition import ExpectedStates, changes_of

from .cache import RecordCache
from .errors import DamagedStoreError
from .names import action_name, record_name
from .owl import QuadStore
from .records import ActionSpec, CondEffect, StoredAction, StoredPlan, StoredState

log = logging.getLogger(__name__)

SCHEMA = ("CREATE TABLE IF NOT EXISTS planhrc_plan_journal (plan_id TEXT PRIMARY KEY, payload BLOB NOT NULL, "
          "object_id TEXT, first_state INTEGER, last_state INTEGER)")
INDEX = ("CREATE INDEX IF NOT EXISTS planhrc_plan_journal_states ON planhrc_plan_journal "
         "(object_id, first_state, last_state)")
# the columns a table made before rows named their states lacks, with their types
NAMED = {"object_id": "TEXT", "first_state": "INTEGER", "last_state": "INTEGER"}
FORMAT = 3  # the payload's layout (3: the header, then the body pickled apart); another layout is refused when read
AS_CHANGES = 2  # the layout before: the body inline (still read, from a store written by it)
WHOLE_STATES = 1  # the layout before that: every expected state whole (still read)
ATOMS_PER_PIECE = 5_000  # the body is pickled in pieces of about this many atoms (`encode_body`)


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
    expected_states: Sequence[frozenset[Atom]]  # a tuple, or `ExpectedStates` (each state made whole when read)

    @property
    def last_state(self) -> int:
        """The counter of its last expected state."""
        return self.first_state + len(self.expected_states) - 1

    def state_id(self, step: int) -> str:
        """The name of expected state `step` (1-based)."""
        return record_name(self.object_id, "state", self.first_state + step - 1)

    def plan_record(self) -> StoredPlan:
        """The plan's record (with its actions), as the store hands it out."""
        actions = tuple(StoredAction(action_name(self.plan_id, step), step, spec)
                        for step, spec in enumerate(self.actions, start=1))
        return StoredPlan(self.plan_id, self.object_id, self.problem_id, self.planner, actions,
                          tuple(self.state_id(step) for step in range(1, len(self.expected_states) + 1)),
                          self.created_at)

    def state_record(self, step: int) -> StoredState:
        """Expected state `step`'s record (1-based), as the store hands it out."""
        return StoredState(self.state_id(step), self.object_id, "expected", frozenset(self.expected_states[step - 1]),
                           self.created_at)

    def cache(self, plans: RecordCache[StoredPlan], actions: RecordCache[StoredAction],
              states: RecordCache[StoredState]) -> StoredPlan:
        """The plan's records put in a store's caches: the plan and its actions, and each expected state's record
        to be made when it is first read (a plan's states are made whole only when read: `ExpectedStates`)."""
        plan = self.plan_record()
        plans.put(plan)
        for action in plan.actions:
            actions.put(action)
        for step, state_id in enumerate(plan.expected_state_ids, start=1):
            states.put_later(state_id, partial(self.state_record, step))
        return plan


def encode_body(actions: tuple[ActionSpec, ...], expected_states: Sequence[frozenset[Atom]]) -> bytes:
    """The row's body: the actions, and the expected states as the first one and, for each next one, the atoms it
    drops and adds. An action changes a few atoms of a state, so the body is a fraction of the plan's states written
    whole. It names nothing the transaction gives (the plan's name, its states' counters), so it is made before the
    write, outside the store's lock (`CheckedPlan.journal_body`): for a large plan it is most of the row's cost
    (absolute 200 x 12, a 607-step plan: 0.8 s), which every other object's write would otherwise wait for. It is
    pickled in pieces of at most `ATOMS_PER_PIECE` atoms: one `pickle.dumps` (or `loads`) of a whole large plan holds
    the interpreter, every other request's thread and the event loop with it, for half a second."""
    rows = [(a.name, tuple(a.params), a.pre, a.eff_neg, a.eff_pos,
             tuple((c.when, c.eff_neg, c.eff_pos) for c in a.cond_eff)) for a in actions]
    first = frozenset(expected_states[0]) if expected_states else frozenset()
    changes = changes_of(expected_states, actions)  # a plan's states are its actions' replay
    return pickle.dumps((_pieces(rows, _action_atoms), len(expected_states), _pieces(tuple(first), lambda a: 1),
                         _pieces(changes, lambda c: len(c[0]) + len(c[1]))), protocol=5)


def _action_atoms(row: tuple[Any, ...]) -> int:
    _, _, pre, neg, pos, conditional = row
    return len(pre) + len(neg) + len(pos) + sum(len(w) + len(n) + len(p) for w, n, p in conditional)


def _pieces(items: list[Any] | tuple[Any, ...], atoms: Any) -> tuple[bytes, ...]:
    """`items` pickled in consecutive pieces of at most `ATOMS_PER_PIECE` atoms (an item larger alone: its own)."""
    pieces: list[bytes] = []
    start, weight = 0, 0
    for i, item in enumerate(items):
        size = atoms(item)
        if i > start and weight + size > ATOMS_PER_PIECE:
            pieces.append(pickle.dumps(tuple(items[start:i]), protocol=5))
            start, weight = i, 0
        weight += size
    if start < len(items):
        pieces.append(pickle.dumps(tuple(items[start:]), protocol=5))
    return tuple(pieces)


def _unpieced(pieces: tuple[bytes, ...]) -> list[Any]:
    return [item for piece in pieces for item in pickle.loads(piece)]


def encode(entry: JournalEntry, body: bytes | None = None) -> bytes:
    """The row, written inside the re-plan's transaction, before the answer: the header and the body
    (`encode_body`, made here unless given)."""
    if body is None:
        body = encode_body(entry.actions, entry.expected_states)
    return pickle.dumps((FORMAT, entry.plan_id, entry.object_id, entry.problem_id, entry.planner,
                         float(entry.created_at), int(entry.first_state), body), protocol=5)


def decode(payload: bytes) -> JournalEntry:
    try:
        data: Any = pickle.loads(payload)
    except (pickle.UnpicklingError, EOFError, ValueError, TypeError) as exc:
        raise DamagedStoreError(f"plan journal: a row that does not read back ({exc})") from None
    if not isinstance(data, tuple) or not data or data[0] not in (WHOLE_STATES, AS_CHANGES, FORMAT):
        found = data[0] if isinstance(data, tuple) and data else "?"
        raise DamagedStoreError(f"plan journal: a row of an unknown layout ({found})")
    if data[0] == FORMAT:
        layout, plan_id, object_id, problem_id, planner, created, first_state, body = data
        try:
            action_pieces, count, first_pieces, change_pieces = pickle.loads(body)
            actions = _unpieced(action_pieces)
            states = (count, frozenset(_unpieced(first_pieces)), tuple(_unpieced(change_pieces)))
        except (pickle.UnpicklingError, EOFError, ValueError, TypeError) as exc:
            raise DamagedStoreError(f"plan journal: a row whose body does not read back ({exc})") from None
    else:
        layout, plan_id, object_id, problem_id, planner, created, first_state, actions, states = data
    specs = tuple(ActionSpec(name=n, params=tuple(p), pre=frozenset(pre), eff_neg=frozenset(neg),
                             eff_pos=frozenset(pos),
                             cond_eff=tuple(CondEffect(frozenset(w), frozenset(cn), frozenset(cp)) for w, cn, cp in ces))
                  for n, p, pre, neg, pos, ces in actions)
    expected = (tuple(frozenset(s) for s in states) if layout == WHOLE_STATES else _replayed(*states))
    return JournalEntry(plan_id, object_id, problem_id, planner, float(created), int(first_state), specs, expected)


def _replayed(count: int, first: frozenset[Atom], changes: tuple[tuple[frozenset[Atom], frozenset[Atom]], ...]
              ) -> Sequence[frozenset[Atom]]:
    """The expected states from the first one and each next one's dropped and added atoms (`ExpectedStates`: each
    made whole when it is read)."""
    if count == 0:
        return ()
    if len(changes) + 1 != count:
        raise DamagedStoreError(f"plan journal: a row holds {len(changes) + 1} expected states, its header says "
                                f"{count}")
    return ExpectedStates(frozenset(first), changes)


class JournalTable:
    """The journal's side table (inside the store's transactions)."""

    def __init__(self, quads: QuadStore) -> None:
        self.quads = quads
        quads.execute(SCHEMA)
        columns = {row[1] for row in quads.execute("PRAGMA table_info(planhrc_plan_journal)")}
        if not set(NAMED) <= columns:
            self._name_states(columns)
        quads.execute(INDEX)

    def _name_states(self, columns: set[str]) -> None:
        """A table written before rows named their states: the columns added, and filled from the payloads."""
        for column, kind in NAMED.items():
            if column not in columns:
                self.quads.execute(f"ALTER TABLE planhrc_plan_journal ADD COLUMN {column} {kind}")
        for (payload,) in self.quads.execute("SELECT payload FROM planhrc_plan_journal").fetchall():
            entry = decode(payload)
            self.quads.execute("UPDATE planhrc_plan_journal SET object_id=?, first_state=?, last_state=? "
                               "WHERE plan_id=?", (entry.object_id, entry.first_state, entry.last_state,
                                                   entry.plan_id))

    def check(self) -> int:
        """Read every row once (a store opened on a row this version cannot read is refused before it serves
        anything: `DamagedStoreError`); how many there are."""
        rows = self.quads.execute("SELECT payload FROM planhrc_plan_journal").fetchall()
        for (payload,) in rows:
            decode(payload)
        return len(rows)

    def append(self, entry: JournalEntry, body: bytes | None = None) -> None:
        self.quads.execute("INSERT INTO planhrc_plan_journal VALUES (?, ?, ?, ?, ?)",
                           (entry.plan_id, encode(entry, body), entry.object_id, entry.first_state,
                            entry.last_state))

    def remove(self, plan_id: str) -> None:
        self.quads.execute("DELETE FROM planhrc_plan_journal WHERE plan_id=?", (plan_id,))

    def entry(self, plan_id: str) -> JournalEntry | None:
        """The row of a plan, if it is in the journal."""
        row = self.quads.execute("SELECT payload FROM planhrc_plan_journal WHERE plan_id=?", (plan_id,)).fetchone()
        return decode(row[0]) if row else None

    def entry_of_state(self, object_id: str, number: int) -> JournalEntry | None:
        """The row of the plan whose expected states include the object's state `number`, if one is."""
        row = self.quads.execute("SELECT payload FROM planhrc_plan_journal WHERE object_id=? AND first_state<=? "
                                 "AND last_state>=? LIMIT 1", (object_id, number, number)).fetchone()
        return decode(row[0]) if row else None

    def states_of(self, object_id: str) -> list[tuple[str, int]]:
        """The object's plans in the journal, each with how many expected states it holds."""
        rows = self.quads.execute("SELECT plan_id, last_state - first_state + 1 FROM planhrc_plan_journal "
                                  "WHERE object_id=?", (object_id,))
        return [(str(plan_id), int(n)) for plan_id, n in rows]

    def plan_ids(self) -> list[str]:
        """The plans in the journal, oldest first."""
        return [str(p) for (p,) in self.quads.execute("SELECT plan_id FROM planhrc_plan_journal ORDER BY rowid")]

    def count(self) -> int:
        row = self.quads.execute("SELECT COUNT(*) FROM planhrc_plan_journal").fetchone()
        return int(row[0]) if row else 0

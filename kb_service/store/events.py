"""The event log: every decision with its reason, goals, dispatches and feedback of an object, append-only.

One side table of the SQLite store's database, written inside its transactions (a row is checked by
`checks.check_event` before)."""
from __future__ import annotations

import json
import time

from .owl import QuadStore
from .records import StoredEvent

SCHEMA = ("CREATE TABLE IF NOT EXISTS planhrc_event (object_id TEXT, seq INTEGER, kind TEXT, reason TEXT, data TEXT,"
          " created_at REAL, client TEXT, PRIMARY KEY (object_id, seq))")
# A store made before events named their client gets the column (null in its old rows).
ADD_CLIENT = "ALTER TABLE planhrc_event ADD COLUMN client TEXT"


class EventLog:
    """Append and read an object's events (the caller checks that the object exists)."""

    def __init__(self, quads: QuadStore) -> None:
        self.quads = quads
        quads.execute(SCHEMA)
        if "client" not in {row[1] for row in quads.execute("PRAGMA table_info(planhrc_event)")}:
            quads.execute(ADD_CLIENT)

    def append(self, object_id: str, kind: str, reason: str, text: str, client: str | None) -> StoredEvent:
        """Write a checked event (inside the open transaction); `client`: who caused it (None: the service)."""
        created = time.time()
        row = self.quads.execute("SELECT MAX(seq) FROM planhrc_event WHERE object_id=?", (object_id,)).fetchone()
        seq = (row[0] or 0) + 1
        self.quads.execute("INSERT INTO planhrc_event (object_id, seq, kind, reason, data, created_at, client) "
                           "VALUES (?,?,?,?,?,?,?)", (object_id, seq, kind, reason, text, created, client))
        return StoredEvent(seq, object_id, kind, reason, json.loads(text), created, client)

    def after(self, object_id: str, after_seq: int = 0, limit: int | None = None) -> tuple[StoredEvent, ...]:
        """Events with seq > after_seq, oldest first, at most `limit` of them (None: all); the primary key
        (object_id, seq) makes a page cost what it returns."""
        rows = self.quads.execute(
            "SELECT seq, kind, reason, data, created_at, client FROM planhrc_event WHERE object_id=? AND seq>?"
            " ORDER BY seq LIMIT ?", (object_id, int(after_seq), -1 if limit is None else int(limit)),
        ).fetchall()
        return tuple(StoredEvent(s, object_id, k, r, json.loads(d), c, who) for s, k, r, d, c, who in rows)

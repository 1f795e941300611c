"""The PostgreSQL engine's side tables, beside the ABox's rows: the event log, the execution cursor and idempotent
responses (the SQLite store's `..events`, `..execution`, `..responses`). The store's core checks a row before it is
written (`..checks`) and runs each write in its unit of work; these only read and write the rows.
"""
from __future__ import annotations

import json
import time
from typing import Any

from planhrc.vocabulary import ExecutionStatus

from ..names import counter_name
from ..records import Execution, StoredEvent
from .replicas import EVENT_CHANNEL
from .session import Session

# An event in one round trip: the object's next seq (its counter's row lock orders the object's events, across
# processes too), the row, and its announcement to the feed (`replicas.PgEventFeed`), sent when the transaction
# commits.
_APPEND_EVENT = (
    "WITH c AS (INSERT INTO planhrc_counter AS c (name, value) VALUES (%s, 1) ON CONFLICT (name) "
    "DO UPDATE SET value = c.value + 1 RETURNING value), "
    "e AS (INSERT INTO planhrc_event (object_id, seq, kind, reason, data, created_at, client) "
    "SELECT %s, value, %s, %s, %s::json, %s, %s FROM c RETURNING seq) "
    "SELECT seq, pg_notify(%s, %s || ' ' || seq) FROM e"
)


class PgEventLog:
    """Append and read an object's events (the caller checks that the object exists)."""

    def __init__(self, session: Session) -> None:
        self._session = session

    def append(self, object_id: str, kind: str, reason: str, text: str, client: str | None) -> StoredEvent:
        """Write a checked event (inside the open transaction); `client`: who caused it (None: the service)."""
        created = time.time()
        row = self._session.execute(_APPEND_EVENT, (counter_name(object_id, "event"), object_id, kind, reason, text,
                                                    created, client, EVENT_CHANNEL, object_id)).fetchone()
        assert row is not None
        return StoredEvent(int(row[0]), object_id, kind, reason, json.loads(text), created, client)

    def after(self, object_id: str, after_seq: int = 0, limit: int | None = None) -> tuple[StoredEvent, ...]:
        """Events with seq > after_seq, oldest first, at most `limit` of them (None: all)."""
        rows = self._session.execute(
            "SELECT seq, kind, reason, data, created_at, client FROM planhrc_event WHERE object_id = %s "
            "AND seq > %s ORDER BY seq LIMIT %s", (object_id, after_seq, limit)).fetchall()
        return tuple(StoredEvent(int(seq), object_id, kind, reason, data, float(created), client)
                     for seq, kind, reason, data, created, client in rows)


class PgExecutionCursor:
    """Read and move an object's execution (the caller resolves and checks the object and the plan)."""

    def __init__(self, session: Session) -> None:
        self._session = session

    def read(self, object_id: str) -> Execution:
        row = self._session.execute("SELECT plan_id, next_step, status, dispatched_action_id FROM "
                                    "planhrc_execution WHERE object_id = %s", (object_id,)).fetchone()
        if row is None:
            return Execution(plan_id=None, next_step=None, status=ExecutionStatus.IDLE)
        plan_id, next_step, status, dispatched = row
        return Execution(plan_id, next_step, ExecutionStatus(status), dispatched)

    def write(self, object_id: str, execution: Execution) -> None:
        """Write a checked execution (inside the open transaction)."""
        row = (object_id, execution.plan_id, execution.next_step, ExecutionStatus(execution.status).value,
               execution.dispatched_action_id)
        self._session.execute(
            "INSERT INTO planhrc_execution VALUES (%s, %s, %s, %s, %s) ON CONFLICT (object_id) DO UPDATE SET "
            "plan_id = EXCLUDED.plan_id, next_step = EXCLUDED.next_step, status = EXCLUDED.status, "
            "dispatched_action_id = EXCLUDED.dispatched_action_id", row)


class PgResponseMemory:
    """The first answer given under an idempotency key, per object."""

    def __init__(self, session: Session) -> None:
        self._session = session

    def recall(self, object_id: str, key: str) -> dict[str, Any] | None:
        row = self._session.execute("SELECT response FROM planhrc_response WHERE object_id = %s AND key = %s",
                                    (str(object_id), str(key))).fetchone()
        return dict(row[0]) if row else None

    def remember(self, object_id: str, key: str, text: str) -> None:
        """Remember a checked response (inside the open transaction); the first one stored under a key wins."""
        self._session.execute("INSERT INTO planhrc_response VALUES (%s, %s, %s::json) ON CONFLICT DO NOTHING",
                              (str(object_id), key, text))

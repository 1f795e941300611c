"""What several service processes on one PostgreSQL store need beyond `KnowledgeStore`: a per-object lock that
works across processes, and a channel that says which object has a new event.

- `ObjectLocking.lock_object(object_id)`: `pg_advisory_xact_lock` inside the open transaction. A perception's
  use case takes it first thing in its `transaction()` block; another process's perception of the same object
  waits for the commit, so each object's writes are one at a time across processes (its event counter's row lock
  orders its events as well). It is released by the commit or the rollback, also when the process dies.
- `PgEventFeed`: a connection of its own that `LISTEN`s on `EVENT_CHANNEL`; every committed event is announced
  there as `<object_id> <seq>` (`pg_notify` in the event's transaction: announced once it commits, never before).
  A process that streams events waits on the feed instead of polling, then reads the log as usual.
"""
from __future__ import annotations

from ..errors import UnavailableError
from ..interface import ObjectLocking
from .session import Connection, connect

EVENT_CHANNEL = "planhrc_event"
LOCK_NAMESPACE = "planhrc-object:"  # hashed with the object id into the advisory lock's key
LOCK_OBJECT = "SELECT pg_advisory_xact_lock(hashtextextended(%s, 0))"  # with LOCK_NAMESPACE + the object's id


__all__ = ["EVENT_CHANNEL", "LOCK_NAMESPACE", "LOCK_OBJECT", "ObjectLocking", "PgEventFeed"]  # protocols: `interface`


class PgEventFeed:
    """Which objects have new events, as they commit (`wait`); close it when done."""

    def __init__(self, db: str, password: str | None) -> None:
        self._conn: Connection = connect(db, password, "planhrc-events")
        self._conn.execute(f"LISTEN {EVENT_CHANNEL}")

    def wait(self, timeout_s: float) -> list[tuple[str, int]]:
        """(object id, seq) of every event committed since the last call, waiting up to `timeout_s` for one."""
        out: list[tuple[str, int]] = []
        try:
            for note in self._conn.notifies(timeout=timeout_s, stop_after=1):
                object_id, _, seq = note.payload.rpartition(" ")
                out.append((object_id, int(seq)))
            for note in self._conn.notifies(timeout=0):  # what arrived with it
                object_id, _, seq = note.payload.rpartition(" ")
                out.append((object_id, int(seq)))
        except Exception as exc:
            if self._conn.broken:
                raise UnavailableError(f"db: the event feed lost its connection ({exc})") from None
            raise
        return out

    def close(self) -> None:
        self._conn.close()

    def __enter__(self) -> PgEventFeed:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

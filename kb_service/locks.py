"""One lock per object: requests on one object are serialized, requests on different objects run in parallel."""
from __future__ import annotations

import threading
from contextlib import contextmanager
from typing import Iterator


class ObjectLocks:
    """A re-entrant lock per object id, created on first use."""

    def __init__(self) -> None:
        self._guard = threading.Lock()
        self._locks: dict[str, threading.RLock] = {}

    def lock_for(self, object_id: str) -> threading.RLock:
        with self._guard:
            lock = self._locks.get(object_id)
            if lock is None:
                lock = self._locks[object_id] = threading.RLock()
            return lock

    @contextmanager
    def hold(self, object_id: str) -> Iterator[None]:
        with self.lock_for(object_id):
            yield

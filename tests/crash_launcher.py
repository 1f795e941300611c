"""The service as `planhrc serve` runs it (`create_app(settings)` under uvicorn), around a store that kills the
process (SIGKILL) inside the store write of its N-th perception: after every row of the write is written, before
the commit. For the crash test (`test_service_crash`), which runs it as a child process:

    python -m tests.crash_launcher --port PORT --db FILE_OR_URL --crash-at N

The service itself has no crash hook: the test brings its own.
"""
from __future__ import annotations

import argparse
import logging
import os
import signal
from contextlib import contextmanager
from typing import Any, Iterator

import uvicorn

from planhrc.kb_service.app import create_app, open_knowledge_base
from planhrc.kb_service.store import KnowledgeStore, StoredState
from planhrc.model import Perception
from planhrc.settings import Settings, make_settings

log = logging.getLogger(__name__)


class CrashingStore:
    """A store of any backend (every call passed on to it), killing its process when the outermost transaction
    holding its `crash_at`-th perception is about to commit. A transaction holds the store's lock from start to end,
    so one transaction at a time counts."""

    def __init__(self, store: KnowledgeStore, crash_at: int) -> None:
        self._store = store
        self.crash_at = crash_at
        self.perceptions = 0
        self._crash_depth = 0
        self._crash_perceived = False

    def __getattr__(self, name: str) -> Any:
        return getattr(self._store, name)

    def add_perception(self, perception: Perception) -> StoredState:
        state = self._store.add_perception(perception)
        self._crash_perceived = True
        return state

    @contextmanager
    def transaction(self) -> Iterator[None]:
        with self._store.transaction():
            self._crash_depth += 1
            try:
                yield
            except BaseException:
                if self._crash_depth == 1:
                    self._crash_perceived = False  # rolled back: it did not count
                raise
            finally:
                self._crash_depth -= 1
            if self._crash_depth == 0 and self._crash_perceived:
                self._crash_perceived = False
                self.perceptions += 1
                if self.perceptions >= self.crash_at:
                    log.critical("killing the service inside its perception write %d", self.perceptions)
                    os.kill(os.getpid(), signal.SIGKILL)


def main() -> None:
    parser = argparse.ArgumentParser(prog="python -m tests.crash_launcher")
    parser.add_argument("--port", type=int, required=True)
    parser.add_argument("--db", required=True)
    parser.add_argument("--crash-at", type=int, required=True)
    args = parser.parse_args()
    settings = make_settings(db_path=args.db, host="127.0.0.1", port=args.port)

    def open_store(s: Settings) -> Any:
        return CrashingStore(open_knowledge_base(s), args.crash_at)

    uvicorn.run(create_app(settings, open_store=open_store), host=settings.host, port=settings.port,
                log_level="warning")


if __name__ == "__main__":
    main()

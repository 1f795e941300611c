"""uvicorn's server as `planhrc serve` runs it (`serve`): the same server, without an idle loop that wakes up, and
stopping at once when it is asked to stop.

Why: uvicorn's main loop sleeps 0.1 s at a time to look for a stop request and to refresh its `Date` header once a
second. Each wake-up costs the service's process some CPU whatever it does (more after a pause than back to back),
and at a robot's pace of a perception every second or so, even one wake-up a second is a visible part of what a
re-plan costs. Here the loop only waits for a stop request (a signal handled as uvicorn handles it, or
`should_exit` set), and the `Date` header is worked out when a response asks for the headers, at most once a
second (`DatedState`), so it stays right to the second without a timer.
"""
from __future__ import annotations

import asyncio
import sys
import time
from email.utils import formatdate
from types import FrameType
from typing import Any

import uvicorn
from uvicorn.server import ServerState

STARTUP_FAILURE = 3  # uvicorn's exit code when the server did not start (`uvicorn.main.STARTUP_FAILURE`)


class DatedState(ServerState):
    """uvicorn's state shared by its connections, whose `default_headers` (what every response starts with: `Date`
    when the config asks for it, then the config's own headers) are made when read, again once the second has
    changed. What uvicorn's loop assigns to them is ignored: they are always the current ones."""

    def __init__(self, config: uvicorn.Config) -> None:
        self._config = config
        self._second: int | None = None
        self._headers: list[tuple[bytes, bytes]] = []
        super().__init__()

    @property
    def default_headers(self) -> list[tuple[bytes, bytes]]:
        now = int(time.time())
        if now != self._second:
            dated = [(b"date", formatdate(now, usegmt=True).encode())] if self._config.date_header else []
            self._headers, self._second = dated + self._config.encoded_headers, now
        return self._headers

    @default_headers.setter
    def default_headers(self, value: list[tuple[bytes, bytes]]) -> None:
        pass


class QuietServer(uvicorn.Server):
    """`uvicorn.Server` whose main loop waits for a stop request instead of polling for one."""

    def __init__(self, config: uvicorn.Config) -> None:
        self._stop: asyncio.Event | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._exiting = False
        super().__init__(config)
        self.server_state = DatedState(config)

    @property
    def should_exit(self) -> bool:
        return self._exiting

    @should_exit.setter
    def should_exit(self, value: bool) -> None:
        """Set by uvicorn's signal handler or by whoever stops the server: the waiting loop wakes at once."""
        self._exiting = value
        loop, stop = self._loop, self._stop
        if value and loop is not None and stop is not None and not loop.is_closed():
            loop.call_soon_threadsafe(stop.set)

    async def main_loop(self) -> None:
        self._loop = asyncio.get_running_loop()
        self._stop = asyncio.Event()
        if await self.on_tick(0):  # asked to stop already, or uvicorn's other reasons to
            return
        if not self._exiting:
            await self._stop.wait()


def serve(app: Any, **options: Any) -> None:
    """What `uvicorn.run(app, **options)` does for one process without reloading, with `QuietServer`."""
    config = uvicorn.Config(app, **options)
    config.load_app()
    server = QuietServer(config)
    try:
        server.run()
    except KeyboardInterrupt:
        pass
    if not server.started:
        sys.exit(STARTUP_FAILURE)

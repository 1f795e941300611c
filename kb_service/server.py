"""uvicorn's server as `planhrc serve` runs it (`serve`): the same server, waking once a second when idle instead of
ten times, and at once when it is asked to stop.

Why: uvicorn's main loop sleeps 0.1 s at a time to look for a stop request and to refresh its `Date` header once a
second. Each of those wake-ups costs the service's process some CPU whatever it does: at a robot's pace of about
one perception a second, ten of them cost about as much as a relative re-plan's VAL run. Here the loop waits for a
stop request (a signal handled as uvicorn handles it, or `should_exit` set) or one second, whichever comes first,
and refreshes the header each time, so the header stays right to the second and a SIGTERM stops it as soon as
before.
"""
from __future__ import annotations

import asyncio
import sys
from types import FrameType
from typing import Any

import uvicorn

STARTUP_FAILURE = 3  # uvicorn's exit code when the server did not start (`uvicorn.main.STARTUP_FAILURE`)
TICK_S = 1.0  # the idle loop's period: uvicorn refreshes its Date header once a second


class QuietServer(uvicorn.Server):
    """`uvicorn.Server` whose main loop waits for a stop request instead of polling for one."""

    def __init__(self, config: uvicorn.Config) -> None:
        super().__init__(config)
        self._stop: asyncio.Event | None = None
        self._loop: asyncio.AbstractEventLoop | None = None

    async def main_loop(self) -> None:
        self._loop = asyncio.get_running_loop()
        self._stop = asyncio.Event()
        counter = 0
        should_exit = await self.on_tick(counter)
        while not should_exit:
            counter = (counter + 10) % 864000  # `on_tick` refreshes the Date header when this is a multiple of 10
            try:
                await asyncio.wait_for(self._stop.wait(), TICK_S)
            except TimeoutError:
                pass
            should_exit = await self.on_tick(counter)

    def handle_exit(self, sig: int, frame: FrameType | None) -> None:
        super().handle_exit(sig, frame)
        loop, stop = self._loop, self._stop
        if loop is not None and stop is not None:
            loop.call_soon_threadsafe(stop.set)


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

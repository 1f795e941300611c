"""Server-Sent Events: an object's event log, live.

The stream polls the (append-only) log and sends every new event as `id: <seq>`, `event: <kind>`,
`data: <json>`; it ends when the client disconnects, after `max_events` events or after `timeout_s` seconds.
A comment line is sent now and then so proxies keep the connection open.
"""
from __future__ import annotations

import json
import time
from dataclasses import asdict
from typing import AsyncIterator, Awaitable, Callable, Sequence

import anyio

from .store import StoredEvent
from .usecases.reads import event_read


def format_sse(event: StoredEvent) -> str:
    payload = json.dumps(asdict(event_read(event)), separators=(",", ":"))
    return f"id: {event.seq}\nevent: {event.kind}\ndata: {payload}\n\n"


async def stream_events(
    read_after: Callable[[int], Sequence[StoredEvent]],
    is_disconnected: Callable[[], Awaitable[bool]],
    after_seq: int = 0,
    max_events: int | None = None,
    timeout_s: float | None = None,
    poll_s: float = 0.2,
    heartbeat_s: float = 10.0,
) -> AsyncIterator[str]:
    """Yield SSE frames for every event with seq > `after_seq`, oldest first, as they are stored."""
    sent = 0
    last = after_seq
    start = last_beat = time.monotonic()
    yield ": planhrc events\n\n"
    while True:
        if await is_disconnected():
            return
        events = await anyio.to_thread.run_sync(read_after, last)
        for event in events:
            yield format_sse(event)
            last = max(last, event.seq)
            sent += 1
            if max_events is not None and sent >= max_events:
                return
        now = time.monotonic()
        if timeout_s is not None and now - start >= timeout_s:
            return
        if now - last_beat >= heartbeat_s:
            last_beat = now
            yield ": keep-alive\n\n"
        await anyio.sleep(poll_s)

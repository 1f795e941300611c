"""Server-Sent Events: an object's event log, live.

The stream sends every new event of the log as `id: <seq>`, `event: <kind>`, `data: <json>`; it ends when the client
disconnects, after `max_events` events or after `timeout_s` seconds. A comment line is sent now and then so proxies
keep the connection open.

When does it read the log again? On a store that one process owns (SQLite) every event is written by this process,
and the stream reads the log every `poll_s`. On a store several service processes share (PostgreSQL), an event may
come from any of them: the process keeps one feed of the events every process commits (`EventBell`, on the store's
`event_feed`: LISTEN/NOTIFY) and a stream reads the log when the feed names its object, and only then. A feed that
lost its connection (the database restarted) is opened again, and every stream reads the log once then, for what
was committed meanwhile.
"""
from __future__ import annotations

import asyncio
import logging
import threading
import time
from contextlib import contextmanager
from typing import Any, AsyncIterator, Awaitable, Callable, ContextManager, Iterator, Protocol, Sequence

import anyio

from .record_schemas import event_public
from .store import EventFeed, StoredEvent, UnavailableError
from .usecases.log import event_read

log = logging.getLogger(__name__)

FEED_WAIT_S = 0.5  # how long the feed's thread waits for news at a time: how soon it sees `close`
REOPEN_S = 1.0  # between attempts to open a feed that lost its connection
LEFT_CHECK_S = 1.0  # how often a stream waiting for news asks whether its client left (nothing else notices)


def format_sse(event: StoredEvent) -> str:
    payload = event_public(event_read(event)).model_dump_json()
    return f"id: {event.seq}\nevent: {event.kind}\ndata: {payload}\n\n"


class News(Protocol):
    """Waits until the object may have new events (True) or `timeout_s` passed (False)."""

    def wait(self, timeout_s: float) -> Awaitable[bool]: ...


class _Polling:
    """News every `poll_s`: the log is read that often (a store one process owns)."""

    def __init__(self, poll_s: float) -> None:
        self._poll_s = poll_s

    async def wait(self, timeout_s: float) -> bool:
        await anyio.sleep(min(self._poll_s, timeout_s))
        return True


class _Bell:
    """One stream's subscription: set, from the feed's thread, when its object has a new event."""

    def __init__(self) -> None:
        self._loop = asyncio.get_running_loop()
        self._rung = asyncio.Event()

    def ring(self) -> None:
        """From any thread."""
        self._loop.call_soon_threadsafe(self._rung.set)

    async def wait(self, timeout_s: float) -> bool:
        with anyio.move_on_after(timeout_s):
            await self._rung.wait()
        rung = self._rung.is_set()
        self._rung.clear()  # before the log is read: an event committed after the read rings again
        return rung


class EventBell:
    """One feed of the events every process commits, for the whole process (`store.EventFeeding.event_feed`),
    rings the streams of each object that has a new event (`subscribe`). Its thread opens the feed (again, after a
    lost connection) until `close`."""

    def __init__(self, open_feed: Callable[[], EventFeed]) -> None:
        self._open_feed = open_feed
        self._guard = threading.Lock()
        self._bells: dict[str, set[_Bell]] = {}
        self._stop = threading.Event()
        self.listening = threading.Event()  # set while the feed is open
        self._thread = threading.Thread(target=self._run, name="planhrc-event-feed", daemon=True)
        self._thread.start()

    @contextmanager
    def subscribe(self, object_id: str) -> Iterator[News]:
        """News of `object_id` while the block runs (inside the event loop that waits on it)."""
        bell = _Bell()
        with self._guard:
            self._bells.setdefault(object_id, set()).add(bell)
        try:
            yield bell
        finally:
            with self._guard:
                bells = self._bells.get(object_id)
                if bells is not None:
                    bells.discard(bell)
                    if not bells:
                        del self._bells[object_id]

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=FEED_WAIT_S * 4)

    def _ring(self, object_ids: set[str] | None) -> None:
        """Ring the streams of `object_ids` (None: every stream)."""
        with self._guard:
            bells = [b for oid, group in self._bells.items() if object_ids is None or oid in object_ids
                     for b in group]
        for bell in bells:
            try:
                bell.ring()
            except RuntimeError:  # its event loop has closed (the service is stopping)
                pass

    def _run(self) -> None:
        feed: EventFeed | None = None
        try:
            while not self._stop.is_set():
                if feed is None:
                    try:
                        feed = self._open_feed()
                    except Exception as exc:  # the database unreachable now (UnavailableError), or refusing
                        log.warning("event feed: %s; trying again", exc)
                        self._stop.wait(REOPEN_S)
                        continue
                    self.listening.set()
                    self._ring(None)  # what was committed while there was no feed
                try:
                    news = feed.wait(FEED_WAIT_S)
                except Exception as exc:  # lost (UnavailableError) or anything else: the streams must not go deaf
                    if isinstance(exc, UnavailableError):
                        log.warning("%s; opening it again", exc)
                    else:
                        log.exception("event feed failed; opening it again")
                    self.listening.clear()
                    try:
                        feed.close()
                    except Exception:  # a connection already gone
                        pass
                    feed = None
                    continue
                if news:
                    self._ring({object_id for object_id, _ in news})
        finally:
            self.listening.clear()
            if feed is not None:
                feed.close()


async def stream_events(
    read_after: Callable[[int], Sequence[StoredEvent]],
    is_disconnected: Callable[[], Awaitable[bool]],
    after_seq: int = 0,
    max_events: int | None = None,
    timeout_s: float | None = None,
    poll_s: float = 0.2,
    heartbeat_s: float = 10.0,
    news: Callable[[], ContextManager[News]] | None = None,
) -> AsyncIterator[str]:
    """Yield SSE frames for every event with seq > `after_seq`, oldest first, as they are stored: the log is read
    again when `news` says the object may have new events (an `EventBell` subscription), else every `poll_s`."""
    sent = 0
    last = after_seq
    start = last_beat = time.monotonic()
    yield ": planhrc events\n\n"
    fresh = True  # the log may hold events not sent yet
    with news() if news is not None else _nothing(_Polling(poll_s)) as waiting:
        while True:
            if await is_disconnected():
                return
            events = await anyio.to_thread.run_sync(read_after, last) if fresh else ()
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
            if events:
                continue  # a page of the log: there may be more, read before waiting
            left = min(heartbeat_s - (now - last_beat), LEFT_CHECK_S)
            if timeout_s is not None:
                left = min(left, timeout_s - (now - start))
            fresh = await waiting.wait(max(left, 0.0))


@contextmanager
def _nothing(value: News) -> Iterator[News]:
    yield value


async def counted_stream(frames: AsyncIterator[str], gauge: Any) -> AsyncIterator[str]:
    """`frames`, with `gauge` (a Prometheus gauge of the streams open) one higher while they are sent."""
    gauge.inc()
    try:
        async for frame in frames:
            yield frame
    finally:
        gauge.dec()

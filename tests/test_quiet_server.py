"""`planhrc serve`'s uvicorn server (`kb_service/server.py`): its idle loop does not wake up at all, it still answers
with a current `Date` header, and a stop request (uvicorn's signal handler, or `should_exit`) ends it at once. A real
uvicorn server on a loopback port, real HTTP."""
from __future__ import annotations

import asyncio
import signal
import threading
import time
from email.utils import parsedate_to_datetime
from typing import Any

import httpx
import pytest
import uvicorn

from planhrc.kb_service.server import QuietServer
from planhrc.service_process import free_port


async def _app(scope: dict[str, Any], receive: Any, send: Any) -> None:
    if scope["type"] != "http":
        return
    await send({"type": "http.response.start", "status": 200, "headers": [(b"content-type", b"text/plain")]})
    await send({"type": "http.response.body", "body": b"ok"})


class CountingServer(QuietServer):
    """`QuietServer` counting its loop's ticks."""

    ticks = 0

    async def on_tick(self, counter: int) -> bool:
        self.ticks += 1
        return await super().on_tick(counter)


@pytest.fixture
def server():
    port = free_port()
    srv = CountingServer(uvicorn.Config(_app, host="127.0.0.1", port=port, log_level="warning", lifespan="off"))
    thread = threading.Thread(target=lambda: asyncio.run(srv.serve()), daemon=True)
    thread.start()
    end = time.monotonic() + 20
    while not srv.started:
        assert time.monotonic() < end, "the server did not start"
        time.sleep(0.02)
    yield srv, f"http://127.0.0.1:{port}", thread
    srv.should_exit = True
    thread.join(10)


def _date(url: str) -> float:
    answer = httpx.get(url)
    assert answer.status_code == 200 and answer.text == "ok"
    return parsedate_to_datetime(answer.headers["date"]).timestamp()


def test_the_idle_loop_does_not_wake_and_the_date_header_stays_current(server):
    srv, url, _ = server
    before = srv.ticks
    time.sleep(2.5)
    assert srv.ticks == before  # uvicorn's own loop would have ticked about 25 times in this while
    first = _date(url)
    assert abs(first - time.time()) <= 1.0
    time.sleep(1.2)  # no timer refreshes it: the response that reads the headers does
    second = _date(url)
    assert second > first and abs(second - time.time()) <= 1.0
    assert srv.ticks == before


def test_a_stop_request_ends_the_loop_at_once(server):
    srv, _, thread = server
    time.sleep(0.2)  # the loop is waiting for its next tick
    t = time.monotonic()
    # what uvicorn's signal handler calls in the server's thread; here from another thread, as a signal may arrive
    srv.handle_exit(signal.SIGTERM, None)
    thread.join(10)
    assert not thread.is_alive()
    assert time.monotonic() - t < 0.5


def test_should_exit_ends_the_loop_at_once(server):
    srv, _, thread = server
    time.sleep(0.2)  # the loop is waiting
    t = time.monotonic()
    srv.should_exit = True  # as a caller that runs the server in a thread stops it
    thread.join(10)
    assert not thread.is_alive()
    assert time.monotonic() - t < 0.5

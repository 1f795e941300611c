"""One way for the tests to run `planhrc serve` as a real process on a loopback port, on a SQLite file or on a
database of the session's PostgreSQL cluster (`store_location`)."""
from __future__ import annotations

import os
import threading
import time
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Callable, Iterator, Mapping, Sequence

import httpx
import pytest

from planhrc.service_process import (RunningService, free_port, running_service, settled_health,  # noqa: F401
                                     wait_until_serving)
from planhrc.service_process import serve_command as _serve_command

REPO = Path(__file__).resolve().parent.parent
TOKEN = "test-token"


def serve_command(port: int, db: Path, args: Sequence[str] = ()) -> list[str]:
    return _serve_command(port, db, ("--log-level", "warning", *args))


def store_location(backend: str, folder: Path, request: pytest.FixtureRequest) -> str:
    """A fresh store of `backend` for a served service: a file in `folder`, or a new database of the session's
    throwaway PostgreSQL cluster (`tests/conftest.py`)."""
    if backend == "sqlite":
        return str(folder / "kb.sqlite3")
    cluster = request.getfixturevalue("pg_cluster")
    url = str(cluster.database())
    request.addfinalizer(lambda: cluster.drop(url))
    return url


def serve_env(env: Mapping[str, str] | None = None) -> dict[str, str]:
    """The test process's environment without its `PLANHRC_*` settings, plus `env`."""
    out = {k: v for k, v in os.environ.items() if not k.startswith("PLANHRC_")}
    out["PYTHONPATH"] = str(REPO) + os.pathsep + out.get("PYTHONPATH", "")
    out.update(env or {})
    return out


@contextmanager
def serving(db: Path | str, port: int | None = None, args: Sequence[str] = (),
            env: Mapping[str, str] | None = None, folder: Path | None = None) -> Iterator[str]:
    """`planhrc serve` on `db` until it answers /health; yields its base URL, stops it (its process group)
    afterwards. The server's output goes to `serve-<port>.log` beside the database (in `folder` for a database
    server's URL) and is shown if it exits early."""
    with served(db, port, args, env, folder) as server:
        yield server.url


@contextmanager
def served(db: Path | str, port: int | None = None, args: Sequence[str] = (),
           env: Mapping[str, str] | None = None, folder: Path | None = None) -> Iterator[RunningService]:
    """`serving`, yielding the running service (its URL and process id)."""
    port = port or free_port()
    folder = folder or Path(db).parent
    with running_service(db, port=port, args=("--log-level", "warning", *args), env=serve_env(env), cwd=folder,
                         log_path=folder / f"serve-{port}.log") as server:
        yield server


def token_client(server: RunningService | str, timeout: float = 60, token: str = TOKEN) -> httpx.Client:
    """An HTTP client of a served service sending `token` as its bearer token."""
    url = server if isinstance(server, str) else server.url
    return httpx.Client(base_url=url, timeout=timeout, headers={"Authorization": f"Bearer {token}"})


def timed_beside(slow_call: Callable[[], Any], started: threading.Event,
                 calls: Sequence[tuple[str, Callable[[], Any]]]) -> tuple[Any, dict[str, float], float]:
    """Run `slow_call` in a thread and, once `started` says its slow stage has begun, each named call in turn,
    each of which must answer 200. Returns the slow call's answer, each call's seconds, and the seconds from the
    start of the slow call until the last call answered."""
    result: dict[str, Any] = {}
    worker = threading.Thread(target=lambda: result.update(r=slow_call()))
    t0 = time.perf_counter()
    worker.start()
    assert started.wait(10)
    timings = {}
    for name, call in calls:
        t = time.perf_counter()
        assert call().status_code == 200, name
        timings[name] = time.perf_counter() - t
    done_before = time.perf_counter() - t0
    worker.join(30)
    return result["r"], timings, done_before

"""What the tests of several `planhrc serve` processes on one PostgreSQL database share: the replicas themselves,
and a look at (or a hand on) the objects' advisory locks, taken by the test's own connection to hold every
replica's write of an object at its lock."""
from __future__ import annotations

import time
from contextlib import ExitStack, contextmanager
from pathlib import Path
from typing import Any, Iterator, Sequence

import httpx

from planhrc.kb_service.store.postgres.replicas import LOCK_NAMESPACE
from planhrc.service_process import RunningService
from tests.servers import TOKEN, served, token_client


@contextmanager
def replicas(db: str, folder: Path, count: int = 2, args: Sequence[str] = (),
             env: dict[str, str] | None = None) -> Iterator[list[tuple[RunningService, httpx.Client]]]:
    """`count` services on one database, each with a client sending the token."""
    with ExitStack() as stack:
        out = []
        for _ in range(count):
            server = stack.enter_context(served(db, args=args, env={"PLANHRC_TOKEN": TOKEN, **(env or {})},
                                                folder=folder))
            out.append((server, stack.enter_context(token_client(server))))
        yield out


@contextmanager
def object_lock_held(db: str, object_id: str) -> Iterator[None]:
    """The object's lock (the one the replicas' writes take), held by the test until the block ends."""
    import psycopg

    with psycopg.connect(db, autocommit=True) as conn, conn.transaction():
        conn.execute("SELECT pg_advisory_xact_lock(hashtextextended(%s, 0))", (LOCK_NAMESPACE + object_id,))
        yield


def advisory_locks(db: str, granted: bool | None = None) -> int:
    """Advisory locks on the database now (held and waited for; `granted`: only those)."""
    import psycopg

    with psycopg.connect(db, autocommit=True) as conn:
        row = conn.execute("SELECT count(*) FROM pg_locks l JOIN pg_database d ON d.oid = l.database "
                           "WHERE l.locktype = 'advisory' AND d.datname = current_database() "
                           "AND (%s::boolean IS NULL OR l.granted = %s)", (granted, granted)).fetchone()
    return int(row[0]) if row else 0


def wait_for_waiters(db: str, count: int, timeout_s: float = 60) -> None:
    """Until `count` sessions wait for an advisory lock."""
    deadline = time.monotonic() + timeout_s
    while advisory_locks(db, granted=False) < count:
        assert time.monotonic() < deadline, f"fewer than {count} requests reached the object's lock"
        time.sleep(0.05)


def perceive(client: httpx.Client, oid: str, links: Sequence[float], key: str | None = None) -> httpx.Response:
    return client.post(f"/objects/{oid}/perceptions", json={"link_orientations_deg": list(links)},
                       headers={"Idempotency-Key": key} if key else None)


def events(client: httpx.Client, oid: str) -> list[dict[str, Any]]:
    return list(client.get(f"/objects/{oid}/events").json())


def new_rod(client: httpx.Client, goal: Sequence[float] = (0, 90, 90)) -> str:
    """A 3-link relative object with a goal."""
    oid = str(client.post("/objects", json={"name": "rod", "links": len(goal), "orientations": 4,
                                            "formulation": "relative"}).json()["id"])
    assert client.put(f"/objects/{oid}/goal", json={"link_orientations_deg": list(goal)}).status_code == 200
    return oid

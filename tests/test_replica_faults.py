"""Faults of a site on one PostgreSQL with several `planhrc serve` replicas, on real processes: a replica killed
(SIGKILL) inside a perception's write, and PostgreSQL restarted under load. Nothing acknowledged is lost, nothing is
half-written, an idempotent retry on another replica gives one decision, the service recovers without a restart,
and no object is left locked. (A planning worker killed mid-job: `test_planning_queue`; two replicas dispatching one
action at once: `test_replicas`.)"""
from __future__ import annotations

import random
import threading
import time
from typing import Any, Iterator

import httpx
import pytest

from planhrc.vocabulary import DecisionKind
from tests.replica_tools import advisory_locks, events, new_rod, perceive, replicas
from tests.servers import store_location, token_client
from tests.test_service_crash import _dead, crashing_service

pytestmark = pytest.mark.integration

DECISIONS = {str(kind) for kind in DecisionKind}


def test_a_replica_killed_inside_a_perception_loses_nothing_acknowledged(pg_cluster, tmp_path, request):
    """Perceptions alternate between replica A and replica B; A dies (SIGKILL) inside the write of its third one,
    holding the object's lock, its rows written but not committed. From B: every acknowledged perception reads back
    whole, and the client's retry of the killed one (same Idempotency-Key) is decided once."""
    db = store_location("postgresql", tmp_path, request)
    configurations = [[0, 0, 0], [0, 90, 0], [90, 0, 0], [0, 0, 90], [90, 90, 0]]
    with crashing_service(db, tmp_path, crash_at=3) as crashing, token_client(crashing) as a, \
            replicas(db, tmp_path, count=1) as [(_, b)]:
        oid = new_rod(a)
        acknowledged: dict[str, tuple[list[int], dict[str, Any]]] = {}
        for i, links in enumerate(configurations):
            key = f"p{i}"
            if i == 4:  # A's third perception: A dies inside its write
                with pytest.raises(httpx.TransportError):
                    perceive(a, oid, links, key)
                break
            answer = perceive(a if i % 2 == 0 else b, oid, links, key)
            assert answer.status_code == 200, answer.text
            acknowledged[key] = (links, answer.json())
        deadline = time.monotonic() + 30
        while not _dead(crashing.pid) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert _dead(crashing.pid)

        log = events(b, oid)
        decided = {e["data"].get("perceived_state_id") for e in log if e["kind"] in DECISIONS}
        for key, (links, answer) in acknowledged.items():
            assert answer["perceived_state_id"] in decided, key
            assert b.get(f"/states/{answer['perceived_state_id']}").status_code == 200
            if answer["plan_id"]:
                assert b.get(f"/plans/{answer['plan_id']}").status_code == 200
            assert perceive(b, oid, links, key).json() == answer  # its remembered answer, from the survivor
        assert len(decided) == len(acknowledged)  # nothing of the killed one
        assert advisory_locks(db) == 0  # the dead replica's lock went with its connection
        t = time.monotonic()
        retried = perceive(b, oid, configurations[4], "p4")
        assert retried.status_code == 200, retried.text
        assert time.monotonic() - t < 30  # not held by a lock
        assert perceive(b, oid, configurations[4], "p4").json() == retried.json()
        after = [e for e in events(b, oid) if e["kind"] in DECISIONS]
        assert len(after) == len(acknowledged) + 1  # one decision for the retried request


@pytest.fixture
def own_cluster() -> Iterator[Any]:
    """A cluster of this test's own, to restart without disturbing the session's."""
    from tests.conftest import throwaway_cluster

    with throwaway_cluster() as cluster:
        yield cluster


@pytest.mark.slow
def test_postgresql_restarted_under_load(own_cluster, tmp_path):
    """Four clients post perceptions (each with its Idempotency-Key) to two replicas while PostgreSQL restarts: each
    request answers 200 or 503 (`UnavailableError`: nothing written, send it again), never anything else; every
    503 sent again succeeds without restarting a replica; each request is decided once and each decision is whole;
    the replicas' event streams follow again; no object is left locked."""
    db = own_cluster.database()
    rng = random.Random(5)
    answered: list[tuple[str, str, list[int], int, dict[str, Any]]] = []
    failures: list[str] = []
    with replicas(db, tmp_path) as [(_, a), (_, b)]:
        oids = [new_rod(a) for _ in range(4)]
        stop = threading.Event()

        def load(n: int, oid: str) -> None:
            client, count = (a, b)[n % 2], 0
            while not stop.is_set():
                links = [rng.choice((0, 90, 180, 270)) for _ in range(3)]
                key = f"{oid}-{count}"
                count += 1
                try:
                    reply = perceive(client, oid, links, key)
                except httpx.TransportError as exc:
                    failures.append(f"{key}: {exc!r}")
                    continue
                answered.append((oid, key, links, reply.status_code, reply.json()))

        clients = [threading.Thread(target=load, args=(n, oid)) for n, oid in enumerate(oids)]
        for thread in clients:
            thread.start()
        deadline = time.monotonic() + 60
        while len({r[0] for r in answered if r[3] == 200}) < len(oids):  # every client under way
            assert time.monotonic() < deadline and not failures, failures
            time.sleep(0.1)
        own_cluster.restart(down_s=1.0)
        time.sleep(3)
        stop.set()
        for thread in clients:
            thread.join(60)
        assert not failures, failures
        statuses = [status for *_, status, _ in answered]
        assert set(statuses) <= {200, 503}, [r for r in answered if r[3] not in (200, 503)]
        assert 503 in statuses and 200 in statuses
        for oid, key, links, status, body in answered:
            if status == 503:
                assert body["detail"].startswith("db: ") and "\n" not in body["detail"], body
                again = perceive(b, oid, links, key)  # sent again: the replicas serve without a restart
                assert again.status_code == 200, again.text
        keys = {(oid, key) for oid, key, *_ in answered}
        for oid in oids:
            log = events(a, oid)
            assert [e["seq"] for e in log] == list(range(1, len(log) + 1))
            decisions = [e for e in log if e["kind"] in DECISIONS]
            assert len(decisions) == len([k for k in keys if k[0] == oid])  # each request decided once
            for event in decisions:  # whole: what each decision names is stored
                data = event["data"]
                assert a.get(f"/states/{data['perceived_state_id']}").status_code == 200
                if data.get("plan_id"):
                    assert b.get(f"/plans/{data['plan_id']}").status_code == 200
        assert advisory_locks(db) == 0
        # the event feed is listening again: B's stream shows what A commits now
        start = events(b, oids[0])[-1]["seq"]
        seen: list[str] = []

        def follow() -> None:
            with b.stream("GET", f"/objects/{oids[0]}/events/stream",
                          params={"after_seq": start, "max_events": 1, "timeout_s": 20}) as r:
                seen.extend(line for line in r.iter_lines() if line.startswith("id: "))

        reader = threading.Thread(target=follow)
        reader.start()
        time.sleep(1.5)
        assert perceive(a, oids[0], [0, 90, 90]).status_code == 200
        reader.join(30)
        assert seen == [f"id: {start + 1}"]

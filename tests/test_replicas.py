"""Several `planhrc serve` processes on one PostgreSQL database serve the same objects: a request may go to any of
them. Each object's writes are one at a time across the processes and each decides on what the others committed
(`usecases.unit_of_work`): an idempotent retry sent to another replica gets the first answer, two replicas taking
the same next action dispatch it once, a perception waiting for another replica's write decides on that write.
The event stream of any replica shows every replica's events as they commit, without polling the log (`events`),
and the console and the API's documentation are served by each."""
from __future__ import annotations

import threading
import time
from concurrent.futures import ThreadPoolExecutor
from typing import Any, Iterator

import httpx
import pytest

from tests.replica_tools import (advisory_locks, events, new_rod, object_lock_held, perceive, replicas,
                                 wait_for_waiters)

pytestmark = pytest.mark.integration


@pytest.fixture
def db(pg_cluster, request) -> str:
    from tests.servers import store_location

    return store_location("postgresql", request.getfixturevalue("tmp_path"), request)


@pytest.fixture(scope="module")
def pair(pg_cluster, tmp_path_factory) -> Iterator[tuple[str, httpx.Client, httpx.Client]]:
    """Two replicas on one database, shared by the tests below that each work on objects of their own (starting
    two services is most of such a test's time)."""
    url = str(pg_cluster.database())
    try:
        with replicas(url, tmp_path_factory.mktemp("replicas")) as [(_, a), (_, b)]:
            yield url, a, b
    finally:
        pg_cluster.drop(url)


def written_out(*clients: httpx.Client, timeout_s: float = 120) -> None:
    """Until every plan the replicas adopted has its triples written out: a plan stays its journal row until its
    triples are read, so each replica exports the whole history (the replicas write plans out side by side)."""
    with ThreadPoolExecutor(len(clients)) as pool:
        exports = [pool.submit(c.get, "/ontology", params={"history": "all"},
                               headers={"Accept": "application/n-triples"}, timeout=timeout_s) for c in clients]
        assert [f.result().status_code for f in exports] == [200] * len(clients)
    assert [c.get("/health").json()["plans_to_write"] for c in clients] == [0] * len(clients)


def test_replicas_serve_one_object_in_turn_each_deciding_on_what_the_other_wrote(pair):
    db, a, b = pair
    oid = new_rod(a)
    first = perceive(a, oid, [0, 0, 0]).json()
    assert first["decision"] == "replan"
    again = perceive(b, oid, [0, 0, 0]).json()  # B knows A's plan: go on with it
    assert (again["decision"], again["plan_id"]) == ("continue", first["plan_id"])
    action = b.post(f"/objects/{oid}/actions/next").json()
    assert action["id"] == first["next_action"]["id"]
    assert a.post(f"/objects/{oid}/actions/next").json()["id"] == action["id"]  # taken again: the same one
    done = a.post(f"/objects/{oid}/actions/{action['id']}/feedback", json={"outcome": "succeeded"})
    assert done.status_code == 200, done.text
    log_a, log_b = events(a, oid), events(b, oid)
    assert log_a == log_b
    assert [e["seq"] for e in log_a] == list(range(1, len(log_a) + 1))
    assert [e["kind"] for e in log_a].count("dispatched") == 1
    for name, client in (("a", a), ("b", b)):  # the console and /docs, from either
        for path in ("/", "/docs", "/openapi.json"):
            assert client.get(path).status_code == 200, (name, path)


def test_a_retry_sent_to_another_replica_gets_the_first_answer(pair):
    """The same request (same Idempotency-Key) on both replicas at once, both held at the object's lock until both
    decided: the first to write answers both, and the log keeps one decision."""
    db, a, b = pair
    oid = new_rod(a)
    before = len(events(a, oid))
    with ThreadPoolExecutor(2) as pool:
        with object_lock_held(db, oid):
            answers = [pool.submit(perceive, c, oid, [0, 0, 0], "same-key") for c in (a, b)]
            wait_for_waiters(db, 2)
        first, second = (f.result(timeout=60) for f in answers)
    assert first.status_code == second.status_code == 200, (first.text, second.text)
    assert first.json() == second.json()
    added = events(b, oid)[before:]
    assert [e["kind"] for e in added] == ["replan"], added
    assert perceive(b, oid, [0, 0, 0], "same-key").json() == first.json()


def test_a_perception_held_behind_another_replicas_write_decides_on_that_write(pair):
    """Two perceptions of the same configuration (different keys) on two replicas at once: each planned from the
    same stored state, but the second to write decides again on the first's plan and goes on with it."""
    db, a, b = pair
    oid = new_rod(a)
    with ThreadPoolExecutor(2) as pool:
        with object_lock_held(db, oid):
            answers = [pool.submit(perceive, c, oid, [0, 0, 0], key) for c, key in ((a, "ka"), (b, "kb"))]
            wait_for_waiters(db, 2)
        replies = [f.result(timeout=60).json() for f in answers]
    decisions = sorted(r["decision"] for r in replies)
    assert decisions == ["continue", "replan"], replies
    assert len({r["plan_id"] for r in replies}) == 1  # one plan, not one per replica
    plans = [e["data"]["plan_id"] for e in events(a, oid) if e["kind"] == "replan"]
    assert len(plans) == 1


def test_two_replicas_taking_the_next_action_at_once_dispatch_it_once(pair):
    db, a, b = pair
    oid = new_rod(a)
    assert perceive(a, oid, [0, 0, 0]).json()["decision"] == "replan"
    with ThreadPoolExecutor(2) as pool:
        with object_lock_held(db, oid):
            taken = [pool.submit(c.post, f"/objects/{oid}/actions/next") for c in (a, b)]
            wait_for_waiters(db, 2)
        answers = [f.result(timeout=60) for f in taken]
    assert [r.status_code for r in answers] == [200, 200]
    assert answers[0].json() is not None and answers[0].json() == answers[1].json()
    assert [e["kind"] for e in events(b, oid)].count("dispatched") == 1
    written_out(a, b)  # a plan written out behind its answer holds its object's lock meanwhile
    assert advisory_locks(db) == 0  # no object left locked


def _stream(client: httpx.Client, oid: str, after_seq: int, want: int, out: list[dict[str, Any]],
            opened: threading.Event) -> None:
    with client.stream("GET", f"/objects/{oid}/events/stream",
                       params={"after_seq": after_seq, "max_events": want, "timeout_s": 30}) as r:
        for line in r.iter_lines():
            opened.set()
            if line.startswith("id: "):
                out.append({"seq": int(line[4:])})
            elif line.startswith("event: "):
                out[-1]["kind"] = line[7:]


def test_a_replicas_event_stream_shows_the_events_another_replica_commits(pair):
    db, a, b = pair
    oid = new_rod(a)
    start = events(a, oid)[-1]["seq"]
    seen: list[dict[str, Any]] = []
    opened = threading.Event()
    reader = threading.Thread(target=_stream, args=(b, oid, start, 2, seen, opened))
    reader.start()
    assert opened.wait(30)
    time.sleep(0.3)  # the stream has read the log and waits for news
    t0 = time.monotonic()
    perceive(a, oid, [0, 0, 0])
    a.post(f"/objects/{oid}/actions/next")
    reader.join(30)
    assert not reader.is_alive()
    assert [e["kind"] for e in seen] == ["replan", "dispatched"]
    assert seen[0]["seq"] == start + 1
    assert time.monotonic() - t0 < 20


def test_a_stream_reads_the_log_when_the_feed_names_its_object_and_only_then(db):
    """In-process, on the real feed: idle, the stream reads the log once (when it starts); another store's write to
    another object wakes no read; a write to its object wakes one, at once."""
    import anyio

    from planhrc.event_log import EventKind, GoalSetData
    from planhrc.kb_service.events import EventBell, stream_events
    from planhrc.kb_service.store import open_store
    from planhrc.kb_service.usecases.log import log_event
    from planhrc.model import make_object
    from planhrc.paths import default_tbox_path

    with open_store(db, default_tbox_path()) as mine, open_store(db, default_tbox_path()) as other:
        for oid in (mine.new_object_id(), mine.new_object_id()):
            mine.create_object(make_object(oid, "relative", 3, 4))
        reads: list[float] = []

        def read_after(seq: int) -> Any:
            reads.append(time.monotonic())
            return mine.list_events("obj1", after_seq=seq)

        async def disconnected() -> bool:
            return False

        bell = EventBell(mine.event_feed)
        assert bell.listening.wait(30)
        got: list[tuple[float, str]] = []

        async def main() -> None:
            async def consume() -> None:
                async for frame in stream_events(read_after, disconnected, max_events=1, timeout_s=20,
                                                 news=lambda: bell.subscribe("obj1")):
                    if frame.startswith("id: "):
                        got.append((time.monotonic(), frame))

            async def write() -> None:
                with anyio.fail_after(30):
                    while not reads:  # the stream has read the log once, and waits
                        await anyio.sleep(0.05)
                await anyio.sleep(0.5)
                await anyio.to_thread.run_sync(lambda: log_event(other, "obj2", EventKind.GOAL_SET, "elsewhere",
                                                                   GoalSetData(goal_state_id="obj2_state_1")))
                await anyio.sleep(1.0)
                assert len(reads) == 1, reads  # idle, and news of another object: no read
                await anyio.to_thread.run_sync(lambda: log_event(other, "obj1", EventKind.GOAL_SET, "here",
                                                                   GoalSetData(goal_state_id="obj1_state_1")))

            async with anyio.create_task_group() as tasks:
                tasks.start_soon(consume)
                tasks.start_soon(write)

        try:
            anyio.run(main)
        finally:
            bell.close()
        assert len(got) == 1 and "event: goal_set" in got[0][1]
        assert len(reads) == 2  # the start, and the news


def test_a_replica_dispatches_another_replicas_plan_only_as_far_as_val_accepted_it(pair):
    """An absolute plan adopted on A on VAL's early answer (its later pieces checked behind the answer, on A) is
    carried out through B: B's gate reads the verdicts A records and checks again the pieces it finds no verdict
    for, so every step leaves only once VAL accepted the piece it lies in."""
    from tests.test_val_gate import GOAL, K, LINKS, START

    db, a, b = pair
    oid = a.post("/objects", json={"name": "bar", "links": LINKS, "orientations": K,
                                   "formulation": "absolute"}).json()["id"]
    assert a.put(f"/objects/{oid}/goal", json={"link_orientations_deg": GOAL}).status_code == 200
    assert perceive(a, oid, START).json()["decision"] == "replan"
    taken = 0
    while (action := b.post(f"/objects/{oid}/actions/next").json()) is not None:
        taken += 1
        done = a.post(f"/objects/{oid}/actions/{action['id']}/feedback", json={"outcome": "succeeded"})
        assert done.status_code == 200, done.text
        assert taken < 100
    accepted: set[int] = set()
    pieces: list[list[int]] = []
    dispatched = before_answer = 0
    for event in events(b, oid):
        data = event["data"]
        if event["kind"] == "replan":
            pieces, accepted = data["val_pieces"], set(data["val_accepted"])
            before_answer = len(accepted)
        elif event["kind"] == "val_verdict" and data["verdict"] == "accepted":
            accepted.add(data["piece"])
        elif event["kind"] == "dispatched":
            dispatched += 1
            number = next(i for i, (lo, hi) in enumerate(pieces, start=1) if lo <= data["step"] <= hi)
            assert number in accepted, (data, accepted)
    assert dispatched == taken and 0 < before_answer < len(pieces)
    assert accepted == set(range(1, len(pieces) + 1))  # every piece checked, the later ones behind the answer


def test_one_replica_compacts_at_a_time(db):
    """Every replica compacts on its schedule: while one compacts (holding the compaction's lock), another's
    compaction leaves the store to it."""
    import psycopg

    from planhrc.kb_service.store import open_store
    from planhrc.kb_service.store.postgres.store import COMPACT_LOCK
    from planhrc.model import make_object
    from planhrc.paths import default_tbox_path

    with open_store(db, default_tbox_path()) as kb:
        obj = make_object(kb.new_object_id(), "relative", 3, 4)
        kb.create_object(obj)
        for joints in ([0, 0], [0, 90], [90, 90]):
            kb.add_state(obj.ident, "perceived", obj.state(joints))
        with psycopg.connect(db, autocommit=True) as other, other.transaction():
            other.execute("SELECT pg_advisory_xact_lock(%s)", (COMPACT_LOCK,))
            assert kb.compact(1).individuals == 0  # left to the other one
        assert kb.compact(1).individuals > 0


def test_replicas_writing_one_object_at_once_store_each_individual_once(pair):
    """Perceptions of one object from four clients on two replicas at once, each with new orientations, and each
    replica writing its plans out behind its answers: every individual the object's states and plans share (an
    orientation atom) is created once, whichever process creates it first, so no triple is stored twice."""
    import random

    import psycopg

    db, a, b = pair
    oid = a.post("/objects", json={"name": "long", "links": 12, "orientations": 12,
                                   "formulation": "relative"}).json()["id"]
    assert a.put(f"/objects/{oid}/goal", json={"link_orientations_deg": [0.0] * 12}).status_code == 200
    end = time.monotonic() + 6

    def post(n: int) -> list[int]:
        rng, statuses = random.Random(n), []
        while time.monotonic() < end:
            links = [float(rng.randrange(12) * 30) for _ in range(12)]
            statuses.append(perceive((a, b)[n % 2], oid, links).status_code)
        return statuses

    with ThreadPoolExecutor(4) as pool:
        statuses = [s for f in [pool.submit(post, n) for n in range(4)] for s in f.result(timeout=120)]
    assert statuses and set(statuses) == {200}
    written_out(a, b)
    with psycopg.connect(db, autocommit=True) as conn:
        twice = conn.execute("SELECT s, p, coalesce(o, lit), count(*) FROM planhrc_triple GROUP BY s, p, o, lit, dt "
                             "HAVING count(*) > 1 LIMIT 5").fetchall()
    assert twice == []

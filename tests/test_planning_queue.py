"""Planning workers anywhere: a service on PostgreSQL with `--planning-queue` puts its large tasks in the database's
job queue (`store/postgres/jobs.py`, `kb_service/planning_queue.py`), and `planhrc planning-worker` processes plan
them. The queue's rules on a real PostgreSQL (two workers never take one job, nor wait for each other; a job past
its deadline is never started; an expired lease is taken over and only the holder's outcome counts), then real
processes: a worker plans a service's task, VAL still gates it; no worker by the deadline is a 503 with nothing
stored; a worker killed (SIGKILL) mid-job has its job leased again by another, and the perception gets one plan."""
from __future__ import annotations

import os
import pickle
import signal
import subprocess
import sys
import threading
import time
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Iterator

import httpx
import pytest

from planhrc.service_process import die_with_parent, free_port, stop_process_group
from tests.replica_tools import events, perceive, replicas
from tests.servers import serve_env, store_location

psycopg = pytest.importorskip("psycopg", reason="the planning queue is a PostgreSQL store's (psycopg 3)")


@pytest.fixture
def db(pg_cluster, tmp_path, request) -> str:
    return store_location("postgresql", tmp_path, request)


@contextmanager
def worker(db: str, folder: Path, lease_s: float = 1.0, name: str = "w",
           *args: str) -> Iterator[subprocess.Popen[bytes]]:
    """`planhrc planning-worker` on `db` (with `args`); its log is `<folder>/worker-<name>.log`."""
    log_path = folder / f"worker-{name}.log"
    with open(log_path, "wb") as log:
        proc = subprocess.Popen([sys.executable, "-m", "planhrc.cli", "planning-worker", "--db", db, "--lease-s",
                                 str(lease_s), *args], env=serve_env(), stdout=log, stderr=subprocess.STDOUT,
                                start_new_session=True, preexec_fn=die_with_parent)
    try:
        yield proc
    finally:
        stop_process_group(proc)


def rows(db: str) -> list[tuple[Any, ...]]:
    with psycopg.connect(db, autocommit=True) as conn:
        return conn.execute("SELECT id, state, worker, attempts FROM planhrc_planning_job ORDER BY id").fetchall()


# -- the queue's rules ------------------------------------------------------------------------------------------
def test_the_queue_hands_each_job_to_one_worker_never_starts_a_late_one_and_keeps_one_outcome(db):
    from planhrc.kb_service.planning_queue import ensure_tables
    from planhrc.kb_service.store.postgres.jobs import CLAIM, COLLECT, FINISH, RENEW, SUBMIT, claimed

    with psycopg.connect(db, autocommit=True) as a, psycopg.connect(db, autocommit=True) as b:
        ensure_tables(a)
        late = a.execute(SUBMIT, ("obj1", b"late", 0.01, None)).fetchone()[0]
        first = a.execute(SUBMIT, ("obj1", b"first", 30, "00-0123456789abcdef0123456789abcdef-0123456789abcdef-01")
                          ).fetchone()[0]
        second = a.execute(SUBMIT, ("obj2", b"second", 30, None)).fetchone()[0]
        time.sleep(0.1)
        b.execute("SET statement_timeout = '30s'")  # a claim that waited for a's would fail, not hang the test
        with a.transaction():  # a worker's claim not committed yet: the other takes the next job, without waiting
            got_a = claimed(a.execute(CLAIM, {"worker": "a", "lease": 0.3}).fetchone())
            got_b = claimed(b.execute(CLAIM, {"worker": "b", "lease": 30}).fetchone())
        assert got_a is not None and got_b is not None
        assert (got_a.id, got_a.blob) == (first, b"first") and (got_b.id, got_b.blob) == (second, b"second")
        assert 20 < got_b.left <= 30 and got_b.attempts == 1 and not got_b.taken_over
        assert got_a.trace is not None and got_a.trace.startswith("00-0123") and got_b.trace is None
        assert claimed(b.execute(CLAIM, {"worker": "b", "lease": 30}).fetchone()) is None  # the late one: never
        time.sleep(0.5)  # worker a stops renewing: its lease expires and b takes the job again
        again = claimed(b.execute(CLAIM, {"worker": "b", "lease": 30}).fetchone())
        assert again is not None and again.id == first and again.attempts == 2 and again.taken_over
        assert a.execute(RENEW, (30, first, "a")).fetchall() == []  # not a's any more
        assert a.execute(FINISH, (b"a's", first, "a")).fetchall() == []  # a's outcome is not kept
        assert len(b.execute(FINISH, (b"b's", first, "b")).fetchall()) == 1
        assert a.execute(COLLECT, (first,)).fetchone()[0] == b"b's"
        assert a.execute(COLLECT, (first,)).fetchone() is None  # collected once
        assert {r[0] for r in rows(db)} == {late, second}


def test_a_job_the_worker_cannot_read_is_answered_with_an_error(db):
    """A job a worker cannot unpickle (a service of another version) gets an `error` outcome, so its service answers
    instead of waiting for the deadline; the worker goes on."""
    from planhrc.kb_service.planning_pool import unpack_outcome
    from planhrc.kb_service.planning_queue import ensure_tables, serve_jobs
    from planhrc.kb_service.store.postgres.jobs import COLLECT, SUBMIT
    from planhrc.paths import default_tbox_path

    with psycopg.connect(db, autocommit=True) as conn:
        ensure_tables(conn)
        job = conn.execute(SUBMIT, ("obj1", b"not a pickle", 30, None)).fetchone()[0]
        stop = threading.Event()
        thread = threading.Thread(target=serve_jobs, args=(db, None, str(default_tbox_path()), 1.0, stop, "test"))
        thread.start()
        try:
            deadline = time.monotonic() + 60
            while (row := conn.execute(COLLECT, (job,)).fetchone()) is None:
                assert time.monotonic() < deadline and thread.is_alive()
                time.sleep(0.05)
        finally:
            stop.set()
            thread.join(10)
        outcome = unpack_outcome(iter(pickle.loads(row[0])))
        assert outcome.status == "error" and "could not read the job" in outcome.message


# -- real processes ---------------------------------------------------------------------------------------------
QUEUED = {"PLANHRC_PLANNING_POOL_MIN_ATOMS": "1"}  # every task through the queue


@pytest.mark.integration
def test_a_worker_plans_the_services_task_and_val_gates_its_dispatch(db, tmp_path):
    """As on the service's own pool's path (`test_val_gate`): the worker plans, VAL runs in the service, the first
    motion's pieces before the answer and the rest behind it, each verdict an event the dispatch gate reads."""
    from tests.test_val_gate import GOAL, K, LINKS, START

    with worker(db, tmp_path), replicas(db, tmp_path, count=1, args=("--planning-queue",), env=QUEUED) as [(_, c)]:
        oid = c.post("/objects", json={"name": "bar", "links": LINKS, "orientations": K,
                                       "formulation": "absolute"}).json()["id"]
        assert c.put(f"/objects/{oid}/goal", json={"link_orientations_deg": GOAL}).status_code == 200
        answer = perceive(c, oid, START)
        assert answer.status_code == 200, answer.text
        assert answer.json()["decision"] == "replan"
        adopted = next(e for e in events(c, oid) if e["kind"] == "replan")["data"]
        assert adopted["val_accepted"] and len(adopted["val_accepted"]) < len(adopted["val_pieces"])
        deadline = time.monotonic() + 60
        while len([e for e in events(c, oid) if e["kind"] == "val_verdict"]) < (
                len(adopted["val_pieces"]) - len(adopted["val_accepted"])):
            assert time.monotonic() < deadline, "VAL's verdicts on the later pieces did not come"
            time.sleep(0.1)
        assert all(e["data"]["verdict"] == "accepted" for e in events(c, oid) if e["kind"] == "val_verdict")
        taken = c.post(f"/objects/{oid}/actions/next").json()
        assert taken is not None and taken["id"] == answer.json()["next_action"]["id"]
        assert rows(db) == []  # collected
    assert "planning job 1 (obj1, attempt 1" in (tmp_path / "worker-w.log").read_text()


@pytest.mark.integration
def test_without_a_worker_the_deadline_holds_and_nothing_is_stored(db, tmp_path):
    env = {**QUEUED, "PLANHRC_PLANNING_DEADLINE_S": "2"}
    with replicas(db, tmp_path, count=1, args=("--planning-queue",), env=env) as [(_, c)]:
        oid = c.post("/objects", json={"name": "bar", "links": 3, "orientations": 4,
                                       "formulation": "relative"}).json()["id"]
        assert c.put(f"/objects/{oid}/goal", json={"link_orientations_deg": [0, 90, 90]}).status_code == 200
        before = events(c, oid)
        t = time.monotonic()
        answer = perceive(c, oid, [0, 0, 0], "k1")
        took = time.monotonic() - t
        assert answer.status_code == 503, answer.text
        assert "deadline" in answer.json()["detail"] and "\n" not in answer.json()["detail"]
        assert 2 <= took < 15, took  # the deadline, its grace, and a loaded machine's slack
        assert events(c, oid) == before and rows(db) == []  # nothing stored, the job withdrawn
        with worker(db, tmp_path):  # a worker now: the same request is planned and answered
            log = tmp_path / "worker-w.log"
            for _ in range(600):
                if "serving the job queue" in log.read_text(errors="replace"):
                    break
                time.sleep(0.1)
            # A worker's first job loads its planner; on a slow day that alone can pass the 2 s deadline, which
            # is again a 503 that stores nothing: the request is sent again, as a client does, a few times.
            for _ in range(4):
                again = perceive(c, oid, [0, 0, 0], "k1")
                if again.status_code != 503:
                    break
                assert "deadline" in again.json()["detail"] and events(c, oid) == before, again.text
        assert again.status_code == 200 and again.json()["decision"] == "replan", again.text


@pytest.mark.integration
@pytest.mark.slow
def test_a_worker_killed_mid_job_has_its_job_leased_again_and_the_perception_gets_one_plan(db, tmp_path):
    env = {**QUEUED, "PLANHRC_PLANNING_DEADLINE_S": "45"}  # a 503 at the deadline comes within the client's 60 s
    links = 40  # an absolute task a worker needs a few seconds for
    ports = {"a": free_port(), "b": free_port()}  # each worker's own /metrics
    with worker(db, tmp_path, 1.0, "a", "--metrics-port", str(ports["a"])) as first, \
            worker(db, tmp_path, 1.0, "b", "--metrics-port", str(ports["b"])) as second, \
            replicas(db, tmp_path, count=1, args=("--planning-queue",), env=env) as [(_, c)]:
        oid = c.post("/objects", json={"name": "long", "links": links, "orientations": 12,
                                       "formulation": "absolute"}).json()["id"]
        goal = [float((30 * k * 7) % 360) for k in range(links)]
        assert c.put(f"/objects/{oid}/goal", json={"link_orientations_deg": goal}).status_code == 200
        answer: dict[str, Any] = {}

        def send() -> None:
            t = time.monotonic()
            answer["r"] = perceive(c, oid, [0.0] * links, "long")
            answer["took"] = time.monotonic() - t

        request = threading.Thread(target=send)
        request.start()
        deadline = time.monotonic() + 60
        holder = None
        while holder is None and time.monotonic() < deadline:
            running = [r for r in rows(db) if r[1] == "running"]
            holder = running[0][2] if running else None
            time.sleep(0.02)
        assert holder is not None, "no worker took the job"
        victim = next(p for p in (first, second) if holder.endswith(f":{p.pid}"))
        os.kill(victim.pid, signal.SIGKILL)
        request.join(120)
        reply = answer["r"]
        assert reply.status_code in (200, 503), reply.text
        assert answer["took"] < 45 + 14  # by the planning deadline (a loaded machine's slack on top)
        if reply.status_code == 200:
            assert reply.json()["decision"] == "replan"
        other = "b" if victim is first else "a"
        survivor = (tmp_path / f"worker-{other}.log").read_text()
        assert "attempt 2" in survivor, survivor
        metrics = httpx.get(f"http://127.0.0.1:{ports[other]}/metrics").text  # the takeover, counted by the taker
        assert "planhrc_planning_leases_taken_over_total 1.0" in metrics, metrics
        plans = [e for e in events(c, oid) if e["kind"] == "replan"]
        assert len(plans) == (1 if reply.status_code == 200 else 0)
        assert rows(db) == []


@pytest.mark.integration
def test_a_worker_stopped_with_sigterm_hands_its_job_back_and_says_so_in_one_line(db, tmp_path):
    """SIGTERM mid-job: the worker stops the pipeline, returns the job to the queue at once (for another worker to
    take, without waiting for the lease), and ends with 143 and one line."""
    import random

    from planhrc.kb_service.planning_queue import ensure_tables
    from planhrc.kb_service.store.postgres.jobs import SUBMIT
    from planhrc.model import make_object
    from planhrc.pipeline import PlanningJob, config_from_settings
    from planhrc.settings import make_settings

    obj = make_object("obj1", "absolute", 40, 12)
    rng = random.Random(3)
    init, goal = (obj.state([rng.choice(obj.orientation_degrees) for _ in obj.joint_indices]) for _ in range(2))
    job = PlanningJob(obj, init, goal, config_from_settings(make_settings(planning_deadline_s=60)), None, 0.0)
    with psycopg.connect(db, autocommit=True) as conn:
        ensure_tables(conn)
        conn.execute(SUBMIT, ("obj1", pickle.dumps(job), 60, None))
    log_path = tmp_path / "worker-w.log"
    with worker(db, tmp_path, lease_s=30) as proc:
        deadline = time.monotonic() + 60
        while "planning job 1 (obj1, attempt 1" not in log_path.read_text():  # it holds the job
            assert time.monotonic() < deadline and proc.poll() is None, log_path.read_text()
            time.sleep(0.02)
        assert [r[1] for r in rows(db)] == ["running"]
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(30) == 143
    (row,) = rows(db)
    assert row[1:] == ("queued", None, 1), row  # back in the queue, not waiting for the 30 s lease
    lines = [line for line in log_path.read_text().splitlines() if "Traceback" in line or line.startswith("planhrc")]
    assert lines == ["planhrc planning-worker: terminated"], log_path.read_text()

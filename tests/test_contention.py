"""A large task plans in the service's planning pool: another object's perceptions and `/health` answer meanwhile,
and no worker process outlives `planhrc serve` (SIGTERM, SIGINT, SIGKILL)."""
from __future__ import annotations

import gc
import os
import random
import signal
import subprocess
import threading
import time
import warnings
from pathlib import Path
from typing import Callable

import httpx
import pytest

with warnings.catch_warnings():
    warnings.simplefilter("ignore")  # starlette's notice about httpx2
    from fastapi.testclient import TestClient

from planhrc.kb_service.app import create_app
from planhrc.settings import make_settings
from tests.servers import free_port, serve_command, serve_env, serving, timed_beside, wait_until_serving
from tests.processes import alive

pytestmark = pytest.mark.slow


def _object(client: httpx.Client, links: int, formulation: str) -> str:
    r = client.post("/objects", json={"name": "rod", "links": links, "orientations": 12,
                                      "formulation": formulation})
    assert r.status_code == 201, r.text
    return r.json()["id"]


def _angles(rng: random.Random, n: int) -> list[int]:
    return [30 * rng.randrange(12) for _ in range(n)]


def test_a_large_task_plans_while_another_object_and_health_answer(tmp_path):
    """A 200-link x 12 absolute object's perception plans for seconds (into its 4 s deadline on a slow machine);
    meanwhile an 8-link object's re-planning perceptions and `/health` keep answering (none waits for the large
    task's answer): the large task's grounding and replay run in a worker process, not in the service's
    interpreter."""
    rng = random.Random(3)
    with serving(tmp_path / "kb.sqlite3", env={"PLANHRC_PLANNING_DEADLINE_S": "4"}) as base, \
            httpx.Client(base_url=base, timeout=60) as client, httpx.Client(base_url=base, timeout=60) as other:
        big, small = _object(client, 200, "absolute"), _object(client, 8, "relative")
        assert client.put(f"/objects/{big}/goal", json={"link_orientations_deg": _angles(rng, 200)}).is_success
        assert client.put(f"/objects/{small}/goal", json={"link_orientations_deg": _angles(rng, 8)}).is_success
        other.get("/health")  # the connection's first answer is not the service's
        started = threading.Event()

        answered: dict[str, float] = {}

        def plan_big() -> httpx.Response:
            with httpx.Client(base_url=base, timeout=60) as c:
                started.set()
                answer = c.post(f"/objects/{big}/perceptions", json={"link_orientations_deg": [0] * 200})
                answered["at"] = time.perf_counter()
                return answer

        def calls_of() -> list[tuple[str, Callable[[], httpx.Response]]]:
            calls = []
            for i in range(25):
                angles = _angles(rng, 8)
                calls.append((f"small-{i}", lambda a=angles: other.post(f"/objects/{small}/perceptions",
                                                                         json={"link_orientations_deg": a})))
                calls.append((f"health-{i}", lambda: other.get("/health")))
            return calls

        # the same calls with nothing else planning first: what this machine answers them in, in this run
        alone = {}
        for name, call in calls_of():
            t = time.perf_counter()
            assert call().status_code == 200, name
            alone[name] = time.perf_counter() - t
        began = time.perf_counter()
        big_answer, timings, done_before = timed_beside(plan_big, started, calls_of())
        # planned in time on a fast machine (its first motion validated), else answered at its deadline
        assert big_answer.status_code == 200 or (big_answer.status_code == 503 and "deadline of 4 s" in
                                                 big_answer.json()["detail"]), big_answer.text
        ends, last = [], began + done_before  # the calls ran one after another: each ended where the next began
        for seconds in reversed(list(timings.values())):
            ends.append(last)
            last -= seconds
        during = sum(end < answered["at"] for end in ends)
        assert during >= 10, (during, answered["at"] - began)  # answered while the large task was planning
        # A stall behind the large task would last its whole 4 s deadline. Beside it the calls share two cores
        # with the large task's worker, so each is held to what the same call took here without it (this run,
        # this machine) plus a margin far below the stall, not to a figure of an idle machine.
        for kind in ("small", "health"):
            beside = sorted(v for k, v in timings.items() if k.startswith(kind))
            before = sorted(v for k, v in alone.items() if k.startswith(kind))
            assert beside[-1] < before[-1] + 2.0, (kind, beside[-5:], before[-5:])
            assert beside[len(beside) // 2] < 3 * before[len(before) // 2] + 0.2, (kind, beside, before)
        assert done_before < 4.0 + sum(alone.values()), done_before  # the calls ran while the large task planned


def _children(pid: int) -> set[int]:
    out: set[int] = set()
    for task in Path(f"/proc/{pid}/task").glob("*"):
        try:
            out.update(int(c) for c in (task / "children").read_text().split())
        except OSError:
            pass
    return out


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT, signal.SIGKILL], ids=lambda s: s.name)
def test_no_planning_worker_outlives_the_service(tmp_path, sig):
    """The service's planning workers (started by an absolute 20-link re-plan; one of them busy with a 200-link
    task when the signal comes) are gone within seconds of `planhrc serve` stopping, however it stops."""
    port = free_port()
    log_path = tmp_path / "serve.log"
    with open(log_path, "w") as log_file:
        proc = subprocess.Popen(serve_command(port, tmp_path / "kb.sqlite3"), cwd=tmp_path, env=serve_env(),
                                stdout=log_file, stderr=subprocess.STDOUT)
    base = f"http://127.0.0.1:{port}"
    workers: set[int] = set()
    try:
        wait_until_serving(proc, base, log_path=log_path)
        rng = random.Random(5)
        with httpx.Client(base_url=base, timeout=60) as client:
            big, mid = _object(client, 200, "absolute"), _object(client, 20, "absolute")
            client.put(f"/objects/{big}/goal", json={"link_orientations_deg": _angles(rng, 200)}).raise_for_status()
            client.put(f"/objects/{mid}/goal", json={"link_orientations_deg": [90] * 20}).raise_for_status()
            busy = threading.Thread(target=lambda: _quietly(lambda: httpx.post(
                f"{base}/objects/{big}/perceptions", json={"link_orientations_deg": _angles(rng, 200)}, timeout=60)))
            busy.start()
            time.sleep(0.5)
            r = client.post(f"/objects/{mid}/perceptions", json={"link_orientations_deg": [0] * 20})
            assert r.status_code == 200 and r.json()["decision"] == "replan", r.text
            workers = _children(proc.pid)
            assert len(workers) == 2, workers  # the pool's two workers, one planning the large task
            assert busy.is_alive()
        proc.send_signal(sig)
        proc.wait(30)
        until = time.monotonic() + 10
        while any(alive(p) for p in workers) and time.monotonic() < until:
            time.sleep(0.1)
        assert not [p for p in workers if alive(p)], log_path.read_text()[-2000:]
        busy.join(60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        for p in workers:
            if alive(p):
                os.kill(p, signal.SIGKILL)


def _quietly(call) -> None:
    try:
        call()
    except httpx.HTTPError:
        pass  # the service was stopped under the request


def test_the_service_leaves_its_start_up_heap_out_of_full_collections(tmp_path):
    """A full collection walks every object not frozen while it holds the interpreter (95-200 ms a pass with
    start-up's objects in it, which /health waited for): the service freezes them while it runs, and unfreezes
    them when it stops, so an app closed in a longer process is collected."""
    app = create_app(make_settings(db_path=str(tmp_path / "kb.sqlite3"), token=None))
    with TestClient(app) as client:
        assert client.get("/health").status_code == 200
        frozen = gc.get_freeze_count()
        kb = app.state.kb
        assert frozen > 10_000, frozen
        assert not any(o is kb for o in gc.get_objects(generation=2))  # frozen: no full pass walks it
    assert gc.get_freeze_count() == 0


def test_a_perception_whose_planning_worker_dies_answers_and_the_next_one_plans(tmp_path):
    """The worker planning an object's perception is killed: that perception still answers (no plan, the reason
    named, nothing planned stored) and the next perception on a pooled task gets a plan from a new worker. (One
    worker, which the big object's goal warms up; once warm it is stopped (SIGSTOP), so the perception's job is sure
    to be on it when it is killed.)"""
    settings = make_settings(db_path=str(tmp_path / "kb.sqlite3"), token=None, planning_deadline_s=60,
                             planning_workers=1)
    app = create_app(settings)
    with TestClient(app) as client:
        big = client.post("/objects", json={"name": "big", "links": 200, "orientations": 12,
                                            "formulation": "absolute"}).json()["id"]
        mid = client.post("/objects", json={"name": "mid", "links": 20, "orientations": 12,
                                            "formulation": "absolute"}).json()["id"]
        rng = random.Random(11)
        pool = app.state.context.pool
        client.put(f"/objects/{big}/goal", json={"link_orientations_deg": _angles(rng, 200)}).raise_for_status()
        (pid,) = pool.pids()  # started for the warm-up
        client.put(f"/objects/{mid}/goal", json={"link_orientations_deg": [90] * 20}).raise_for_status()
        until = time.monotonic() + 120
        while pool.warming() and time.monotonic() < until:
            time.sleep(0.05)
        assert not pool.warming() and pool.pids() == (pid,)
        os.kill(pid, signal.SIGSTOP)
        answer: dict = {}
        worker = threading.Thread(target=lambda: answer.update(r=client.post(
            f"/objects/{big}/perceptions", json={"link_orientations_deg": _angles(rng, 200)})))
        worker.start()
        time.sleep(0.5)  # the job on its way to the stopped worker (or not yet: either way it is that worker's)
        os.kill(pid, signal.SIGKILL)
        worker.join(60)
        r = answer["r"]
        assert r.status_code == 200 and r.json()["decision"] == "no_plan", r.text
        assert "planning worker stopped" in r.json()["reason"], r.text
        assert client.get(f"/objects/{big}/plan").status_code == 404
        r = client.post(f"/objects/{mid}/perceptions", json={"link_orientations_deg": [0] * 20})
        assert r.status_code == 200 and r.json()["decision"] == "replan", r.text
        assert pool.pids() and pid not in pool.pids()

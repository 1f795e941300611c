"""The service as a real process (`planhrc serve`, or `python -m planhrc.kb_service.cli serve` when the planhrc CLI
does not offer it), driven over HTTP by a simulated worker: whole episodes, a restart on the same database,
two objects in parallel, idempotent retries, the bearer token from the environment and the live event stream.
"""
from __future__ import annotations

import sys
import threading
import time
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator

import httpx
import pytest

REPO = Path(__file__).resolve().parent.parent
if str(REPO / "tests") not in sys.path:  # the simulated worker lives beside this file (any pytest import mode)
    sys.path.insert(0, str(REPO / "tests"))

from tests.servers import serving, store_location  # noqa: E402
from test_service_api import drive_to_goal, links_of, move, noisy, perceive  # noqa: E402

pytestmark = pytest.mark.integration


@contextmanager
def running_server(db: Path | str, token: str | None = None, folder: Path | None = None) -> Iterator[httpx.Client]:
    env = {"PLANHRC_MERGE_MACRO_STEPS": "false"}  # one plan step per action: the episodes name expected states
    if token:
        env["PLANHRC_TOKEN"] = token
    with serving(db, env=env, folder=folder) as base:
        headers = {"Authorization": f"Bearer {token}"} if token else {}
        with httpx.Client(base_url=base, timeout=30, headers=headers) as client:
            yield client


def create(client: httpx.Client, formulation: str = "relative", links: int = 4, k: int = 4) -> str:
    r = client.post("/objects", json={"name": "rod", "links": links, "orientations": k, "formulation": formulation})
    assert r.status_code == 201, r.text
    return r.json()["id"]


@pytest.mark.parametrize("backend", ["sqlite", "postgresql"])
def test_whole_episode_then_restart_on_the_same_database(tmp_path, backend, request):
    db = store_location(backend, tmp_path, request)
    with running_server(db, folder=tmp_path) as c:
        oid = create(c)
        assert c.put(f"/objects/{oid}/goal", json={"link_orientations_deg": [0, 180, 180, 0]}).status_code == 200
        links = [0.0, 0.0, 0.0, 0.0]

        # 1. first perception: a plan of four single steps
        first = perceive(c, oid, noisy(links))
        assert first["decision"] == "replan" and first["next_action"]["step"] == 1
        plan_id = first["plan_id"]
        plan = c.get(f"/objects/{oid}/plan").json()
        assert len(plan["steps"]) == 4

        # 2. nominal: the robot executes a_1
        action = c.post(f"/objects/{oid}/actions/next").json()
        links = move(links, action)
        assert c.post(f"/objects/{oid}/actions/{action['id']}/feedback", json={"outcome": "succeeded"}).status_code == 200
        answer = perceive(c, oid, noisy(links))
        assert (answer["decision"], answer["matched_expected_step"]) == ("continue", 2)

        # 3. a failed action: nothing moved, the same configuration is perceived -> retry a_2
        action = c.post(f"/objects/{oid}/actions/next").json()
        assert action["step"] == 2
        assert c.post(f"/objects/{oid}/actions/{action['id']}/feedback", json={"outcome": "failed"}).status_code == 200
        answer = perceive(c, oid, noisy(links))
        assert answer["decision"] == "continue" and answer["next_action"]["id"] == action["id"]

        # 4. a human does a_2 and a_3 while the robot waits: resume from s^e_4, ahead of the next step (2)
        links = links_of(plan["expected_states"][3], "relative", first_link_deg=0)
        answer = perceive(c, oid, noisy(links))
        assert answer["decision"] == "resume" and answer["plan_id"] == plan_id
        assert answer["matched_expected_step"] == 4 > action["step"]
        assert answer["next_action"]["step"] == 4

        # 5. a disturbance off the plan (j2 and j3 knocked away, so no s^e_i and not pre(a_4)): re-plan
        links = [0, 180, 270, 270]
        answer = perceive(c, oid, noisy(links))
        assert answer["decision"] == "replan" and answer["plan_id"] != plan_id
        plan_id = answer["plan_id"]

        # 6. the robot finishes the new plan: goal reached
        links, answers = drive_to_goal(c, oid, links, "relative")
        assert answers[-1]["decision"] == "goal_reached"
        assert all(a["decision"] == "continue" for a in answers[:-1])
        events = c.get(f"/objects/{oid}/events").json()
        plan = c.get(f"/objects/{oid}/plan").json()
        obj = c.get(f"/objects/{oid}").json()
        assert obj["execution"]["status"] == "goal_reached"
        kinds = [e["kind"] for e in events]
        for kind in ("replan", "continue", "resume", "goal_reached", "feedback", "dispatched"):
            assert kind in kinds

    with running_server(db, folder=tmp_path) as c:
        assert c.get(f"/objects/{oid}").json() == obj
        assert c.get(f"/objects/{oid}/plan").json() == plan
        assert plan["id"] == plan_id
        assert c.get(f"/objects/{oid}/events").json() == events
        # the restarted service continues from the stored state: the goal still holds
        assert perceive(c, oid, noisy(links))["decision"] == "goal_reached"
        # and a new goal is planned from a new perception
        c.put(f"/objects/{oid}/goal", json={"joint_angles_deg": [0, 0, 0]})
        assert perceive(c, oid, noisy(links))["decision"] == "replan"


def test_two_objects_in_parallel_and_idempotent_retries(tmp_path):
    with running_server(tmp_path / "kb.sqlite3") as c:
        specs = [("relative", [0, 90, 180, 270]), ("absolute", [90, 180, 180, 90])]
        ids = []
        for formulation, goal in specs:
            oid = create(c, formulation)
            c.put(f"/objects/{oid}/goal", json={"link_orientations_deg": goal})
            ids.append(oid)
        results: dict[str, object] = {}

        def episode(oid: str, formulation: str) -> None:
            try:
                results[oid] = drive_to_goal(c, oid, [0.0, 0.0, 0.0, 0.0], formulation)
            except BaseException as exc:  # reported by the main thread
                results[oid] = exc

        threads = [threading.Thread(target=episode, args=(oid, f)) for oid, (f, _) in zip(ids, specs)]
        for t in threads:
            t.start()
        for t in threads:
            t.join(timeout=120)
        for oid, (formulation, goal) in zip(ids, specs):
            result = results[oid]
            assert not isinstance(result, BaseException), result
            links, answers = result
            assert answers[-1]["decision"] == "goal_reached"
            if formulation == "absolute":
                assert [round(v) % 360 for v in links] == goal
            events = c.get(f"/objects/{oid}/events").json()
            assert all(e["object_id"] == oid for e in events)
            assert [e["seq"] for e in events] == list(range(1, len(events) + 1))

        # the same perception retried concurrently with one Idempotency-Key: one answer, one stored state
        oid = ids[0]
        before = len(c.get(f"/objects/{oid}/events").json())
        answers: list[dict] = []

        def retry() -> None:
            answers.append(perceive(c, oid, [5.0, 10.0, 20.0, 30.0], key="retry-1"))

        threads = [threading.Thread(target=retry) for _ in range(4)]
        for t in threads:
            t.start()
        for t in threads:
            t.join(timeout=60)
        assert len(answers) == 4 and all(a == answers[0] for a in answers)
        assert len(c.get(f"/objects/{oid}/events").json()) == before + 1


def test_token_from_the_environment_and_live_events(tmp_path):
    with running_server(tmp_path / "kb.sqlite3", token="tok") as c:
        anonymous = httpx.Client(base_url=str(c.base_url), timeout=10)
        body = {"name": "rod", "links": 3, "orientations": 4, "formulation": "relative"}
        assert anonymous.post("/objects", json=body).status_code == 401
        assert anonymous.get("/objects").json() == []
        oid = create(c, links=3)
        c.put(f"/objects/{oid}/goal", json={"joint_angles_deg": [90, 90]})

        received: list[str] = []

        def listen() -> None:
            with anonymous.stream("GET", f"/objects/{oid}/events/stream",
                                  params={"after_seq": 2, "max_events": 2, "timeout_s": 20}) as r:
                for line in r.iter_lines():
                    if line.startswith("event: "):
                        received.append(line[len("event: "):])

        listener = threading.Thread(target=listen)
        listener.start()
        time.sleep(0.5)  # the stream is open before the events happen
        perceive(c, oid, [0, 0, 0])
        c.post(f"/objects/{oid}/actions/next")
        listener.join(timeout=30)
        anonymous.close()
        assert received == ["replan", "dispatched"]

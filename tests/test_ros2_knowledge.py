"""The knowledge service over ROS 2: a real rclpy peer in a process of its own (`tests/ros2_knowledge_peer.py`,
knowing only the documented names, types and QoS) asks SPARQL and subsumption questions on the request/answer topics
and gets what the HTTP routes answer; bad requests are answered naming the field; a reasoning request and the
std_srvs/srv/Trigger service `reason_now` run real reasoning jobs, a request sent again starting none."""
from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import httpx
import pytest

from planhrc.bench.knowledge import CURRENT_STATE_QUERY
from planhrc.client import KBClient

from .servers import TOKEN
from .test_ros2_bridge import ROS2_PYTHON, bridge, ros_env, run_peer, service  # noqa: F401 (fixtures)

PEER = Path(__file__).with_name("ros2_knowledge_peer.py")

pytestmark = [pytest.mark.ros2, pytest.mark.integration,
              pytest.mark.skipif(not ROS2_PYTHON.exists(),
                                 reason=".venv-ros2 is missing: `python3 ./run.py test` makes it (it needs PyPI)")]


def ask(steps: list[dict[str, Any]], env: dict[str, str], timeout_s: float = 180) -> list[dict]:
    return run_peer(PEER, [json.dumps(steps)], env, timeout_s)


@pytest.fixture
def stored(service):  # noqa: F811 (the fixture imported above)
    with KBClient(service, token=TOKEN) as kb:
        oid = kb.create_object("rod", 4, 4, "relative")["id"]
        kb.set_goal(oid, link_orientations_deg=[0, 90, 90, 180])
        for angles in ([0, 0, 0, 0], [0, 90, 0, 0]):
            kb.post_perception(oid, angles)
        obj = kb.read_object(oid)
    return service, oid, obj


def test_sparql_and_subsumption_over_ros2_answer_as_http(stored, ros_env, tmp_path):  # noqa: F811
    url, oid, obj = stored
    goal = obj["goal_state_id"]
    perceived = f"{oid}_state_3"
    with bridge(url, ros_env, tmp_path / "bridge.log"):
        answers = ask([
            {"ask": "sparql", "request": {"request_id": "q1", "query": CURRENT_STATE_QUERY}},
            {"ask": "sparql", "request": {"request_id": "q2", "query": CURRENT_STATE_QUERY, "accept": "text/csv"}},
            {"ask": "sparql", "request": {"request_id": "q3", "query": "SELEKT ?s WHERE { ?s ?p ?o }"}},
            {"ask": "subsumption", "request": {"request_id": "s1", "state_id": perceived, "by_state_id": goal}},
            {"ask": "subsumption", "request": {"request_id": "s2", "state_id": perceived}},
            {"ask": "subsumption", "request": {"request_id": "s3", "state_id": perceived, "by_state_id": "nostate"}},
        ], ros_env)
    by_id = {a["answer"]["request_id"]: a["answer"] for a in answers}
    with httpx.Client(base_url=url, timeout=30) as http:
        direct = http.post("/sparql", data={"query": CURRENT_STATE_QUERY}).json()
        subsumption = http.get(f"/states/{perceived}/subsumed-by/{goal}").json()
    q1 = by_id["q1"]
    assert q1["ok"] and q1["media_type"] == "application/sparql-results+json" and q1["result_count"] == 3
    assert json.loads(q1["body"]) == direct
    assert by_id["q2"]["media_type"] == "text/csv" and len(by_id["q2"]["body"].strip().splitlines()) == 1 + 3
    assert by_id["q3"]["ok"] is False and by_id["q3"]["status"] == 400 and "not SPARQL 1.1" in by_id["q3"]["detail"]
    s1 = {k: v for k, v in by_id["s1"].items() if k not in ("request_id", "ok")}
    assert by_id["s1"]["ok"] and s1 == subsumption and s1["subsumed"] is False and s1["missing"]
    assert by_id["s2"] == {"request_id": "s2", "ok": False, "status": None, "detail": "subsumption.by_state_id: required"}
    assert by_id["s3"]["ok"] is False and by_id["s3"]["status"] == 404 and "nostate" in by_id["s3"]["detail"]


@pytest.mark.reasoner
def test_reasoning_over_ros2_by_topic_and_by_the_trigger_service(stored, ros_env, tmp_path):  # noqa: F811
    url, oid, _ = stored
    with bridge(url, ros_env, tmp_path / "bridge.log"):
        answers = ask([
            {"ask": "reasoning", "request": {"request_id": "r1", "reasoner": "pellet", "object_id": oid}},
            {"ask": "reasoning", "request": {"request_id": "r1", "reasoner": "pellet", "object_id": oid}},
            {"ask": "reasoning", "request": {"request_id": "r2", "reasoner": "fact++"}},
            {"call": "reason_now"},
        ], ros_env)
    first, again, bad, now = answers
    assert first["answer"]["ok"] and first["answer"]["status"] == "done" and first["answer"]["consistent"] is True
    assert first["answer"]["object_id"] == oid and first["answer"]["inferred"] > 0
    assert again["answer"] == first["answer"]  # answered again, not run again
    assert bad["answer"]["ok"] is False and bad["answer"]["status"] == 422 and "reasoner" in bad["answer"]["detail"]
    assert now["success"] is True and now["message"]["consistent"] is True and now["message"]["object_id"] is None
    # two jobs in all: the one request r1 (however often it was sent) and reason_now
    assert (first["answer"]["id"], now["message"]["id"]) == ("job1", "job2")

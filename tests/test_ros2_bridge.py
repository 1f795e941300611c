"""The ROS 2 bridge against a real `planhrc serve` and real rclpy peers (`tests/ros2_peer.py`, run by
`.venv-ros2/bin/python` in processes of their own), each test on a random ROS_DOMAIN_ID with localhost-only
discovery. The peers publish and subscribe the documented topics; the tests check the messages and what the
service recorded (its events and states)."""
from __future__ import annotations

import json
import math
import os
import random
import signal
import subprocess
import time
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Iterator

import pytest

from planhrc.client import KBClient
from planhrc.service_process import stop_process_group

from .servers import REPO, TOKEN, serving

ROS2_PYTHON = REPO / ".venv-ros2" / "bin" / "python"
PEER = Path(__file__).with_name("ros2_peer.py")

pytestmark = [pytest.mark.ros2, pytest.mark.integration,
              pytest.mark.skipif(not ROS2_PYTHON.exists(),
                                 reason=".venv-ros2 is missing: `python3 ./run.py test` makes it (it needs PyPI)")]


@pytest.fixture
def ros_env() -> dict[str, str]:
    """This test's own ROS 2 graph: a random domain, discovery on this machine only."""
    env = {k: v for k, v in os.environ.items() if not k.startswith(("PLANHRC_", "_ROS_WHEELS"))}
    env.update(ROS_DOMAIN_ID=str(random.randint(1, 100)), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
               PLANHRC_TOKEN=TOKEN)
    return env


@pytest.fixture
def service(tmp_path: Path) -> Iterator[str]:
    with serving(tmp_path / "kb.sqlite3", env={"PLANHRC_TOKEN": TOKEN}) as url:
        yield url


@contextmanager
def bridge(url: str, env: dict[str, str], log: Path, *args: str) -> Iterator[subprocess.Popen[bytes]]:
    with open(log, "wb") as out:
        proc = subprocess.Popen([str(ROS2_PYTHON), "-m", "planhrc.cli", "ros2-bridge", "--kb", url, "--poll", "0.3",
                                 *args], env=env, stdout=out, stderr=subprocess.STDOUT, start_new_session=True)
        try:
            yield proc
        finally:
            stop_process_group(proc, grace_s=10)


def peer(object_id: str, steps: list[dict[str, Any]], env: dict[str, str], timeout_s: float = 90) -> list[dict]:
    """Run a peer to the end; its messages, or a failure showing what it printed."""
    return run_peer(PEER, [object_id, json.dumps(steps)], env, timeout_s)


def run_peer(script: Path, args: list[str], env: dict[str, str], timeout_s: float) -> list[dict]:
    """Run a peer script (`.venv-ros2`'s Python) to the end; the JSON lines it printed before `{"done": true}`."""
    proc = subprocess.Popen([str(ROS2_PYTHON), str(script), *args], env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        out, err = proc.communicate(timeout=timeout_s)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        out, err = proc.communicate()
        pytest.fail(f"the peer did not finish in {timeout_s} s:\n{out[-3000:]}\n{err[-3000:]}")
    lines = [json.loads(line) for line in out.splitlines() if line.startswith("{")]
    assert proc.returncode == 0 and lines and lines[-1] == {"done": True}, f"{out[-4000:]}\n{err[-3000:]}"
    return lines[:-1]


def on(messages: list[dict], topic: str) -> list[Any]:
    return [m["msg"] for m in messages if m.get("topic") == topic]


def rad(deg_clockwise: float) -> float:
    return math.remainder(-math.radians(deg_clockwise), 2 * math.pi)


def links(*deg: float) -> dict[str, Any]:
    return {"names": [f"l{k}" for k in range(1, len(deg) + 1)], "positions": [rad(v) for v in deg]}


def test_a_perception_over_ros2_is_decided_dispatched_and_its_feedback_recorded(service, ros_env, tmp_path):
    with KBClient(service, token=TOKEN) as kb:
        oid = kb.create_object("rod", 4, 4, "relative")["id"]
        with bridge(service, ros_env, tmp_path / "bridge.log"):
            steps = [
                {"publish": "goal", **links(0, 90, 90, 180), "stamp": [1, 5]},
                {"wait": "object", "match": {"answer_to.topic": "goal", "answer_to.request_id": "1.000000005"}},
                {"publish": "perceived", **links(0, 0, 0, 0), "stamp": [2, 7]},
                {"wait": "decision", "match": {"perception_stamp": [2, 7]}},
                {"wait": "next_action", "count": 1},
                {"wait": "object", "match": {"answer_to.request_id": "2.000000007"}},
                {"publish": "feedback", "data": {"outcome": "succeeded", "request_id": "f1"}},
                {"wait": "object", "match": {"answer_to.request_id": "f1"}},
                {"wait": "markers", "count": 1},
            ]
            messages = peer(oid, steps, ros_env)
        events = kb.read_events(oid)
        decision = next(d for d in on(messages, "decision") if d["perception_stamp"] == [2, 7])
        assert decision["decision"] == "replan" and decision["event_seq"] is None
        state = kb.read_state(decision["perceived_state_id"])
        assert state["link_orientations_deg"] == pytest.approx([0, 0, 0, 0], abs=1e-9)
        assert kb.read_state(kb.read_object(oid)["goal_state_id"])["joint_values_deg"] == {
            f"{oid}_j1": 90, f"{oid}_j2": 0, f"{oid}_j3": 90}
        action = decision["next_action"]
        (trajectory,) = on(messages, "next_action")
        assert trajectory["joint_names"] == [f"l{action['held_link_index']}", f"l{action['turned_link_index']}"]
        start, end = trajectory["points"][0]["positions"], trajectory["points"][1]["positions"]
        assert end[0] == start[0] and end[1] - start[1] == pytest.approx(-math.radians(action["delta_deg"]))
        assert trajectory["frame_id"] == "base" and trajectory["points"][1]["time_from_start"] > 0
        kinds = [e["kind"] for e in events]
        assert kinds[-3:] == ["replan", "dispatched", "feedback"]
        feedback = events[-1]["data"]
        assert feedback["action_id"] == action["id"] and feedback["outcome"] == "succeeded"
        answered = [o for o in on(messages, "object") if (o["answer_to"] or {}).get("request_id") == "f1"]
        assert answered[-1]["answer_to"]["ok"] and answered[-1]["object"]["execution"]["next_step"] == 2
        plan = on(messages, "plan")[-1]
        assert plan["id"] == decision["plan_id"] and plan["steps"][0]["id"] == action["id"]
        markers = {m["ns"].split("/")[-1]: m for m in on(messages, "markers")[-1]["markers"]}
        assert {"perceived", "goal", "expected"} <= set(markers) and markers["perceived"]["frame_id"] == "base"
        assert len(markers["perceived"]["points"]) == 5 and len(markers["expected"]["points"]) == 5


def test_decisions_caused_over_http_and_objects_created_later_reach_ros2(service, ros_env, tmp_path):
    with KBClient(service, token=TOKEN) as kb:
        with bridge(service, ros_env, tmp_path / "bridge.log"):
            time.sleep(1.0)  # the bridge serves no object yet: this one comes later
            oid = kb.create_object("bar", 3, 4, "relative")["id"]
            kb.set_goal(oid, link_orientations_deg=[0, 90, 180])
            listener = subprocess.Popen(
                [str(ROS2_PYTHON), str(PEER), oid, json.dumps([{"wait": "decision", "count": 2, "timeout": 60}])],
                env=ros_env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
            try:
                time.sleep(3.0)
                first = kb.post_perception(oid, [0, 0, 0])
                second = kb.post_perception(oid, [0, 0, None])
                out, err = listener.communicate(timeout=90)
            finally:
                if listener.poll() is None:
                    os.killpg(listener.pid, signal.SIGKILL)
        assert listener.returncode == 0, f"{out[-3000:]}\n{err[-3000:]}"
        decisions = [json.loads(line)["msg"] for line in out.splitlines()
                     if line.startswith("{") and json.loads(line).get("topic") == "decision"]
        events = {e["seq"]: e for e in kb.read_events(oid)}
        assert [d["decision"] for d in decisions] == [str(first.decision), str(second.decision)]
        assert decisions[1]["decision"] == "incomplete_perception" and decisions[1]["unseen_links"] == [3]
        for d, answer in zip(decisions, (first, second)):
            assert d["perception_stamp"] is None and events[d["event_seq"]]["kind"] == d["decision"]
            assert d["reason"] == answer.reason and d["plan_id"] == answer.plan_id
        assert decisions[0]["next_action"]["id"] == first.next_action["id"]


def test_bad_messages_change_nothing_and_are_answered_naming_the_field(service, ros_env, tmp_path):
    with KBClient(service, token=TOKEN) as kb:
        oid = kb.create_object("rod", 3, 4, "relative")["id"]
        with bridge(service, ros_env, tmp_path / "bridge.log", "--object", oid):
            before = kb.read_events(oid)
            steps = [
                {"publish": "perceived", "names": ["l1", "l7"], "positions": [0.0, 0.0], "stamp": [3, 1]},
                {"wait": "object", "match": {"answer_to.request_id": "3.000000001"}},
                {"publish": "goal", **links(0, 90), "stamp": [3, 2]},
                {"wait": "object", "match": {"answer_to.request_id": "3.000000002"}},
                {"publish": "feedback", "data": '{"outcome": "done"}'},
                {"wait": "object", "match": {"answer_to.topic": "feedback"}},
                {"publish": "feedback", "data": {"outcome": "succeeded", "request_id": "f9"}},
                {"wait": "object", "match": {"answer_to.request_id": "f9"}},
                # two published after the refusals were answered: the second surely counts them all
                {"wait": "/diagnostics", "count": 2, "fresh": True},
            ]
            messages = peer(oid, steps, ros_env)
        answers = {o["answer_to"]["request_id"]: o["answer_to"] for o in on(messages, "object") if o["answer_to"]}
        assert answers["3.000000001"]["detail"].startswith("perceived.name: 'l7'")
        assert answers["3.000000002"]["detail"].startswith("goal.position: every link")
        assert answers[None]["detail"].startswith("feedback.outcome:")
        assert answers["f9"]["detail"].startswith("feedback.action_id: no action was dispatched")
        assert not any(a["ok"] for a in answers.values())
        assert kb.read_events(oid) == before and kb.read_object(oid)["goal_state_id"] is None
        status = {s["name"]: s for s in on(messages, "/diagnostics")[-1]["status"]}
        assert status["planhrc_bridge: service"]["level"] == 0
        assert status[f"planhrc_bridge: {oid}"]["level"] == 1
        assert int(status[f"planhrc_bridge: {oid}"]["values"]["refused"]) >= 3


def test_sigterm_stops_the_bridge_at_once_and_leaves_nothing_running(service, ros_env, tmp_path):
    with KBClient(service, token=TOKEN) as kb:
        kb.create_object("rod", 3, 4, "relative")
    log = tmp_path / "bridge.log"
    with bridge(service, ros_env, log) as proc:
        deadline = time.monotonic() + 60
        while "serving" not in log.read_text(errors="replace") and time.monotonic() < deadline:
            time.sleep(0.2)
        assert "serving obj1" in log.read_text(errors="replace")
        started = time.monotonic()
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=15) == 143
        assert time.monotonic() - started < 10
    lines = [line for line in log.read_text(errors="replace").splitlines() if line.strip()]
    assert lines[-1] == "planhrc ros2-bridge: terminated" and "Traceback" not in log.read_text()
    assert subprocess.run(["pgrep", "-g", str(proc.pid)], capture_output=True).returncode == 1


def test_an_unknown_object_is_refused_in_one_line(service, ros_env, tmp_path):
    result = subprocess.run([str(ROS2_PYTHON), "-m", "planhrc.cli", "ros2-bridge", "--kb", service, "--object", "obj9"],
                            env=ros_env, capture_output=True, text=True, timeout=120)
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert result.returncode == 1 and "Traceback" not in result.stderr
    assert lines[-1].startswith("planhrc ros2-bridge: --object: obj9: GET /objects/obj9: 404")

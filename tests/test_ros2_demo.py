"""`planhrc demo --ros2`: the service, a ROS 2 bridge and the Baxter worker talking ROS 2 only run Fig 13 to the
goal with the same decisions and actions as the demo over HTTP (and `--record` writes its bag); SIGTERM leaves
neither the service nor the bridge behind."""
from __future__ import annotations

import json
import os
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from .test_bag_record import check_episode
from .test_hygiene import processes, wait_for
from .test_ros2_bridge import ROS2_PYTHON

pytestmark = [pytest.mark.ros2, pytest.mark.sim, pytest.mark.slow, pytest.mark.integration,
              pytest.mark.skipif(not ROS2_PYTHON.exists(),
                                 reason=".venv-ros2 is missing: `python3 ./run.py test` makes it (it needs PyPI)")]


def demo_command(python: Path | str, out: Path, *args: str) -> tuple[list[str], dict[str, str]]:
    env = {k: v for k, v in os.environ.items() if not k.startswith(("PLANHRC_", "_ROS_WHEELS"))}
    env.update(ROS_DOMAIN_ID=str(random.randint(1, 100)), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    return [str(python), "-m", "planhrc.cli", "demo", "--scenario", "fig13", "--out", str(out), *args], env


def episode(out: Path) -> dict:
    return json.loads((out / "summary.json").read_text())["results"][0]


def test_fig13_over_ros2_reaches_the_goal_as_over_http(tmp_path):
    command, env = demo_command(ROS2_PYTHON, tmp_path / "ros2", "--ros2", "--record")
    ros2 = subprocess.run(command, env=env, capture_output=True, text=True, timeout=600)
    assert ros2.returncode == 0, ros2.stderr[-3000:]
    command, env = demo_command(sys.executable, tmp_path / "http")
    http = subprocess.run(command, env=env, capture_output=True, text=True, timeout=600)
    assert http.returncode == 0, http.stderr[-3000:]
    over_ros2, over_http = episode(tmp_path / "ros2"), episode(tmp_path / "http")
    assert json.loads((tmp_path / "ros2" / "summary.json").read_text())["worker_link"] == "ros2"
    assert over_ros2["reached_goal"] and over_http["reached_goal"]
    assert [d["kind"] for d in over_ros2["decisions"]] == [d["kind"] for d in over_http["decisions"]]
    assert over_ros2["actions"] == over_http["actions"] and over_ros2["outcomes"] == over_http["outcomes"]
    # the worker's requests went over ROS 2: the bridge posted them (its log names the object it served)
    log = (tmp_path / "ros2" / "episode-001" / "ros2-bridge.log").read_text(errors="replace")
    assert f"serving {over_ros2['object_id']}" in log and "Traceback" not in log
    check_episode(over_ros2)  # recorded over ROS 2 as over HTTP: the bag holds what the summary holds


@pytest.mark.parametrize("signum, code, word", [(signal.SIGTERM, 143, "terminated"), (signal.SIGINT, 130, "interrupted")])
def test_a_signalled_demo_over_ros2_leaves_no_bridge_and_no_service(tmp_path, signum, code, word):
    out = tmp_path / "out"
    command, env = demo_command(ROS2_PYTHON, out, "--ros2", "--perception", "fallback")
    demo = subprocess.Popen(command, env=env, text=True, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            start_new_session=True)
    try:
        bridge = wait_for(lambda: [pid for pid, (_, _, cmd) in processes().items()
                                   if "ros2-bridge" in cmd and "--object" in cmd
                                   and _descends(pid, demo.pid)], 120, "the bridge")
        wait_for(lambda: "/perceptions" in (out / "kb-service.log").read_text(errors="replace"), 120,
                 "the first perception over ROS 2")
        demo.send_signal(signum)
        _, stderr = demo.communicate(timeout=60)
    finally:
        if demo.poll() is None:
            os.killpg(demo.pid, signal.SIGKILL)
            demo.communicate()
    assert demo.returncode == code, stderr[-3000:]
    assert "Traceback" not in stderr and stderr.strip().splitlines()[-1] == f"planhrc demo: {word}"
    time.sleep(0.2)
    left = [cmd for pid, (_, _, cmd) in processes().items() if str(out) in cmd or pid in bridge]
    assert left == [], f"outlived the demo: {left}"


def _descends(pid: int, ancestor: int) -> bool:
    table = processes()
    while pid in table and pid != ancestor:
        pid = table[pid][0]
    return pid == ancestor


def test_planhrc_worker_over_ros2_reaches_the_goal_through_a_running_bridge(tmp_path):
    from planhrc.client import KBClient

    from .servers import TOKEN, serving
    from .test_ros2_bridge import bridge

    _, env = demo_command(ROS2_PYTHON, tmp_path)
    env["PLANHRC_TOKEN"] = TOKEN
    with serving(tmp_path / "kb.sqlite3", env={"PLANHRC_TOKEN": TOKEN}) as url, KBClient(url, token=TOKEN) as kb:
        oid = kb.create_object("paper-3-4", 3, 4, "relative", base_point_xy=(0.7, 0.2325))["id"]
        with bridge(url, env, tmp_path / "bridge.log", "--object", oid):
            worker = subprocess.run(
                [str(ROS2_PYTHON), "-m", "planhrc.cli", "worker", "--ros2", "--object", oid, "--perception", "fallback",
                 "--initial", "90,90,90", "--base", "0.7,0.2325", "--goal", "90,180,270", "--max-steps", "12",
                 "--out", str(tmp_path / "worker")], env=env, capture_output=True, text=True, timeout=600)
        assert worker.returncode == 0, worker.stderr[-3000:]
        summary = json.loads(worker.stdout)
        assert summary["reached_goal"] and summary["decisions"][-1] == "goal_reached"
        kinds = [e["kind"] for e in kb.read_events(oid)]
        # every request of the worker reached the service through the bridge: the goal, perceptions, dispatches
        # and the feedback of each action
        assert kinds.count("dispatched") == kinds.count("feedback") == len(summary["outcomes"]) > 0
        assert "goal_set" in kinds and kinds[-1] == "goal_reached"

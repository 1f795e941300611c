"""`planhrc perceive-calibrate` and `planhrc perceive-node` on the ROS 2 graph, with a real rclpy camera
(`tests/ros2_camera_peer.py`, `.venv-ros2`'s Python) publishing the kept views the worker never takes
(tests/data/perception/, see tests/test_perception_views.py) as sensor_msgs/Image in rgb8, bgr8 and mono8.

For each camera: the calibration command watches the camera's first view and writes the calibration file (the
camera's pose within a centimetre of the truth); the node, started with it, answers each view with the object's
perceived JointState (REP 103 radians, NaN = unseen): every link reported seen within 2 degrees of the truth, no
hidden link reported seen, the base point within a centimetre, the detail with each marker's reprojection error."""
from __future__ import annotations

import json
import math
import subprocess
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator

import numpy as np
import pytest

from planhrc.robot_sim.camera import Calibration, CameraPose
from planhrc.service_process import stop_process_group

from .test_ros2_bridge import ROS2_PYTHON, ros_env, run_peer  # noqa: F401 (the fixture)

pytestmark = [pytest.mark.ros2, pytest.mark.integration,
              pytest.mark.skipif(not ROS2_PYTHON.exists(),
                                 reason=".venv-ros2 is missing: `python3 ./run.py test` makes it (it needs PyPI)")]

DATA = Path(__file__).parent / "data" / "perception"
VIEWS = json.loads((DATA / "views.json").read_text())["views"]
CAMERA = Path(__file__).with_name("ros2_camera_peer.py")


@contextmanager
def planhrc(env: dict[str, str], log: Path, *args: str) -> Iterator[subprocess.Popen[bytes]]:
    with open(log, "wb") as out:
        proc = subprocess.Popen([str(ROS2_PYTHON), "-m", "planhrc.cli", *args], env=env, stdout=out,
                                stderr=subprocess.STDOUT, start_new_session=True)
        try:
            yield proc
        finally:
            stop_process_group(proc, grace_s=10)


def rad_to_deg(rad: float) -> float:
    return (-math.degrees(rad)) % 360.0


def test_the_node_reads_views_it_never_saw_from_its_own_calibration(ros_env, tmp_path):
    rigs = sorted({v["rig"]["name"] for v in VIEWS})
    seen = visible = 0
    for n, rig in enumerate(rigs):
        views = [v for v in VIEWS if v["rig"]["name"] == rig]
        calibration = tmp_path / f"{rig}.json"
        with planhrc(ros_env, tmp_path / f"{rig}-calibrate.log", "perceive-calibrate", "--board",
                     str(DATA / "board.json"), "--out", str(calibration), "--frames", "3", "--timeout", "60") as proc:
            run_peer(CAMERA, [json.dumps({"mode": "calibrate", "dir": str(DATA), "views": [views[0]["file"]],
                                          "until": str(calibration), "timeout": 90})], ros_env, 120)
            assert proc.wait(timeout=30) == 0, (tmp_path / f"{rig}-calibrate.log").read_text()
        found = Calibration.read(calibration)
        truth = CameraPose.of_data(views[0]["truth"]["pose"])
        assert np.linalg.norm(found.pose.position - truth.position) < 0.01, rig
        assert "perceive-calibrate] camera at" in (tmp_path / f"{rig}-calibrate.log").read_text()
        with planhrc(ros_env, tmp_path / f"{rig}-node.log", "perceive-node", "--calibration", str(calibration),
                     "--object", "obj1=0-4", "--every-image"):
            answers = run_peer(CAMERA, [json.dumps({"mode": "perceive", "dir": str(DATA), "object": "obj1",
                                                    "views": [v["file"] for v in views], "timeout": 120,
                                                    "bad_first": n == 0})], ros_env, 150)
        node_log = (tmp_path / f"{rig}-node.log").read_text(errors="replace")
        assert "Traceback" not in node_log and node_log.strip().endswith("planhrc perceive-node: terminated")
        if n == 0:  # an image the node cannot read is refused, saying which field, and the node goes on
            assert "image.encoding: 'yuv422'" in answers.pop(0)["diagnostics"]["message"]
        assert [a["file"] for a in answers] == [v["file"] for v in views]
        for answer, view in zip(answers, views):
            links = view["truth"]["links"]
            assert answer["names"][:5] == ["l1", "l2", "l3", "l4", "l5"] and answer["frame_id"] == "base"
            for link, value, sighting in zip(links, answer["positions"], answer["detail"]["links"]):
                visible += not link["hidden"]
                assert (value is not None) == sighting["seen"]
                if value is None:
                    continue
                seen += 1
                assert not link["hidden"], f"{view['file']}: hidden l{link['link']} reported seen"
                error = abs((rad_to_deg(value) - link["deg"] + 180.0) % 360.0 - 180.0)
                assert error < 2.0, (view["file"], link, error)
                assert sighting["reprojection_px"] <= 2.5 and sighting["angle_sigma_deg"] <= 1.0
            if answer["positions"][0] is not None:  # l1 seen: the base point comes with it
                base = dict(zip(answer["names"], answer["positions"]))
                assert math.dist((base["base_x"], base["base_y"]), view["truth"]["base_point_xy"]) < 0.01
            else:
                assert "base_x" not in answer["names"]
    assert seen >= 0.6 * visible


def test_a_calibration_without_a_camera_says_so_in_one_line_and_writes_nothing(ros_env, tmp_path):
    done = subprocess.run([str(ROS2_PYTHON), "-m", "planhrc.cli", "perceive-calibrate", "--board",
                           str(DATA / "board.json"), "--out", str(tmp_path / "cal.json"), "--timeout", "2"],
                          env=ros_env, capture_output=True, text=True, timeout=60)
    assert done.returncode == 1 and not (tmp_path / "cal.json").exists()
    assert done.stderr.strip().splitlines()[-1] == \
        "planhrc perceive-calibrate: calibration: no image on /camera/image_raw in 2 s"

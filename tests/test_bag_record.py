"""`planhrc demo --record`: each episode as a rosbag2 bag (MCAP storage, CDR, metadata.yaml), read back with the
MCAP project's own reader and ROS 2 decoder (`mcap`, `mcap-ros2-support`: nothing of planhrc, nor the `rosbags`
library that wrote it), and checked against the episode's summary: the topics and their types, the order of each
step's messages, and that the bag holds every perception, decision, action and outcome the summary holds."""
from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml

REPO = Path(__file__).resolve().parents[1]
LAYOUT = REPO / "docs" / "foxglove-layout.json"
TYPES = {"/camera/image_raw/compressed": "sensor_msgs/msg/CompressedImage",
         "/camera/camera_info": "sensor_msgs/msg/CameraInfo", "/tf": "tf2_msgs/msg/TFMessage",
         "perceived": "sensor_msgs/msg/JointState", "goal": "sensor_msgs/msg/JointState",
         "decision": "std_msgs/msg/String", "markers": "visualization_msgs/msg/MarkerArray",
         "plan": "std_msgs/msg/String", "next_action": "trajectory_msgs/msg/JointTrajectory",
         "feedback": "std_msgs/msg/String", "give_up": "std_msgs/msg/String", "events": "std_msgs/msg/String"}

pytestmark = [pytest.mark.sim, pytest.mark.integration, pytest.mark.slow]


def read_bag(folder: Path) -> list[tuple[str, str, int, object]]:
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    (mcap_file,) = folder.glob("*.mcap")
    with open(mcap_file, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        assert reader.get_header().profile == "ros2"
        out = []
        for schema, channel, message, decoded in reader.iter_decoded_messages(log_time_order=True):
            assert (schema.encoding, channel.message_encoding) == ("ros2msg", "cdr")
            out.append((channel.topic, schema.name, message.log_time, decoded))
    return out


def short(topic: str, object_id: str) -> str:
    return topic.removeprefix(f"/planhrc/objects/{object_id}/")


def stamp(msg: object) -> list[int]:
    return [msg.header.stamp.sec, msg.header.stamp.nanosec]  # type: ignore[attr-defined]


@pytest.fixture(scope="module")
def demo(tmp_path_factory: pytest.TempPathFactory) -> dict:
    out = tmp_path_factory.mktemp("recorded")
    for scenario in ("fig13", "bimanual"):
        done = subprocess.run([sys.executable, "-m", "planhrc.cli", "demo", "--scenario", scenario, "--record",
                               "--out", str(out / scenario)], capture_output=True, text=True, timeout=300)
        assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-3000:]
    return {scenario: json.loads((out / scenario / "summary.json").read_text()) for scenario in ("fig13", "bimanual")}


@pytest.mark.parametrize("scenario", ["fig13", "bimanual"])
def test_the_bag_holds_every_perception_decision_action_and_outcome_of_the_summary(demo, scenario):
    (result,) = demo[scenario]["results"]
    check_episode(result)


def check_episode(result: dict) -> dict[str, int]:
    """The checks of one episode of a demo's summary against its bag; the counts checked."""
    folder = Path(result["out_dir"])
    episode = json.loads((folder / "summary.json").read_text())
    oid = result["object_id"]
    metadata = yaml.safe_load((folder / "bag" / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert metadata["storage_identifier"] == "mcap"
    messages = read_bag(folder / "bag")
    assert metadata["message_count"] == len(messages)
    listed = {t["topic_metadata"]["name"]: (t["topic_metadata"]["type"], t["message_count"])
              for t in metadata["topics_with_message_count"]}
    by_topic: dict[str, list] = {}
    for topic, schema, log_time, msg in messages:
        name = short(topic, oid)
        assert TYPES[name] == schema == listed[topic][0], topic
        assert topic.startswith("/camera/") or topic == "/tf" or topic.startswith(f"/planhrc/objects/{oid}/")
        by_topic.setdefault(name, []).append((log_time, msg))
    assert {short(t, oid): n for t, (_, n) in listed.items()} == {k: len(v) for k, v in by_topic.items()}
    times = [log_time for _, _, log_time, _ in messages]
    assert times == sorted(times)  # one look (image, camera_info, tf, perceived) shares its time

    steps = episode["steps"]
    relooks = sum(1 for s in steps if s["outcome"] in ("failed", "partial") and s["reached_deg"] is not None)
    perceived = [m for _, m in by_topic["perceived"]]
    assert len(perceived) == len(steps) + relooks == len(by_topic["/camera/image_raw/compressed"])
    for step, msg in zip((s for s in steps), perceived):  # no re-look before the last failure: in step order
        if relooks:
            break
        values = [None if math.isnan(p) else (-math.degrees(p)) % 360.0 for p in list(msg.position)[:len(step["perceived_deg"])]]
        for got, want in zip(values, step["perceived_deg"]):
            assert (got is None) == (want is None) and (got is None or abs((got - want + 180) % 360 - 180) < 0.02)
    for _, image in by_topic["/camera/image_raw/compressed"]:
        assert image.format == "jpeg"
        assert cv2.imdecode(np.frombuffer(bytes(image.data), np.uint8), cv2.IMREAD_COLOR).shape == (720, 960, 3)

    # every decision the service recorded (the demo's summary reads them from its event log), in order
    decisions = [json.loads(m.data) for _, m in by_topic["decision"]]
    assert [(d["decision"], d["reason"]) for d in decisions] == [(d["kind"], d["reason"]) for d in result["decisions"]]
    perceived_stamps = [stamp(m) for m in perceived]
    answered = [d for d in decisions if d["perception_stamp"] is not None]
    assert [d["decision"] for d in answered] == [s["decision"] for s in steps if s["reason"] != "no link seen (not posted)"]
    assert all(d["perception_stamp"] in perceived_stamps for d in answered)
    assert len(by_topic["markers"]) == len(decisions)

    # every dispatched action and its outcome, each after the decision that named it and before the next look
    trajectories = [m for _, m in by_topic["next_action"] if m.points]
    assert len(trajectories) == len(result["actions"])
    feedback = [json.loads(m.data) for _, m in by_topic.get("feedback", [])]
    assert [f["outcome"] for f in feedback] == result["outcomes"]
    order = [short(topic, oid) if short(topic, oid) != "next_action" or msg.points else "hold still"
             for topic, _, _, msg in messages
             if short(topic, oid) in ("perceived", "decision", "next_action", "feedback")]
    for i, name in enumerate(order):
        if name == "next_action":
            assert order[i - 1] == "decision" and order[i + 1:i + 2] in (["feedback"], ["perceived"]), order[i - 2:i + 2]
        if name == "feedback":
            assert "next_action" in order[max(0, i - 2):i]
    for trajectory, action in zip(trajectories, result["actions"]):
        turn = trajectory.points[1].positions[1] - trajectory.points[0].positions[1]
        assert list(trajectory.joint_names) == [f"l{action['held_link_index']}", f"l{action['turned_link_index']}"]
        assert turn == pytest.approx(-math.radians(action["delta_deg"]), abs=1e-6)
    events = [json.loads(m.data) for _, m in by_topic["events"]]
    assert [e["step"] for e in events if e["kind"] == "step"] == [s["step"] for s in steps]
    assert events[-1] == {"kind": "stop", "stop_reason": episode["stop_reason"],
                          "reached_goal": episode["reached_goal"], "message": episode["stop_message"]}
    (goal,) = [m for _, m in by_topic["goal"]]
    assert [(-math.degrees(p)) % 360.0 for p in goal.position] == pytest.approx(result["goal_deg"], abs=1e-9)
    return {"messages": len(messages), "perceived": len(perceived), "decisions": len(decisions),
            "actions": len(trajectories), "outcomes": len(feedback)}


def test_the_foxglove_layout_shows_the_bags_topics(demo):
    layout = json.loads(LAYOUT.read_text())
    named = {value.split(".")[0] for panel in layout["configById"].values() for value in _strings(panel)
             if value.startswith("/")}
    (result,) = demo["fig13"]["results"]
    recorded = {topic for topic, *_ in read_bag(Path(result["out_dir"]) / "bag")}
    generic = {t.replace(f"/{result['object_id']}/", "/obj1/") for t in recorded}
    assert named and named <= generic | recorded, named - generic


def _strings(value: object) -> list[str]:
    if isinstance(value, str):
        return [value]
    if isinstance(value, dict):
        return [s for v in value.values() for s in _strings(v)] + [k for k in value if isinstance(k, str)]
    if isinstance(value, list):
        return [s for v in value for s in _strings(v)]
    return []


def test_an_episode_is_drawn_from_its_bag(demo, tmp_path):
    from PIL import Image

    from planhrc.ros2.bag_picture import draw_episode, read_episode

    (result,) = demo["bimanual"]["results"]
    bag = Path(result["out_dir"]) / "bag"
    episode = read_episode(bag)
    assert len(episode["decisions"]) == len(result["decisions"]) and len(episode["actions"]) == len(result["actions"])
    picture = draw_episode(bag, tmp_path / "episode.png")
    assert Image.open(picture).size[0] > 800
    done = subprocess.run([sys.executable, "-m", "planhrc.cli", "bag-picture", str(tmp_path), "--out",
                           str(tmp_path / "x.png")], capture_output=True, text=True, timeout=60)
    assert done.returncode == 1 and done.stderr.strip().endswith("has no metadata.yaml (a rosbag2 folder is expected)")


def test_the_worker_records_its_episode_with_the_fallback_perception(tmp_path):
    from planhrc.client import KBClient

    from .servers import TOKEN, serving

    with serving(tmp_path / "kb.sqlite3", env={"PLANHRC_TOKEN": TOKEN}) as url:
        with KBClient(url, token=TOKEN) as kb:
            oid = kb.create_object("rod", 3, 4, "relative", base_point_xy=(0.7, 0.2325))["id"]
        out = tmp_path / "worker"
        done = subprocess.run([sys.executable, "-m", "planhrc.cli", "worker", "--record", "--kb", url, "--token", TOKEN,
                               "--object", oid, "--initial", "90,90,90", "--base", "0.7,0.2325", "--goal", "90,180,270",
                               "--perception", "fallback", "--out", str(out)], capture_output=True, text=True,
                              timeout=300)
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-3000:]
    steps = json.loads((out / "summary.json").read_text())["steps"]
    by_topic: dict[str, list] = {}
    for topic, _, _, msg in read_bag(out / "bag"):
        by_topic.setdefault(short(topic, oid), []).append(msg)
    assert len(by_topic["perceived"]) == len(steps) == len(by_topic["/camera/image_raw/compressed"])
    assert [json.loads(m.data)["decision"] for m in by_topic["decision"]] == [s["decision"] for s in steps]
    assert len([m for m in by_topic["next_action"] if m.points]) == sum(s["action"] is not None for s in steps)

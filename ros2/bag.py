"""Every episode as a rosbag2 bag (`planhrc demo --record`, `planhrc worker --record`): a folder `bag/` in the
episode's folder, MCAP storage, ROS 2's CDR encoding, with its `metadata.yaml`, written with `rosbags` (pure
Python: no rclpy needed, it runs in `.venv`). A ROS user replays it with `ros2 bag play`, or opens it in Foxglove
(the layout `docs/foxglove-layout.json`) or RViz.

The recorder wraps the worker's link to the service and its perceiver (`planhrc.robot_sim.recording`), so each
message is stamped when it happened. Topics, on the bridge's names (docs/ros2.md) for the object `<id>`:

* `/camera/image_raw/compressed` (sensor_msgs/CompressedImage, JPEG), `/camera/camera_info` (CameraInfo) and
  `/tf` (tf2_msgs/TFMessage: `base` -> `head_camera_optical`) at each look of the head camera;
* `/planhrc/objects/<id>/perceived` (sensor_msgs/JointState, REP 103 radians, NaN = not seen, `base_x`, `base_y`)
  at each look; `/planhrc/objects/<id>/goal` (JointState) once known;
* `/planhrc/objects/<id>/decision` (std_msgs/String, JSON): each answer to a perception (with the perceived
  JointState's stamp as `perception_stamp`) and each give-up's answer (`event_seq`);
* `/planhrc/objects/<id>/markers` (visualization_msgs/MarkerArray) after each decision, `/plan` (String) when a
  plan is followed, `/next_action` (trajectory_msgs/JointTrajectory) for each action dispatched, `/feedback` and
  `/give_up` (String, JSON) as the worker sent them;
* `/planhrc/objects/<id>/events` (String, JSON): each step as the worker's summary records it (human moves, help,
  skills, outcomes), written when the episode ends.
"""
from __future__ import annotations

import json
import logging
import math
import shutil
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from planhrc.client import Decision
from planhrc.robot_sim.episode import WorkerSummary
from planhrc.robot_sim.perception import CameraPerception, Perceiver, Perception
from planhrc.robot_sim.service_link import ServiceLink
from planhrc.vocabulary import ActionOutcome, FailureReason

from . import topics
from .convert import decision_text, goal_orientations, joint_state_fields, turn_target
from .errors import Ros2Error
from .markers import LINE_STRIP, NAMESPACES, object_shapes

log = logging.getLogger(__name__)

BAG_FOLDER = "bag"
IMAGE_TOPIC = "/camera/image_raw/compressed"
CAMERA_INFO_TOPIC = "/camera/camera_info"
TF_TOPIC = "/tf"
CAMERA_FRAME = "head_camera_optical"
EVENTS_SUFFIX = "events"
JPEG_QUALITY = 85
NUMERIC = {"bool": np.bool_, "int8": np.int8, "uint8": np.uint8, "byte": np.uint8, "char": np.uint8,
           "int16": np.int16, "uint16": np.uint16, "int32": np.int32, "uint32": np.uint32, "int64": np.int64,
           "uint64": np.uint64, "float32": np.float32, "float64": np.float64}


def object_topics(object_id: str) -> dict[str, tuple[str, str]]:
    """Name -> (topic, type) of what a bag holds for one object."""
    specs = {spec.suffix: spec for spec in topics.OBJECT_TOPICS}
    out = {suffix: (specs[suffix].name(object_id), specs[suffix].type_name)
           for suffix in ("perceived", "goal", "decision", "markers", "plan", "next_action", "feedback", "give_up")}
    out[EVENTS_SUFFIX] = (f"{topics.NAMESPACE}/{object_id}/{EVENTS_SUFFIX}", "std_msgs/msg/String")
    out["image"] = (IMAGE_TOPIC, "sensor_msgs/msg/CompressedImage")
    out["camera_info"] = (CAMERA_INFO_TOPIC, "sensor_msgs/msg/CameraInfo")
    out["tf"] = (TF_TOPIC, "tf2_msgs/msg/TFMessage")
    return out


class MessageMaker:
    """rosbags' message classes of ROS 2 Kilted, filled by field name; every field not given gets its zero."""

    def __init__(self) -> None:
        from rosbags.typesys import Stores, get_typestore

        self.store = get_typestore(Stores.ROS2_KILTED)

    def make(self, msgtype: str, **given: Any) -> Any:
        _, fields = self.store.fielddefs[msgtype]
        values = {}
        for name, (kind, info) in fields:
            values[name] = self._value(kind, info, given[name]) if name in given else self._zero(kind, info)
        return self.store.types[msgtype](**values)

    def _value(self, kind: int, info: Any, value: Any) -> Any:
        if kind in (3, 4) and info[0][0] == 1 and info[0][1][0] in NUMERIC:  # numbers: a numpy array
            return np.asarray(value, dtype=NUMERIC[info[0][1][0]])
        return value

    def _zero(self, kind: int, info: Any) -> Any:
        if kind == 1:
            return "" if info[0] == "string" else False if info[0] == "bool" else \
                0.0 if info[0].startswith("float") else 0
        if kind == 2:
            return self.make(info)
        (sub_kind, sub_info), size = info
        if sub_kind == 1 and sub_info[0] in NUMERIC:
            return np.zeros(size if kind == 3 else 0, dtype=NUMERIC[sub_info[0]])
        return [self._zero(sub_kind, sub_info) for _ in range(size if kind == 3 else 0)]

    def header(self, t_ns: int, frame_id: str) -> Any:
        return self.make("std_msgs/msg/Header", stamp=self.time(t_ns), frame_id=frame_id)

    def time(self, t_ns: int) -> Any:
        return self.make("builtin_interfaces/msg/Time", sec=t_ns // 1_000_000_000, nanosec=t_ns % 1_000_000_000)

    def string(self, data: Mapping[str, Any]) -> Any:
        return self.make("std_msgs/msg/String", data=json.dumps(data, separators=(",", ":"), default=str))


@dataclass(frozen=True)
class Recorded:
    t_ns: int
    topic: str
    msgtype: str
    msg: Any


def quaternion(r: np.ndarray) -> tuple[float, float, float, float]:
    """(x, y, z, w) of a rotation matrix."""
    w = math.sqrt(max(0.0, 1.0 + r[0, 0] + r[1, 1] + r[2, 2])) / 2.0
    x = math.copysign(math.sqrt(max(0.0, 1.0 + r[0, 0] - r[1, 1] - r[2, 2])) / 2.0, r[2, 1] - r[1, 2])
    y = math.copysign(math.sqrt(max(0.0, 1.0 - r[0, 0] + r[1, 1] - r[2, 2])) / 2.0, r[0, 2] - r[2, 0])
    z = math.copysign(math.sqrt(max(0.0, 1.0 - r[0, 0] - r[1, 1] + r[2, 2])) / 2.0, r[1, 0] - r[0, 1])
    return x, y, z, w


class EpisodeBag:
    """One episode's messages, kept in memory as they happen and written, in time order, when it ends."""

    def __init__(self, folder: Path, obj: Mapping[str, Any], goal_deg: Sequence[float] | None,
                 frame_id: str = "base") -> None:
        self.path = folder / BAG_FOLDER
        self.obj, self.frame_id = obj, frame_id
        self.object_id = str(obj["id"])
        self.n_links = len(obj.get("links") or ())
        self.link_lengths = [float(link["length_m"]) for link in obj.get("links") or ()]
        self.topics = object_topics(self.object_id)
        self.maker = MessageMaker()
        self.messages: list[Recorded] = []
        self.last_ns = 0
        self.goal_deg = tuple(float(v) for v in goal_deg) if goal_deg is not None else None
        self.perceived: tuple[tuple[float | None, ...], tuple[float, float] | None] | None = None
        self.perceived_stamp: tuple[int, int] | None = None
        self.plan_id: str | None = None
        self.closed = False
        if self.goal_deg is not None:
            self.goal(self.goal_deg)

    # -- what the worker hands over --------------------------------------------------------------------------
    def link(self, kb: ServiceLink) -> ServiceLink:
        return RecordingLink(kb, self)

    def perceiver(self, perceiver: Perceiver, camera: CameraPerception) -> Perceiver:
        return RecordingPerceiver(perceiver, camera, self)

    # -- recording -------------------------------------------------------------------------------------------
    def now_ns(self) -> int:
        """Wall-clock nanoseconds, strictly increasing: two messages never share a time, so the order is kept."""
        self.last_ns = max(time.time_ns(), self.last_ns + 1)
        return self.last_ns

    def add(self, name: str, msg: Any, t_ns: int | None = None) -> int:
        topic, msgtype = self.topics[name]
        t = self.now_ns() if t_ns is None else t_ns
        self.messages.append(Recorded(t, topic, msgtype, msg))
        return t

    def look(self, seen: Perception, camera: CameraPerception) -> None:
        import cv2

        t = self.now_ns()
        m = self.maker
        frame = seen.frame if seen.frame is not None else camera.render()
        ok, jpeg = cv2.imencode(".jpg", frame[:, :, ::-1], [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY])
        if ok:
            self.add("image", m.make("sensor_msgs/msg/CompressedImage", header=m.header(t, CAMERA_FRAME),
                                     format="jpeg", data=np.asarray(jpeg).ravel()), t)
        k = camera.intrinsics
        projection = [k.k[0], 0.0, k.k[2], 0.0, 0.0, k.k[4], k.k[5], 0.0, 0.0, 0.0, 1.0, 0.0]
        self.add("camera_info", m.make("sensor_msgs/msg/CameraInfo", header=m.header(t, CAMERA_FRAME),
                                       height=k.height, width=k.width, distortion_model="plumb_bob",
                                       d=[0.0] * 5, k=list(k.k), r=[1.0, 0, 0, 0, 1.0, 0, 0, 0, 1.0], p=projection), t)
        pose = camera.pose
        x, y, z = (float(v) for v in pose.position)
        qx, qy, qz, qw = quaternion(pose.r.T)  # the camera's axes in the cell's frame
        transform = m.make("geometry_msgs/msg/TransformStamped", header=m.header(t, self.frame_id),
                           child_frame_id=CAMERA_FRAME,
                           transform=m.make("geometry_msgs/msg/Transform",
                                            translation=m.make("geometry_msgs/msg/Vector3", x=x, y=y, z=z),
                                            rotation=m.make("geometry_msgs/msg/Quaternion", x=qx, y=qy, z=qz, w=qw)))
        self.add("tf", m.make("tf2_msgs/msg/TFMessage", transforms=[transform]), t)
        names, positions = joint_state_fields(seen.link_orientations_deg, seen.base_point_xy)
        self.add("perceived", m.make("sensor_msgs/msg/JointState", header=m.header(t, self.frame_id), name=names,
                                     position=positions), t)
        self.perceived = (seen.link_orientations_deg, seen.base_point_xy)
        self.perceived_stamp = (t // 1_000_000_000, t % 1_000_000_000)

    def goal(self, link_orientations_deg: Sequence[float]) -> None:
        self.goal_deg = tuple(float(v) for v in link_orientations_deg)
        names, positions = joint_state_fields(self.goal_deg)
        t = self.now_ns()
        self.add("goal", self.maker.make("sensor_msgs/msg/JointState", header=self.maker.header(t, self.frame_id),
                                         name=names, position=positions), t)

    def decision(self, answer: Mapping[str, Any], kb: ServiceLink, event_seq: int | None = None) -> None:
        stamp = self.perceived_stamp if event_seq is None else None
        self.add("decision", self.maker.make("std_msgs/msg/String", data=decision_text(answer, stamp, event_seq)))
        plan_id = answer.get("plan_id")
        if plan_id and plan_id != self.plan_id:
            try:
                self.add("plan", self.maker.string(kb.read_plan(str(plan_id))))
                self.plan_id = str(plan_id)
            except Exception as exc:  # a plan that cannot be read leaves the bag without it, nothing else
                log.warning("bag: plan %s not recorded (%s)", plan_id, exc)
        self._markers(answer.get("next_action"), kb)

    def _markers(self, action: Mapping[str, Any] | None, kb: ServiceLink) -> None:
        if self.perceived is None:
            return
        values, base = self.perceived
        goal = self.goal_deg
        if goal is None and self.obj.get("goal_state_id"):
            try:
                state = kb.read_state(str(self.obj["goal_state_id"]))
                goal = goal_orientations(str(self.obj.get("formulation")), state.get("joint_values_deg") or {},
                                         self.n_links, values[0] if values else None)
            except Exception as exc:
                log.warning("bag: the goal is not drawn (%s)", exc)
        turn = None
        if action and action.get("turned_link_index") is not None:
            turn = (int(action["turned_link_index"]), int(action["held_link_index"]), float(action["delta_deg"]))
        m = self.maker
        t = self.now_ns()
        markers = []
        for shape in object_shapes(self.link_lengths, base, values, goal, turn):
            common = dict(header=m.header(t, self.frame_id), ns=f"{self.object_id}/{shape.namespace}",
                          id=NAMESPACES.index(shape.namespace))
            if not shape.points:
                markers.append(m.make("visualization_msgs/msg/Marker", action=2, **common))
                continue
            r, g, b, a = shape.rgba
            markers.append(m.make(
                "visualization_msgs/msg/Marker", action=0, type=4 if shape.kind == LINE_STRIP else 7,
                pose=m.make("geometry_msgs/msg/Pose", orientation=m.make("geometry_msgs/msg/Quaternion", w=1.0)),
                scale=m.make("geometry_msgs/msg/Vector3", x=shape.scale_m, y=shape.scale_m, z=shape.scale_m),
                color=m.make("std_msgs/msg/ColorRGBA", r=r, g=g, b=b, a=a),
                points=[m.make("geometry_msgs/msg/Point", x=x, y=y, z=z) for x, y, z in shape.points], **common))
        self.add("markers", m.make("visualization_msgs/msg/MarkerArray", markers=markers), t)

    def dispatched(self, action: Mapping[str, Any] | None) -> None:
        m = self.maker
        t = self.now_ns()
        msg = m.make("trajectory_msgs/msg/JointTrajectory", header=m.header(0, self.frame_id))  # empty: hold still
        if action and self.perceived is not None:
            try:
                target = turn_target(action, self.perceived[0])
            except (Ros2Error, KeyError, TypeError, ValueError) as exc:
                log.warning("bag: next_action %s not drawn as a trajectory (%s)", action.get("id"), exc)
            else:
                seconds = int(target.duration_s)
                end = m.make("builtin_interfaces/msg/Duration", sec=seconds,
                             nanosec=int(round((target.duration_s - seconds) * 1e9)))
                msg = m.make("trajectory_msgs/msg/JointTrajectory", header=m.header(0, self.frame_id),
                             joint_names=list(target.joint_names),
                             points=[m.make("trajectory_msgs/msg/JointTrajectoryPoint", positions=list(target.start)),
                                     m.make("trajectory_msgs/msg/JointTrajectoryPoint", positions=list(target.end),
                                            time_from_start=end)])
        self.add("next_action", msg, t)

    def close(self, summary: WorkerSummary | None) -> None:
        """Write the bag: every message in time order, the steps' records last."""
        if self.closed:
            return
        self.closed = True
        for step in summary.steps if summary is not None else ():
            self.add(EVENTS_SUFFIX, self.maker.string({"kind": "step", **step_record(step)}))
        if summary is not None:
            self.add(EVENTS_SUFFIX, self.maker.string({"kind": "stop", "stop_reason": summary.stop_reason,
                                                       "reached_goal": summary.reached_goal,
                                                       "message": summary.stop_message}))
        write_bag(self.path, self.messages, self.maker)


def step_record(step: Any) -> dict[str, Any]:
    """A step of the summary as the events topic carries it (without the timings, which the bag's times give)."""
    record = asdict(step)
    return {key: value for key, value in record.items() if key not in ("perception_s", "service_s", "action_s")}


def write_bag(path: Path, messages: Sequence[Recorded], maker: MessageMaker) -> Path:
    """A rosbag2 folder (MCAP storage, CDR) with the messages in time order (`path` is replaced)."""
    from rosbags.rosbag2 import StoragePlugin, Writer

    if path.exists():
        shutil.rmtree(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        connections: dict[str, Any] = {}
        for record in sorted(messages, key=lambda r: r.t_ns):
            if record.topic not in connections:
                connections[record.topic] = writer.add_connection(record.topic, record.msgtype, typestore=maker.store)
            writer.write(connections[record.topic], record.t_ns,
                         maker.store.serialize_cdr(record.msg, record.msgtype))
    return path


class RecordingPerceiver:
    """The worker's perceiver, each look recorded (the frame, the camera, the perceived state)."""

    def __init__(self, inner: Perceiver, camera: CameraPerception, bag: EpisodeBag) -> None:
        self.inner, self.camera, self.bag = inner, camera, bag

    def perceive(self) -> Perception:
        seen = self.inner.perceive()
        self.bag.look(seen, self.camera)
        return seen

    def look(self) -> Perception:
        seen = self.inner.look()
        self.bag.look(seen, self.camera)
        return seen


class RecordingLink:
    """The worker's link to the service, each call recorded with its answer as it happens."""

    def __init__(self, inner: ServiceLink, bag: EpisodeBag) -> None:
        self.inner, self.bag = inner, bag

    def read_object(self, object_id: str) -> dict[str, Any]:
        return self.inner.read_object(object_id)

    def read_state(self, state_id: str) -> dict[str, Any]:
        return self.inner.read_state(state_id)

    def read_plan(self, plan_id: str) -> dict[str, Any]:
        return self.inner.read_plan(plan_id)

    def set_goal(self, object_id: str, link_orientations_deg: Sequence[float] | None = None,
                 joint_angles_deg: Sequence[float | None] | None = None,
                 allow_infeasible: bool = False) -> dict[str, Any]:
        answer = self.inner.set_goal(object_id, link_orientations_deg, joint_angles_deg, allow_infeasible)
        if link_orientations_deg is not None:
            self.bag.goal(link_orientations_deg)
        return answer

    def post_perception(self, object_id: str, link_orientations_deg: Sequence[float | None],
                        base_point_xy: Sequence[float] | None = None) -> Decision:
        decision = self.inner.post_perception(object_id, link_orientations_deg, base_point_xy)
        self.bag.decision(decision.raw or {"decision": str(decision.decision), "reason": decision.reason}, self.inner)
        return decision

    def next_action(self, object_id: str) -> dict[str, Any] | None:
        action = self.inner.next_action(object_id)
        self.bag.dispatched(action)
        return action

    def post_feedback(self, object_id: str, action_id: str, outcome: ActionOutcome | str, message: str = "",
                      reason: FailureReason | str | None = None, measured_deg: float | None = None,
                      refusal: dict[str, Any] | None = None, hands_open: bool = False) -> dict[str, Any]:
        answer = self.inner.post_feedback(object_id, action_id, outcome, message, reason, measured_deg, refusal,
                                          hands_open)
        self.bag.add("feedback", self.bag.maker.string(
            {"action_id": action_id, "outcome": str(outcome), "message": message,
             "reason": None if reason is None else str(reason), "measured_deg": measured_deg, "refusal": refusal,
             "hands_open": hands_open}))
        return answer

    def give_up(self, object_id: str, reason: str, message: str) -> dict[str, Any]:
        self.bag.add("give_up", self.bag.maker.string({"reason": reason, "message": message}))
        answer = self.inner.give_up(object_id, reason, message)
        if answer.get("decision"):
            self.bag.decision(answer, self.inner, event_seq=int(answer.get("event_seq") or 0))
        return answer


def episode_bag(folder: Path, obj: Mapping[str, Any], goal_deg: Sequence[float] | None) -> EpisodeBag:
    """The `Recording` the robot's commands get for `--record`."""
    return EpisodeBag(folder, obj, goal_deg)

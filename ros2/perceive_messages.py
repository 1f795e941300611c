"""What `planhrc perceive-node` reads and writes, as plain values (no rclpy here: tested in `.venv`): a camera's
Image and CameraInfo fields as an image and its intrinsics, an object's reading as the bridge's perceived
JointState and as the detail JSON, the objects it is configured for, and when it publishes a perception.

When: a camera sends many images a second, and every perception the bridge gets is a request the service
answers (and stores). So by default an object's state is published when it is new to the service: the first
image, the first image after an action's feedback (the action is over: its result is what the robot waits for),
or an image where it changed (a link seen or lost, an orientation by more than `change_deg`, the base point by
more than `change_m`), at most once every `period_s`, and never while an action is under way (from a non-empty
`next_action` until its `feedback`, at most `action_timeout_s`). `every_image` publishes every image.
"""
from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np

from planhrc.robot_sim.camera import Calibration, Intrinsics
from planhrc.robot_sim.errors import SimError
from planhrc.robot_sim.vision import Limits, ObjectMarkers, ObjectReading

from .convert import joint_state_fields, to_ros_rad
from .errors import Ros2Error

ENCODINGS = {"mono8": 1, "rgb8": 3, "bgr8": 3, "rgba8": 4, "bgra8": 4}
DISTORTION_MODELS = ("plumb_bob", "rational_polynomial", "")
OBJECT_SPEC = re.compile(r"^([A-Za-z0-9_]+)=(\d+)(?:-(\d+)|((?:,\d+)*))$")


def grey_from_image(encoding: str, width: int, height: int, step: int, data: Any) -> np.ndarray:
    """A sensor_msgs/Image's pixels as a grey image (H x W, uint8): rgb8, bgr8, mono8 (rgba8, bgra8 too)."""
    import cv2

    channels = ENCODINGS.get(encoding)
    if channels is None:
        raise Ros2Error(f"image.encoding: {encoding!r} is not read; send one of {', '.join(ENCODINGS)}")
    if width < 1 or height < 1:
        raise Ros2Error(f"image: empty ({width} x {height})")
    if step < width * channels:
        raise Ros2Error(f"image.step: {step} bytes is less than a row of {width} {encoding} pixels")
    buffer = np.frombuffer(data, dtype=np.uint8)
    if buffer.size < step * height:
        raise Ros2Error(f"image.data: {buffer.size} bytes, {step * height} expected ({height} rows of {step})")
    rows = buffer[: step * height].reshape(height, step)[:, : width * channels]
    if channels == 1:
        return rows
    pixels = rows.reshape(height, width, channels)
    code = {"rgb8": cv2.COLOR_RGB2GRAY, "bgr8": cv2.COLOR_BGR2GRAY, "rgba8": cv2.COLOR_RGBA2GRAY,
            "bgra8": cv2.COLOR_BGRA2GRAY}[encoding]
    return np.asarray(cv2.cvtColor(pixels, code))


def intrinsics_from_camera_info(width: int, height: int, k: Sequence[float], d: Sequence[float],
                                distortion_model: str) -> Intrinsics:
    """A sensor_msgs/CameraInfo as the camera's intrinsics (its K, D and size)."""
    if distortion_model not in DISTORTION_MODELS:
        raise Ros2Error(f"camera_info.distortion_model: {distortion_model!r} is not read; "
                        f"use {' or '.join(m for m in DISTORTION_MODELS if m)}")
    try:
        return Intrinsics(int(width), int(height), tuple(float(v) for v in k), tuple(float(v) for v in d))
    except SimError as exc:
        raise Ros2Error(str(exc).replace("camera.", "camera_info.", 1)) from None


def parse_object(text: str) -> tuple[str, tuple[int, ...]]:
    """`obj1=0-4` (markers 0..4 on links l1..l5) or `obj1=7,3,5` (l1 carries 7, l2 3, l3 5)."""
    match = OBJECT_SPEC.match(text.strip())
    if match is None:
        raise ValueError(f"expected ID=FIRST-LAST or ID=M1,M2,... (marker ids of l1, l2, ...), got {text!r}")
    object_id, first, last, rest = match.groups()
    if last is not None:
        ids = tuple(range(int(first), int(last) + 1))
    else:
        ids = (int(first),) + tuple(int(v) for v in (rest or "").split(",") if v)
    if not ids or len(set(ids)) != len(ids) or max(ids) > 49:
        raise ValueError(f"marker ids must be distinct and within 0..49 (DICT_4X4_50), got {text!r}")
    return object_id, ids


@dataclass(frozen=True)
class PerceivedState:
    """What the node publishes for one object and one image."""

    names: list[str]
    positions: list[float]
    detail: dict[str, Any]


def perceived_state(reading: ObjectReading, markers: ObjectMarkers, stamp: tuple[int, int], published: bool,
                    why: str, latency_ms: float | None = None) -> PerceivedState:
    """The bridge's perceived JointState (`l1`..`lN` in radians, REP 103, NaN = not seen; `base_x`, `base_y` when
    l1 is seen) and the detail: per link what the camera made of its marker, and how sure it is."""
    names, positions = joint_state_fields(reading.link_orientations_deg, reading.base_point_xy)
    links = []
    for s in reading.sightings:
        m = s.measure
        links.append({"link": s.link, "marker_id": s.marker_id, "seen": s.seen,
                      "orientation_deg": round(m.angle_deg, 3) if s.seen and m else None,
                      "position_rad": round(to_ros_rad(m.angle_deg), 5) if s.seen and m else None,
                      "reprojection_px": round(m.reprojection_px, 3) if m else None,
                      "angle_sigma_deg": round(m.angle_sigma_deg, 3) if m else None,
                      "side_px": round(m.side_px, 1) if m else None, "problem": s.problem})
    detail = {"object_id": markers.object_id, "stamp": list(stamp), "published": published, "why": why,
              "base_point_xy": list(reading.base_point_xy) if reading.base_point_xy else None,
              "unseen": [f"l{k}" for k in reading.missing_links], "links": links,
              "latency_ms": None if latency_ms is None else round(latency_ms, 2)}
    return PerceivedState(names, positions, detail)


def detail_text(detail: dict[str, Any]) -> str:
    return json.dumps(detail, separators=(",", ":"))


@dataclass
class PublishPolicy:
    """When an object's state goes to the bridge (see the module's docstring). Times are seconds on one clock."""

    period_s: float = 1.0
    change_deg: float = 3.0
    change_m: float = 0.01
    action_timeout_s: float = 120.0
    every_image: bool = False
    last: ObjectReading | None = None
    last_at: float = -math.inf
    acting_since: float | None = None
    feedback_since_last: bool = False
    counts: dict[str, int] = field(default_factory=dict)

    def on_next_action(self, now: float, empty: bool) -> None:
        self.acting_since = None if empty else now

    def on_feedback(self) -> None:
        self.acting_since = None
        self.feedback_since_last = True

    def decide(self, now: float, reading: ObjectReading) -> tuple[bool, str]:
        """(publish?, why) for this image's reading."""
        if self.every_image:
            return self._publish(now, reading, "every image")
        if self.acting_since is not None and now - self.acting_since < self.action_timeout_s:
            return False, "held: an action is under way"
        if now - self.last_at < self.period_s:
            return False, "held: period"
        if self.last is None:
            return self._publish(now, reading, "first")
        if self.feedback_since_last:
            return self._publish(now, reading, "after feedback")
        if self._changed(reading):
            return self._publish(now, reading, "changed")
        return False, "held: unchanged"

    def _publish(self, now: float, reading: ObjectReading, why: str) -> tuple[bool, str]:
        self.last, self.last_at, self.feedback_since_last = reading, now, False
        self.counts[why] = self.counts.get(why, 0) + 1
        return True, why

    def _changed(self, reading: ObjectReading) -> bool:
        last = self.last
        if last is None:
            return True
        for a, b in zip(reading.link_orientations_deg, last.link_orientations_deg):
            if (a is None) != (b is None):
                return True
            if a is not None and b is not None and abs((a - b + 180.0) % 360.0 - 180.0) > self.change_deg:
                return True
        if (reading.base_point_xy is None) != (last.base_point_xy is None):
            return True
        return bool(reading.base_point_xy and last.base_point_xy
                    and math.dist(reading.base_point_xy, last.base_point_xy) > self.change_m)


@dataclass(frozen=True)
class PerceiveSettings:
    """What `planhrc perceive-node` runs with."""

    calibration: Calibration
    objects: tuple[ObjectMarkers, ...]
    image_topic: str = "/camera/image_raw"
    camera_info_topic: str = "/camera/camera_info"
    policy: PublishPolicy | None = None  # a template: each object gets its own copy
    limits: Limits = Limits()
    best_effort: bool = False  # subscribe to the camera best effort (a sensor-data publisher)
    node_name: str = "planhrc_perceive"

"""`planhrc perceive-node` and `planhrc perceive-calibrate`: a camera's images to the objects' perceived states, on
the ROS 2 graph (rclpy).

The node subscribes to a camera's `sensor_msgs/Image` and `sensor_msgs/CameraInfo` (the newest image only: a
frame it has no time for is dropped, never queued), finds the links' ArUco markers and reads each configured
object with the same code as the simulated worker's head camera (`planhrc.robot_sim.vision`), the camera's pose
in the cell's frame coming from a calibration file that `perceive-calibrate` wrote from the board's markers on
the table. For each object it publishes the bridge's perceived JointState (`perception_messages`: when it
publishes) and, for every image, the detail as JSON (each link's marker, its reprojection error and how sure the
orientation is, why the state was or was not sent); and its health on /diagnostics once a second.
"""
from __future__ import annotations

import logging
import time
from typing import Any, Callable

import numpy as np
import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions
from sensor_msgs.msg import CameraInfo, Image, JointState
from std_msgs.msg import String
from trajectory_msgs.msg import JointTrajectory

from planhrc.robot_sim.camera import Board, Calibration, Intrinsics, calibrate
from planhrc.robot_sim.vision import MarkerFinder, find_links, read_object

from . import topics
from .channel import qos_of
from .errors import Ros2Error
from .perceive_messages import (PerceiveSettings, PublishPolicy, detail_text, grey_from_image,
                                intrinsics_from_camera_info, perceived_state)

log = logging.getLogger(__name__)

DETAIL_SUFFIX = "perception"  # /planhrc/objects/<id>/perception: the detail of every image, JSON


def camera_qos(best_effort: bool) -> QoSProfile:
    """A camera's images: the newest only. Reliable by default (a camera driver's usual QoS; a best-effort reader
    lost most 1280 x 720 images in fragments on this machine's loopback); best effort to match a camera that
    publishes with the sensor-data profile."""
    reliability = ReliabilityPolicy.BEST_EFFORT if best_effort else ReliabilityPolicy.RELIABLE
    return QoSProfile(depth=1, history=HistoryPolicy.KEEP_LAST, reliability=reliability)


def _stamp(msg: Any) -> tuple[int, int]:
    return int(msg.header.stamp.sec), int(msg.header.stamp.nanosec)


class CameraInput:
    """The newest CameraInfo, and each Image as a grey image checked against it."""

    def __init__(self) -> None:
        self.intrinsics: Intrinsics | None = None
        self.problem = ""

    def on_camera_info(self, msg: CameraInfo) -> None:
        try:
            if msg.binning_x > 1 or msg.binning_y > 1 or msg.roi.width:
                raise Ros2Error("camera_info.binning, roi: a binned or cropped image is not read; send the full one")
            self.intrinsics = intrinsics_from_camera_info(msg.width, msg.height, msg.k, msg.d, msg.distortion_model)
            self.problem = ""
        except Ros2Error as exc:
            self.intrinsics, self.problem = None, str(exc)

    def grey(self, msg: Image) -> tuple[np.ndarray, Intrinsics]:
        if self.intrinsics is None:
            raise Ros2Error(self.problem or "camera_info: none received yet (its K is needed to read an image)")
        camera = self.intrinsics
        if (msg.width, msg.height) != (camera.width, camera.height):
            raise Ros2Error(f"image: {msg.width} x {msg.height}, but camera_info says {camera.width} x {camera.height}")
        return grey_from_image(msg.encoding, msg.width, msg.height, msg.step, msg.data), camera


class PerceiveNode:
    def __init__(self, node: Node, settings: PerceiveSettings) -> None:
        self.node, self.settings = node, settings
        self.camera = CameraInput()
        self.finder = MarkerFinder()
        template = settings.policy or PublishPolicy()
        self.policies = {o.object_id: PublishPolicy(template.period_s, template.change_deg, template.change_m,
                                                    template.action_timeout_s, template.every_image)
                         for o in settings.objects}
        self.counts = {"images": 0, "refused": 0, "published": 0}
        self.last_problem = self.last_refusal = ""
        self.latencies: list[float] = []
        self.perceived = {o.object_id: node.create_publisher(JointState, topics.PERCEIVED.name(o.object_id),
                                                             qos_of(topics.PERCEIVED)) for o in settings.objects}
        self.detail = {o.object_id: node.create_publisher(
            String, f"{topics.NAMESPACE}/{o.object_id}/{DETAIL_SUFFIX}", 10) for o in settings.objects}
        self.diagnostics = node.create_publisher(DiagnosticArray, topics.DIAGNOSTICS_TOPIC, 10)
        qos = camera_qos(settings.best_effort)
        self.subs = [node.create_subscription(Image, settings.image_topic, self.on_image, qos),
                     node.create_subscription(CameraInfo, settings.camera_info_topic, self.camera.on_camera_info, qos)]
        for o in settings.objects:
            policy = self.policies[o.object_id]
            self.subs.append(node.create_subscription(
                JointTrajectory, topics.NEXT_ACTION.name(o.object_id),
                lambda msg, p=policy: p.on_next_action(time.monotonic(), not msg.points), qos_of(topics.NEXT_ACTION)))
            self.subs.append(node.create_subscription(String, topics.FEEDBACK.name(o.object_id),
                                                      lambda msg, p=policy: p.on_feedback(), qos_of(topics.FEEDBACK)))
        self.timer = node.create_timer(1.0, self.publish_health)

    def on_image(self, msg: Image) -> None:
        received = time.perf_counter()
        self.counts["images"] += 1
        try:
            grey, camera = self.camera.grey(msg)
        except Ros2Error as exc:
            self.counts["refused"] += 1
            if str(exc) != self.last_problem:
                log.warning("%s", exc)
            self.last_problem = self.last_refusal = str(exc)
            return
        self.last_problem = ""  # the camera's images are read again: the warning ends (the last refusal is kept)
        stamp = _stamp(msg)
        if stamp == (0, 0):
            now = self.node.get_clock().now().to_msg()
            stamp = (int(now.sec), int(now.nanosec))
        found = find_links(grey, self.finder, self.settings.objects, camera, self.settings.calibration.pose)
        pose, frame_id = self.settings.calibration.pose, self.settings.calibration.frame_id
        for markers in self.settings.objects:
            reading = read_object(found, markers, camera, pose, self.settings.limits)
            publish, why = self.policies[markers.object_id].decide(time.monotonic(), reading)
            latency_ms = (time.perf_counter() - received) * 1000.0
            state = perceived_state(reading, markers, stamp, publish, why, latency_ms)
            if publish:
                out = JointState(name=state.names, position=state.positions)
                out.header.stamp.sec, out.header.stamp.nanosec = stamp
                out.header.frame_id = frame_id
                self.perceived[markers.object_id].publish(out)
                self.counts["published"] += 1
            self.detail[markers.object_id].publish(String(data=detail_text(state.detail)))
        self.latencies = (self.latencies + [(time.perf_counter() - received) * 1000.0])[-100:]

    def publish_health(self) -> None:
        array = DiagnosticArray()
        array.header.stamp = self.node.get_clock().now().to_msg()
        status = DiagnosticStatus(name=f"{self.settings.node_name}: camera", hardware_id=self.settings.image_topic)
        problem = self.last_problem or self.camera.problem
        status.level = DiagnosticStatus.WARN if problem else DiagnosticStatus.OK
        status.message = problem or ("no image yet" if not self.counts["images"] else "reading images")
        p95 = float(np.percentile(self.latencies, 95)) if self.latencies else None
        status.values = [KeyValue(key=k, value=str(v)) for k, v in self.counts.items()]
        status.values.append(KeyValue(key="image_to_state_p95_ms", value="" if p95 is None else f"{p95:.1f}"))
        status.values.append(KeyValue(key="last_refusal", value=self.last_refusal))
        array.status.append(status)
        for object_id, policy in sorted(self.policies.items()):
            s = DiagnosticStatus(name=f"{self.settings.node_name}: {object_id}", hardware_id=object_id)
            s.level = DiagnosticStatus.OK
            s.message = "acting: holding perceptions" if policy.acting_since is not None else "watching"
            s.values = [KeyValue(key=k, value=str(v)) for k, v in sorted(policy.counts.items())]
            array.status.append(s)
        self.diagnostics.publish(array)


def _spin(node_name: str, build: Callable[[Node], Any], until: Callable[[Any], bool] | None = None,
          timeout_s: float | None = None) -> Any:
    """rclpy up, one node spun on this thread until `until(built)` or the timeout (or Ctrl-C, SIGTERM: the command
    line's handlers unwind the stack); everything is closed then."""
    rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
    node = executor = None
    try:
        node = Node(node_name)
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        built = build(node)
        deadline = None if timeout_s is None else time.monotonic() + timeout_s
        while rclpy.ok() and not (until is not None and until(built)):
            if deadline is not None and time.monotonic() > deadline:
                break
            try:
                executor.spin_once(timeout_sec=0.2)
            except Ros2Error:
                raise
            except Exception:  # a fault in one callback: logged, and the node goes on
                log.exception("a callback failed")
        return built
    finally:
        if executor is not None:
            executor.shutdown(timeout_sec=2.0)
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()


def run_perceive_node(settings: PerceiveSettings, on_ready: Callable[[PerceiveNode], None] | None = None) -> None:
    def build(node: Node) -> PerceiveNode:
        perceiver = PerceiveNode(node, settings)
        if on_ready is not None:
            on_ready(perceiver)
        return perceiver

    _spin(settings.node_name, build)


class BoardWatcher:
    """Collects images in which the board's markers are found, for a calibration."""

    def __init__(self, node: Node, board: Board, image_topic: str, camera_info_topic: str, frames: int,
                 best_effort: bool = False) -> None:
        self.board, self.frames = board, frames
        self.camera = CameraInput()
        self.finder = MarkerFinder()
        self.views: list[dict[int, np.ndarray]] = []
        self.images = 0
        self.best_seen: set[int] = set()
        self.problem = ""
        qos = camera_qos(best_effort)
        self.subs = [node.create_subscription(Image, image_topic, self.on_image, qos),
                     node.create_subscription(CameraInfo, camera_info_topic, self.camera.on_camera_info, qos)]

    def on_image(self, msg: Image) -> None:
        self.images += 1
        try:
            grey, _ = self.camera.grey(msg)
        except Ros2Error as exc:
            self.problem = str(exc)
            return
        found = self.finder.find(grey, self.board.ids)
        self.best_seen |= set(found)
        if len(found) >= 2 and len(self.views) < self.frames:
            self.views.append(found)

    def done(self) -> bool:
        return len(self.views) >= self.frames


def run_calibration(board: Board, image_topic: str, camera_info_topic: str, frames: int, timeout_s: float,
                    frame_id: str = "base", best_effort: bool = False) -> Calibration:
    """Watch the camera until `frames` images show the board (or the timeout), then fit the camera's pose."""
    watcher: BoardWatcher = _spin("planhrc_perceive_calibrate",
                                  lambda node: BoardWatcher(node, board, image_topic, camera_info_topic, frames,
                                                            best_effort),
                                  until=lambda w: w.done(), timeout_s=timeout_s)
    if not watcher.views:
        if not watcher.images:
            raise Ros2Error(f"calibration: no image on {image_topic} in {timeout_s:g} s")
        if watcher.problem:
            raise Ros2Error(f"calibration: {watcher.problem}")
        raise Ros2Error(f"calibration: {watcher.images} images, none showing two of the board's markers "
                        f"{sorted(board.ids)} (seen: {sorted(watcher.best_seen) or 'none'})")
    assert watcher.camera.intrinsics is not None
    return calibrate(watcher.views, watcher.camera.intrinsics, board, frame_id=frame_id)

"""The bridge: one rclpy node that serves the objects of a running KB service on the ROS 2 graph (rclpy).

`run_bridge(settings)` starts the node, serves the objects named (or every object, and each one created later:
the service's list is read again every `poll_s` seconds), answers questions to the knowledge service (`knowledge`,
on a thread of its own), publishes its health on /diagnostics once a second, and spins until Ctrl-C or SIGTERM (the command line's handlers unwind the stack; everything is closed then).
Each object has a node of its own; every node is spun by one single-threaded executor on the main thread, so
requests are handled one at a time, in the order they are taken: a re-plan of one object waits for the request
before it, whichever object that was. Callbacks handed to other threads (a multi-threaded executor, or an executor
per object on a thread of its own) made every perception markedly slower on a busy machine (docs/ros2.md).
"""
from __future__ import annotations

import logging
import threading
from dataclasses import dataclass
from typing import Any, Callable

import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions

from planhrc.client import KBClient, ProtocolError, RetryPolicy

from . import topics
from .channel import EventFollower, ObjectChannel, latest_seq
from .errors import Ros2Error
from .knowledge import KnowledgeThread

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class BridgeSettings:
    kb_url: str
    token: str | None = None
    object_ids: tuple[str, ...] = ()  # empty: every object, and those created later
    poll_s: float = 1.0
    frame_id: str = "base"  # the cell's frame: +x the robot's forward axis, +y its left, +z up
    node_name: str = "planhrc_bridge"


class Bridge:
    """The node, its objects and their event followers."""

    def __init__(self, settings: BridgeSettings, node: Node, executor: SingleThreadedExecutor) -> None:
        self.settings, self.node, self.executor = settings, node, executor
        self.kb = KBClient(settings.kb_url, token=settings.token)
        self.probe = KBClient(settings.kb_url, token=settings.token, retry=RetryPolicy(attempts=1), timeout_s=2.0)
        self.channels: dict[str, ObjectChannel] = {}
        self.followers: list[EventFollower] = []
        self.nodes: list[Node] = []
        self.stop = threading.Event()
        self.service_problem = ""
        self.lock = threading.Lock()
        self.diagnostics = node.create_publisher(DiagnosticArray, topics.DIAGNOSTICS_TOPIC, 10)
        # the knowledge service's topics and service, on a node and a thread of their own (`knowledge`)
        self.knowledge = KnowledgeThread(Node(f"{settings.node_name}_knowledge", context=node.context),
                                         settings.kb_url, settings.token, self.stop)
        self.timers = [node.create_timer(1.0, self.publish_health)]
        if not settings.object_ids:
            self.timers.append(node.create_timer(settings.poll_s, self.discover))

    def start(self) -> None:
        """Serve the objects named (each must exist) or every object there is now."""
        if self.settings.object_ids:
            for object_id in self.settings.object_ids:
                try:
                    obj = self.kb.read_object(object_id)
                except ProtocolError as exc:
                    raise Ros2Error(f"--object: {object_id}: {exc}") from None
                self.serve(obj)
        else:
            self.discover()

    def discover(self) -> None:
        try:
            objects = self.probe.list_objects()  # one attempt: a service that is down does not hold up the node
        except ProtocolError as exc:
            log.warning("cannot list the service's objects (%s)", exc)
            return
        for obj in objects:
            if obj["id"] not in self.channels:
                self.serve(obj)

    def serve(self, obj: dict[str, Any]) -> None:
        with self.lock:
            if obj["id"] in self.channels or self.stop.is_set():
                return
            seq, last_decision = latest_seq(self.kb, obj["id"])
            node = Node(f"{self.settings.node_name}_{obj['id']}", context=self.node.context)
            channel = ObjectChannel(node, self.kb, obj, self.settings.frame_id)
            self.nodes.append(node)
            self.channels[obj["id"]] = channel
        self.executor.add_node(node)
        channel.publish_initial(last_decision)
        follower = EventFollower(self.settings.kb_url, self.settings.token, channel, seq, self.stop)
        self.followers.append(follower)
        follower.start()
        log.info("serving %s on %s", obj["id"], topics.PERCEIVED.name(obj["id"]).rsplit("/", 1)[0])

    def publish_health(self) -> None:
        try:
            health = self.probe.health()
            self.service_problem = ""
        except ProtocolError as exc:
            health, self.service_problem = {}, str(exc)
        array = DiagnosticArray()
        array.header.stamp = self.node.get_clock().now().to_msg()
        service = DiagnosticStatus(name=f"{self.settings.node_name}: service", hardware_id=self.settings.kb_url)
        service.level = DiagnosticStatus.ERROR if self.service_problem else DiagnosticStatus.OK
        service.message = self.service_problem or f"service {health.get('version', '')} answers"
        service.values = [KeyValue(key="objects_served", value=str(len(self.channels))),
                          KeyValue(key="objects_stored", value=str(health.get("objects", "")))]
        service.values += [KeyValue(key=f"knowledge_{key}", value=str(n))
                           for key, n in self.knowledge.channel.counts.items()]
        array.status.append(service)
        for object_id, channel in sorted(self.channels.items()):
            status = DiagnosticStatus(name=f"{self.settings.node_name}: {object_id}", hardware_id=object_id)
            status.level = DiagnosticStatus.WARN if channel.last_refusal else DiagnosticStatus.OK
            status.message = channel.last_decision or "no decision yet"
            status.values = [KeyValue(key=key, value=str(channel.counts[key]))
                             for key in ("perceptions", "decisions", "dispatched", "withheld", "feedback", "refused")]
            status.values.append(KeyValue(key="last_refusal", value=channel.last_refusal))
            array.status.append(status)
        self.diagnostics.publish(array)

    def close(self) -> None:
        self.stop.set()
        self.knowledge.close()
        for follower in self.followers:
            follower.join(timeout=0.5)  # daemon threads: one still inside a read ends with the process
        for timer in self.timers:
            self.node.destroy_timer(timer)
        for channel in self.channels.values():
            channel.destroy()
        for node in self.nodes:
            self.executor.remove_node(node)
            node.destroy_node()
        self.kb.close()
        self.probe.close()


def run_bridge(settings: BridgeSettings, on_ready: Callable[[Bridge], None] | None = None) -> None:
    """Serve until interrupted. rclpy's own signal handlers stay off: the command line's unwind the stack."""
    rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
    node = executor = bridge = None
    try:
        node = Node(settings.node_name)
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        bridge = Bridge(settings, node, executor)
        bridge.start()
        if on_ready is not None:
            on_ready(bridge)
        while rclpy.ok():
            try:
                executor.spin_once(timeout_sec=0.2)
            except Exception:  # a fault in one callback: logged, and the bridge goes on serving
                log.exception("a callback failed")
    finally:
        if bridge is not None:
            bridge.close()
        if executor is not None:
            executor.shutdown(timeout_sec=2.0)
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()

"""The worker's link to the service over ROS 2: the calls the worker makes on `KBClient`, made through the
bridge's topics instead of HTTP (rclpy).

Each request is published (again every RESEND_S seconds until answered) and answered by the bridge: a perception
by the decision topic (matched by the JointState's stamp) and the object topic (`answer_to` the same stamp, after
the bridge dispatched the next action); a goal, a feedback or a give-up by the object topic's `answer_to`. A
refusal raises `ProtocolError` with the bridge's reason, as a refused HTTP request does. The link's node has a
context of its own (so it can live in a process that runs other rclpy nodes) and is spun by the calling thread
while it waits for an answer: no thread hands a message over to another on the way (docs/ros2.md).
"""
from __future__ import annotations

import itertools
import json
import math
import time
import uuid
from typing import Any, Callable, Sequence

import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions
from sensor_msgs.msg import JointState
from std_msgs.msg import String

from planhrc.client import Decision, ProtocolError
from planhrc.vocabulary import ActionOutcome, FailureReason

from . import topics
from .channel import qos_of
from .convert import joint_state_fields, stamp_id

_names = itertools.count(1)
# A request not answered within this time is sent again (same id: the bridge answers it again, does not redo it).
# Discovery can match a writer to the bridge's reader before the reader knows the writer; what is sent in between
# is lost, and a busy machine widens that window.
RESEND_S = 1.0


class Ros2Link:
    """`KBClient`'s worker calls for one object, over the bridge's topics. Close it (or use `with`)."""

    def __init__(self, object_id: str, timeout_s: float = 120.0, connect_timeout_s: float = 60.0) -> None:
        self.object_id, self.timeout_s = object_id, timeout_s
        self.context = Context()
        rclpy.init(context=self.context, signal_handler_options=SignalHandlerOptions.NO)
        self.node = Node(f"planhrc_worker_{next(_names)}", context=self.context)
        self.decisions: dict[tuple[int, int], dict[str, Any]] = {}
        self.received_at: dict[tuple[int, int], float] = {}  # perf_counter() when each decision arrived
        self.other_decisions = 0  # decisions other callers caused (with an event_seq), as they arrive
        self.answers: dict[tuple[str, str | None], dict[str, Any]] = {}
        self.plans: dict[str, dict[str, Any]] = {}
        self.latest: dict[str, Any] | None = None
        self.last_perception: tuple[int, int] | None = None
        self.last_stamp = (0, 0)
        self.pub = {spec.suffix: self.node.create_publisher(msg_type, spec.name(object_id), qos_of(spec))
                    for spec, msg_type in ((topics.PERCEIVED, JointState), (topics.GOAL, JointState),
                                           (topics.FEEDBACK, String), (topics.GIVE_UP, String))}
        for spec, handler in ((topics.DECISION, self._on_decision), (topics.OBJECT, self._on_object),
                              (topics.PLAN, self._on_plan)):
            # a deep queue: every answer counts, and two may arrive before this node takes the first
            self.node.create_subscription(String, spec.name(object_id), handler, qos_of(spec, depth=100))
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        try:
            self._wait(lambda: self.latest is not None and all(p.get_subscription_count() > 0
                                                               for p in self.pub.values()),
                       "connect", connect_timeout_s)
        except ProtocolError:
            self.close()
            raise

    # -- what comes in ------------------------------------------------------------------------------------
    def _on_decision(self, msg: String) -> None:
        arrived = time.perf_counter()
        body = json.loads(msg.data)
        stamp = body.get("perception_stamp")
        if stamp:
            self.decisions[(int(stamp[0]), int(stamp[1]))] = body
            self.received_at[(int(stamp[0]), int(stamp[1]))] = arrived
        elif body.get("event_seq") is not None:
            self.other_decisions += 1

    def _on_object(self, msg: String) -> None:
        body = json.loads(msg.data)
        self.latest = body
        answer = body.get("answer_to")
        if answer:
            self.answers[(answer["topic"], answer.get("request_id"))] = body

    def _on_plan(self, msg: String) -> None:
        plan = json.loads(msg.data)
        self.plans[plan["id"]] = plan

    def _spin_until(self, ready: Callable[[], bool], timeout_s: float) -> bool:
        """Take what arrives until `ready()` or `timeout_s` passes."""
        deadline = time.monotonic() + timeout_s
        while not ready():
            left = deadline - time.monotonic()
            if left <= 0:
                return False
            self.executor.spin_once(timeout_sec=min(left, 0.1))
        return True

    def _wait(self, ready: Callable[[], bool], what: str, timeout_s: float | None = None) -> None:
        if not self._spin_until(ready, timeout_s or self.timeout_s):
            raise ProtocolError(f"{what}: no answer on {topics.NAMESPACE}/{self.object_id}/ within "
                                f"{timeout_s or self.timeout_s:g} s (is `planhrc ros2-bridge` serving it?)")

    def _send(self, publisher: Any, msg: Any, ready: Callable[[], bool], what: str) -> None:
        """Publish `msg` until `ready()` (an answer came), sending it again every RESEND_S seconds."""
        deadline = time.monotonic() + self.timeout_s
        while True:
            publisher.publish(msg)
            if self._spin_until(ready, max(0.0, min(RESEND_S, deadline - time.monotonic()))):
                return
            if time.monotonic() >= deadline:
                raise ProtocolError(f"{what}: no answer on {topics.NAMESPACE}/{self.object_id}/ within "
                                    f"{self.timeout_s:g} s (is `planhrc ros2-bridge` serving it?)")

    def _answer(self, topic: str, request_id: str) -> dict[str, Any]:
        key = (topic, request_id)
        self._wait(lambda: key in self.answers, topic)
        body = self.answers.pop(key)
        if not body["answer_to"]["ok"]:
            raise ProtocolError(f"{topic}: refused by the bridge: {body['answer_to']['detail']}")
        return body

    def _stamp(self) -> tuple[int, int]:
        """A header stamp later than the previous one: it is the request's id."""
        now = self.node.get_clock().now().seconds_nanoseconds()
        stamp = max((int(now[0]), int(now[1])), (self.last_stamp[0], self.last_stamp[1] + 1))
        self.last_stamp = stamp
        return stamp

    def _joint_state(self, values: Sequence[float | None], base: Sequence[float] | None) -> JointState:
        msg = JointState()
        msg.header.stamp.sec, msg.header.stamp.nanosec = self._stamp()
        msg.name, msg.position = joint_state_fields(values, base)
        return msg

    # -- the worker's calls ---------------------------------------------------------------------------------
    def read_object(self, object_id: str) -> dict[str, Any]:
        self._check(object_id)
        assert self.latest is not None  # connected
        return dict(self.latest["object"])

    def read_state(self, state_id: str) -> dict[str, Any]:
        goal = (self.latest or {}).get("goal_state")
        if goal is None or goal.get("id") != state_id:
            raise ProtocolError(f"state: {state_id} is not the goal the bridge published")
        return dict(goal)

    def read_plan(self, plan_id: str) -> dict[str, Any]:
        self._wait(lambda: plan_id in self.plans, f"plan {plan_id}", min(self.timeout_s, 10.0))
        return self.plans[plan_id]

    def set_goal(self, object_id: str, link_orientations_deg: Sequence[float] | None = None,
                 joint_angles_deg: Sequence[float | None] | None = None,
                 allow_infeasible: bool = False) -> dict[str, Any]:
        self._check(object_id)
        if link_orientations_deg is None or joint_angles_deg is not None or allow_infeasible:
            raise ProtocolError("goal: over ROS 2 a goal is every link's orientation (link_orientations_deg)")
        msg = self._joint_state(link_orientations_deg, None)
        key = ("goal", stamp_id(msg.header.stamp.sec, msg.header.stamp.nanosec))
        self._send(self.pub["goal"], msg, lambda: key in self.answers, "goal")
        body = self._answer(*key)
        return {"goal_state_id": body["object"]["goal_state_id"]}

    def post_perception(self, object_id: str, link_orientations_deg: Sequence[float | None],
                        base_point_xy: Sequence[float] | None = None) -> Decision:
        self._check(object_id)
        msg = self._joint_state(link_orientations_deg, base_point_xy)
        stamp = (msg.header.stamp.sec, msg.header.stamp.nanosec)
        key = ("perceived", stamp_id(*stamp))
        self._send(self.pub["perceived"], msg, lambda: stamp in self.decisions or key in self.answers, "perceived")
        if stamp not in self.decisions:  # refused before it reached the service
            self._answer(*key)
        self._wait(lambda: key in self.answers, "perceived")  # the bridge has dispatched the next action, if any
        self.last_perception = stamp
        return Decision.from_json(self.decisions[stamp])

    def next_action(self, object_id: str) -> dict[str, Any] | None:
        """The action the bridge dispatched after the last perception, or None (none, or withheld)."""
        self._check(object_id)
        if self.last_perception is None:
            return None
        key = ("perceived", stamp_id(*self.last_perception))
        action = self.decisions[self.last_perception].get("next_action")
        body = self.answers.get(key)
        execution = (body or {}).get("object", {}).get("execution") or {}
        if action is None or execution.get("dispatched_action_id") != action.get("id"):
            return None
        return dict(action)

    def post_feedback(self, object_id: str, action_id: str, outcome: ActionOutcome | str, message: str = "",
                      reason: FailureReason | str | None = None, measured_deg: float | None = None,
                      refusal: dict[str, Any] | None = None, hands_open: bool = False) -> dict[str, Any]:
        self._check(object_id)
        request_id = str(uuid.uuid4())
        body: dict[str, Any] = {"action_id": action_id, "outcome": str(outcome), "message": message,
                                "request_id": request_id}
        if reason is not None:
            body["reason"] = str(reason)
        if measured_deg is not None and math.isfinite(measured_deg):
            body["measured_deg"] = float(measured_deg)
        if hands_open:
            body["hands_open"] = True
        # `refusal` does not cross the bridge (its feedback message has no such field): the service remembers a
        # refused turn from the latest perception instead
        key = ("feedback", request_id)
        self._send(self.pub["feedback"], String(data=json.dumps(body)), lambda: key in self.answers, "feedback")
        execution: dict[str, Any] = self._answer(*key)["object"]["execution"]
        return execution

    def give_up(self, object_id: str, reason: str, message: str) -> dict[str, Any]:
        self._check(object_id)
        request_id = str(uuid.uuid4())
        msg = String(data=json.dumps({"reason": reason, "message": message, "request_id": request_id}))
        key = ("give_up", request_id)
        self._send(self.pub["give_up"], msg, lambda: key in self.answers, "give_up")
        answer: dict[str, Any] = self._answer(*key)["object"]
        return answer

    def _check(self, object_id: str) -> None:
        if object_id != self.object_id:
            raise ProtocolError(f"object_id: this link serves {self.object_id}, not {object_id}")

    def close(self) -> None:
        self.executor.shutdown(timeout_sec=1.0)
        self.node.destroy_node()
        self.context.try_shutdown()

    def __enter__(self) -> "Ros2Link":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

"""One object on the ROS 2 graph: its topics, and what the bridge does with each message (rclpy).

Requests from ROS 2 (perceived, goal, feedback, give_up) go to the service through `KBClient`; the answers go
out at once: the decision, then (when it names a next action) the dispatched action as a JointTrajectory, then
the plan, the help request, the markers and the object. Decisions other callers caused arrive from the service's
event stream (`EventFollower`, one thread per object) and go out on the decision topic as well; the bridge's own
ones are skipped there, since they went out already. One lock per object keeps an answer and its event in order.

A request the bridge cannot make (bad message, refused by the service) changes nothing; the object topic's
`answer_to` says which request it was and why, and the bridge logs it and counts it in its diagnostics.
"""
from __future__ import annotations

import json
import logging
import threading
from collections import Counter, OrderedDict
from typing import Any, Callable

from builtin_interfaces.msg import Duration
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_msgs.msg import String
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint
from visualization_msgs.msg import Marker, MarkerArray

from planhrc.client import KBClient, ProtocolError
from planhrc.event_log import DecisionData
from planhrc.vocabulary import DecisionKind

from . import topics
from .convert import (DECISION_KINDS, JointReading, decision_from_event, decision_key, decision_of, decision_text,
                      goal_orientations, read_feedback, read_give_up, read_joint_state, stamp_id, turn_target)
from .errors import Ros2Error
from .markers import LINE_STRIP, NAMESPACES, object_shapes

log = logging.getLogger(__name__)

# events after which the object's execution or goal changed: the object topic is published again
OBJECT_EVENTS = frozenset({"goal_set", "dispatched", "feedback", "worker_gave_up"})
# How many handled requests (with an id) are remembered: a request sent again is answered again, not redone.
REMEMBERED_REQUESTS = 64


def qos_of(spec: topics.TopicSpec, depth: int | None = None) -> QoSProfile:
    """The topic's QoS; a subscriber may keep a deeper queue (`depth`) than the topic's publishers."""
    durability = (DurabilityPolicy.TRANSIENT_LOCAL if spec.durability is topics.Durability.TRANSIENT_LOCAL
                  else DurabilityPolicy.VOLATILE)
    return QoSProfile(depth=depth or spec.depth, history=HistoryPolicy.KEEP_LAST,
                      reliability=ReliabilityPolicy.RELIABLE, durability=durability)


class ObjectChannel:
    """The topics of one object and the bridge's handling of them, on a node of the object's own: its callbacks run
    one at a time on that node's executor thread; the event stream's thread takes the same lock."""

    def __init__(self, node: Node, kb: KBClient, obj: dict[str, Any], frame_id: str) -> None:
        self.node, self.kb, self.frame_id = node, kb, frame_id
        self.object_id: str = obj["id"]
        self.obj = obj
        self.n_links = len(obj["links"])
        self.lock = threading.Lock()
        self.answered: Counter[tuple[str, str | None, str]] = Counter()
        self.dispatched_action_id: str | None = None
        self.shown_plan_id: str | None = None
        self.help_shown = False
        self.goal_state: dict[str, Any] | None = None
        self.counts: Counter[str] = Counter()
        self.last_refusal = ""
        self.last_decision = ""
        # (topic, request id) -> the decision text it got (perceptions) or None: what a request sent again gets
        self.handled: OrderedDict[tuple[str, str], str | None] = OrderedDict()
        self.last_answer: dict[tuple[str, str], str] = {}
        self.plan: dict[str, Any] | None = None  # the last plan read (plans never change once stored)
        self.pub: dict[str, Any] = {
            spec.suffix: node.create_publisher(msg_type, spec.name(self.object_id), qos_of(spec))
            for spec, msg_type in ((topics.DECISION, String), (topics.NEXT_ACTION, JointTrajectory),
                                   (topics.MARKERS, MarkerArray), (topics.HELP, String), (topics.PLAN, String),
                                   (topics.OBJECT, String))}
        handlers: tuple[tuple[topics.TopicSpec, type, Callable[[Any], None]], ...] = (
            (topics.PERCEIVED, JointState, self.on_perceived), (topics.GOAL, JointState, self.on_goal),
            (topics.FEEDBACK, String, self.on_feedback), (topics.GIVE_UP, String, self.on_give_up))
        self.subs = [node.create_subscription(msg_type, spec.name(self.object_id), handler, qos_of(spec))
                     for spec, msg_type, handler in handlers]

    # -- requests from ROS 2 ------------------------------------------------------------------------------
    def on_perceived(self, msg: JointState) -> None:
        stamp = (msg.header.stamp.sec, msg.header.stamp.nanosec)
        request = ("perceived", stamp_id(*stamp))
        with self.lock:
            if self._answered_again(request):
                return
            try:
                reading = read_joint_state("perceived", msg.name, msg.position, self.n_links)
                decision = self.kb.post_perception(self.object_id, reading.link_orientations_deg,
                                                   reading.base_point_xy)
            except (Ros2Error, ProtocolError) as exc:
                self._refuse(request, exc)
                return
            answer = decision.raw
            text = decision_text(answer, stamp)
            self.pub["decision"].publish(String(data=text))
            self._remember(request, text)
            self.answered[decision_key(answer["decision"], answer.get("perceived_state_id"), answer["reason"])] += 1
            self.counts["perceptions"] += 1
            detail = ""
            if answer.get("next_action") is not None:
                detail = self._dispatch(reading)
            self._after_decision(answer, reading, request, detail)

    def on_goal(self, msg: JointState) -> None:
        request = ("goal", stamp_id(msg.header.stamp.sec, msg.header.stamp.nanosec))
        with self.lock:
            if self._answered_again(request):
                return
            try:
                reading = read_joint_state("goal", msg.name, msg.position, self.n_links, complete=True)
                goal = [v for v in reading.link_orientations_deg if v is not None]  # complete: every link
                self.kb.set_goal(self.object_id, link_orientations_deg=goal)
            except (Ros2Error, ProtocolError) as exc:
                self._refuse(request, exc)
                return
            self.counts["goals"] += 1
            self._publish_object(request)

    def on_feedback(self, msg: String) -> None:
        with self.lock:
            try:
                feedback = read_feedback(msg.data)
            except Ros2Error as exc:
                self._refuse(("feedback", None), exc)
                return
            action_id = feedback.action_id or self.dispatched_action_id
            request = ("feedback", feedback.request_id or action_id)
            if feedback.request_id and self._answered_again(request):
                return
            try:
                if action_id is None:
                    raise Ros2Error("feedback.action_id: no action was dispatched here; name the action")
                self.kb.post_feedback(self.object_id, action_id, feedback.outcome, feedback.message,
                                      reason=feedback.reason, measured_deg=feedback.measured_deg,
                                      hands_open=feedback.hands_open)
            except (Ros2Error, ProtocolError) as exc:
                self._refuse(request, exc)
                return
            self.counts["feedback"] += 1
            self._publish_object(request)

    def on_give_up(self, msg: String) -> None:
        with self.lock:
            try:
                give_up = read_give_up(msg.data)
                request = ("give_up", give_up.request_id)
                if give_up.request_id and self._answered_again(request):
                    return
                self.kb.give_up(self.object_id, give_up.reason, give_up.message)
            except Ros2Error as exc:
                self._refuse(("give_up", None), exc)
                return
            except ProtocolError as exc:
                self._refuse(request, exc)
                return
            self._publish_object(request)

    # -- events from the service ----------------------------------------------------------------------------
    def on_event(self, event: dict[str, Any]) -> None:
        """An event of the service's log: a decision nobody here has published yet goes out."""
        kind = str(event.get("kind"))
        with self.lock:
            if kind in DECISION_KINDS:
                try:
                    record = decision_of(event)
                except Ros2Error as exc:  # not a decision this bridge can read: the others still go out
                    log.warning("%s: %s", self.object_id, exc)
                    return
                perceived = record.perceived_state_id if isinstance(record, DecisionData) else None
                key = decision_key(kind, perceived, str(event.get("reason", "")))
                if self.answered[key] > 0:  # the bridge's own answer, published already
                    self.answered[key] -= 1
                    return
                self.publish_event_decision(event)
            elif kind in OBJECT_EVENTS:
                self._publish_object(None)

    def publish_initial(self, last_decision: dict[str, Any] | None) -> None:
        """The latched topics start from the object's current state: its latest decision, or the object alone."""
        with self.lock:
            if last_decision is not None:
                self.publish_event_decision(last_decision)
            else:
                self._publish_object(None)

    def publish_event_decision(self, event: dict[str, Any]) -> None:
        """Publish a decision from the log (another caller's, or the latest at start-up). Holds the lock."""
        try:
            record = decision_of(event)
            decided = record if isinstance(record, DecisionData) else DecisionData()
            step = self._plan_step(decided.plan_id, decided.next_action_id)
            answer = decision_from_event(event, step)
            self.pub["decision"].publish(String(data=decision_text(answer, None, int(event["seq"]))))
            perceived = None
            if answer.get("perceived_state_id"):
                state = self.kb.read_state(answer["perceived_state_id"])
                values = state.get("link_orientations_deg")
                perceived = JointReading(tuple(values)) if values and len(values) == self.n_links else None
            self._after_decision(answer, perceived, None, "")
        except (ProtocolError, Ros2Error) as exc:
            log.warning("%s: decision %s not published in full (%s)", self.object_id, event.get("seq"), exc)

    # -- what follows a decision ----------------------------------------------------------------------------
    def _dispatch(self, reading: JointReading) -> str:
        """Take the next action (the service marks it dispatched) and publish it; an empty trajectory when the
        service withheld it. Returns why nothing was dispatched, or ''."""
        try:
            action = self.kb.next_action(self.object_id)
        except ProtocolError as exc:
            action, why = None, f"next_action: {exc}"
        else:
            why = "" if action is not None else "next_action: the service withheld the action (see its events)"
        trajectory = JointTrajectory()
        trajectory.header.frame_id = self.frame_id  # stamp 0: start on receipt
        if action is not None:
            self.dispatched_action_id = action["id"]
            try:
                target = turn_target(action, reading.link_orientations_deg)
            except Ros2Error as exc:
                why = str(exc)
            else:
                trajectory.joint_names = list(target.joint_names)
                seconds = int(target.duration_s)
                trajectory.points = [
                    JointTrajectoryPoint(positions=list(target.start), time_from_start=Duration(sec=0, nanosec=0)),
                    JointTrajectoryPoint(positions=list(target.end), time_from_start=Duration(
                        sec=seconds, nanosec=int((target.duration_s - seconds) * 1e9)))]
        self.pub["next_action"].publish(trajectory)
        self.counts["dispatched" if trajectory.points else "withheld"] += 1
        return why

    def _after_decision(self, answer: dict[str, Any], reading: JointReading | None,
                        request: tuple[str, str | None] | None, detail: str) -> None:
        self.last_decision = f"{answer['decision']}: {answer['reason']}"
        self.counts["decisions"] += 1
        plan_id = answer.get("plan_id")
        if plan_id and plan_id != self.shown_plan_id:
            try:
                self.pub["plan"].publish(String(data=json.dumps(self._read_plan(plan_id), separators=(",", ":"))))
                self.shown_plan_id = plan_id
            except ProtocolError as exc:  # the next decision tries again; the answers below still go out
                log.warning("%s: plan %s not published (%s)", self.object_id, plan_id, exc)
        if answer["decision"] == DecisionKind.HUMAN_HELP_REQUESTED or self.help_shown:
            self.help_shown = answer["decision"] == DecisionKind.HUMAN_HELP_REQUESTED
            help_body = {"help": (answer.get("help") or []) if self.help_shown else [], "reason": answer["reason"]}
            self.pub["help"].publish(String(data=json.dumps(help_body, separators=(",", ":"))))
        self._publish_object(request, ok=not detail, detail=detail)
        action = answer.get("next_action")
        turn = None if action is None else (int(action["turned_link_index"]), int(action["held_link_index"]),
                                            float(action.get("delta_deg", 0)))
        self._publish_markers(reading, turn)

    def _publish_object(self, request: tuple[str, str | None] | None, ok: bool = True, detail: str = "") -> None:
        """The object as it is now, with the goal's state and which request this answers."""
        try:
            self.obj = self.kb.read_object(self.object_id)
            goal_id = self.obj.get("goal_state_id")
            if goal_id and (self.goal_state is None or self.goal_state.get("id") != goal_id):
                self.goal_state = self.kb.read_state(goal_id)
        except ProtocolError as exc:  # the answer still goes out, with the object as last read
            detail = detail or f"object not read again: {exc}"
        answer_to = None if request is None else {"topic": request[0], "request_id": request[1], "ok": ok,
                                                  "detail": detail}
        body = {"object": self.obj, "goal_state": self.goal_state if self.obj.get("goal_state_id") else None,
                "answer_to": answer_to}
        text = json.dumps(body, separators=(",", ":"))
        self.pub["object"].publish(String(data=text))
        if request is not None and request[1]:
            self.handled.setdefault((request[0], request[1]), None)
            self.last_answer[(request[0], request[1])] = text
            while len(self.handled) > REMEMBERED_REQUESTS:
                self.last_answer.pop(self.handled.popitem(last=False)[0], None)

    def _remember(self, request: tuple[str, str], decision: str) -> None:
        self.handled[request] = decision

    def _answered_again(self, request: tuple[str, str | None]) -> bool:
        """A request the bridge handled already (sent again after a lost answer, or twice): its answers go out
        again and nothing is redone. A request without an id (stamp 0) is always new."""
        if not request[1] or request[1] == stamp_id(0, 0) or (request[0], request[1]) not in self.last_answer:
            return False
        key = (request[0], request[1])
        decision = self.handled.get(key)
        if decision is not None:
            self.pub["decision"].publish(String(data=decision))
        self.pub["object"].publish(String(data=self.last_answer[key]))
        return True

    def _publish_markers(self, reading: JointReading | None, turn: tuple[int, int, float] | None) -> None:
        perceived = None if reading is None else reading.link_orientations_deg
        base = (reading.base_point_xy if reading is not None and reading.base_point_xy is not None
                else self.obj.get("base_point_xy"))
        goal = None
        if self.goal_state is not None and self.obj.get("goal_state_id"):
            first = perceived[0] if perceived else None
            goal = goal_orientations(str(self.obj["formulation"]), self.goal_state.get("joint_values_deg") or {},
                                     self.n_links, first)
        shapes = object_shapes([link["length_m"] for link in self.obj["links"]], base, perceived, goal, turn)
        markers = MarkerArray()
        now = self.node.get_clock().now().to_msg()
        for shape in shapes:
            marker = Marker()
            marker.header.frame_id, marker.header.stamp = self.frame_id, now
            marker.ns, marker.id = f"{self.object_id}/{shape.namespace}", NAMESPACES.index(shape.namespace)
            if not shape.points:
                marker.action = Marker.DELETE
            else:
                marker.action = Marker.ADD
                marker.type = Marker.LINE_STRIP if shape.kind == LINE_STRIP else Marker.SPHERE_LIST
                marker.pose.orientation.w = 1.0
                marker.scale.x = marker.scale.y = marker.scale.z = shape.scale_m
                marker.color.r, marker.color.g, marker.color.b, marker.color.a = shape.rgba
                for x, y, z in shape.points:
                    point = type(marker.pose.position)()
                    point.x, point.y, point.z = x, y, z
                    marker.points.append(point)
            markers.markers.append(marker)
        self.pub["markers"].publish(markers)

    def _plan_step(self, plan_id: str | None, action_id: str | None) -> dict[str, Any] | None:
        if not plan_id or not action_id:
            return None
        return next((s for s in self._read_plan(plan_id).get("steps", []) if s.get("id") == action_id), None)

    def _read_plan(self, plan_id: str) -> dict[str, Any]:
        if self.plan is None or self.plan.get("id") != plan_id:
            self.plan = self.kb.read_plan(plan_id)
        return self.plan

    def _refuse(self, request: tuple[str, str | None], exc: Exception) -> None:
        """A request that changed nothing: say so on the object topic, in the log and in the diagnostics."""
        self.counts["refused"] += 1
        self.last_refusal = f"{request[0]}: {exc}"
        log.warning("%s: refused %s", self.object_id, self.last_refusal)
        self._publish_object(request, ok=False, detail=str(exc))

    def destroy(self) -> None:
        for sub in self.subs:
            self.node.destroy_subscription(sub)
        for pub in self.pub.values():
            self.node.destroy_publisher(pub)


class EventFollower(threading.Thread):
    """Follows one object's event stream and hands each event to its channel; reconnects after a dropped
    connection from the last event it saw."""

    def __init__(self, kb_url: str, token: str | None, channel: ObjectChannel, after_seq: int,
                 stop: threading.Event, window_s: float = 5.0) -> None:
        super().__init__(name=f"events-{channel.object_id}", daemon=True)
        self.kb = KBClient(kb_url, token=token)
        self.channel, self.after_seq, self.stop, self.window_s = channel, after_seq, stop, window_s

    def run(self) -> None:
        try:
            while not self.stop.is_set():
                try:
                    for event in self.kb.stream_events(self.channel.object_id, self.after_seq, self.window_s):
                        if self.stop.is_set():
                            return
                        self.channel.on_event(event)
                        self.after_seq = max(self.after_seq, int(event["seq"]))
                except ProtocolError as exc:
                    log.warning("%s: event stream interrupted (%s); reconnecting", self.channel.object_id, exc)
                    self.stop.wait(1.0)
        finally:
            self.kb.close()


def latest_seq(kb: KBClient, object_id: str) -> tuple[int, dict[str, Any] | None]:
    """The seq of the object's last event and its latest decision event (read page by page)."""
    seq, decision = 0, None
    while True:
        page = kb.read_events(object_id, after_seq=seq)
        if not page:
            return seq, decision
        for event in page:
            if event["kind"] in DECISION_KINDS:
                decision = event
        seq = int(page[-1]["seq"])

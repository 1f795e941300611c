"""Pure conversions between ROS 2 messages' fields and the service's bodies (no rclpy here: tested in `.venv`).

Angles: ROS 2 follows REP 103 (radians, counter-clockwise about +z, seen from above, from the robot's forward
axis +x); the service uses degrees in [0, 360) clockwise seen from above from the same axis (CONVENTIONS.md).
Both share the cell's frame (+x forward, +y left, +z up), so a base point's x, y pass unchanged.

A link's name on ROS 2 is `lK` (K = 1..N); `l0` names the table, what an absolute plan's first link is held
against. A measured base point travels in the same JointState as the prismatic pseudo-joints `base_x`, `base_y`.
"""
from __future__ import annotations

import json
import math
import re
from dataclasses import asdict, dataclass
from typing import Any, Mapping, Sequence

from planhrc.event_log import DecisionData, IncompleteData, data_of
from planhrc.json_record import RecordError
from planhrc.model import absolute_from_relative
from planhrc.vocabulary import ActionOutcome, DecisionKind, FailureReason, one_of

from .errors import Ros2Error

LINK_NAME = re.compile(r"^l([1-9][0-9]*)$")
BASE_NAMES = ("base_x", "base_y")
JOINT_INDEX = re.compile(r"_j([0-9]+)$")
# A nominal pace for the target point's time_from_start: a hint for a controller, which may rescale it.
TURN_RATE_DEG_S = 30.0
DECISION_KINDS = frozenset(str(kind) for kind in DecisionKind)


def to_service_deg(rad: float) -> float:
    """REP 103 radians (counter-clockwise) -> the service's degrees clockwise in [0, 360)."""
    return (-math.degrees(rad)) % 360.0


def to_ros_rad(deg: float) -> float:
    """The service's degrees clockwise -> REP 103 radians counter-clockwise in [-pi, pi]."""
    return math.remainder(-math.radians(deg), 2 * math.pi)


def stamp_id(sec: int, nanosec: int) -> str:
    """A header stamp as the request id the bridge answers with."""
    return f"{sec}.{nanosec:09d}"


@dataclass(frozen=True)
class JointReading:
    """A JointState read as the service's perception (or goal): None = a link not seen."""

    link_orientations_deg: tuple[float | None, ...]
    base_point_xy: tuple[float, float] | None = None


def read_joint_state(topic: str, names: Sequence[str], positions: Sequence[float], n_links: int,
                     complete: bool = False) -> JointReading:
    """Check a JointState's names and positions against an object of `n_links` links. A link that is missing or
    NaN is not seen (refused when `complete`, as for a goal); at least one link must be seen."""
    if len(names) != len(positions):
        raise Ros2Error(f"{topic}.position: {len(positions)} values for {len(names)} names")
    values: dict[int, float | None] = {}
    base: dict[str, float] = {}
    for name, position in zip(names, positions):
        value = float(position)
        if name in BASE_NAMES:
            if not math.isfinite(value):
                raise Ros2Error(f"{topic}.position[{name}]: must be a finite number of metres, got {value}")
            base[name] = value
            continue
        match = LINK_NAME.match(name)
        if match is None:
            raise Ros2Error(f"{topic}.name: {name!r} is not a link (l1..l{n_links}) nor one of {', '.join(BASE_NAMES)}")
        k = int(match.group(1))
        if k > n_links:
            raise Ros2Error(f"{topic}.name: {name!r} is past the object's last link l{n_links}")
        if k in values:
            raise Ros2Error(f"{topic}.name: {name!r} is given twice")
        if math.isinf(value):
            raise Ros2Error(f"{topic}.position[{name}]: must be finite (NaN = not seen), got {value}")
        values[k] = None if math.isnan(value) else to_service_deg(value)
    if len(base) == 1:
        raise Ros2Error(f"{topic}.name: give both {' and '.join(BASE_NAMES)} or neither")
    orientations = tuple(values.get(k) for k in range(1, n_links + 1))
    unseen = [f"l{k}" for k, v in enumerate(orientations, start=1) if v is None]
    if complete and unseen:
        raise Ros2Error(f"{topic}.position: every link needs a finite orientation, missing {', '.join(unseen)}")
    if len(unseen) == n_links:
        raise Ros2Error(f"{topic}.position: no link seen (every link is missing or NaN)")
    base_xy = (base["base_x"], base["base_y"]) if base else None
    return JointReading(orientations, base_xy)


def joint_state_fields(link_orientations_deg: Sequence[float | None],
                       base_point_xy: Sequence[float] | None = None) -> tuple[list[str], list[float]]:
    """The JointState `name` and `position` of a perception in the service's terms (None = NaN, not seen)."""
    names = [f"l{k}" for k in range(1, len(link_orientations_deg) + 1)]
    positions = [math.nan if v is None else to_ros_rad(v) for v in link_orientations_deg]
    if base_point_xy is not None:
        names += list(BASE_NAMES)
        positions += [float(base_point_xy[0]), float(base_point_xy[1])]
    return names, positions


# -- decisions ------------------------------------------------------------------------------------------------
def decision_key(kind: str, perceived_state_id: str | None, reason: str) -> tuple[str, str | None, str]:
    """What an answer and the event the service logged for it share: the bridge publishes its own answers at once
    and skips their events when the stream brings them."""
    return str(kind), perceived_state_id, reason


def decision_text(answer: Mapping[str, Any], perception_stamp: tuple[int, int] | None = None,
                  event_seq: int | None = None) -> str:
    """The decision topic's JSON: the perception's answer, plus where it came from."""
    body = dict(answer)
    body["perception_stamp"] = list(perception_stamp) if perception_stamp is not None else None
    body["event_seq"] = event_seq
    return json.dumps(body, separators=(",", ":"))


def decision_of(event: Mapping[str, Any]) -> DecisionData | IncompleteData:
    """The record of a decision's event as the service's stream and log send it (`planhrc.event_log`)."""
    try:
        record = data_of(str(event.get("kind")), event.get("data") or {})
    except RecordError as exc:
        raise Ros2Error(f"event {event.get('seq')}: {exc}") from None
    if not isinstance(record, (DecisionData, IncompleteData)):
        raise Ros2Error(f"event {event.get('seq')}: {event.get('kind')!r} is not a decision")
    return record


def decision_from_event(event: Mapping[str, Any], plan_step: Mapping[str, Any] | None) -> dict[str, Any]:
    """The answer body of a decision another caller caused, rebuilt from its event; `next_action` is the plan's
    step as GET /plans/{id} lists it (without the merging of macro steps, which the dispatch does)."""
    record = decision_of(event)
    decided = record if isinstance(record, DecisionData) else DecisionData()
    action = None
    if plan_step is not None:
        action = {key: plan_step[key] for key in ("id", "name", "params", "step", "joint_index", "turned_link_index",
                                                   "held_link_index", "delta_deg") if key in plan_step}
        action["plan_id"] = decided.plan_id
    return {"decision": event["kind"], "plan_id": decided.plan_id, "perceived_state_id": decided.perceived_state_id,
            "next_action": action, "matched_expected_step": decided.matched_expected_step,
            "reason": event.get("reason", ""),
            "help": [asdict(h) for h in decided.help] if decided.help is not None else None,
            "unseen_links": list(record.unseen_links) if isinstance(record, IncompleteData) else None}


# -- the next action ------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class TurnTarget:
    """A JointTrajectory's content: [held, turned] links, their orientations now and at the target (radians,
    REP 103, unwrapped so that end - start has the turn's sign), and the target's time from start."""

    joint_names: tuple[str, str]
    start: tuple[float, float]
    end: tuple[float, float]
    duration_s: float


def turn_target(action: Mapping[str, Any], link_orientations_deg: Sequence[float | None]) -> TurnTarget:
    """The dispatched `action` (the service's body) as a turn from the perceived orientations."""
    turned, held = int(action["turned_link_index"]), int(action["held_link_index"])
    delta = float(action["delta_deg"])
    n = len(link_orientations_deg)
    if not 1 <= turned <= n or not 0 <= held <= n:
        raise Ros2Error(f"next_action: links {held} and {turned} do not fit an object of {n} links")

    def now(k: int) -> float:
        value = 0.0 if k == 0 else link_orientations_deg[k - 1]
        if value is None:
            raise Ros2Error(f"next_action: link l{k} was not seen, its orientation is unknown")
        return to_ros_rad(value)

    start = (now(held), now(turned))
    end = (start[0], start[1] - math.radians(delta))  # + clockwise in the service is - in REP 103
    return TurnTarget((f"l{held}", f"l{turned}"), start, end, max(0.5, abs(delta) / TURN_RATE_DEG_S))


# -- requests as JSON -----------------------------------------------------------------------------------------
@dataclass(frozen=True)
class FeedbackRequest:
    outcome: str
    action_id: str | None = None
    message: str = ""
    reason: str | None = None
    measured_deg: float | None = None
    request_id: str | None = None
    hands_open: bool = False


@dataclass(frozen=True)
class GiveUpRequest:
    reason: str
    message: str
    request_id: str | None = None


def _json_object(topic: str, text: str) -> dict[str, Any]:
    try:
        data = json.loads(text)
    except ValueError as exc:
        raise Ros2Error(f"{topic}.data: not JSON ({exc})") from None
    if not isinstance(data, dict):
        raise Ros2Error(f"{topic}.data: expected a JSON object, got {type(data).__name__}")
    return data


def _optional_text(topic: str, data: Mapping[str, Any], key: str) -> str | None:
    value = data.get(key)
    if value is not None and not isinstance(value, str):
        raise Ros2Error(f"{topic}.{key}: expected a string, got {value!r}")
    return value


def read_feedback(text: str, topic: str = "feedback") -> FeedbackRequest:
    data = _json_object(topic, text)
    outcome = data.get("outcome")
    if outcome not in set(ActionOutcome):
        raise Ros2Error(f"{topic}.outcome: must be {one_of(ActionOutcome)}, got {outcome!r}")
    reason = _optional_text(topic, data, "reason")
    if reason is not None and reason not in set(FailureReason):
        raise Ros2Error(f"{topic}.reason: must be {one_of(FailureReason)}, got {reason!r}")
    measured = data.get("measured_deg")
    if measured is not None and (isinstance(measured, bool) or not isinstance(measured, (int, float))
                                 or not math.isfinite(measured)):
        raise Ros2Error(f"{topic}.measured_deg: must be a finite number, got {measured!r}")
    hands_open = data.get("hands_open", False)
    if not isinstance(hands_open, bool):
        raise Ros2Error(f"{topic}.hands_open: must be true or false, got {hands_open!r}")
    return FeedbackRequest(str(outcome), _optional_text(topic, data, "action_id"),
                           _optional_text(topic, data, "message") or "", reason,
                           None if measured is None else float(measured), _optional_text(topic, data, "request_id"),
                           hands_open)


def read_give_up(text: str, topic: str = "give_up") -> GiveUpRequest:
    data = _json_object(topic, text)
    reason, message = _optional_text(topic, data, "reason"), _optional_text(topic, data, "message")
    if not reason:
        raise Ros2Error(f"{topic}.reason: a short code is required, e.g. \"repeated_failure\"")
    if not message:
        raise Ros2Error(f"{topic}.message: a sentence is required")
    return GiveUpRequest(reason, message, _optional_text(topic, data, "request_id"))


# -- states ---------------------------------------------------------------------------------------------------
def goal_orientations(formulation: str, joint_values_deg: Mapping[str, float], n_links: int,
                      first_deg: float | None) -> tuple[float, ...] | None:
    """Each link's orientation in a goal state (None when the goal leaves a joint free). Absolute: jK carries
    theta_K. Bimanual: jK carries theta_(K+1) - theta_1. Relative: jK carries theta_(K+1) - theta_K. In the last
    two l1 stays where it is (`first_deg`, perceived)."""
    by_index: dict[int, float] = {}
    for name, value in joint_values_deg.items():
        match = JOINT_INDEX.search(name)
        if match:
            by_index[int(match.group(1))] = float(value)
    if formulation == "absolute":
        values = [by_index.get(k) for k in range(1, n_links + 1)]
        return None if any(v is None for v in values) else tuple(float(v) % 360.0 for v in values if v is not None)
    if formulation == "bimanual":
        from_first = [by_index.get(k) for k in range(1, n_links)]
        if first_deg is None or any(v is None for v in from_first):
            return None
        first = float(round(first_deg)) % 360.0
        return (first,) + tuple((first + float(v)) % 360.0 for v in from_first if v is not None)
    relative = [by_index.get(k) for k in range(1, n_links)]
    if first_deg is None or any(v is None for v in relative):
        return None
    return tuple(float(v) for v in absolute_from_relative(round(first_deg), [round(v) for v in relative if v is not None]))

"""The object's event log: one frozen record per kind of event, the data of every event the service writes and
every reader takes (the service's memory, the HTTP API and its stream, the ROS 2 bridge, the benches). `DATA`
says which record each kind holds; `data_of` reads an event's data, and nothing else picks its keys.

| kind | record |
|---|---|
| `object_created` | `ObjectCreatedData` |
| `goal_set` | `GoalSetData` |
| a decision (`DecisionKind`) but `incomplete_perception` | `DecisionData` |
| `incomplete_perception` | `IncompleteData` |
| `dispatched`, `dispatch_withheld` | `DispatchData` |
| `feedback` | `FeedbackData` (a refused turn: `RefusalData`) |
| `worker_gave_up` | `GaveUpData` |
| `val_verdict` | `ValVerdictData` |

Each record is kept as its JSON data without the fields left at their defaults (`json_record`), so a field added
later reads from an older row as its default; the HTTP API lists every field. The client who caused an event is
the event's own field (`client`), never its data's.
"""
from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum
from typing import Annotated, Any, Literal, Mapping

from pydantic import Field

from planhrc.json_record import JsonRecord, RecordError
from planhrc.model import Atom, Formulation
from planhrc.ordering import HelpItem, RefusedMotion
from planhrc.vocabulary import (Accepted, ActionOutcome, DecisionKind, FailureReason, Infeasible, PlanningStatus,
                                Remedy, Skill)


class EventKind(StrEnum):
    """The kinds of event besides the decisions (`DecisionKind`)."""

    OBJECT_CREATED = "object_created"
    GOAL_SET = "goal_set"
    DISPATCHED = "dispatched"
    FEEDBACK = "feedback"
    WORKER_GAVE_UP = "worker_gave_up"
    VAL_VERDICT = "val_verdict"  # one per piece checked after the answer
    DISPATCH_WITHHELD = "dispatch_withheld"  # a step not sent: VAL refused (or has not decided on) its piece


XY = tuple[float, float]


@dataclass(frozen=True)
class SkillRequest(JsonRecord):
    """A robot skill asked for (`DecisionKind.ROBOT_SKILL`): slide the object, its base point to `base_point_xy`,
    holding links `links`; or straighten it, turning links back onto the orientation grid (`turns`, in order, the
    base point staying where it lies); why in words."""

    name: Skill
    """The skill (`slide`, `straighten`)."""
    base_point_xy: XY
    """Where the object's base point is to be, in metres."""
    links: tuple[int, ...]
    """The links the robot holds (straighten: the links it turns)."""
    sentence: str
    """What the robot does, in words."""
    turns: Annotated[tuple[tuple[int, int, float], ...], Field(exclude_if=lambda turns: not turns)] = ()
    """straighten: each turn (the turned link, the held one, 0 = the table; degrees, + clockwise), in order (a
    slide's request has none, and reads as it always has)."""


@dataclass(frozen=True)
class PlannedSkill(JsonRecord):
    """A robot skill a plan makes between two of its turns: before its step `before_step`."""

    before_step: int
    """The plan's step (1-based) the skill comes before."""
    skill: SkillRequest
    """The skill."""


class EventData(JsonRecord):
    """The data of an event, one record per kind (`DATA`)."""


@dataclass(frozen=True, kw_only=True)
class ObjectCreatedData(EventData):
    """An object created: its formulation, size and, when it was placed in the cell, its base point."""

    formulation: Formulation
    """`relative`, `absolute` or `bimanual`."""
    links: int
    """How many links."""
    orientations: int
    """How many orientations each joint may take."""
    base_point_xy: XY | None = None
    """Where its base point lies on the table, in metres (null: an abstract object, no geometric checks)."""

    @property
    def step_deg(self) -> int:
        """The orientation step (0 when the record names no orientations)."""
        return 360 // self.orientations if self.orientations else 0


@dataclass(frozen=True, kw_only=True)
class GoalSetData(EventData):
    """A goal set: the state stored for it and, when a perception was stored before, the problem from it."""

    goal_state_id: str
    """The goal state."""
    problem_id: str | None = None
    """The problem from the latest perceived state (null before the first perception)."""
    warnings: tuple[str, ...] = ()
    """What the goal's geometric check said (out of reach, too near an edge...)."""


@dataclass(frozen=True, kw_only=True)
class DecisionData(EventData):
    """A decision on a perception (every kind but `incomplete_perception`), or the help request a worker's give-up
    became: the answer's ids and what a restarted service reads back (the measured base point, the remedy, a
    re-plan's pieces under VAL...)."""

    perceived_state_id: str | None = None
    """The perceived state decided on (a give-up: the latest one)."""
    plan_id: str | None = None
    """The plan followed after the decision (a slide: the plan whose turns follow it)."""
    next_step: int | None = None
    """The step of the next action."""
    next_action_id: str | None = None
    """The next action (not dispatched yet)."""
    matched_expected_step: int | None = None
    """K of the expected state s^e_K the perceived state matched."""
    base_point_xy: XY | None = None
    """The base point the perception measured, in metres."""
    goal_state_id: str | None = None
    """The goal decided towards."""
    remedy: Remedy | None = None
    """What is done instead of retrying a failed motion identically."""
    val_pieces: tuple[tuple[int, int], ...] = ()
    """A re-plan answered early: every piece of the plan VAL checks (first and last step)."""
    val_accepted: tuple[int, ...] = ()
    """A re-plan answered early: the pieces VAL accepted before the answer (1-based)."""
    planning_status: PlanningStatus | None = None
    """A re-plan: how planning ended."""
    problem_id: str | None = None
    """A re-plan: the problem stored for it."""
    timings: Mapping[str, float] | None = None
    """A re-plan: seconds of each stage."""
    ordering: str = ""
    """A re-plan: what the search for an order that fits the table did, in words."""
    help: tuple[HelpItem, ...] | None = None
    """`human_help_requested`: what the human is asked to do."""
    skill: SkillRequest | None = None
    """`robot_skill`: the slide asked for before the plan's (`plan_id`) turns, or one it makes between them."""
    later_skills: tuple[PlannedSkill, ...] = ()
    """A re-plan: the slides its plan makes between its turns (relative and absolute objects)."""
    gave_up: str | None = None
    """A help request a worker's give-up became: the worker's reason."""


@dataclass(frozen=True, kw_only=True)
class IncompleteData(EventData):
    """A perception with links not seen (`incomplete_perception`): recorded, it changes nothing."""

    unseen_links: tuple[int, ...]
    """The links not seen (1-based)."""
    link_orientations_deg: tuple[float | None, ...] = ()
    """What was seen (null: not seen)."""
    base_point_xy: XY | None = None
    """The base point as measured (recorded, not used)."""


@dataclass(frozen=True, kw_only=True)
class DispatchData(EventData):
    """An action dispatched (`dispatched`), or not dispatched (`dispatch_withheld`: VAL refused or has not decided
    on its piece)."""

    plan_id: str
    """The plan."""
    action_id: str
    """The action."""
    step: int
    """Its step in the plan."""


@dataclass(frozen=True, kw_only=True)
class RefusalData(JsonRecord):
    """A turn refused before it moved: the worker's geometric fact, the turn and the pose it was refused from."""

    from_deg: tuple[float, ...]
    """The measured link orientations it was judged from."""
    base_point_xy: XY
    """The measured base point it was judged at, in metres."""
    turned: int
    """The link turned."""
    held: int
    """The link held."""
    direction: int
    """+1 clockwise, -1 anticlockwise."""
    code: Infeasible | None = None
    """What the worker's judge found (null: the worker said no more)."""
    link: int | None = None
    """The link concerned (null: the turned one)."""
    against: str = ""
    """What it runs against."""
    distance_m: float = 0.0
    """How far off, in metres."""

    def motion(self, step_deg: int, fact: str) -> RefusedMotion:
        """The refused turn as the planner avoids it: from the state its pose snaps to (`step_deg` a step)."""
        step = step_deg or 1
        state = tuple(int(round(v / step)) * step % 360 for v in self.from_deg)
        return RefusedMotion(state, self.base_point_xy, self.turned, self.held, self.direction, step,
                             self.code or Infeasible.OUT_OF_REACH, self.link or self.turned, fact or "refused")


@dataclass(frozen=True, kw_only=True)
class FeedbackData(EventData):
    """A worker's feedback on the dispatched action, and for a bimanual object the robot's control facts after it."""

    action_id: str
    """The action reported on."""
    step: int
    """Its step in the plan."""
    outcome: ActionOutcome
    """What the worker reports."""
    accepted: Accepted
    """`current`: it moved the execution on; `late`: a perception had already moved it."""
    reason: FailureReason | None = None
    """Why the action did not succeed."""
    measured_deg: float | None = None
    """The turned link's measured orientation after release."""
    message: str = ""
    """The worker's sentence."""
    joint_index: int | None = None
    """K of the joint turned about."""
    turned_link_index: int | None = None
    """The link turned."""
    refusal: RefusalData | None = None
    """A turn refused before it moved (never proposed again from the same state)."""
    control: tuple[Atom, ...] | None = None
    """Bimanual: the robot's control facts after the feedback, sorted (null: not a bimanual object)."""


@dataclass(frozen=True, kw_only=True)
class GaveUpData(EventData):
    """A worker gave up on the object (`worker_gave_up`)."""

    reason: str
    """The worker's short code."""
    message: str = ""
    """The worker's sentence."""
    plan_id: str | None = None
    """The plan then."""
    dropped_action_id: str | None = None
    """The action dispatched then, dropped."""


@dataclass(frozen=True, kw_only=True)
class ValVerdictData(EventData):
    """VAL's verdict on a piece of a plan checked after the answer (`val_verdict`)."""

    plan_id: str
    """The plan."""
    piece: int
    """The piece (1-based)."""
    first_step: int
    """Its first step."""
    last_step: int
    """Its last step."""
    verdict: Literal["accepted", "refused"]
    """VAL's verdict."""
    reason: str = ""
    """VAL's words."""
    seconds: float = 0.0
    """VAL's time on it."""


DATA: dict[str, type[EventData]] = {
    EventKind.OBJECT_CREATED: ObjectCreatedData, EventKind.GOAL_SET: GoalSetData,
    **{kind: DecisionData for kind in DecisionKind if kind != DecisionKind.INCOMPLETE_PERCEPTION},
    DecisionKind.INCOMPLETE_PERCEPTION: IncompleteData,
    EventKind.DISPATCHED: DispatchData, EventKind.DISPATCH_WITHHELD: DispatchData,
    EventKind.FEEDBACK: FeedbackData, EventKind.WORKER_GAVE_UP: GaveUpData, EventKind.VAL_VERDICT: ValVerdictData,
}


def data_of(kind: str, data: Mapping[str, Any]) -> EventData:
    """The record an event of `kind` holds (as stored, or as the API lists it); RecordError for a kind this log
    does not know or data its record cannot read."""
    record = DATA.get(kind)
    if record is None:
        raise RecordError(f"kind: no event of kind {kind!r} is written to an object's log")
    return record.of_data(data)

"""Per-object memory the use cases share, each piece owned by one small class and passed explicitly:

* `Memory`: what each object's event log says (its goal, latest perceived state, last feedback, failures, VAL's
  verdicts...), read incrementally since the log is append-only, so a restarted service continues where it stopped;
* `PlanViews`: the cooperation model's view of each object's current plan (its expected states and preconditions),
  one plan per object.
"""
from __future__ import annotations

import threading
from dataclasses import dataclass, replace

from planhrc.cooperation import FailureHistory, PlanView
from planhrc.event_log import (DecisionData, EventData, EventKind, FeedbackData, GoalSetData, ObjectCreatedData,
                               PlannedSkill, ValVerdictData)
from planhrc.model import Atom
from planhrc.pipeline import PieceRecord
from planhrc.ordering import RefusedMotion
from planhrc.vocabulary import Accepted, ActionOutcome, DecisionKind, Remedy, Skill

from ..store import KnowledgeStore, StoredPlan
from .log import piece_record_of, read_event, verdict_of

MAX_REFUSED = 200  # refused turns remembered per object: the latest


@dataclass(frozen=True)
class ObjectMemo:
    """What the event log says about an object, up to event `seq`."""

    seq: int = 0
    changed_seq: int = 0  # the last event that changed the object (every kind but VAL's verdicts: `unit_of_work`)
    goal_state_id: str | None = None
    perceived_state_id: str | None = None
    last_outcome: ActionOutcome | None = None  # a feedback informs only the next decision
    base_point_xy: tuple[float, float] | None = None  # set: the object is placed in the cell (geometric checks)
    measured_base_xy: tuple[float, float] | None = None  # where the latest perception measured the base point
    failure: FailureHistory | None = None  # the motion failing since the last success, and the remedies tried
    split_plans: frozenset[str] = frozenset()  # plans whose macro steps are dispatched step by step
    last_decision: str | None = None  # the kind of the last decision logged
    val: PieceRecord | None = None  # the latest plan adopted with only its first motion validated, and its verdicts
    refused: tuple[RefusedMotion, ...] = ()  # turns the robot refused, each from a state: never proposed again
    slides: int = 0  # slides asked for since the goal was set
    straightens: int = 0  # straightenings asked for since the goal was set
    last_skill: Skill | None = None  # the skill of the last robot_skill decision
    slide_from_xy: tuple[float, float] | None = None  # where the object's base point was when the last was asked
    step_deg: int = 0  # the object's orientation step (from its creation)
    control: frozenset[Atom] | None = None  # bimanual: the robot's control facts after the last feedback (None: none)
    later_skills: tuple[PlannedSkill, ...] = ()  # the slides plan `later_plan_id` makes between its turns
    later_plan_id: str | None = None

    def planned_skills(self, plan_id: str) -> tuple[PlannedSkill, ...]:
        """The slides plan `plan_id` makes between its turns (none for any other plan)."""
        return self.later_skills if plan_id == self.later_plan_id else ()

    def skill_before(self, plan_id: str, step: int) -> PlannedSkill | None:
        """The slide plan `plan_id` makes before its step `step`, if any."""
        return next((s for s in self.planned_skills(plan_id) if s.before_step == step), None)

    @property
    def where(self) -> tuple[float, float] | None:
        """The base point the geometric checks use: the latest measured one, else the one the object was created
        with; None for an abstract object (created without a base point and never perceived with one: no geometric
        checks). A perception that carries a base point places the object from then on."""
        return self.measured_base_xy or self.base_point_xy


class Memory:
    """One `ObjectMemo` per object, brought up to date with its event log by `of` (the caller holds the object's
    lock, so one object's memo is read and replaced by one request at a time)."""

    def __init__(self) -> None:
        self._guard = threading.Lock()
        self._memos: dict[str, ObjectMemo] = {}

    def of(self, store: KnowledgeStore, object_id: str) -> ObjectMemo:
        with self._guard:
            memo = self._memos.get(object_id) or ObjectMemo()
        events = store.list_events(object_id, after_seq=memo.seq)
        if not events:
            return memo
        for event in events:
            changed = memo.changed_seq if event.kind == EventKind.VAL_VERDICT else max(memo.changed_seq, event.seq)
            memo = _read(replace(memo, seq=max(memo.seq, event.seq), changed_seq=changed), event.kind,
                         read_event(event))
        with self._guard:
            self._memos[object_id] = memo
        return memo


def _read(memo: ObjectMemo, kind: str, data: EventData) -> ObjectMemo:
    """The memo after one more event (an incomplete perception, a dispatch, a give-up change none of it)."""
    if isinstance(data, ObjectCreatedData):
        return replace(memo, base_point_xy=data.base_point_xy, step_deg=data.step_deg)
    if isinstance(data, GoalSetData):
        return replace(memo, goal_state_id=data.goal_state_id, failure=None, slides=0, slide_from_xy=None,
                       straightens=0)
    if isinstance(data, FeedbackData):
        refused = memo.refused
        if data.refusal is not None:
            refused = (refused + (data.refusal.motion(memo.step_deg, data.message),))[-MAX_REFUSED:]
        return replace(memo, last_outcome=data.outcome, failure=next_failure(memo.failure, data), refused=refused,
                       control=frozenset(data.control) if data.control is not None else memo.control)
    if isinstance(data, ValVerdictData):
        if memo.val is not None and memo.val.plan_id == data.plan_id:
            return replace(memo, val=memo.val.with_verdict(data.piece, verdict_of(data)))
        return memo
    if isinstance(data, DecisionData):
        failure = memo.failure
        if kind == DecisionKind.ROBOT_SKILL and data.skill is not None and data.skill.name == Skill.STRAIGHTEN:
            memo = replace(memo, straightens=memo.straightens + 1, last_skill=Skill.STRAIGHTEN)
        elif kind == DecisionKind.ROBOT_SKILL:
            memo = replace(memo, slides=memo.slides + 1, slide_from_xy=data.base_point_xy or memo.where,
                           last_skill=Skill.SLIDE)
        if data.remedy and failure is not None:
            failure = replace(failure, tried=failure.tried + (data.remedy,))
        split = memo.split_plans | {data.plan_id} if data.remedy == Remedy.SPLIT and data.plan_id else None
        if data.problem_id is not None:  # a re-plan: its plan's slides between turns (none: none)
            memo = replace(memo, later_skills=data.later_skills, later_plan_id=data.plan_id)
        return replace(
            memo, val=piece_record_of(data) or memo.val,
            perceived_state_id=data.perceived_state_id or memo.perceived_state_id,
            measured_base_xy=data.base_point_xy or memo.measured_base_xy,
            last_outcome=None, last_decision=kind, failure=failure, split_plans=split or memo.split_plans)
    return memo


def next_failure(failure: FailureHistory | None, data: FeedbackData) -> FailureHistory | None:
    """The failure record after one feedback event: cleared by a success, counted for the same motion, started
    anew for another; a failure without a reason is not a motion's failure."""
    if data.outcome == ActionOutcome.SUCCEEDED or data.accepted == Accepted.LATE:
        return None if data.outcome == ActionOutcome.SUCCEEDED else failure
    reason, joint, turned = data.reason, data.joint_index, data.turned_link_index
    if reason is None or joint is None or turned is None:
        return None
    if failure is not None and (failure.joint, failure.turned) == (joint, turned):
        return replace(failure, reason=reason, failures=failure.failures + 1)
    return FailureHistory(joint, turned, reason)


class PlanViews:
    """The cooperation model's view of each object's plan, one plan per object (not every plan it ever had)."""

    def __init__(self) -> None:
        self._guard = threading.Lock()
        self._views: dict[str, tuple[StoredPlan, PlanView]] = {}  # plan id -> view
        self._view_of: dict[str, str] = {}  # object id -> the plan id cached in _views

    def get(self, store: KnowledgeStore, plan_id: str | None) -> tuple[StoredPlan | None, PlanView | None]:
        if plan_id is None:
            return None, None
        with self._guard:
            cached = self._views.get(plan_id)
        if cached is not None:
            return cached
        plan = store.get_plan(plan_id)
        view = PlanView(
            expected_states=tuple(store.get_state(sid).atoms for sid in plan.expected_state_ids),
            preconditions=tuple(a.spec.pre for a in sorted(plan.actions, key=lambda a: a.step)),
        )
        self.keep(plan, view)
        return plan, view

    def keep(self, plan: StoredPlan, view: PlanView) -> None:
        """Cache the view of an object's plan in place of the object's previous one."""
        with self._guard:
            previous = self._view_of.get(plan.object_id)
            if previous is not None and previous != plan.id:
                self._views.pop(previous, None)
            self._views[plan.id] = (plan, view)
            self._view_of[plan.object_id] = plan.id

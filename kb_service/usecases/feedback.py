"""A worker's feedback on the dispatched action: with `succeeded` the execution moves past the motion's last step
and the next perception checks the expected state there; otherwise the next perception decides whether to retry,
resume or re-plan. Feedback on an action a perception already moved past is recorded as *late* and moves nothing.
For a bimanual object the feedback event also keeps the robot's control facts after it (`planhrc.control`): what
the next perceived states hold beside the perceived orientations."""
from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any, Mapping

from planhrc.control import control_after
from planhrc.event_log import EventKind, FeedbackData, RefusalData
from planhrc.json_record import JsonRecord
from planhrc.pipeline import action_motion
from planhrc.vocabulary import Accepted, ActionOutcome, ExecutionStatus, FailureReason, Infeasible

from ..store import ConflictError, Execution, StoredAction
from .actions import last_step, merges
from .context import Context
from .idempotency import fingerprint, recall, remember
from .inputs import action_outcome, failure_reason, finite_or_none
from .log import log_event
from .unit_of_work import object_write, read_mark, serialized
from .values import FeedbackResult


@dataclass(frozen=True, kw_only=True)
class RefusalFact(JsonRecord):
    """What a worker says of a turn it refused before it moved (`schemas.RefusalFactPublic`): which link, against
    what, how far, and the pose it judged from (None: the latest perception's)."""

    code: Infeasible
    link: int
    against: str = ""
    distance_m: float = 0.0
    from_deg: tuple[float, ...] | None = None
    base_point_xy: tuple[float, float] | None = None


@dataclass(frozen=True)
class FeedbackRequest:
    """A worker's report on action `action_id`: its outcome, why it failed (`reason`, a FailureReason) and the
    turned link's measured orientation (`measured_deg`) when it did not succeed."""

    object_id: str
    action_id: str
    outcome: str
    message: str = ""
    idempotency_key: str | None = None
    reason: str | None = None
    measured_deg: float | None = None
    refusal: RefusalFact | None = None  # a turn refused before it moved: the geometric fact
    hands_open: bool = False  # bimanual: the robot opened its hands after the action (`control.control_after`)


def give_feedback(context: Context, request: FeedbackRequest) -> FeedbackResult:
    """Record the feedback and move the execution (see the module's note)."""
    return serialized(context, request.object_id, lambda: _give_feedback(context, request))


def _give_feedback(context: Context, request: FeedbackRequest) -> FeedbackResult:
    outcome = action_outcome(request.outcome)
    failure = failure_reason(outcome, request.reason)
    measured_deg = finite_or_none(request.measured_deg, "measured_deg")
    store, object_id, action_id, message = context.store, request.object_id, request.action_id, request.message
    with context.locks.hold(object_id):
        obj = store.get_object(object_id)
        mark = read_mark(context, object_id)  # before the remembered answer and the execution are read
        said: dict[str, Any] = ({"feedback": [action_id, outcome, message]}
                                if failure is None and measured_deg is None else
                                {"feedback": [action_id, outcome, message, failure, measured_deg]}
                                if request.refusal is None else
                                {"feedback": [action_id, outcome, message, failure, measured_deg,
                                              request.refusal.to_data(defaults=True)]})
        print_ = fingerprint({**said, "hands_open": True} if request.hands_open else said)
        recalled = recall(store, object_id, request.idempotency_key, print_, FeedbackResult)
        if recalled is not None:
            return recalled
        action = store.get_action(action_id)
        execution = store.get_execution(object_id)
        if execution.dispatched_action_id != action_id:
            current = execution.dispatched_action_id or "none"
            raise ConflictError(
                f"action_id: {action_id} is not the current dispatched action of {object_id} (current: {current})")
        if request.hands_open and not obj.grippers:
            raise ConflictError(f"hands_open: {object_id} is a {obj.formulation.value} object: its plans have no "
                                "hands to open")
        memo = context.memory.of(store, object_id)
        done: tuple[StoredAction, ...] = (action,)  # the motion's actions: feedback on a merged one covers each step
        if execution.status == ExecutionStatus.DISPATCHED:
            accepted = Accepted.CURRENT
            plan, _ = context.views.get(store, execution.plan_id)
            last = (last_step(merges(context.settings.merge_macro_steps, memo, plan.id), obj, plan, action)
                    if plan else action.step)
            done = tuple(a for a in plan.actions if action.step <= a.step <= last) if plan else done
            next_step = last + 1 if outcome == ActionOutcome.SUCCEEDED else action.step
            new = Execution(execution.plan_id, next_step, ExecutionStatus.READY, None)
            text = f"a_{action.step} {outcome}" + (
                f": the next perception checks s^e_{next_step}" if outcome == ActionOutcome.SUCCEEDED
                else ": the next perception decides whether to retry, resume or re-plan")
        else:
            accepted = Accepted.LATE
            new = replace(execution, dispatched_action_id=None)
            text = f"a_{action.step} {outcome}, reported after a perception had already moved the execution"
        result = FeedbackResult(action_id, accepted, new)
        why = (f" [{failure}]" if failure is not None else "") + ("; then the hands opened" if request.hands_open
                                                                  else "")
        motion = action_motion(obj, action)
        refused = (refusal_data(context, object_id, request.refusal, motion)
                   if outcome == ActionOutcome.FAILED and failure in REFUSALS else None)
        control = None
        if obj.grippers:  # bimanual: what the robot's grippers hold and where the centre is now (`planhrc.control`)
            control = tuple(sorted(control_after(memo.control or obj.initial_control(), [a.spec for a in done],
                                                 outcome == ActionOutcome.SUCCEEDED, request.hands_open)))
        data = FeedbackData(action_id=action_id, step=action.step, outcome=outcome, accepted=accepted, reason=failure,
                            measured_deg=measured_deg, message=message, joint_index=motion["joint_index"],
                            turned_link_index=motion["turned_link_index"], refusal=refused, control=control)
        with object_write(context, object_id, mark):
            store.set_execution(object_id, new)
            log_event(store, object_id, EventKind.FEEDBACK, text + why + (f" ({message})" if message else ""), data)
            remember(store, object_id, request.idempotency_key, print_, result)
        return result


# A failed turn for one of these reasons did not start (the worker's judge or its arms refused it): the same turn
# from the same state is not proposed again (`memory.ObjectMemo.refused`).
REFUSALS = frozenset({FailureReason.LEFT_TABLE, FailureReason.COLLISION, FailureReason.UNREACHABLE})


def refusal_data(context: Context, object_id: str, fact: RefusalFact | None, motion: Mapping[str, int]
                 ) -> RefusalData | None:
    """What the feedback event keeps of a refused turn: the turn (link turned and held, direction), the pose it was
    refused from (the worker's, else the latest perception's and measured base point) and the fact; None when there
    is no pose to remember it by."""
    memo = context.memory.of(context.store, object_id)
    pose = fact.from_deg if fact is not None else None
    if pose is None and memo.perceived_state_id is not None:
        pose = context.store.get_state(memo.perceived_state_id).link_orientations_deg
    base = (fact.base_point_xy if fact is not None else None) or memo.where
    if not pose or base is None:
        return None
    code, link, against, distance = ((fact.code, fact.link, fact.against, fact.distance_m) if fact is not None
                                     else (None, None, "", 0.0))
    return RefusalData(from_deg=tuple(float(v) for v in pose), base_point_xy=(float(base[0]), float(base[1])),
                       turned=motion["turned_link_index"], held=motion["held_link_index"],
                       direction=1 if motion["delta_deg"] > 0 else -1, code=code, link=link, against=against,
                       distance_m=distance)

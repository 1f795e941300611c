"""A worker gives up on an object: recorded, and the execution left idle with nothing dispatched (the plan stays;
the next perception decides anew). A give-up is never silent: it becomes a help request, recorded as the decision
`human_help_requested` beside the give-up (the console shows it), naming what the human should do (each link the
object still has to change, to its orientation at the goal, upstream first) and why no robot motion exists (the
worker's reason). Without a perception of the whole object to plan from, the request asks the human to bring the
object to its goal (or into the robot's view) and names no link: no robot motion can be planned from nothing seen.
Only an object without a goal, or at it, ends without a request."""
from __future__ import annotations

from dataclasses import dataclass

from planhrc.event_log import DecisionData, EventKind, GaveUpData
from planhrc.geometry import ObjectGeometry
from planhrc.model import ArticulatedObject, Formulation, ModelError, State, snap_angle
from planhrc.ordering import HelpItem, Placement, final_configuration, help_for
from planhrc.pipeline import move_of
from planhrc.vocabulary import DecisionKind, ExecutionStatus

from ..store import Execution, KnowledgeStore
from .context import Context
from .refine import whole_turn_deg
from .log import log_event
from .memory import ObjectMemo
from .unit_of_work import object_write, read_mark, serialized
from .values import GaveUp


@dataclass(frozen=True)
class GiveUpRequest:
    object_id: str
    reason: str  # a short machine-readable code
    message: str


def give_up(context: Context, request: GiveUpRequest) -> GaveUp:
    return serialized(context, request.object_id, lambda: _give_up(context, request))


def _give_up(context: Context, request: GiveUpRequest) -> GaveUp:
    store, object_id = context.store, request.object_id
    with context.locks.hold(object_id):
        obj = store.get_object(object_id)
        mark = read_mark(context, object_id)  # before the execution and the object's log are read
        execution = store.get_execution(object_id)
        memo = context.memory.of(store, object_id)
        why = f"the robot stopped ({request.reason}: {request.message})"
        items = help_after(store, obj, execution, memo, why)
        unseen = not items and goal_open_unseen(store, obj, memo)
        if items:
            reason = f"{why}; the robot asks the human for help: {'; '.join(h.sentence for h in items)}"
        elif unseen:
            reason = (f"{why}; the robot asks the human for help: bring the object to its goal, or into the robot's "
                      "view (no perception of the whole object is stored, so no robot motion can be planned)")
        else:
            reason = f"{why}; no goal is left to ask the human for"
        asking = bool(items) or unseen
        with object_write(context, object_id, mark):
            store.set_execution(object_id, Execution(execution.plan_id, None, ExecutionStatus.IDLE, None))
            event = log_event(store, object_id, EventKind.WORKER_GAVE_UP,
                              f"the worker gave up ({request.reason}): {request.message}",
                              GaveUpData(reason=request.reason, message=request.message, plan_id=execution.plan_id,
                                         dropped_action_id=execution.dispatched_action_id))
            if asking:
                log_event(store, object_id, DecisionKind.HUMAN_HELP_REQUESTED, reason,
                          DecisionData(perceived_state_id=memo.perceived_state_id, plan_id=execution.plan_id,
                                       help=items, gave_up=request.reason))
        return GaveUp(event.seq, DecisionKind.HUMAN_HELP_REQUESTED if asking else None, reason, items)


def help_after(store: KnowledgeStore, obj: ArticulatedObject, execution: Execution, memo: ObjectMemo,
               why: str) -> tuple[HelpItem, ...]:
    """What to ask the human when the robot stops short of the goal: the rest of the plan from the latest perceived
    state (`ordering.help_for`) when it still ends at the goal, else each link the goal still changes; nothing
    without a goal or a perception. The rest may no longer end at the goal: a plan goes on after a human's move
    its next action does not mind (its preconditions hold), and steps carried out since the latest whole
    perception are not in what was seen."""
    if memo.goal_state_id is None or memo.perceived_state_id is None:
        return ()
    perceived = store.get_state(memo.perceived_state_id)
    goal = store.get_state(memo.goal_state_id)
    raw = perceived.link_orientations_deg or ()
    if len(raw) != obj.n_links:
        return ()
    seen = tuple(float(snap_angle(v, obj.orientations)) for v in raw)
    base = memo.where
    if execution.plan_id is not None and execution.next_step is not None and base is not None:
        plan = store.get_plan(execution.plan_id)
        moves = [move_of(obj, a.spec) for a in sorted(plan.actions, key=lambda a: a.step)
                 if a.step >= execution.next_step]
        placed = Placement(ObjectGeometry.of(obj, base), seen, whole_turn_deg=whole_turn_deg(obj))
        end = tuple(float(snap_angle(v, obj.orientations)) for v in final_configuration(placed, moves)[1])
        items = help_for(placed, moves, None, why=why) if not goal_help(obj, end, goal.atoms, why) else ()
        if items:
            return items
    return goal_help(obj, seen, goal.atoms, why)


def goal_open_unseen(store: KnowledgeStore, obj: ArticulatedObject, memo: ObjectMemo) -> bool:
    """A goal is set and no perception of the whole object is stored to tell what it still changes (so nothing
    says it is reached)."""
    if memo.goal_state_id is None:
        return False
    if memo.perceived_state_id is None:
        return True
    raw = store.get_state(memo.perceived_state_id).link_orientations_deg or ()
    return len(raw) != obj.n_links


def goal_help(obj: ArticulatedObject, seen: tuple[float, ...], goal: State, why: str) -> tuple[HelpItem, ...]:
    """Each link whose orientation the goal still changes, to its orientation there, upstream first (a human turns
    a link about its joint with the one before, carrying the links beyond)."""
    values = obj.joint_values_of(goal)
    now = list(obj.joint_values_from_links([int(v) % 360 for v in seen]))
    wanted = [values.get(k, v) for k, v in zip(obj.joint_indices, now)]
    try:
        if obj.formulation is Formulation.ABSOLUTE:
            end = tuple(wanted)
        else:
            end = obj.link_orientations_of(obj.configuration_atoms(wanted), int(seen[0]))
    except ModelError:
        return ()
    return tuple(HelpItem(k, int(end[k - 1]) % 360, f"turn link {k} to {int(end[k - 1]) % 360}° ({why})")
                 for k in range(1, obj.n_links + 1) if int(end[k - 1]) % 360 != int(seen[k - 1]) % 360)

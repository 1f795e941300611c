"""What a perception decides, beyond the cooperation model's own rule (`cooperation.decide`): each step below takes
a decision and returns it, or a better one, for the object as it lies now.

* `recheck_at`: going on with the plan, checked at the base point as measured now (re-plan if it leaves the table);
* `escalate`: after a failure of the motion it would dispatch, not the same motion again (`cooperation.escalate`);
* `gate_decision`: a motion VAL refused is not dispatched (re-plan);
* `replan_request`: what a re-plan starts from (a joint turned the other way round, else the planner).
"""
from __future__ import annotations

from typing import Sequence

from planhrc.cooperation import Decision, FailureHistory, escalate as escalate_failure
from planhrc.geometry import ObjectGeometry, link_centres, reach_shortfall
from planhrc.model import ArticulatedObject, Formulation, Perception, State
from planhrc.ordering import Move, Placement, leaves_the_table
from planhrc.pipeline import ReplanRequest, action_motion, move_of
from planhrc.vocabulary import ActionOutcome, DecisionKind, Remedy

from ..store import StoredPlan
from .actions import last_step, merges
from .context import Context
from .gate import val_gate
from .memory import ObjectMemo

Base = tuple[float, float] | None  # where a placed object's base point lies (None: an abstract object)
DISPATCHING = (DecisionKind.CONTINUE, DecisionKind.RESUME)


def recheck_at(obj: ArticulatedObject, base: Base, plan: StoredPlan | None, perception: Perception,
               decision: Decision) -> Decision:
    """A decision to go on with the current plan, checked where the object lies now: when the rest of the plan
    would put a link past the table's edge or inside the robot with the base point at `base` (as measured;
    the plan was checked where the base point was then), the plan is not dispatched as is: re-plan."""
    if base is None or plan is None or decision.next_step is None or decision.kind not in DISPATCHING:
        return decision
    rest = [move_of(obj, a.spec) for a in sorted(plan.actions, key=lambda a: a.step) if a.step >= decision.next_step]
    step, problem = leaves_the_table(Placement(ObjectGeometry.of(obj, base),
                                               tuple(float(v) for v in perception.snapped_deg)), rest)
    if step is None or problem is None:
        return decision
    where = f"({base[0]:.3f}, {base[1]:.3f})"
    return Decision(DecisionKind.REPLAN, None, decision.matched_expected_step,
                    f"{decision.reason}; but with the base point measured at {where} step "
                    f"a_{decision.next_step + step - 1} of {plan.id} would end with {problem.message}: re-plan")


def escalate(context: Context, obj: ArticulatedObject, plan: StoredPlan | None, perception: Perception,
             decision: Decision, memo: ObjectMemo, base: Base) -> Decision:
    """`cooperation.escalate` for the motion the decision would dispatch: after a failure of that motion (or
    while the human is asked for it) it is not dispatched identically again."""
    failure = memo.failure
    asked = (failure is not None and Remedy.ASK_HUMAN in failure.tried
             and memo.last_decision == DecisionKind.HUMAN_HELP_REQUESTED)  # still waiting for the human
    fresh = memo.last_outcome in (ActionOutcome.FAILED, ActionOutcome.PARTIAL)
    if failure is None or plan is None or decision.next_step is None or not (fresh or asked):
        return decision
    if not 1 <= decision.next_step <= len(plan.actions):
        return decision
    action = plan.actions[decision.next_step - 1]
    motion = action_motion(obj, action)
    merge = merges(context.settings.merge_macro_steps, memo.split_plans, plan.id)
    macro = last_step(merge, obj, plan, action) - action.step + 1
    reachable = _reachable(perception, obj, base, motion["turned_link_index"], motion["held_link_index"])
    return escalate_failure(decision, failure, (motion["joint_index"], motion["turned_link_index"]), macro,
                            reachable)


def gate_decision(context: Context, obj: ArticulatedObject, plan: StoredPlan | None, decision: Decision,
                  deadline_at: float) -> Decision:
    """A decision that would dispatch a step of `plan` (continue, resume) stands only when VAL has accepted
    every piece the motion lies in (`gate.val_gate`); when VAL refused one, it becomes a re-plan saying so."""
    if (decision.kind not in DISPATCHING or plan is None or decision.next_step is None
            or not 1 <= decision.next_step <= len(plan.actions)):
        return decision
    refusal = val_gate(context, obj, plan, plan.actions[decision.next_step - 1], deadline_at)
    if refusal is None:
        return decision
    return Decision(DecisionKind.REPLAN, None, decision.matched_expected_step,
                    f"{decision.reason}; but {refusal}: re-plan from the perceived state")


def replan_request(obj: ArticulatedObject, perception: Perception, goal: State, plan: StoredPlan | None,
                   decision: Decision, memo: ObjectMemo, base: Base, deadline_at: float) -> ReplanRequest:
    """The re-plan a decision asks for: the current plan's rest with the failing joint turned the other way round
    (remedy other_way), else the planner's; ordered on the table for a placed object, its base point at `base`."""
    moves = None
    if (decision.remedy == Remedy.OTHER_WAY and plan is not None and memo.failure is not None
            and decision.matched_expected_step is not None):
        rest = [a for a in sorted(plan.actions, key=lambda a: a.step) if a.step >= decision.matched_expected_step]
        turned = other_way(obj, [move_of(obj, a.spec) for a in rest], memo.failure)
        moves = tuple(turned) if turned is not None else None
    return ReplanRequest(obj, perception.atoms, goal, deadline_at, placement(obj, perception.snapped_deg, base),
                         moves)


def placement(obj: ArticulatedObject, link_deg: Sequence[float], base: Base) -> Placement | None:
    """Where a placed object lies with its links at `link_deg` and its base point at `base` (None for an abstract
    one: no geometric checks)."""
    if base is None:
        return None
    return Placement(ObjectGeometry.of(obj, base), tuple(float(v) for v in link_deg),
                     whole_turn_deg=whole_turn_deg(obj))


def whole_turn_deg(obj: ArticulatedObject) -> int:
    """The step by which a human may turn the whole object without changing its state (`Placement`): relative and
    bimanual objects, whose states do not say where l1 points."""
    return 0 if obj.formulation is Formulation.ABSOLUTE else obj.step


def other_way(obj: ArticulatedObject, moves: Sequence[Move], failure: FailureHistory) -> list[Move] | None:
    """`moves` with the failing joint's steps replaced by the other way round (360° - delta), or None when that
    joint has nothing left to turn in them, or the plan's turns lie between grasps and releases (bimanual: the
    planner makes the new plan)."""
    if obj.grippers:
        return None
    group = [m for m in moves if (m.joint, m.turned) == (failure.joint, failure.turned)]
    total = sum(m.delta_deg for m in group)
    if not group or total % 360 == 0:
        return None
    forward = group[0] if (group[0].delta_deg > 0) == (total > 0) else group[0].other_way()
    turned_back = [forward.other_way()] * ((360 - abs(total) % 360) // obj.step)
    first = list(moves).index(group[0])
    rest = [m for m in moves if (m.joint, m.turned) != (failure.joint, failure.turned)]
    return rest[:first] + turned_back + rest[first:]


def _reachable(perception: Perception, obj: ArticulatedObject, base: Base, *links: int) -> bool:
    """Whether the robot reaches the grasp points of `links` as perceived, the base point at `base` (always, for
    an abstract object)."""
    if base is None:
        return True
    centres = link_centres(ObjectGeometry.of(obj, base), perception.snapped_deg)
    return all(reach_shortfall(centres[k - 1]) <= 1e-9 for k in links if k >= 1)

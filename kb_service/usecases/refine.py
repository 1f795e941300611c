"""What a perception decides (`decision_for`): the cooperation model's own rule (`cooperation.decide`), then each
step below, which takes what the perception found (`seen.Seen`) and a decision and returns it, or a better one, for
the object as it lies now.

* `slide_due`: going on with the plan where it slides the object before its next step: the slide first;
* `recheck_at`: going on with the plan, checked at the base point as measured now (re-plan if it leaves the table),
  up to the next slide it makes;
* `escalate`: after a failure of the motion it would dispatch, not the same motion again (`cooperation.escalate`);
* `gate_decision`: a motion VAL refused is not dispatched (re-plan).

`replan_request` is what a re-plan starts from (a joint turned the other way round, else the planner).
"""
from __future__ import annotations

import math
from typing import Callable, Sequence

from planhrc.cooperation import Decision, FailureHistory, decide, escalate as escalate_failure
from planhrc.geometry import Cell, ObjectGeometry, link_centres, reach_shortfall
from planhrc.judge import judge_motion
from planhrc.model import ArticulatedObject, Formulation, Perception
from planhrc.ordering import Move, Placement, RefusedMotion, leaves_the_table
from planhrc.pipeline import ReplanRequest, action_motion, move_of
from planhrc.vocabulary import ActionOutcome, DecisionKind, Remedy, Skill

from .actions import last_step, merges, next_action
from .context import Context
from .gate import val_gate
from .memory import ObjectMemo
from .seen import Base, Seen

DISPATCHING = (DecisionKind.CONTINUE, DecisionKind.RESUME)


def decision_for(context: Context, seen: Seen) -> Decision:
    """The decision on a perception of an object with a goal: the cooperation model's, refined by each step in
    `STEPS`, in that order."""
    assert seen.goal is not None  # without a goal there is nothing to decide towards
    decision = decide(seen.perception.atoms, seen.goal.atoms, seen.view, seen.execution.next_step,
                      seen.memo.last_outcome)
    for step in STEPS:
        decision = step(context, seen, decision)
    return decision


def slide_due(context: Context, seen: Seen, decision: Decision) -> Decision:
    """A decision to go on with the plan at a step the plan makes a slide before (`ObjectMemo.later_skills`)
    becomes that slide (`robot_skill`): the robot slides the object and perceives again, and the next decision goes
    on with the step. Right after a slide it is not asked again (the next perception shows where the object lies:
    `recheck_at` judges the rest from there)."""
    plan, memo = seen.plan, seen.memo
    if plan is None or decision.next_step is None or decision.kind not in DISPATCHING:
        return decision
    if memo.last_decision == DecisionKind.ROBOT_SKILL:
        return decision
    planned = memo.skill_before(plan.id, decision.next_step)
    if planned is None:
        return decision
    return Decision(kind=DecisionKind.ROBOT_SKILL, next_step=decision.next_step,
                    matched_expected_step=decision.matched_expected_step,
                    reason=f"{decision.reason}; the plan makes room before a_{decision.next_step}: "
                           f"{planned.skill.sentence}")


def recheck_at(context: Context, seen: Seen, decision: Decision) -> Decision:
    """A decision to go on with the current plan, checked where the object lies now, as measured: the motion it
    would dispatch is judged as the worker will judge it (`planhrc.judge.judge_motion`, from the measured pose)
    and must not be one the robot refused from this state before; the rest of the plan must not put a link past
    the table's edge or inside the robot with the base point at `base` (the plan was checked where the base point
    was then), up to the next slide the plan makes (its turns after it are made where the slide takes the object).
    Otherwise the plan is not dispatched as is: re-plan."""
    obj, base, plan, memo = seen.obj, seen.base, seen.plan, seen.memo
    if base is None or plan is None or decision.next_step is None or decision.kind not in DISPATCHING:
        return decision
    if not 1 <= decision.next_step <= len(plan.actions):
        return decision
    geometry, pose = ObjectGeometry.of(obj, base), tuple(float(v) for v in seen.perception.raw_deg)
    merge = merges(context.settings.merge_macro_steps, memo, plan.id)
    motion = next_action(merge, obj, plan, plan.actions[decision.next_step - 1])
    move = Move(motion.name, motion.turned_link_index, motion.held_link_index, motion.joint_index, motion.delta_deg)
    refused = next((r for r in memo.refused if r.forbids(geometry, pose, move)), None)
    verdict = judge_motion(geometry, pose, move.turned, move.held, move.delta_deg, Cell(), motion.ends_plan)
    if refused is not None or not verdict.ok:
        why = (f"the robot refused that turn from this state before ({refused.fact})" if refused is not None
               else verdict.sentence())
        return _replan(decision, f"{decision.reason}; but with the base point measured at ({base[0]:.3f}, "
                                 f"{base[1]:.3f}) and the links as measured, turning link {move.turned} by "
                                 f"{move.delta_deg:+d}° ({motion.id}) would end with {why}: re-plan")
    until = min((s.before_step for s in memo.planned_skills(plan.id) if s.before_step > decision.next_step),
                default=len(plan.actions) + 1)
    rest = [move_of(obj, a.spec) for a in sorted(plan.actions, key=lambda a: a.step)
            if decision.next_step <= a.step < until]
    step, problem = leaves_the_table(Placement(geometry, pose), rest)
    if step is None or problem is None:
        return decision
    where = f"({base[0]:.3f}, {base[1]:.3f})"
    return _replan(decision, f"{decision.reason}; but with the base point measured at {where} step "
                             f"a_{decision.next_step + step - 1} of {plan.id} would end with {problem.message}: "
                             "re-plan")


def escalate(context: Context, seen: Seen, decision: Decision) -> Decision:
    """`cooperation.escalate` for the motion the decision would dispatch: after a failure of that motion (or
    while the human is asked for it) it is not dispatched identically again."""
    obj, plan, memo = seen.obj, seen.plan, seen.memo
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
    merge = merges(context.settings.merge_macro_steps, memo, plan.id)
    macro = last_step(merge, obj, plan, action) - action.step + 1
    reachable = _reachable(seen.perception, obj, seen.base, motion["turned_link_index"], motion["held_link_index"])
    return escalate_failure(decision, failure, (motion["joint_index"], motion["turned_link_index"]), macro,
                            reachable)


def gate_decision(context: Context, seen: Seen, decision: Decision) -> Decision:
    """A decision that would dispatch a step of `plan` (continue, resume) stands only when VAL has accepted
    every piece the motion lies in (`gate.val_gate`); when VAL refused one, it becomes a re-plan saying so."""
    plan = seen.plan
    if (decision.kind not in DISPATCHING or plan is None or decision.next_step is None
            or not 1 <= decision.next_step <= len(plan.actions)):
        return decision
    refusal = val_gate(context, seen.obj, plan, plan.actions[decision.next_step - 1], seen.deadline_at)
    if refusal is None:
        return decision
    return _replan(decision, f"{decision.reason}; but {refusal}: re-plan from the perceived state")


# The refinement steps, in the order `decision_for` takes them.
STEPS: tuple[Callable[[Context, Seen, Decision], Decision], ...] = (slide_due, recheck_at, escalate, gate_decision)


def _replan(decision: Decision, reason: str) -> Decision:
    """A decision to go on with the plan, turned into a re-plan for `reason`."""
    return Decision(kind=DecisionKind.REPLAN, next_step=None, matched_expected_step=decision.matched_expected_step,
                    reason=reason)


def replan_request(seen: Seen, decision: Decision) -> ReplanRequest:
    """The re-plan a decision asks for: the current plan's rest with the failing joint turned the other way round
    (remedy other_way), else the planner's; ordered on the table for a placed object, its base point at `base`."""
    obj, plan, memo, base = seen.obj, seen.plan, seen.memo, seen.base
    assert seen.goal is not None  # a re-plan is decided towards a goal
    moves = None
    if (decision.remedy == Remedy.OTHER_WAY and plan is not None and memo.failure is not None
            and decision.matched_expected_step is not None):
        rest = [a for a in sorted(plan.actions, key=lambda a: a.step) if a.step >= decision.matched_expected_step]
        turned = other_way(obj, [move_of(obj, a.spec) for a in rest], memo.failure)
        moves = tuple(turned) if turned is not None else None
    return ReplanRequest(obj=obj, init=seen.perception.atoms, goal=seen.goal.atoms, deadline_at=seen.deadline_at,
                         placement=placement(obj, seen.perception.raw_deg, base, memo.refused, may_slide(memo, base),
                                             memo.straightens < MAX_STRAIGHTENS),
                         moves=moves)


# Slides asked for per goal: room is made a few times at most (a slide the object ends short of, a human's move may
# need another); a plan that still does not fit goes to the human.
MAX_SLIDES = 4
MAX_STRAIGHTENS = 2  # straightenings asked for per goal (`pipeline.order.straightening`)


def may_slide(memo: ObjectMemo, base: Base) -> bool:
    """Whether the robot may be asked to slide the object (`DecisionKind.ROBOT_SKILL`): not more than `MAX_SLIDES`
    times per goal, and not again right after a slide that left the base point where it was (it did not work)."""
    if base is None or memo.slides >= MAX_SLIDES:
        return False
    if memo.last_decision == DecisionKind.ROBOT_SKILL and memo.last_skill == Skill.SLIDE and memo.slide_from_xy:
        return math.dist(base, memo.slide_from_xy) > 0.02
    return True


def placement(obj: ArticulatedObject, link_deg: Sequence[float], base: Base,
              refused: Sequence[RefusedMotion] = (), slides: bool = True, straightens: bool = True
              ) -> Placement | None:
    """Where a placed object lies with its links at `link_deg` (as measured: the one judge's pose) and its base
    point at `base`, with the turns the robot refused before and whether it may slide the object first (None for
    an abstract one: no geometric checks)."""
    if base is None:
        return None
    return Placement(ObjectGeometry.of(obj, base), tuple(float(v) for v in link_deg),
                     whole_turn_deg=whole_turn_deg(obj), refused=frozenset(refused), grid_deg=obj.step, slides=slides,
                     straightens=straightens)


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

"""What a decision writes, inside the perception's one write: `follow` moves the execution within the current plan
(goal reached, continue, resume) or asks the human for the next motion; `adopt` stores a re-plan's problem and, when
VAL accepted it, its plan with its expected states. Each returns what it wrote (`Written`): the perception's
`Turn` and what the decision's event keeps besides. `decision_data` is that event's data (`log.DecisionData`)."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping

from planhrc.cooperation import Decision, PlanView
from planhrc.event_log import DecisionData, PlannedSkill, SkillRequest
from planhrc.geometry import ObjectGeometry
from planhrc.model import snap_angle
from planhrc.motion_search import Slide
from planhrc.ordering import Placement, help_for
from planhrc.pipeline import EarlyAnswer, move_of
from planhrc.vocabulary import DecisionKind, ExecutionStatus, PlanningStatus, Remedy, Skill

from ..store import Execution, StoredPlan, StoredState
from .actions import Merging, last_step, merges, next_action
from .context import Context
from .memory import ObjectMemo
from .refine import whole_turn_deg
from .seen import NewPlan, Seen
from .values import Turn

IDLE, READY, DISPATCHED = ExecutionStatus.IDLE, ExecutionStatus.READY, ExecutionStatus.DISPATCHED


@dataclass(frozen=True)
class Written:
    """A decision's writes: the answer, and for a re-plan its problem, planning status and timings, what the
    ordering on the table did, the pieces VAL checks behind the answer (early answer) and the plan adopted."""

    turn: Turn
    problem_id: str | None = None
    planning_status: PlanningStatus | None = None
    timings: Mapping[str, float] | None = None
    ordering: str = ""
    early: EarlyAnswer | None = None
    adopted: tuple[StoredPlan, PlanView] | None = None
    later_skills: tuple[PlannedSkill, ...] = ()


def follow(context: Context, seen: Seen, perceived: StoredState, decision: Decision) -> Written:
    """Goal reached, continue or resume: the execution moves within the current plan; or the robot first makes the
    slide its plan makes before the next step (`robot_skill`), or the human is asked to do the next motion, and the
    execution waits for the next perception."""
    store, obj, execution, plan, memo = context.store, seen.obj, seen.execution, seen.plan, seen.memo
    if decision.kind == DecisionKind.GOAL_REACHED:
        store.set_execution(obj.ident, Execution(execution.plan_id, None, ExecutionStatus.GOAL_REACHED,
                                                 execution.dispatched_action_id))
        return Written(turn=Turn(decision=DecisionKind.GOAL_REACHED, plan_id=execution.plan_id,
                                 perceived_state_id=perceived.id, next_action=None,
                                 matched_expected_step=decision.matched_expected_step, reason=decision.reason))
    assert plan is not None and decision.next_step is not None
    # a split remedy dispatches this plan's steps one by one from now on (its event says so too, for the memo)
    merge = merges(context.settings.merge_macro_steps and decision.remedy != Remedy.SPLIT, memo, plan.id)
    action = plan.actions[decision.next_step - 1]
    if decision.kind == DecisionKind.ROBOT_SKILL:  # a slide the plan makes before this step (`refine.slide_due`)
        planned = memo.skill_before(plan.id, decision.next_step)
        assert planned is not None  # `refine.slide_due` decides a slide only where the plan makes one
        store.set_execution(obj.ident, Execution(plan.id, decision.next_step, IDLE, None))
        return Written(turn=Turn(decision=DecisionKind.ROBOT_SKILL, plan_id=plan.id, perceived_state_id=perceived.id,
                                 next_action=None, matched_expected_step=decision.matched_expected_step,
                                 reason=decision.reason, skill=planned.skill))
    if decision.kind == DecisionKind.HUMAN_HELP_REQUESTED:
        last = last_step(merge, obj, plan, action)
        moves = [move_of(obj, a.spec) for a in sorted(plan.actions, key=lambda a: a.step)
                 if action.step <= a.step <= last]
        pose = tuple(float(snap_angle(v, obj.orientations)) for v in perceived.link_orientations_deg or ())
        if len(pose) != obj.n_links:  # not a perceived state with its observation: the plan's own view
            pose = tuple(float(v) for v in obj.link_orientations_of(perceived.atoms))
        placed = Placement(ObjectGeometry.of(obj, seen.base), pose, whole_turn_deg=whole_turn_deg(obj))
        help_items = help_for(placed, moves, None, why=_failure_words(memo))
        store.set_execution(obj.ident, Execution(plan.id, decision.next_step, IDLE, None))
        return Written(turn=Turn(decision=DecisionKind.HUMAN_HELP_REQUESTED, plan_id=plan.id,
                                 perceived_state_id=perceived.id, next_action=None,
                                 matched_expected_step=decision.matched_expected_step, reason=decision.reason,
                                 help=tuple(help_items)))
    still_dispatched = execution.status == DISPATCHED and execution.dispatched_action_id == action.id
    store.set_execution(obj.ident, Execution(plan.id, decision.next_step, DISPATCHED if still_dispatched else READY,
                                             execution.dispatched_action_id))
    return Written(turn=Turn(decision=DecisionKind(decision.kind), plan_id=plan.id, perceived_state_id=perceived.id,
                             next_action=next_action(merge, obj, plan, action),
                             matched_expected_step=decision.matched_expected_step, reason=decision.reason))


def adopt(context: Context, seen: Seen, perceived: StoredState, decision: Decision, new: NewPlan) -> Written:
    """Store the re-planning's problem and, when solved (and, with VAL on, accepted by VAL: the whole plan, or
    with the early answer its first motion), its plan with expected states; move the execution. A plan whose turns
    come after a slide is answered with the slide (`robot_skill`): the robot slides the object, perceives again and
    goes on with the plan from its first step; the slides it makes between its turns are in the decision's event
    (`later_skills`), each asked for before its step (`refine.slide_due`). No plan where the links lie but one once
    links a turn dragged off the grid are back on it: the straightening is asked for (`robot_skill`, after a slide
    when it needs room), no plan stored; the next perception plans from there. With the early answer the
    decision's event names the plan's pieces and those accepted (`decision_data`): the record the dispatch gate
    starts from, through a restart."""
    store, obj, goal, outcome, early = context.store, seen.obj, seen.goal, new.outcome, new.early
    assert goal is not None  # a re-plan is decided towards a goal
    problem = store.add_problem(obj.ident, perceived.id, goal.id)

    def written(turn: Turn, behind: EarlyAnswer | None = None,
                adopted: tuple[StoredPlan, PlanView] | None = None) -> Written:
        later = tuple(PlannedSkill(before_step=s.before_step, skill=_slide_request(s.slide))
                      for s in outcome.later_slides) if adopted is not None else ()
        return Written(turn=turn, problem_id=problem.id, planning_status=outcome.status, timings=outcome.timings,
                       ordering=outcome.ordering, early=behind, adopted=adopted, later_skills=later)

    if outcome.solved and outcome.actions:
        plan = store.add_plan(problem.id, outcome.planner, outcome.actions, outcome.expected_states, new.checks)
        store.set_execution(obj.ident, Execution(plan.id, 1, READY, None))
        view = PlanView(expected_states=outcome.expected_states, preconditions=tuple(a.pre for a in outcome.actions))
        ordering = f" ({outcome.ordering})" if outcome.ordering else ""
        checked_by = (f"; VAL accepted a_1..a_{outcome.validated_steps}, a_{outcome.validated_steps + 1}.."
                      f"a_{len(plan.actions)} are checked before they are dispatched" if early is not None else "")
        reason = f"{decision.reason}; new plan {plan.id} of {len(plan.actions)} actions{ordering}{checked_by}"
        if outcome.slide is not None:  # the plan's turns are made where the robot slides the object first
            store.set_execution(obj.ident, Execution(plan.id, 1, IDLE, None))  # nothing dispatched before it
            slide = outcome.slide
            skill = _slide_request(slide)
            turn = Turn(decision=DecisionKind.ROBOT_SKILL, plan_id=plan.id, perceived_state_id=perceived.id,
                        next_action=None, matched_expected_step=decision.matched_expected_step,
                        reason=f"{reason}; the robot makes room first: {slide.sentence()}", skill=skill)
            return written(turn, early, (plan, view))
        breaks = frozenset(s.before_step for s in outcome.later_slides)
        action = next_action(Merging(context.settings.merge_macro_steps, breaks), obj, plan, plan.actions[0])
        turn = Turn(decision=DecisionKind.REPLAN, plan_id=plan.id, perceived_state_id=perceived.id,
                    next_action=action, matched_expected_step=decision.matched_expected_step, reason=reason)
        return written(turn, early, (plan, view))
    if outcome.solved:  # the perceived state already satisfies the goal
        store.set_execution(obj.ident, Execution(None, None, ExecutionStatus.GOAL_REACHED, None))
        return written(Turn(decision=DecisionKind.GOAL_REACHED, plan_id=None, perceived_state_id=perceived.id,
                            next_action=None, matched_expected_step=None, reason=outcome.message))
    if outcome.straighten:  # a plan fits once links a turn dragged off the grid are back on it: that first
        store.set_execution(obj.ident, Execution(None, None, IDLE, None))
        base = seen.base or (0.0, 0.0)
        skill = (_slide_request(outcome.slide) if outcome.slide is not None else  # room to straighten it first
                 SkillRequest(Skill.STRAIGHTEN, (float(base[0]), float(base[1])),
                              tuple(t for t, _, _ in outcome.straighten), outcome.message, outcome.straighten))
        first = "slides the object to straighten the links there" if outcome.slide else "straightens the links first"
        return written(Turn(decision=DecisionKind.ROBOT_SKILL, plan_id=None, perceived_state_id=perceived.id,
                            next_action=None, matched_expected_step=decision.matched_expected_step,
                            reason=f"{decision.reason}; {outcome.message}; the robot {first}", skill=skill))
    if outcome.help:  # a plan exists but the robot cannot carry it out on this table: ask the human
        store.set_execution(obj.ident, Execution(None, None, IDLE, None))
        reason = f"{decision.reason}; {outcome.message}; the robot asks the human for help"
        return written(Turn(decision=DecisionKind.HUMAN_HELP_REQUESTED, plan_id=None, perceived_state_id=perceived.id,
                            next_action=None, matched_expected_step=decision.matched_expected_step, reason=reason,
                            help=outcome.help))
    store.set_execution(obj.ident, Execution(None, None, ExecutionStatus.NO_PLAN, None))
    reason = (f"{decision.reason}; planning {outcome.status}: {outcome.message}; "
              "a human must bring the object to a workable configuration")
    return written(Turn(decision=DecisionKind.NO_PLAN, plan_id=None, perceived_state_id=perceived.id,
                        next_action=None, matched_expected_step=decision.matched_expected_step, reason=reason))


def decision_data(written: Written, goal_state_id: str | None, remedy: Remedy | None,
                  measured: tuple[float, float] | None) -> DecisionData:
    """The data of a decision's event: the answer's ids, and what a restarted service reads back (the measured
    base point, kept with the perception's event: a restarted service checks there too; the goal, the remedy, a
    re-plan's pieces under VAL...)."""
    turn, early = written.turn, written.early
    action = turn.next_action
    return DecisionData(
        perceived_state_id=turn.perceived_state_id, plan_id=turn.plan_id,
        next_step=action.step if action else None, next_action_id=action.id if action else None,
        matched_expected_step=turn.matched_expected_step, base_point_xy=measured, goal_state_id=goal_state_id,
        remedy=remedy, val_pieces=early.pieces if early is not None else (),
        val_accepted=tuple(range(1, early.accepted + 1)) if early is not None else (),
        planning_status=written.planning_status,
        problem_id=written.problem_id if written.planning_status is not None else None,
        timings={k: round(v, 6) for k, v in (written.timings or {}).items()}
        if written.planning_status is not None else None,
        ordering=written.ordering, help=turn.help, skill=turn.skill, later_skills=written.later_skills)


def _slide_request(slide: Slide) -> SkillRequest:
    return SkillRequest(Skill.SLIDE, slide.to_xy, slide.links, slide.sentence())


def _failure_words(memo: ObjectMemo) -> str | None:
    failure = memo.failure
    if failure is None:
        return None
    return f"the robot failed {failure.failures} time{'s' if failure.failures > 1 else ''}: {failure.reason}"

"""A perception, as the paper's cooperation loop draws it (`perceive`): snap the perceived configuration to a state,
decide (the expected state it matches: continue or resume; else re-plan), plan when the decision asks for it, write.

It stores all it leads to in one write: the perceived state and, after a re-plan, its problem, plan and expected
states, then the execution, the decision's event and the idempotent answer. A refused or failed write stores none
of it. A perception may arrive at any time: if it moves the execution to another step of the same plan while an
action is dispatched, that action stays on record for feedback only (its feedback is then *late*); a new plan
drops the dispatched action (its feedback then gets a conflict).

Planning and VAL run under the object's lock only: the store (shared by every object) is held just for the write.
A re-plan calls the pipeline once (`pipeline.plan_for_service`), which hands back the plan with a handle on VAL's
verdict, VAL running in its own processes; the store's checks of the plan run meanwhile, and the write overlaps VAL
as the unit of work says (`unit_of_work.write_on_verdict`: the one place a write is retried or waits on VAL). A plan
VAL refuses is never stored; a re-plan that does not finish within the planning deadline raises DeadlineError and
stores nothing.
"""
from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from typing import Callable

from planhrc.cooperation import Decision
from planhrc.event_log import IncompleteData
from planhrc.model import ArticulatedObject, ModelError, perceive as snap
from planhrc.pipeline import PieceVerdict, PlannedTurn, PlanOutcome, deadline_from, plan_for_service
from planhrc.pipeline.later import Precheck
from planhrc.vocabulary import DecisionKind

from ..store import CheckedPlan, DeadlineError, ValidationError
from . import refine
from .context import Context
from .idempotency import fingerprint, recall, remember
from .inputs import check_count, check_finite, measured_base
from .log import log_event, record_verdict
from .seen import NewPlan, Seen
from .turns import Written, adopt, decision_data, follow
from .unit_of_work import object_write, read_mark, serialized, write_on_verdict
from .values import Turn

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class PerceptionRequest:
    """A perceived configuration: every link's measured orientation (None: not seen), the base point as measured
    (optional), and the request's idempotency key."""

    object_id: str
    link_orientations_deg: tuple[float | None, ...]
    idempotency_key: str | None = None
    base_point_xy: tuple[float, ...] | None = None


def perceive(context: Context, request: PerceptionRequest) -> Turn:
    """Decide on one perception and store all it leads to in one write (see the module's note), deciding again when
    another process wrote the object meanwhile (`unit_of_work`); the planning deadline holds for all of it."""
    deadline_at = deadline_from(context.planning)
    with context.observer.span("perceive", object_id=request.object_id) as span:
        turn = serialized(context, request.object_id, lambda: _perceive(context, request, deadline_at), deadline_at)
        if span is not None:
            span.set_attribute("decision", str(turn.decision))
        return turn


def _perceive(context: Context, request: PerceptionRequest, deadline_at: float) -> Turn:
    with context.locks.hold(request.object_id):
        # snap: the perceived state, and where the object's cooperation stands
        seen = _snap(context, request, deadline_at)
        if not isinstance(seen, Seen):  # answered already (the idempotency key), or links not seen
            return seen
        if seen.goal is None:
            return _write(context, seen, None).turn  # no decision: nothing to count

        # decide: the goal reached, continue or resume the plan, the human asked (written at once); else re-plan
        decision = refine.decision_for(context, seen)
        if decision.kind not in (DecisionKind.REPLAN, DecisionKind.NO_PLAN):
            written = _write(context, seen, decision)
            context.observer.decided(written.turn.decision, None)
            return written.turn

        # plan, then write once VAL's verdict is in (read inside the write when it comes soon: `unit_of_work`)
        planned = _plan(context, seen, decision)
        written = write_on_verdict(context, seen.obj.ident, planned, lambda: _check_plan(context, seen, planned),
                                   lambda new_plan: _write(context, seen, decision, new_plan))
        obj, store = seen.obj, context.store
        verdict = planned.verdict.outcome(0) if planned.outcome.solved and planned.outcome.actions else None
        if verdict is not None and "validate" in verdict.timings:
            context.observer.validated(verdict.validated or verdict.validated_steps > 0, verdict.timings["validate"],
                                       verdict.timings.get("validate_cpu"))
        context.observer.decided(written.turn.decision, written.timings)

        # after the commit: the object's plan changed (or is gone); its checks behind the answer follow it
        adopted = written.adopted
        if adopted is not None:
            context.views.keep(*adopted)
        plan_id = adopted[0].id if adopted is not None else None

        def record(piece: PieceVerdict) -> None:
            assert plan_id is not None  # only an adopted plan's pieces are checked behind the answer
            record_verdict(store, obj.ident, plan_id, piece)
            context.observer.validated(piece.verdict.accepted, piece.seconds, piece.cpu_s)

        context.validator.follow(obj.ident, plan_id, planned.verdict, record, _later_checks(context, obj, planned))
        return written.turn


def _snap(context: Context, request: PerceptionRequest, deadline_at: float) -> Seen | Turn:
    """What the perception finds under the object's lock: the perceived state (snapped once, here) and where the
    object's cooperation stands; or the answer at once (the request's key answered before, links not seen)."""
    store, links = context.store, request.link_orientations_deg
    measured = measured_base(request.base_point_xy)
    obj = store.get_object(request.object_id)
    mark = read_mark(context, obj.ident)  # before the remembered answer and the state are read
    print_ = fingerprint({"perception": list(links)} if measured is None else
                         {"perception": list(links), "base_point_xy": list(measured)})
    recalled = recall(store, obj.ident, request.idempotency_key, print_, Turn)
    if recalled is not None:
        return recalled
    if any(v is None for v in links):
        return _incomplete(context, obj, request, print_, measured, mark)
    memo = context.memory.of(store, obj.ident)
    try:  # validated and snapped once, here; a bimanual state takes the robot's control facts (`planhrc.control`)
        perception = snap(obj, links, control=memo.control)
    except ModelError as exc:
        raise ValidationError(str(exc)) from None
    execution = store.get_execution(obj.ident)
    goal = store.get_state(memo.goal_state_id) if memo.goal_state_id is not None else None
    plan, view = context.views.get(store, execution.plan_id)
    return Seen(obj=obj, perception=perception, execution=execution, goal=goal, plan=plan, view=view, memo=memo,
                base=measured or memo.where,  # a perception with a base point places the object (None: abstract)
                measured=measured, deadline_at=deadline_at, key=request.idempotency_key, fingerprint=print_,
                mark=mark)


def _plan(context: Context, seen: Seen, decision: Decision) -> PlannedTurn:
    """The re-plan a decision asks for: the pipeline once, VAL checking the new plan in its own processes after."""
    context.validator.stop(seen.obj.ident)  # the plan being replaced needs no more checking
    request = refine.replan_request(seen, decision)
    with context.observer.span("plan"):  # the object: on `perceive`
        return plan_for_service(request, context.planning, context.validator, context.pool)


def _write(context: Context, seen: Seen, decision: Decision | None,
           new_plan: Callable[[], NewPlan] | None = None) -> Written:
    """The perception's one write. After a re-plan it reads the new plan as VAL checked it (`new_plan()`) once the
    perceived state is written: inside the write, as the unit of work lets it (`unit_of_work.write_on_verdict`),
    so it commits a plan VAL accepted or none (a plan VAL refuses is stored as a problem without a plan)."""
    store, obj, goal = context.store, seen.obj, seen.goal
    started = time.perf_counter()
    with context.observer.span("store"), object_write(context, obj.ident, seen.mark):
        perceived = store.add_perception(seen.perception)
        new = new_plan() if new_plan is not None else None
        if goal is None or decision is None:
            written = Written(turn=Turn(decision=DecisionKind.NO_PLAN, plan_id=None, perceived_state_id=perceived.id,
                                        next_action=None, matched_expected_step=None,
                                        reason="no goal is set: PUT /objects/{id}/goal first"))
        elif new is None:
            written = follow(context, seen, perceived, decision)
        else:
            written = adopt(context, seen, perceived, decision, new)
        turn = written.turn
        data = decision_data(written, goal.id if goal is not None else None,
                             decision.remedy if decision is not None else None, seen.measured)
        log_event(store, obj.ident, turn.decision, turn.reason, data)
        remember(store, obj.ident, seen.key, seen.fingerprint, turn)
    context.observer.stored(time.perf_counter() - started, replanned=new_plan is not None)
    return written


def _check_plan(context: Context, seen: Seen, planned: PlannedTurn) -> CheckedPlan | None:
    """The store's checks of a new plan (outside the store's lock), while VAL checks it in its own processes: of
    its first steps only when VAL checks only those before the answer (the rest: `_later_checks`)."""
    outcome: PlanOutcome = planned.outcome
    if not (outcome.solved and outcome.actions):
        return None
    try:
        return context.store.check_plan(seen.obj.ident, outcome.actions, outcome.expected_states, seen.deadline_at,
                                        planned.verdict.steps_before_answer)
    except DeadlineError as exc:  # said as every other stage says it: with the deadline the settings give
        where = str(exc).removeprefix("planning: the deadline passed")
        raise DeadlineError(f"planning: planning deadline of {context.planning.deadline_s:g} s exceeded{where}") \
            from None


def _later_checks(context: Context, obj: ArticulatedObject, planned: PlannedTurn) -> Precheck:
    """The store's checks of a later piece's steps, run behind the answer before VAL on that piece."""
    outcome = planned.outcome

    def check(first: int, last: int) -> str | None:
        try:
            context.store.check_steps(obj.ident, outcome.actions, outcome.expected_states, first, last)
        except ValidationError as exc:
            return f"the store's check refused a_{first}..a_{last}: {exc}"
        return None

    return check


def _incomplete(context: Context, obj: ArticulatedObject, request: PerceptionRequest, print_: str,
                measured: tuple[float, float] | None, mark: int) -> Turn:
    """A perception with unseen links (None): validated like any, then answered `incomplete_perception`. It
    stores no state and changes no plan or execution; only its event (naming the unseen links) is kept."""
    links = request.link_orientations_deg
    check_count(obj, links, "link_orientations_deg")
    check_finite(links, "link_orientations_deg")
    unseen = [k for k, v in enumerate(links, start=1) if v is None]
    if len(unseen) == obj.n_links:
        raise ValidationError("link_orientations_deg: at least one link must be seen (every value is null)")
    named = " and ".join([", ".join(map(str, unseen[:-1])), str(unseen[-1])] if len(unseen) > 1 else
                         [str(unseen[0])])
    reason = (f"link{'s' if len(unseen) > 1 else ''} {named} {'were' if len(unseen) > 1 else 'was'} not seen: "
              "look again")
    turn = Turn(decision=DecisionKind.INCOMPLETE_PERCEPTION, plan_id=None, perceived_state_id=None, next_action=None,
                matched_expected_step=None, reason=reason, unseen_links=tuple(unseen))
    store = context.store
    with object_write(context, obj.ident, mark):  # the base point recorded, not used: it changes nothing
        log_event(store, obj.ident, DecisionKind.INCOMPLETE_PERCEPTION, reason,
                  IncompleteData(unseen_links=tuple(unseen), link_orientations_deg=links, base_point_xy=measured))
        remember(store, obj.ident, request.idempotency_key, print_, turn)
    return turn

"""A perception: perceive -> decide -> (re-plan) -> write, in one function (`perceive`).

It stores all it leads to in one write: the perceived state and, after a re-plan, its problem, plan and expected
states, then the execution, the decision's event and the idempotent answer. A refused or failed write stores none
of it. A perception may arrive at any time: if it moves the execution to another step of the same plan while an
action is dispatched, that action stays on record for feedback only (its feedback is then *late*); a new plan
drops the dispatched action (its feedback then gets a conflict).

Planning and VAL run under the object's lock only: the store (shared by every object) is held just for the write.
A re-plan calls the pipeline once (`pipeline.plan_for_service`), which hands back the plan with a handle on VAL's
verdict, VAL running in its own processes; the store's checks of the plan run meanwhile. A plan VAL checks in one
short run has its write begun before VAL answered: the write reads the verdict inside the store's transaction,
waiting `OVERLAP_WAIT_S` at most, so that a slow VAL (a loaded machine) does not hold the store every object
writes to: the write is then rolled back, VAL waited for outside the store, and the write done again. A plan VAL
refuses is never stored; a re-plan that does not finish within the planning deadline raises DeadlineError and
stores nothing.
"""
from __future__ import annotations

import logging
import time
from dataclasses import dataclass, replace

from planhrc.cooperation import Decision, decide
from planhrc.event_log import IncompleteData
from planhrc.model import ArticulatedObject, ModelError, Perception, perceive as snap
from planhrc.pipeline import PieceVerdict, PlannedTurn, PlanOutcome, deadline_from, plan_for_service
from planhrc.pipeline.later import Precheck
from planhrc.vocabulary import DecisionKind, PlanningStatus

from ..store import DeadlineError, Execution, StoredPlan, StoredState, ValidationError
from ..store import CheckedPlan
from . import refine
from .context import Context
from .idempotency import fingerprint, recall, remember
from .inputs import check_count, check_finite, measured_base
from .log import log_event, record_verdict
from .memory import ObjectMemo
from .turns import Written, adopt, decision_data, follow
from .unit_of_work import object_write, read_mark, serialized
from .values import Turn

log = logging.getLogger(__name__)

# How long a perception's write, begun while VAL checks its new plan in one short run, waits for VAL inside the
# store's transaction: on a quiet machine VAL answers within it; a slower run is waited for outside the store.
OVERLAP_WAIT_S = 0.02


@dataclass(frozen=True)
class PerceptionRequest:
    """A perceived configuration: every link's measured orientation (None: not seen), the base point as measured
    (optional), and the request's idempotency key."""

    object_id: str
    link_orientations_deg: tuple[float | None, ...]
    idempotency_key: str | None = None
    base_point_xy: tuple[float, ...] | None = None


class _ValStillRunning(Exception):
    """VAL did not answer within OVERLAP_WAIT_S of the write: roll it back and wait outside the store."""


@dataclass(frozen=True)
class _Seen:
    """What a perception found before its write: the object as perceived, where its cooperation stands, and the
    decision taken (None: no goal to decide towards)."""

    obj: ArticulatedObject
    perception: Perception
    execution: Execution
    goal: StoredState | None
    plan: StoredPlan | None
    memo: ObjectMemo
    base: refine.Base  # where the checks place a placed object's base point (None: abstract)
    measured: tuple[float, float] | None  # the base point the perception measured
    key: str | None  # the request's idempotency key, and its fingerprint
    fingerprint: str
    mark: int  # where the object's log stood before anything was read (`unit_of_work.read_mark`)
    decision: Decision | None = None


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
    store, links, key = context.store, request.link_orientations_deg, request.idempotency_key
    measured = measured_base(request.base_point_xy)
    with context.locks.hold(request.object_id):
        obj = store.get_object(request.object_id)
        mark = read_mark(context, obj.ident)  # before the remembered answer and the state are read
        print_ = fingerprint({"perception": list(links)} if measured is None else
                             {"perception": list(links), "base_point_xy": list(measured)})
        recalled = recall(store, obj.ident, key, print_, Turn)
        if recalled is not None:
            return recalled
        if any(v is None for v in links):
            return _incomplete(context, obj, request, print_, measured, mark)

        # where the object's cooperation stands
        memo = context.memory.of(store, obj.ident)
        try:  # validated and snapped once, here; a bimanual state takes the robot's control facts (`planhrc.control`)
            perception = snap(obj, links, control=memo.control)
        except ModelError as exc:
            raise ValidationError(str(exc)) from None
        execution = store.get_execution(obj.ident)
        goal = store.get_state(memo.goal_state_id) if memo.goal_state_id is not None else None
        plan, view = context.views.get(store, execution.plan_id)
        base = measured or memo.where  # a perception with a base point places the object (None: abstract)
        seen = _Seen(obj, perception, execution, goal, plan, memo, base, measured, key, print_, mark)
        if goal is None:
            return _write(context, seen).turn  # no decision: nothing to count

        # decide
        decision = decide(perception.atoms, goal.atoms, view, execution.next_step, memo.last_outcome)
        decision = refine.recheck_at(context, obj, base, plan, perception, decision, memo)
        decision = refine.escalate(context, obj, plan, perception, decision, memo, base)
        decision = refine.gate_decision(context, obj, plan, decision, deadline_at)
        seen = replace(seen, decision=decision)
        if decision.kind not in (DecisionKind.REPLAN, DecisionKind.NO_PLAN):
            written = _write(context, seen)
            context.observer.decided(written.turn.decision, None)
            return written.turn

        # re-plan: the pipeline once, VAL running in its own processes meanwhile
        context.validator.stop(obj.ident)  # the plan being replaced needs no more checking
        replan = refine.replan_request(obj, perception, goal.atoms, plan, decision, memo, base, deadline_at)
        with context.observer.span("plan"):  # the object: on `perceive`
            planned = plan_for_service(replan, context.planning, context.validator, context.pool)
        try:
            if planned.outcome.status is PlanningStatus.TIMEOUT:
                raise DeadlineError(f"planning: {planned.outcome.message}")
            checked = _check_plan(context, obj, planned.outcome, deadline_at, planned.verdict.steps_before_answer)
            with context.observer.span("val"):
                if not planned.verdict.read_in_write:
                    planned.verdict.outcome(None)  # VAL's verdict before the write: the store is not held meanwhile
                try:
                    written = _write(context, seen, planned, checked)
                except _ValStillRunning:
                    log.info("VAL was slower than %.0f ms on %s's plan: the write waited for it outside the store",
                             OVERLAP_WAIT_S * 1000, obj.ident)
                    planned.verdict.outcome(None)
                    written = _write(context, seen, planned, checked)
        except BaseException:
            planned.verdict.cancel()  # no VAL process outlives the request
            raise
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


def _write(context: Context, seen: _Seen, planned: PlannedTurn | None = None, checked: CheckedPlan | None = None
           ) -> Written:
    """The perception's one write. With a re-plan whose VAL verdict is read inside the write (`read_in_write`),
    it waits for the verdict before it uses the plan, so it commits a plan VAL accepted or none (a plan VAL
    refuses is stored as a problem without a plan), or raises _ValStillRunning (rolled back) after
    OVERLAP_WAIT_S."""
    store, obj, goal, decision = context.store, seen.obj, seen.goal, seen.decision
    started = time.perf_counter()
    with context.observer.span("store"), object_write(context, obj.ident, seen.mark):
        perceived = store.add_perception(seen.perception)
        outcome: PlanOutcome | None = None
        if planned is not None:
            outcome = planned.verdict.outcome(OVERLAP_WAIT_S if planned.verdict.read_in_write else None)
            if outcome is None:
                raise _ValStillRunning()
            if outcome.status is PlanningStatus.TIMEOUT:
                raise DeadlineError(f"planning: {outcome.message}")
        if goal is None or decision is None:
            written = Written(Turn(DecisionKind.NO_PLAN, None, perceived.id, None, None,
                                   "no goal is set: PUT /objects/{id}/goal first"))
        elif planned is None or outcome is None:
            written = follow(context, obj, perceived, seen.execution, seen.plan, decision, seen.memo, seen.base)
        else:
            written = adopt(context, obj, perceived, goal, decision, outcome, checked, planned.verdict.early_answer())
        turn = written.turn
        data = decision_data(written, goal.id if goal is not None else None,
                             decision.remedy if decision is not None else None, seen.measured)
        log_event(store, obj.ident, turn.decision, turn.reason, data)
        remember(store, obj.ident, seen.key, seen.fingerprint, turn)
    context.observer.stored(time.perf_counter() - started, replanned=planned is not None)
    return written


def _check_plan(context: Context, obj: ArticulatedObject, outcome: PlanOutcome, deadline_at: float,
                first_steps: int | None) -> CheckedPlan | None:
    """The store's checks of a new plan (outside the store's lock), while VAL checks it in its own processes: of
    its first `first_steps` steps only when VAL checks only those before the answer (the rest: `_later_checks`)."""
    if not (outcome.solved and outcome.actions):
        return None
    try:
        return context.store.check_plan(obj.ident, outcome.actions, outcome.expected_states, deadline_at,
                                        first_steps)
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
    turn = Turn(DecisionKind.INCOMPLETE_PERCEPTION, None, None, None, None, reason, unseen_links=tuple(unseen))
    store = context.store
    with object_write(context, obj.ident, mark):  # the base point recorded, not used: it changes nothing
        log_event(store, obj.ident, DecisionKind.INCOMPLETE_PERCEPTION, reason,
                  IncompleteData(unseen_links=tuple(unseen), link_orientations_deg=links, base_point_xy=measured))
        remember(store, obj.ident, request.idempotency_key, print_, turn)
    return turn

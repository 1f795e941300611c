"""The service's one orchestrator: perception -> perceived State -> cooperation model -> (re-)plan -> execution.

Every request that touches an object runs under that object's lock, so one object's requests are serialized
while different objects proceed in parallel. Each entry point validates its input completely before the first
write, so a refused request leaves the knowledge base as it was.

Choices the paper leaves open (see also the service README in the report):

* A goal is stored when it is set (PUT goal), together with a Problem from the latest perceived state when one
  exists. Planning happens at the next perception (the paper: setting a goal triggers a perception), so a goal
  set before any perception simply waits for the first one.
* A perception may arrive at any time. If it moves the execution to another step of the same plan while an
  action is dispatched, that action stays on record for feedback only: its feedback is then recorded as *late*
  and does not move the execution again (the perception already did). A new plan or a new goal drops the
  dispatched action (the store keeps a dispatched action only within its plan): its feedback then gets a
  conflict.
* The current goal, the latest perceived state and the last feedback are read back from the event log, so a
  restarted service continues where it stopped.
"""
from __future__ import annotations

import hashlib
import json
import logging
import math
import os
import signal
import threading
import time
from dataclasses import dataclass, field, replace
from typing import Any, Callable, Iterator, Sequence, TypeVar

from planhrc import pipeline
from planhrc.cooperation import Decision, FailureHistory, PlanView, decide, escalate
from planhrc.geometry import GeometryError, ObjectGeometry, configuration_feasible, link_centres, reach_shortfall
from planhrc.ordering import HelpItem, Move, Placement, help_for, leaves_the_table
from .store import (ConflictError, DeadlineError, Execution, KnowledgeBase, NotFoundError, StoredAction, StoredEvent,
                    StoredPlan, StoredState, ValidationError)
from planhrc.model import ArticulatedObject, Formulation, ModelError, Perception, State, make_object, perceive, snap_angle
from planhrc.planner.armed import ArmedValidators
from planhrc.planner.errors import PlannerError
from planhrc.planner.fast_downward import has_conditional_effects
from planhrc.pipeline import (PlanningConfig, PlanOutcome, action_motion, config_from_settings, merge_macro_steps,
                              move_of)
from planhrc.settings import Settings
from planhrc.translator import PddlTask, domain_text, read_domain_model, translate
from planhrc.vocabulary import (ActionOutcome, DecisionKind, ExecutionStatus, FailureReason, PlanningStatus, Remedy,
                                one_of)

from .locks import ObjectLocks
from .planning_pool import PlanningJob, PlanningPool
from .val_gate import VERDICT_EVENT, WITHHELD_EVENT, LaterPieces, PieceRecord, Verdict, check_piece, verdict_data, verdict_of
from .store import CheckedPlan
from .store.knowledge_base import MAX_EVENTS_PAGE
from .public import (event_public, execution_public, object_public, plan_public, problem_public,
                     state_public)

log = logging.getLogger(__name__)

_T = TypeVar("_T")

IDLE, READY, DISPATCHED = ExecutionStatus.IDLE, ExecutionStatus.READY, ExecutionStatus.DISPATCHED


@dataclass(frozen=True)
class Pending:
    """VAL still checking a new plan, in its own process (`pipeline.start_val`): `outcome(t)` waits up to t seconds
    (None: until VAL answers or the deadline passes) and gives the checked outcome, or None while VAL still runs;
    `stop()` ends the run (`Orchestrator._validate_and_check`)."""

    plan: PlanOutcome
    check: pipeline.ValCheck
    config: PlanningConfig
    deadline_at: float

    def outcome(self, timeout_s: float | None) -> PlanOutcome | None:
        return pipeline.finish_val(self.plan, self.check, self.config, self.deadline_at, timeout_s)

    def stop(self) -> None:
        self.check.cancel()

# How long a perception's write, begun while VAL checks its new plan, waits for VAL inside the store's transaction.
# Relative 20 x 12: VAL answers 1-4 ms into the write on a quiet machine; a slower run waits outside the store.
OVERLAP_WAIT_S = 0.02


class _ValStillRunning(Exception):
    """VAL did not answer within OVERLAP_WAIT_S of the write: roll it back and wait outside the store."""


@dataclass
class _ObjectMemo:
    """What the event log says about an object, read incrementally (events are append-only)."""

    seq: int = 0
    goal_state_id: str | None = None
    perceived_state_id: str | None = None
    last_outcome: ActionOutcome | None = None
    base_point_xy: tuple[float, float] | None = None  # set: the object is placed in the cell (geometric checks)
    measured_base_xy: tuple[float, float] | None = None  # where the latest perception measured the base point

    @property
    def where(self) -> tuple[float, float] | None:
        """The base point the geometric checks use: the latest measured one, else the one the object was created
        with; None for an abstract object (no geometric checks)."""
        if self.base_point_xy is None:
            return None
        return self.measured_base_xy or self.base_point_xy
    failure: FailureHistory | None = None  # the motion failing since the last success, and the remedies tried
    split_plans: set[str] = field(default_factory=set)  # plans whose macro steps are dispatched step by step
    last_decision: str | None = None  # the kind of the last decision logged
    val: PieceRecord | None = None  # the latest plan adopted with only its first piece validated, and its verdicts


class Orchestrator:
    """Runs the cooperation loop of every object against one knowledge base."""

    def __init__(self, kb: KnowledgeBase, settings: Settings, locks: ObjectLocks | None = None,
                 pool: PlanningPool | None = None) -> None:
        self.kb = kb
        self.pool = pool  # large tasks are planned there (see planning_pool), the rest in this process
        self.settings = settings
        self.planning = config_from_settings(settings)
        self.merge_macro_steps = settings.merge_macro_steps
        self.locks = locks or ObjectLocks()
        self._views: dict[str, tuple[StoredPlan, PlanView]] = {}  # plan id -> view, one plan per object
        self._view_of: dict[str, str] = {}  # object id -> the plan id cached in _views
        self._memos: dict[str, _ObjectMemo] = {}
        self._guard = threading.Lock()
        self._perceptions = 0  # counted only for the crash test's hook
        self._later: dict[str, tuple[str, LaterPieces]] = {}  # object id -> (plan id, its later pieces under VAL)
        self.armed = ArmedValidators() if settings.val_armed and settings.validate_plans else None

    def close(self) -> None:
        """Stop the VAL runs still checking plans' later pieces and the armed VAL processes (the service stops)."""
        with self._guard:
            runs = [later for _, later in self._later.values()]
            self._later.clear()
        for later in runs:
            later.cancel()
        if self.armed is not None:
            self.armed.close()

    # -- objects ------------------------------------------------------------------------------------------
    def create_object(self, name: str, links: int | Sequence[float], orientations: int,
                      formulation: str, base_point_xy: Sequence[float] | None = None) -> ArticulatedObject:
        """Create an object; with `base_point_xy` it is placed in the cell (kept in its `object_created` event,
        which the log keeps whole), and its goals and plans are checked geometrically. Its planning task
        (links x orientations) is bounded by the setting `max_task_size`."""
        probe = make_object("probe", formulation, links, orientations, name)  # ModelError before an id is taken
        size = probe.n_links * probe.orientations
        if size > self.settings.max_task_size:
            raise ValidationError(
                f"links, orientations: {probe.n_links} links x {probe.orientations} orientations = {size} is over "
                f"the largest planning task this service takes ({self.settings.max_task_size}, "
                "PLANHRC_MAX_TASK_SIZE)")
        base = None
        if base_point_xy is not None:
            try:
                base = ObjectGeometry.of(probe, (base_point_xy[0], base_point_xy[1])).base_point_xy
            except (GeometryError, IndexError, TypeError) as exc:
                raise ValidationError(f"base_point_xy: expected [x, y] in metres ({exc})") from None
        object_id = self.kb.new_object_id()
        obj = make_object(object_id, formulation, links, orientations, name)
        with self.locks.hold(object_id), self.kb.transaction():
            self.kb.create_object(obj)
            self.kb.add_event(object_id, "object_created", f"object {object_id} created",
                              {"formulation": obj.formulation.value, "links": obj.n_links,
                               "orientations": obj.orientations,
                               "base_point_xy": list(base) if base is not None else None})
        return obj

    def base_point(self, object_id: str) -> tuple[float, float] | None:
        """Where the object's base point lies now: as last measured, else as created (None: abstract)."""
        return self._memo(object_id).where

    def goal_state_id(self, object_id: str) -> str | None:
        return self._memo(object_id).goal_state_id

    # -- goal ---------------------------------------------------------------------------------------------
    def set_goal(self, object_id: str, link_orientations_deg: Sequence[float] | None = None,
                 joint_angles_deg: Sequence[float | None] | None = None,
                 allow_infeasible: bool = False) -> dict[str, Any]:
        """Store a goal. For a placed object a complete goal configuration is checked first: one off the table,
        inside the robot or folded onto itself is refused naming the links (unless `allow_infeasible`); links
        beyond the robot's reach are accepted with a warning (the robot will ask the human for them)."""
        with self.locks.hold(object_id):
            obj = self.kb.get_object(object_id)
            atoms = _goal_atoms(obj, link_orientations_deg, joint_angles_deg)
            memo = self._memo(object_id)
            warnings = self._goal_warnings(obj, memo, atoms, link_orientations_deg, allow_infeasible)
            with self.kb.transaction():
                goal = self.kb.add_state(object_id, "goal", atoms)
                problem = None
                if memo.perceived_state_id is not None:
                    problem = self.kb.add_problem(object_id, memo.perceived_state_id, goal.id)
                # The old plan was made for another goal: the next perception decides anew.
                self.kb.set_execution(object_id, Execution(None, None, IDLE, None))
                self._check_later(obj, None, None)
                self.kb.add_event(object_id, "goal_set",
                                  "goal set; the next perception plans towards it"
                                  + (f" ({'; '.join(warnings)})" if warnings else ""),
                                  {"goal_state_id": goal.id, "problem_id": problem.id if problem else None,
                                   "warnings": warnings})
            return {"goal_state_id": goal.id, "problem_id": problem.id if problem else None, "warnings": warnings}

    def _goal_warnings(self, obj: ArticulatedObject, memo: _ObjectMemo, atoms: frozenset,
                       link_orientations_deg: Sequence[float] | None, allow_infeasible: bool) -> list[str]:
        """The geometric check of a goal (placed objects, complete goals): raises ValidationError for an infeasible
        one unless allowed; the warnings to answer with."""
        base = memo.where
        if base is None:
            return []
        links = self._goal_links(obj, memo, atoms, link_orientations_deg)
        if links is None:
            return []
        result = configuration_feasible(ObjectGeometry.of(obj, base), links)
        blocking = [r for r in result.reasons if r.code != "out_of_reach"]
        warnings = [f"goal: {r.message}" for r in result.reasons if r.code == "out_of_reach"]
        if blocking and not allow_infeasible:
            raise ValidationError("goal: " + "; ".join(r.message for r in blocking)
                                  + " (send allow_infeasible: true to set it anyway)")
        if blocking:
            warnings = [f"goal accepted although infeasible: {r.message}" for r in blocking] + warnings
        return warnings

    def _goal_links(self, obj: ArticulatedObject, memo: _ObjectMemo, atoms: frozenset,
                    link_orientations_deg: Sequence[float] | None) -> tuple[int, ...] | None:
        """Every link's absolute orientation in a complete goal. Absolute formulation: as given. Relative: the goal
        holds only the angles between links and the robot turns downstream links, so l1 stays where it was last
        perceived (where it is given, before the first perception); None when the goal leaves a joint free or l1
        is not known."""
        values = obj.joint_values_of(atoms)
        if len(values) != obj.n_joints:
            return None
        if obj.formulation is Formulation.ABSOLUTE:
            return tuple(values[k] for k in obj.joint_indices)
        perceived = self.kb.get_state(memo.perceived_state_id) if memo.perceived_state_id is not None else None
        if perceived is not None and perceived.link_orientations_deg:
            first = snap_angle(perceived.link_orientations_deg[0], obj.orientations)
        elif link_orientations_deg is not None:
            first = int(float(link_orientations_deg[0])) % 360
        else:
            return None
        return obj.link_orientations_of(atoms, first)

    # -- perception ---------------------------------------------------------------------------------------
    def handle_perception(self, object_id: str, link_orientations_deg: Sequence[float | None],
                          idempotency_key: str | None = None,
                          base_point_xy: Sequence[float] | None = None) -> dict[str, Any]:
        """Decide on one perception and store all it leads to in one write: the perceived state and, after a
        re-plan, its problem, plan and expected states, then the execution, the decision's event and the
        idempotent response. A refused or failed write stores none of it.

        Planning and VAL run under the object's lock only: the store (shared by every object) is held just for
        the write. While VAL checks a new plan (its own processes), the plan is validated for the store
        (`check_plan`); a plan VAL checks in one short run (no conditional effects) has its write begun
        meanwhile, which waits for VAL's verdict inside the transaction for `OVERLAP_WAIT_S` at most
        (`_decide_and_write`). A plan VAL refuses is
        never stored; a re-plan that does not finish within the planning deadline raises DeadlineError and
        stores nothing. With the early answer (`val_early_answer`, domains with conditional effects) VAL has
        accepted the new plan's first motion before the write and checks the rest behind the answer; a continue
        or resume passes the VAL gate first (`_gate_decision`).

        `base_point_xy` is where the worker measured the object's base point p1 (the object is a physical body:
        turns and hands slide it). It is kept with the perception's event, and from then on the goals, plans,
        reach and help of a placed object are checked there instead of where the object was created; a plan
        whose rest would leave the table at the measured point is not dispatched as is but re-planned."""
        measured = _measured_base(base_point_xy)
        with self.locks.hold(object_id):
            obj = self.kb.get_object(object_id)
            fingerprint = _fingerprint({"perception": list(link_orientations_deg)} if measured is None else
                                       {"perception": list(link_orientations_deg), "base_point_xy": list(measured)})
            recalled = self._recall(object_id, idempotency_key, fingerprint)
            if recalled is not None:
                return recalled
            if any(v is None for v in link_orientations_deg):
                return self._incomplete_perception(obj, link_orientations_deg, idempotency_key, fingerprint,
                                                   measured)
            try:
                perception = perceive(obj, link_orientations_deg)  # validated and snapped once, here
            except ModelError as exc:
                raise ValidationError(str(exc)) from None
            memo = self._memo(object_id)
            base = (measured or memo.where) if memo.base_point_xy is not None else None
            execution = self.kb.get_execution(object_id)
            goal = self.kb.get_state(memo.goal_state_id) if memo.goal_state_id is not None else None
            plan, view = self._plan_view(execution.plan_id)
            decision = None
            outcome = None
            checked = None
            later = None
            pending = None
            if goal is not None:
                deadline_at = pipeline.deadline_from(self.planning)
                decision = decide(perception.atoms, goal.atoms, view, execution.next_step, memo.last_outcome)
                decision = self._recheck_at(obj, base, plan, perception, decision)
                decision = self._escalate(obj, plan, perception, decision, memo, base)
                decision = self._gate_decision(obj, plan, decision, deadline_at)
                if decision.kind in (DecisionKind.REPLAN, DecisionKind.NO_PLAN):
                    self._check_later(obj, None, None)  # the plan being replaced needs no more checking
                    outcome, checked, later, pending = self._plan_for(obj, perception, goal.atoms, plan, decision,
                                                                      memo, base, deadline_at)
                    if outcome.status is PlanningStatus.TIMEOUT:
                        raise DeadlineError(f"planning: {outcome.message}")
            try:
                answer = self._decide_and_write(obj, perception, execution, goal, plan, decision, outcome, checked,
                                                later, idempotency_key, fingerprint, pending, measured)
            except BaseException:
                if later is not None:
                    later.cancel()
                if pending is not None:
                    pending.stop()  # no VAL process outlives the request
                raise
            return answer

    def _decide_and_write(self, obj: ArticulatedObject, perception: Perception, execution: Execution,
                          goal: StoredState | None, plan: StoredPlan | None, decision: Decision | None,
                          outcome: PlanOutcome | None, checked: CheckedPlan | None, later: LaterPieces | None,
                          idempotency_key: str | None, fingerprint: str,
                          pending: Pending | None = None,
                          measured: tuple[float, float] | None = None) -> dict[str, Any]:
        """The perception's one write (see `handle_perception`); then the new plan's later pieces, if VAL is still
        checking them, record their verdicts against the stored plan.

        With `pending`, VAL is still checking the new plan: the write begins meanwhile and waits for VAL's verdict
        before it uses the plan, so it commits a plan VAL accepted or none (a plan VAL refuses is stored as a
        problem without a plan, as before). It waits inside the store's transaction for `OVERLAP_WAIT_S` at most:
        a VAL run slower than that (a loaded machine) must not hold the store every object writes to, so the
        write is rolled back, VAL waited for outside the store, and the write done again."""
        if pending is not None:
            try:
                return self._write_decision(obj, perception, execution, goal, plan, decision, outcome, checked, later,
                                            idempotency_key, fingerprint, pending, measured)
            except _ValStillRunning:
                outcome = pending.outcome(None)
                log.info("VAL was slower than %.0f ms on %s's plan: the write waited for it outside the store",
                         OVERLAP_WAIT_S * 1000, obj.ident)
        return self._write_decision(obj, perception, execution, goal, plan, decision, outcome, checked, later,
                                    idempotency_key, fingerprint, None, measured)

    def _write_decision(self, obj: ArticulatedObject, perception: Perception, execution: Execution,
                        goal: StoredState | None, plan: StoredPlan | None, decision: Decision | None,
                        outcome: PlanOutcome | None, checked: CheckedPlan | None, later: LaterPieces | None,
                        idempotency_key: str | None, fingerprint: str, pending: Pending | None,
                        measured: tuple[float, float] | None = None) -> dict[str, Any]:
        object_id = obj.ident
        new_view = None
        with self.kb.transaction():
            perceived = self.kb.add_perception(perception)
            if pending is not None:
                outcome = pending.outcome(OVERLAP_WAIT_S)
                if outcome is None:
                    raise _ValStillRunning()
            if outcome is not None and outcome.status is PlanningStatus.TIMEOUT:
                raise DeadlineError(f"planning: {outcome.message}")
            extra: dict[str, Any] = {}
            if measured is not None:  # kept with the perception's event: a restarted service checks there too
                extra["base_point_xy"] = list(measured)
            if goal is None or decision is None:
                answer = _answer(DecisionKind.NO_PLAN, None, perceived.id, None, None,
                                 "no goal is set: PUT /objects/{id}/goal first")
            else:
                extra["goal_state_id"] = goal.id
                if decision.remedy is not None:
                    extra["remedy"] = decision.remedy
                if outcome is None:
                    answer = self._follow(obj, perceived, execution, plan, decision, extra)
                else:
                    answer, new_view = self._adopt(obj, perceived, goal, decision, outcome, extra, checked,
                                                   later)
            self._log_decision(object_id, answer, extra)
            self._remember(object_id, idempotency_key, fingerprint, answer)
            self._crash_point()
        if new_view is not None:
            self._keep_view(*new_view)
        if outcome is not None:  # the object's plan changed (or is gone): its checks in the background follow
            self._check_later(obj, new_view[0].id if new_view is not None else None,
                              later if "val_pieces" in extra else None)
        return answer

    # -- VAL behind the answer, and the gate of every dispatch ----------------------------------------------------
    def _check_later(self, obj: ArticulatedObject, plan_id: str | None, later: LaterPieces | None) -> None:
        """The object's plan is now `plan_id`: stop checking the previous plan's later pieces; with `later`, record
        each verdict on the new plan's later pieces as it comes (an event each, `val_verdict`)."""
        with self._guard:
            previous = self._later.pop(obj.ident, None)
            if later is not None and plan_id is not None:
                self._later[obj.ident] = (plan_id, later)
        if previous is not None and previous[1] is not later:
            previous[1].cancel()
        if later is not None and plan_id is not None:
            numbers = {p.first: i for i, p in enumerate(later.pieces, start=max(1, len(later.accepted)) + 1)}
            later.attach(lambda piece, result: self._record_verdict(
                obj.ident, plan_id, numbers[piece.first], (piece.first, piece.last),
                Verdict(result.valid, "Plan valid" if result.valid else result.reason), result.seconds))
            later.start()  # only now: the first piece's VAL and the write had the cores to themselves

    def _record_verdict(self, object_id: str, plan_id: str, number: int, piece: tuple[int, int], verdict: Verdict,
                        seconds: float) -> None:
        words = "accepted" if verdict.accepted else f"refused ({verdict.reason})"
        self.kb.add_event(object_id, VERDICT_EVENT,
                          f"VAL {words} piece {number} of plan {plan_id}: a_{piece[0]}..a_{piece[1]}",
                          verdict_data(plan_id, number, piece, verdict, seconds))

    def _gate_decision(self, obj: ArticulatedObject, plan: StoredPlan | None, decision: Decision,
                       deadline_at: float) -> Decision:
        """A decision that would dispatch a step of `plan` (continue, resume) stands only when VAL has accepted
        every piece the motion lies in (`_val_gate`); when VAL refused one, it becomes a re-plan saying so."""
        if (decision.kind not in (DecisionKind.CONTINUE, DecisionKind.RESUME) or plan is None
                or decision.next_step is None or not 1 <= decision.next_step <= len(plan.actions)):
            return decision
        refusal = self._val_gate(obj, plan, plan.actions[decision.next_step - 1], deadline_at)
        if refusal is None:
            return decision
        return Decision(DecisionKind.REPLAN, None, decision.matched_expected_step,
                        f"{decision.reason}; but {refusal}: re-plan from the perceived state")

    def _val_gate(self, obj: ArticulatedObject, plan: StoredPlan, action: StoredAction, deadline_at: float
                  ) -> str | None:
        """None when VAL has accepted every piece of `plan` holding the motion that starts with `action` (plans
        validated whole before they were stored always pass); else VAL's refusal in words. A verdict still to
        come is waited for; one that will not come (the service restarted while VAL ran, or the verdict could
        not be recorded) is asked of VAL again here. Raises DeadlineError when no verdict comes by
        `deadline_at`."""
        last = self._last_step(obj, plan, action)
        waited: set[int] = set()
        while True:
            record = self._memo(obj.ident).val
            if record is None or record.plan_id != plan.id:
                return None
            missing = None
            for number in record.covering(action.step, last):
                verdict = record.verdicts.get(number)
                if verdict is None:
                    missing = number
                    break
                if not verdict.accepted:
                    first, end = record.bounds(number)
                    return f"VAL refused piece {number} of plan {plan.id} (a_{first}..a_{end}): {verdict.reason}"
            if missing is None:
                return None
            first, end = record.bounds(missing)
            left = deadline_at - time.monotonic()
            with self._guard:
                running = self._later.get(obj.ident)
            if missing not in waited and running is not None and running[0] == plan.id and not running[1].cancelled:
                waited.add(missing)
                if not running[1].wait(first, left):
                    raise DeadlineError(f"planning: planning deadline of {self.planning.deadline_s:g} s exceeded "
                                        f"while VAL checked a_{first}..a_{end} of plan {plan.id}")
                continue
            self._recheck(obj, plan, record, missing, deadline_at)

    def _recheck(self, obj: ArticulatedObject, plan: StoredPlan, record: PieceRecord, number: int,
                 deadline_at: float) -> None:
        """VAL on one piece of a stored plan, built again from the store (its problem, steps and expected
        states), and its verdict recorded."""
        first, last = record.bounds(number)
        problem = self.kb.get_problem(plan.problem_id)
        init, goal = self.kb.get_state(problem.init_state_id), self.kb.get_state(problem.goal_state_id)
        task = translate(obj, init.atoms, goal.atoms, read_domain_model(self.planning.tbox_path, obj.formulation.value),
                         pipeline.problem_name(obj))
        _, view = self._plan_view(plan.id)
        assert view is not None
        steps = tuple(pipeline.step_text(a.spec) for a in sorted(plan.actions, key=lambda a: a.step))
        piece = pipeline.piece_of(obj, task.problem, steps, view.expected_states, first, last)
        left = deadline_at - time.monotonic()
        try:
            if left <= 0:
                raise PlannerError("no time left for VAL")
            result = check_piece(task.validation_domain, piece, left, raising=True)
        except PlannerError as exc:
            raise DeadlineError(f"planning: planning deadline of {self.planning.deadline_s:g} s exceeded while VAL "
                                f"checked a_{first}..a_{last} of plan {plan.id} again ({exc})") from None
        log.info("VAL checked piece %d of plan %s again: %s", number, plan.id, result.reason)
        self._record_verdict(obj.ident, plan.id, number, (first, last),
                             Verdict(result.valid, "Plan valid" if result.valid else result.reason), result.seconds)

    def _crash_point(self) -> None:
        """The crash test's hook (setting `crash_in_perception_write`, off by default): die like a killed process,
        with the perception's write complete but not committed."""
        if not self.settings.crash_in_perception_write:
            return
        with self._guard:
            self._perceptions += 1
            due = self._perceptions >= self.settings.crash_in_perception_write
        if due:
            log.critical("crash_in_perception_write: killing the service inside a perception's write")
            os.kill(os.getpid(), signal.SIGKILL)

    def _incomplete_perception(self, obj: ArticulatedObject, link_orientations_deg: Sequence[float | None],
                               idempotency_key: str | None, fingerprint: str,
                               measured: tuple[float, float] | None = None) -> dict[str, Any]:
        """A perception with unseen links (None): validated like any, then answered `incomplete_perception`. It
        stores no state and changes no plan or execution; only its event (naming the unseen links) is kept."""
        if len(link_orientations_deg) != obj.n_links:
            raise ValidationError(f"link_orientations_deg: expected {obj.n_links} values (one per link), "
                                  f"got {len(link_orientations_deg)}")
        _check_finite(link_orientations_deg, "link_orientations_deg")
        unseen = [k for k, v in enumerate(link_orientations_deg, start=1) if v is None]
        if len(unseen) == obj.n_links:
            raise ValidationError("link_orientations_deg: at least one link must be seen (every value is null)")
        named = " and ".join([", ".join(map(str, unseen[:-1])), str(unseen[-1])] if len(unseen) > 1 else
                             [str(unseen[0])])
        reason = f"link{'s' if len(unseen) > 1 else ''} {named} {'were' if len(unseen) > 1 else 'was'} not seen: look again"
        answer = _answer(DecisionKind.INCOMPLETE_PERCEPTION, None, None, None, None, reason)
        answer["unseen_links"] = unseen
        with self.kb.transaction():
            data: dict[str, Any] = {"unseen_links": unseen, "link_orientations_deg": list(link_orientations_deg)}
            if measured is not None:  # recorded, not used: an incomplete perception changes nothing
                data["base_point_xy"] = list(measured)
            self.kb.add_event(obj.ident, DecisionKind.INCOMPLETE_PERCEPTION, reason, data)
            self._remember(obj.ident, idempotency_key, fingerprint, answer)
        return answer

    def _placement(self, obj: ArticulatedObject, perception: Perception,
                   base: tuple[float, float] | None) -> Placement | None:
        """Where a placed object lies at this perception, its base point at `base` (None for an abstract one: no
        geometric checks)."""
        if base is None:
            return None
        return Placement(ObjectGeometry.of(obj, base), tuple(float(v) for v in perception.snapped_deg),
                         whole_turn_deg=_whole_turn_deg(obj))

    def _validate_and_check(self, obj: ArticulatedObject, outcome: PlanOutcome, deadline_at: float,
                            started: pipeline.ValCheck | None = None
                            ) -> tuple[PlanOutcome, CheckedPlan | None, LaterPieces | None, Pending | None]:
        """VAL on a new plan beside the store's checks of the plan (`check_plan`, outside the store's lock). The plan
        is usable only when VAL accepted it (`validated`), or, with the early answer, as far as VAL accepted it
        (`validated_steps`): then the later pieces come back too (`LaterPieces`), for the caller to start VAL on them
        once the plan is stored, and to record their verdicts.

        A plan VAL checks in one short run (a domain without conditional effects: VAL's fixed cost, a few ms) comes
        back with VAL still running in its own process (`started`, begun by the pipeline before the replay, or
        begun here) as `Pending` (the last item), whose `outcome(t)` gives the checked outcome once VAL answered:
        the caller begins its write meanwhile (`_decide_and_write`). Nothing in this process waits for that VAL run
        on a thread, so the write does not compete with it for the interpreter. Otherwise Pending is None and VAL
        has answered (its pieces in threads that wait for their processes, beside `check_plan`)."""
        if not (outcome.solved and outcome.actions):
            if started is not None:
                started.cancel()
            return outcome, None, None, None
        if started is None and self._val_beside(outcome.task):
            assert outcome.task is not None
            begun = self._start_val(obj, outcome.task, outcome.steps)
            if isinstance(begun, PlanOutcome):
                return begun, None, None, None
            started = begun
        if started is not None:
            try:
                checked = self.kb.check_plan(obj.ident, outcome.actions, outcome.expected_states, deadline_at)
            except BaseException:
                started.cancel()
                raise
            return outcome, checked, None, Pending(outcome, started, self.planning, deadline_at)
        first = (pipeline.early_answer_first_piece(obj, outcome, self.merge_macro_steps)
                 if self.planning.validate and not outcome.validated and self.settings.val_early_answer else None)
        if first is not None:
            return self._check_first(obj, outcome, first, deadline_at)
        checked_outcome: list[PlanOutcome] = []
        val = None
        if self.planning.validate and not outcome.validated:
            def run() -> PlanOutcome:
                return pipeline.validate(outcome, obj, self.planning, deadline_at)
            val = threading.Thread(target=lambda: checked_outcome.append(self._guarded(obj, run)), name="planhrc-val")
            val.start()
        try:
            checked = self.kb.check_plan(obj.ident, outcome.actions, outcome.expected_states, deadline_at)
        except BaseException:
            if val is not None:
                val.join()
            raise
        if val is None:
            return outcome, checked, None, None
        val.join()
        return checked_outcome[0], checked, None, None

    def _check_first(self, obj: ArticulatedObject, outcome: PlanOutcome, first: int, deadline_at: float
                     ) -> tuple[PlanOutcome, CheckedPlan | None, LaterPieces | None, Pending | None]:
        """The early answer: VAL on the plan's first motion (its first `first` steps) before the answer, cut into
        `val_pieces` pieces whose runs (on armed processes) go on beside the store's `check_plan`, the rest of the
        plan returned as `LaterPieces`. VAL's cost grows with the steps of this domain (about 7 ms a step on the
        absolute 20 x 12 task, 4 ms fixed), so two pieces at once answer a 5-step motion in about two thirds of
        one run's time."""
        assert outcome.task is not None
        parts = max(1, self.planning.val_pieces)
        pieces = pipeline.early_pieces(obj, outcome, self.planning.val_pieces, first, parts)
        before = tuple(p for p in pieces if p.last <= first)
        later = LaterPieces(outcome.task.validation_domain, pieces[len(before):], self.planning.deadline_s,
                            accepted=tuple((p.first, p.last) for p in before))
        task = outcome.task
        checks = self._guarded(obj, lambda: pipeline.start_pieces(task, before, self.armed))
        if isinstance(checks, PlanOutcome):
            later.cancel()
            return checks, None, None, None
        try:
            checked = self.kb.check_plan(obj.ident, outcome.actions, outcome.expected_states, deadline_at)
        except BaseException:
            for check in checks:
                check.cancel()
            later.cancel()
            raise
        result = self._guarded(obj, lambda: pipeline.finish_first(outcome, before, checks, self.planning,
                                                                  deadline_at))
        if not (result.solved and result.validated_steps):
            later.cancel()
            return result, checked, None, None
        return result, checked, later, None

    def _start_val(self, obj: ArticulatedObject, task: PddlTask, steps: Sequence[str]
                   ) -> pipeline.ValCheck | PlanOutcome:
        """`pipeline.start_val`, or the error outcome when VAL cannot be started."""
        return self._guarded(obj, lambda: pipeline.start_val(task, steps, self.armed))

    def _val_beside(self, task: PddlTask | None) -> bool:
        """Whether a plan of this task is checked by one VAL run started at once and read after the write began:
        VAL on, and a domain without conditional effects (one short run)."""
        return (self.planning.validate and task is not None
                and not has_conditional_effects(task.validation_domain))

    def _run_pipeline(self, obj: ArticulatedObject, init: State, goal: State,
                      placement: Placement | None = None, deadline_at: float | None = None
                      ) -> tuple[PlanOutcome, pipeline.ValCheck | None]:
        """The pipeline up to VAL (left to `_validate_and_check`): in a worker of the planning pool for a large
        task, else here; here, a plan VAL checks in one short run has VAL started on its steps before the replay
        (the second item, else None)."""
        pool = self.pool
        if pool is not None and pool.takes(obj):
            # with the early answer VAL runs here, after the worker's outcome: the first piece beside `check_plan`
            config = replace(self.planning, validate=False) if self.settings.val_early_answer else self.planning
            job = PlanningJob(obj, init, goal, config, placement,
                              pipeline.deadline_from(self.planning) if deadline_at is None else deadline_at)
            return self._guarded(obj, lambda: pool.plan(job)), None
        deadline_at = pipeline.deadline_from(self.planning) if deadline_at is None else deadline_at
        found = self._guarded(obj, lambda: pipeline.find_plan(obj, init, goal, self.planning, placement=placement,
                                                              deadline_at=deadline_at))
        if isinstance(found, PlanOutcome):
            return found, None
        started = self._start_val(obj, found.task, found.steps) if self._val_beside(found.task) else None
        if isinstance(started, PlanOutcome):
            return started, None
        try:
            return self._guarded(obj, lambda: pipeline.expect(obj, init, goal, found, deadline_at)), started
        except BaseException:
            if started is not None:
                started.cancel()
            raise

    def _guarded(self, obj: ArticulatedObject, stage: Callable[[], _T]) -> _T | PlanOutcome:
        try:
            return stage()
        except Exception as exc:  # a crashing stage must not leave the perception without a decision
            log.exception("planning failed for %s", obj.ident)
            return PlanOutcome(PlanningStatus.ERROR, f"{type(exc).__name__}: {exc}", self.planning.planner)

    def _escalate(self, obj: ArticulatedObject, plan: StoredPlan | None, perception: Perception,
                  decision: Decision, memo: _ObjectMemo, base: tuple[float, float] | None) -> Decision:
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
        macro = self._last_step(obj, plan, action) - action.step + 1
        reachable = self._reachable(obj, perception, base, motion["turned_link_index"], motion["held_link_index"])
        return escalate(decision, failure, (motion["joint_index"], motion["turned_link_index"]), macro, reachable)

    def _recheck_at(self, obj: ArticulatedObject, base: tuple[float, float] | None, plan: StoredPlan | None,
                    perception: Perception, decision: Decision) -> Decision:
        """A decision to go on with the current plan, checked where the object lies now: when the rest of the plan
        would put a link past the table's edge or inside the robot with the base point at `base` (as measured;
        the plan was checked where the base point was then), the plan is not dispatched as is: re-plan."""
        if (base is None or plan is None or decision.next_step is None
                or decision.kind not in (DecisionKind.CONTINUE, DecisionKind.RESUME)):
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

    def _reachable(self, obj: ArticulatedObject, perception: Perception, base: tuple[float, float] | None,
                   *links: int) -> bool:
        """Whether the robot reaches the grasp points of `links` as perceived, the base point at `base` (always,
        for an abstract object)."""
        if base is None:
            return True
        centres = link_centres(ObjectGeometry.of(obj, base), perception.snapped_deg)
        return all(reach_shortfall(centres[k - 1]) <= 1e-9 for k in links if k >= 1)

    def _plan_for(self, obj: ArticulatedObject, perception: Perception, goal: State, plan: StoredPlan | None,
                  decision: Decision, memo: _ObjectMemo, base: tuple[float, float] | None,
                  deadline_at: float | None = None
                  ) -> tuple[PlanOutcome, CheckedPlan | None, LaterPieces | None, Pending | None]:
        """The new plan a decision asks for: the current plan's rest with the failing joint turned the other way
        round (remedy other_way), else the planner's (ordered on the table for a placed object, its base point at
        `base`); checked by VAL and by the store (`_validate_and_check`, whose VAL may still be running: see
        there), all within the planning deadline."""
        deadline_at = pipeline.deadline_from(self.planning) if deadline_at is None else deadline_at
        outcome, started = self._new_plan(obj, perception, goal, plan, decision, memo, deadline_at, base)
        return self._validate_and_check(obj, outcome, deadline_at, started)

    def _new_plan(self, obj: ArticulatedObject, perception: Perception, goal: State, plan: StoredPlan | None,
                  decision: Decision, memo: _ObjectMemo, deadline_at: float,
                  base: tuple[float, float] | None) -> tuple[PlanOutcome, pipeline.ValCheck | None]:
        placement = self._placement(obj, perception, base)
        if (decision.remedy == Remedy.OTHER_WAY and plan is not None and memo.failure is not None
                and decision.matched_expected_step is not None):
            rest = [a for a in sorted(plan.actions, key=lambda a: a.step) if a.step >= decision.matched_expected_step]
            moves = _other_way(obj, [move_of(obj, a.spec) for a in rest], memo.failure)
            if moves is not None:
                try:
                    return pipeline.plan_moves(obj, perception.atoms, goal, moves, self.planning,
                                               placement=placement, defer_validation=True), None
                except Exception as exc:  # the composed plan does not hold: let the planner try
                    log.warning("the other way round failed for %s: %s", obj.ident, exc)
        return self._run_pipeline(obj, perception.atoms, goal, placement, deadline_at)

    def _follow(self, obj: ArticulatedObject, perceived: StoredState, execution: Execution,
                plan: StoredPlan | None, decision: Decision, extra: dict[str, Any]) -> dict[str, Any]:
        """Goal reached, continue or resume: the execution moves within the current plan; or the human is asked
        to do the next motion, and the execution waits for the next perception."""
        if decision.kind == DecisionKind.HUMAN_HELP_REQUESTED:
            assert plan is not None and decision.next_step is not None
            action = plan.actions[decision.next_step - 1]
            last = self._last_step(obj, plan, action)
            moves = [move_of(obj, a.spec) for a in sorted(plan.actions, key=lambda a: a.step)
                     if action.step <= a.step <= last]
            where = self._memo(obj.ident).where  # None: an abstract object
            base = (_base_of(extra) or where) if where is not None else None
            seen = tuple(float(snap_angle(v, obj.orientations)) for v in perceived.link_orientations_deg or ())
            if len(seen) != obj.n_links:  # not a perceived state with its observation: the plan's own view
                seen = tuple(float(v) for v in obj.link_orientations_of(perceived.atoms))
            geometry = ObjectGeometry.of(obj, base)
            help_items = help_for(Placement(geometry, seen, whole_turn_deg=_whole_turn_deg(obj)), moves, None,
                                  why=_failure_words(self._memo(obj.ident)))
            self.kb.set_execution(obj.ident, Execution(plan.id, decision.next_step, IDLE, None))
            answer = _answer(DecisionKind.HUMAN_HELP_REQUESTED, plan.id, perceived.id, None,
                             decision.matched_expected_step, decision.reason)
            answer["help"] = _help_public(help_items)
            extra["help"] = answer["help"]
            return answer
        if decision.remedy == Remedy.SPLIT and plan is not None:  # its event says so too, for a restarted service
            self._memo(obj.ident).split_plans.add(plan.id)
        if decision.kind == DecisionKind.GOAL_REACHED:
            self.kb.set_execution(obj.ident, Execution(execution.plan_id, None, ExecutionStatus.GOAL_REACHED,
                                                       execution.dispatched_action_id))
            return _answer(DecisionKind.GOAL_REACHED, execution.plan_id, perceived.id, None,
                           decision.matched_expected_step, decision.reason)
        assert plan is not None and decision.next_step is not None
        action = plan.actions[decision.next_step - 1]
        still_dispatched = execution.status == DISPATCHED and execution.dispatched_action_id == action.id
        self.kb.set_execution(obj.ident, Execution(plan.id, decision.next_step,
                                                   DISPATCHED if still_dispatched else READY,
                                                   execution.dispatched_action_id))
        return _answer(DecisionKind(decision.kind), plan.id, perceived.id, self._action_public(obj, plan, action),
                       decision.matched_expected_step, decision.reason)

    def _adopt(self, obj: ArticulatedObject, perceived: StoredState, goal: StoredState, decision: Decision,
               outcome: PlanOutcome, extra: dict[str, Any], checked: CheckedPlan | None = None,
               later: LaterPieces | None = None) -> tuple[dict[str, Any], tuple[StoredPlan, PlanView] | None]:
        """Store the re-planning's problem and, when solved (and, with VAL on, accepted by VAL: the whole plan, or
        with the early answer its first piece), its plan with expected states; move the execution. With the early
        answer the decision's event names the plan's pieces and the one accepted (`val_pieces`, `val_accepted`):
        the record the dispatch gate starts from, through a restart."""
        problem = self.kb.add_problem(obj.ident, perceived.id, goal.id)
        early = later is not None and outcome.solved and bool(outcome.actions) and not outcome.validated
        if early:
            assert later is not None
            extra["val_pieces"] = ([[a, b] for a, b in later.accepted or ((1, outcome.validated_steps),)]
                                   + [[p.first, p.last] for p in later.pieces])
            extra["val_accepted"] = list(range(1, max(1, len(later.accepted)) + 1))
        if outcome.solved and outcome.actions:
            plan = self.kb.add_plan(problem.id, outcome.planner, outcome.actions, outcome.expected_states, checked)
            self.kb.set_execution(obj.ident, Execution(plan.id, 1, READY, None))
        extra.update({"planning_status": outcome.status, "problem_id": problem.id,
                      "timings": {k: round(v, 6) for k, v in outcome.timings.items()}})
        if outcome.ordering:
            extra["ordering"] = outcome.ordering
        if outcome.solved and outcome.actions:
            view = PlanView(expected_states=outcome.expected_states,
                            preconditions=tuple(a.pre for a in outcome.actions))
            ordering = f" ({outcome.ordering})" if outcome.ordering else ""
            checked_by = (f"; VAL accepted a_1..a_{outcome.validated_steps}, a_{outcome.validated_steps + 1}.."
                          f"a_{len(plan.actions)} are checked before they are dispatched" if early else "")
            reason = f"{decision.reason}; new plan {plan.id} of {len(plan.actions)} actions{ordering}{checked_by}"
            return _answer(DecisionKind.REPLAN, plan.id, perceived.id,
                           self._action_public(obj, plan, plan.actions[0]),
                           decision.matched_expected_step, reason), (plan, view)
        if outcome.solved:  # the perceived state already satisfies the goal
            self.kb.set_execution(obj.ident, Execution(None, None, ExecutionStatus.GOAL_REACHED, None))
            return _answer(DecisionKind.GOAL_REACHED, None, perceived.id, None, None, outcome.message), None
        if outcome.help:  # a plan exists but the robot cannot carry it out on this table: ask the human
            self.kb.set_execution(obj.ident, Execution(None, None, IDLE, None))
            reason = f"{decision.reason}; {outcome.message}; the robot asks the human for help"
            answer = _answer(DecisionKind.HUMAN_HELP_REQUESTED, None, perceived.id, None,
                             decision.matched_expected_step, reason)
            answer["help"] = _help_public(outcome.help)
            extra["help"] = answer["help"]
            return answer, None
        self.kb.set_execution(obj.ident, Execution(None, None, ExecutionStatus.NO_PLAN, None))
        reason = (f"{decision.reason}; planning {outcome.status}: {outcome.message}; "
                  "a human must bring the object to a workable configuration")
        return _answer(DecisionKind.NO_PLAN, None, perceived.id, None, decision.matched_expected_step, reason), None

    def _log_decision(self, object_id: str, answer: dict[str, Any], extra: dict[str, Any]) -> None:
        action = answer["next_action"]
        data = {
            "perceived_state_id": answer["perceived_state_id"],
            "plan_id": answer["plan_id"],
            "next_step": action["step"] if action else None,
            "next_action_id": action["id"] if action else None,
            "matched_expected_step": answer["matched_expected_step"],
            **extra,
        }
        self.kb.add_event(object_id, answer["decision"], answer["reason"], data)

    # -- reads: the records as response bodies ------------------------------------------------------------
    def list_objects(self) -> list[dict[str, Any]]:
        return [self.describe_object(obj.ident) for obj in self.kb.list_objects()]

    def describe_object(self, object_id: str) -> dict[str, Any]:
        """One object with its goal and execution state."""
        obj = self.kb.get_object(object_id)
        with self.locks.hold(obj.ident):
            execution = self.kb.get_execution(obj.ident)
            goal_state_id = self.goal_state_id(obj.ident)
            base = self._memo(obj.ident).base_point_xy
        return object_public(obj, execution, goal_state_id, base)

    def current_plan(self, object_id: str) -> dict[str, Any]:
        """The plan being followed (or, when none is, the latest one), with its expected states."""
        self.kb.get_object(object_id)
        execution = self.kb.get_execution(object_id)
        plan = self.kb.get_plan(execution.plan_id) if execution.plan_id else self.kb.latest_plan(object_id)
        if plan is None:
            raise NotFoundError(f"plan: object {object_id} has no plan yet")
        return self._plan_public(plan)

    def describe_plan(self, plan_id: str) -> dict[str, Any]:
        return self._plan_public(self.kb.get_plan(plan_id))

    def describe_state(self, state_id: str) -> dict[str, Any]:
        return state_public(self.kb.get_state(state_id))

    def describe_problem(self, problem_id: str) -> dict[str, Any]:
        return problem_public(self.kb.get_problem(problem_id))

    def list_events(self, object_id: str, after_seq: int = 0, limit: int | None = None) -> list[dict[str, Any]]:
        """A page of the object's log, oldest first: at most `limit` events after `after_seq`."""
        return [event_public(e) for e in self.kb.list_events(object_id, after_seq=after_seq, limit=limit)]

    def events_after(self, object_id: str, after_seq: int = 0,
                     limit: int = MAX_EVENTS_PAGE) -> tuple[StoredEvent, ...]:
        """One page of events after `after_seq` (a stream reads the next page at its next poll)."""
        return self.kb.list_events(object_id, after_seq=after_seq, limit=limit)

    def export_ontology(self, fmt: str, history: str = "current", object_id: str | None = None) -> bytes:
        """TBox and ABox (the current ABox, or the whole `history`) as RDF/XML (`xml`) or Turtle (`turtle`)."""
        return self.kb.export(fmt, history, None if object_id is None else [object_id])

    def export_ntriples(self, history: str = "current", object_id: str | None = None) -> Iterator[str]:
        """TBox and ABox as N-Triples lines, read as they are sent."""
        return self.kb.export_lines(history, None if object_id is None else [object_id])

    def health(self) -> dict[str, Any]:
        """Counts kept by the store's commits: no scan and no lock, so /health answers while anything runs."""
        return {"objects": self.kb.object_count(), "triples": self.kb.triple_count(),
                "plans_to_write": self.kb.plans_to_write()}

    def _plan_public(self, plan: StoredPlan) -> dict[str, Any]:
        obj = self.kb.get_object(plan.object_id)
        return plan_public(obj, plan, [self.kb.get_state(sid) for sid in plan.expected_state_ids])

    # -- PDDL -------------------------------------------------------------------------------------------------
    def pddl_task(self, object_id: str, with_problem: bool = False) -> PddlTask:
        """The PDDL of the object's latest Problem as the planner saw it (`with_problem`), or only its domain."""
        obj = self.kb.get_object(object_id)
        model = read_domain_model(self.planning.tbox_path, obj.formulation.value)
        if not with_problem:
            return PddlTask(domain_text(model, False, obj.formulation is Formulation.ABSOLUTE), "", "")
        problem = self.kb.latest_problem(object_id)
        if problem is None:
            raise NotFoundError(f"problem: object {object_id} has no problem yet (set a goal and send a perception)")
        init, goal = self.kb.get_state(problem.init_state_id), self.kb.get_state(problem.goal_state_id)
        return translate(obj, init.atoms, goal.atoms, model, pipeline.problem_name(obj))

    # -- dispatch and feedback -------------------------------------------------------------------------------
    def take_next_action(self, object_id: str) -> dict[str, Any] | None:
        """The action to execute now, marked dispatched (taking it again returns the same action); None when
        there is none (no plan, done, goal)."""
        with self.locks.hold(object_id):
            obj = self.kb.get_object(object_id)
            execution = self.kb.get_execution(object_id)
            plan, _ = self._plan_view(execution.plan_id)
            if plan is None or execution.status not in (READY, DISPATCHED) or execution.next_step is None:
                return None
            if not 1 <= execution.next_step <= len(plan.actions):
                return None
            action = plan.actions[execution.next_step - 1]
            if execution.status == DISPATCHED and execution.dispatched_action_id == action.id:
                return self._action_public(obj, plan, action)
            try:
                refusal = self._val_gate(obj, plan, action, pipeline.deadline_from(self.planning))
            except DeadlineError as exc:  # nothing dispatched; the next call or perception asks again
                self.kb.add_event(object_id, WITHHELD_EVENT, f"a_{action.step} not dispatched: {exc}",
                                  {"plan_id": plan.id, "action_id": action.id, "step": action.step})
                return None
            if refusal is not None:  # the next perception re-plans (the gate refuses this step again)
                with self.kb.transaction():
                    self.kb.set_execution(object_id, Execution(plan.id, execution.next_step, IDLE, None))
                    self.kb.add_event(object_id, WITHHELD_EVENT,
                                      f"a_{action.step} not dispatched: {refusal}; the next perception re-plans",
                                      {"plan_id": plan.id, "action_id": action.id, "step": action.step})
                return None
            with self.kb.transaction():
                self.kb.set_execution(object_id, Execution(plan.id, execution.next_step, DISPATCHED, action.id))
                self.kb.add_event(object_id, "dispatched", f"a_{action.step} ({action.spec.name}) dispatched",
                                  {"plan_id": plan.id, "action_id": action.id, "step": action.step})
            return self._action_public(obj, plan, action)

    def handle_feedback(self, object_id: str, action_id: str, outcome: str, message: str = "",
                        idempotency_key: str | None = None, reason: str | None = None,
                        measured_deg: float | None = None) -> dict[str, Any]:
        """Record a worker's report on the dispatched action, with why it failed (`reason`, a FailureReason) and
        the turned link's measured orientation (`measured_deg`) when it did not succeed."""
        if outcome not in set(ActionOutcome):
            raise ValidationError(f"outcome: must be {one_of(ActionOutcome)}, got {outcome!r}")
        outcome = ActionOutcome(outcome)
        failure = _failure_reason(outcome, reason)
        if measured_deg is not None and (isinstance(measured_deg, bool) or not isinstance(measured_deg, (int, float))
                                         or not math.isfinite(measured_deg)):
            raise ValidationError(f"measured_deg: must be a finite number, got {measured_deg!r}")
        with self.locks.hold(object_id):
            self.kb.get_object(object_id)
            fingerprint = _fingerprint({"feedback": [action_id, outcome, message]}
                                       if failure is None and measured_deg is None else
                                       {"feedback": [action_id, outcome, message, failure, measured_deg]})
            recalled = self._recall(object_id, idempotency_key, fingerprint)
            if recalled is not None:
                return recalled
            action = self.kb.get_action(action_id)
            execution = self.kb.get_execution(object_id)
            if execution.dispatched_action_id != action_id:
                current = execution.dispatched_action_id or "none"
                raise ConflictError(
                    f"action_id: {action_id} is not the current dispatched action of {object_id} (current: {current})"
                )
            if execution.status == DISPATCHED:
                accepted = "current"
                plan, _ = self._plan_view(execution.plan_id)
                last = self._last_step(self.kb.get_object(object_id), plan, action) if plan else action.step
                next_step = last + 1 if outcome == ActionOutcome.SUCCEEDED else action.step
                new = Execution(execution.plan_id, next_step, READY, None)
                text = f"a_{action.step} {outcome}" + (
                    ": the next perception checks s^e_{}".format(next_step) if outcome == ActionOutcome.SUCCEEDED
                    else ": the next perception decides whether to retry, resume or re-plan")
            else:
                accepted = "late"
                new = replace(execution, dispatched_action_id=None)
                text = f"a_{action.step} {outcome}, reported after a perception had already moved the execution"
            answer = {"action_id": action_id, "accepted": accepted, "execution": execution_public(new)}
            with self.kb.transaction():
                self.kb.set_execution(object_id, new)
                why = f" [{failure}]" if failure is not None else ""
                motion = action_motion(self.kb.get_object(object_id), action)
                self.kb.add_event(object_id, "feedback", text + why + (f" ({message})" if message else ""),
                                  {"action_id": action_id, "step": action.step, "outcome": outcome,
                                   "accepted": accepted, "reason": failure, "measured_deg": measured_deg,
                                   "message": message, "joint_index": motion["joint_index"],
                                   "turned_link_index": motion["turned_link_index"]})
                self._remember(object_id, idempotency_key, fingerprint, answer)
            return answer

    def give_up(self, object_id: str, reason: str, message: str) -> dict[str, Any]:
        """A worker stopped working on the object: record it, and leave the execution idle with nothing dispatched
        (the plan stays; the next perception decides anew)."""
        with self.locks.hold(object_id):
            self.kb.get_object(object_id)
            execution = self.kb.get_execution(object_id)
            with self.kb.transaction():
                self.kb.set_execution(object_id, Execution(execution.plan_id, None, IDLE, None))
                event = self.kb.add_event(object_id, "worker_gave_up", f"the worker gave up ({reason}): {message}",
                                          {"reason": reason, "message": message, "plan_id": execution.plan_id,
                                           "dropped_action_id": execution.dispatched_action_id})
            return {"event_seq": event.seq}

    # -- helpers --------------------------------------------------------------------------------------------
    def _plan_view(self, plan_id: str | None) -> tuple[StoredPlan | None, PlanView | None]:
        if plan_id is None:
            return None, None
        with self._guard:
            cached = self._views.get(plan_id)
        if cached is not None:
            return cached
        plan = self.kb.get_plan(plan_id)
        view = PlanView(
            expected_states=tuple(self.kb.get_state(sid).atoms for sid in plan.expected_state_ids),
            preconditions=tuple(a.spec.pre for a in sorted(plan.actions, key=lambda a: a.step)),
        )
        self._keep_view(plan, view)
        return plan, view

    def _keep_view(self, plan: StoredPlan, view: PlanView) -> None:
        """Cache the view of an object's plan in place of the object's previous one: the cache holds one plan per
        object, not every plan an object ever had."""
        with self._guard:
            previous = self._view_of.get(plan.object_id)
            if previous is not None and previous != plan.id:
                self._views.pop(previous, None)
            self._views[plan.id] = (plan, view)
            self._view_of[plan.object_id] = plan.id

    def _memo(self, object_id: str) -> _ObjectMemo:
        """Bring the memo of an object up to date with its event log (caller holds the object's lock)."""
        with self._guard:
            memo = self._memos.setdefault(object_id, _ObjectMemo())
        for event in self.kb.list_events(object_id, after_seq=memo.seq):
            memo.seq = max(memo.seq, event.seq)
            if event.kind == "object_created":
                base = event.data.get("base_point_xy")
                memo.base_point_xy = (float(base[0]), float(base[1])) if base else None
            elif event.kind == "goal_set":
                memo.goal_state_id = event.data.get("goal_state_id")
                memo.failure = None
            elif event.kind == DecisionKind.INCOMPLETE_PERCEPTION:
                continue  # it stored no state and decided nothing: the last feedback still informs the next decision
            elif event.kind == "feedback":
                outcome = event.data.get("outcome")
                memo.last_outcome = ActionOutcome(outcome) if outcome else None
                memo.failure = _next_failure(memo.failure, event.data)
            elif event.kind == VERDICT_EVENT:
                if memo.val is not None and memo.val.plan_id == event.data.get("plan_id"):
                    memo.val.verdicts[int(event.data["piece"])] = verdict_of(event.data)
            elif event.kind in set(DecisionKind):
                if event.data.get("val_pieces"):
                    memo.val = PieceRecord.from_event(event.data["plan_id"], event.data)
                memo.perceived_state_id = event.data.get("perceived_state_id") or memo.perceived_state_id
                memo.measured_base_xy = _base_of(event.data) or memo.measured_base_xy
                memo.last_outcome = None  # a feedback informs only the next decision
                memo.last_decision = event.kind
                remedy = event.data.get("remedy")
                if remedy and memo.failure is not None:
                    memo.failure = replace(memo.failure, tried=memo.failure.tried + (Remedy(remedy),))
                if remedy == Remedy.SPLIT and event.data.get("plan_id"):
                    memo.split_plans.add(event.data["plan_id"])
        return memo

    def _last_step(self, obj: ArticulatedObject, plan: StoredPlan, action: StoredAction) -> int:
        """Last plan step of the motion that starts with `action` (itself unless macro steps are merged; not in a
        plan whose merged motion failed, remedy split). Every single step of a placed object's plan was checked
        geometrically, sweep included, so a merged motion sweeps only through checked configurations."""
        if not self.merge_macro_steps or plan.id in self._memo(plan.object_id).split_plans:
            return action.step
        rest = [a for a in plan.actions if a.step >= action.step]
        return merge_macro_steps(obj, rest, first_only=True)[0].last_step

    def _action_public(self, obj: ArticulatedObject, plan: StoredPlan, action: StoredAction) -> dict[str, Any]:
        motion = action_motion(obj, action)
        last = self._last_step(obj, plan, action)
        if last > action.step:
            merged = merge_macro_steps(obj, [a for a in plan.actions if action.step <= a.step <= last], True)[0]
            motion.update(delta_deg=merged.delta_deg, macro_steps=last - action.step + 1)
        return {"id": action.id, "name": action.spec.name, "params": list(action.spec.params),
                "step": action.step, "last_step": last, "plan_id": plan.id, **motion}

    def _recall(self, object_id: str, key: str | None, fingerprint: str) -> dict[str, Any] | None:
        if not key:
            return None
        stored = self.kb.recall_response(object_id, key)
        if stored is None:
            return None
        if stored.get("fingerprint") != fingerprint:
            raise ConflictError(f"Idempotency-Key: {key!r} was already used with a different request")
        return stored["response"]

    def _remember(self, object_id: str, key: str | None, fingerprint: str, answer: dict[str, Any]) -> None:
        if key:
            self.kb.remember_response(object_id, key, {"fingerprint": fingerprint, "response": answer})


def _answer(kind: DecisionKind, plan_id: str | None, perceived_state_id: str | None,
            next_action: dict[str, Any] | None, matched: int | None, reason: str) -> dict[str, Any]:
    return {"decision": kind, "plan_id": plan_id, "perceived_state_id": perceived_state_id,
            "next_action": next_action, "matched_expected_step": matched, "reason": reason, "help": None,
            "unseen_links": None}


def _next_failure(failure: FailureHistory | None, data: dict[str, Any]) -> FailureHistory | None:
    """The failure record after one feedback event: cleared by a success, counted for the same motion, started
    anew for another; a failure without a reason is not a motion's failure."""
    if data.get("outcome") == ActionOutcome.SUCCEEDED or data.get("accepted") == "late":
        return None if data.get("outcome") == ActionOutcome.SUCCEEDED else failure
    reason, joint, turned = data.get("reason"), data.get("joint_index"), data.get("turned_link_index")
    if reason is None or joint is None or turned is None:
        return None
    if failure is not None and (failure.joint, failure.turned) == (joint, turned):
        return replace(failure, reason=FailureReason(reason), failures=failure.failures + 1)
    return FailureHistory(int(joint), int(turned), FailureReason(reason))


def _other_way(obj: ArticulatedObject, moves: Sequence[Move], failure: FailureHistory) -> list[Move] | None:
    """`moves` with the failing joint's steps replaced by the other way round (360° - delta), or None when that
    joint has nothing left to turn in them."""
    group = [m for m in moves if (m.joint, m.turned) == (failure.joint, failure.turned)]
    total = sum(m.delta_deg for m in group)
    if not group or total % 360 == 0:
        return None
    forward = group[0] if (group[0].delta_deg > 0) == (total > 0) else group[0].other_way()
    turned_back = [forward.other_way()] * ((360 - abs(total) % 360) // obj.step)
    first = moves.index(group[0])
    rest = [m for m in moves if (m.joint, m.turned) != (failure.joint, failure.turned)]
    return rest[:first] + turned_back + rest[first:]


def _whole_turn_deg(obj: ArticulatedObject) -> int:
    """The step by which a human may turn the whole object without changing its state (`Placement`): relative
    objects only, whose states do not say where l1 points."""
    return obj.step if obj.formulation is Formulation.RELATIVE else 0


def _failure_words(memo: _ObjectMemo) -> str | None:
    failure = memo.failure
    if failure is None:
        return None
    return f"the robot failed {failure.failures} time{'s' if failure.failures > 1 else ''}: {failure.reason}"


def _help_public(items: Sequence[HelpItem]) -> list[dict[str, Any]]:
    return [{"link": h.link, "to_deg": h.to_deg, "sentence": h.sentence} for h in items]


def _failure_reason(outcome: ActionOutcome, reason: str | None) -> FailureReason | None:
    if reason is None:
        return None
    if reason not in set(FailureReason):
        raise ValidationError(f"reason: must be {one_of(FailureReason)} or null, got {reason!r}")
    if outcome == ActionOutcome.SUCCEEDED:
        raise ValidationError(f"reason: must be null when the outcome is succeeded, got {reason!r}")
    return FailureReason(reason)


def _measured_base(value: Sequence[float] | None) -> tuple[float, float] | None:
    """A measured base point as [x, y] metres, validated (ValidationError naming the field), or None."""
    if value is None:
        return None
    try:
        return ObjectGeometry((1.0,), (value[0], value[1])).base_point_xy if len(value) == 2 else _bad_base(value)
    except (GeometryError, IndexError, TypeError):
        return _bad_base(value)


def _bad_base(value: object) -> tuple[float, float]:
    raise ValidationError(f"base_point_xy: expected [x, y], two finite numbers in metres, got {value!r}")


def _base_of(data: dict[str, Any]) -> tuple[float, float] | None:
    """The measured base point a decision's event keeps (None when its perception carried none)."""
    base = data.get("base_point_xy")
    return (float(base[0]), float(base[1])) if base else None


def _fingerprint(body: dict[str, Any]) -> str:
    return hashlib.sha256(json.dumps(body, sort_keys=True).encode()).hexdigest()


def _check_finite(values: Sequence[float | None], field: str) -> None:
    for i, v in enumerate(values):
        if v is not None and (isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v)):
            raise ValidationError(f"{field}[{i}]: must be a finite number, got {v!r}")


def _allowed(obj: ArticulatedObject, values: Sequence[float | None], field: str) -> list[int | None]:
    allowed = set(obj.orientation_degrees)
    out: list[int | None] = []
    for i, v in enumerate(values):
        if v is None:
            out.append(None)
            continue
        if float(v) % 360 not in allowed:
            raise ValidationError(f"{field}[{i}]: {v} is not one of the allowed orientations {sorted(allowed)}")
        out.append(int(float(v) % 360))
    return out


def _goal_atoms(obj: ArticulatedObject, link_orientations_deg: Sequence[float] | None,
                joint_angles_deg: Sequence[float | None] | None) -> frozenset:
    if (link_orientations_deg is None) == (joint_angles_deg is None):
        raise ValidationError("link_orientations_deg, joint_angles_deg: give exactly one of them")
    if link_orientations_deg is not None:
        field = "link_orientations_deg"
        if len(link_orientations_deg) != obj.n_links:
            raise ValidationError(
                f"{field}: expected {obj.n_links} values (one per link), got {len(link_orientations_deg)}")
        _check_finite(link_orientations_deg, field)
        if any(v is None for v in link_orientations_deg):
            raise ValidationError(f"{field}: every link needs an orientation")
        values = obj.joint_values_from_links([int(v) for v in _allowed(obj, link_orientations_deg, field) if v is not None])
        return obj.configuration_atoms(values)
    assert joint_angles_deg is not None
    return obj.partial_configuration_atoms(joint_angles_deg, field="joint_angles_deg")

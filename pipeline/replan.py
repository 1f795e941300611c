"""A re-plan for the service, in one call: `plan_for_service` makes the new plan (a plan composed of motions the
caller asks for, else the planner's: in a worker of the service's planning pool for a large task, else here) and
hands back the plan with a handle on VAL's verdict (`PlannedTurn`), VAL already running in its own processes.

For a plan VAL checks in one short run, VAL starts on the plan's steps as soon as `find_plan` has them, before the
expected states are replayed, so that VAL runs on the other core beside the replay and whatever the caller does
next (the store's checks of the plan, the start of its write). A plan checked with the early answer (VAL on its first
motion before the answer) has that VAL started the same way, on the first motion read from the steps' text, its
few steps replayed for the pieces' states, before the rest is replayed. Likewise for a large task planned in a worker
with the early answer: the worker sends the plan's steps before it replays them, and VAL starts on the first motion
here (`Validator.start_first`) while the worker replays the rest; only for objects of `EARLY_VAL_MIN_LINKS` links or
more, whose replay is long enough to hide VAL behind it (for a smaller object the service's own replay of the first
motion costs more than it saves: docs/results/validation-speed/large-warm-up.md).
"""
from __future__ import annotations

import logging
from dataclasses import dataclass, replace
from typing import Callable, Protocol, TypeVar

from planhrc.model import ArticulatedObject, State, is_subsumed
from planhrc.ordering import Move, Placement
from planhrc.translator.translate import PddlTask
from planhrc.vocabulary import PlanningStatus

from . import stages
from .config import PlanningConfig, PlanOutcome
from .val_runs import ValCheck
from .validation import FirstPieces, Validator, VerdictHandle

log = logging.getLogger(__name__)

_T = TypeVar("_T")

EARLY_VAL_MIN_LINKS = 50  # the least object a worker's plan has VAL started on its first motion before the replay


@dataclass(frozen=True)
class PlanningJob:
    """One pipeline run, as a value: `plan(obj, init, goal, config, placement=..., deadline_at=...)`, VAL included
    when `config.validate` (what a planning pool's worker runs)."""

    obj: ArticulatedObject
    init: State
    goal: State
    config: PlanningConfig
    placement: Placement | None
    deadline_at: float  # time.monotonic()


def warm_up_job(obj: ArticulatedObject, goal: State, config: PlanningConfig, deadline_at: float) -> PlanningJob:
    """A job towards `goal` from a configuration the goal does not hold (every joint at the first orientation, or
    else at the second): planning it (`warm_up`) does a re-plan's work that does not depend on the perceived state
    (the domain read, the planner's grounding of the object's task), which a later job on the object then finds
    memoised."""
    degrees = obj.orientation_degrees
    init = obj.state([degrees[0]] * obj.n_joints)
    if is_subsumed(init, goal):
        init = obj.state([degrees[1 % len(degrees)]] * obj.n_joints)
    return PlanningJob(obj, init, goal, replace(config, validate=False), None, deadline_at)


def warm_up(job: PlanningJob) -> PlanOutcome:
    """Translate and plan `job` (`stages.find_plan`), nothing more: what counts is what the planning process
    memoises on the way. The outcome carries neither actions, expected states nor the task."""
    found = stages.find_plan(job.obj, job.init, job.goal, job.config, deadline_at=job.deadline_at)
    if isinstance(found, PlanOutcome):
        return replace(found, actions=(), expected_states=(), task=None)
    return PlanOutcome(PlanningStatus.SOLVED, "warmed up: planned, not replayed", found.result.planner,
                       timings=found.timings)


StepsKnown = Callable[[PddlTask, tuple[str, ...]], None]  # a job's plan's task and steps, before its replay


class LargeTaskPlanning(Protocol):
    """Where large tasks are planned (the service's worker processes, `kb_service.planning_pool`)."""

    def takes(self, obj: ArticulatedObject) -> bool: ...

    def plan(self, job: PlanningJob, steps_known: StepsKnown | None = None) -> PlanOutcome:
        """The job's outcome; `steps_known`, when given, may be called (on the caller's thread, before this
        returns) with the plan's task and steps as soon as they are known, before the expected states are."""

    def warm(self, job: PlanningJob) -> None:
        """Start `warm_up(job)` where the object's next jobs will be planned, off the caller's thread (or do
        nothing where that cannot help)."""


@dataclass(frozen=True)
class ReplanRequest:
    """A re-plan from `init` to `goal` by `deadline_at` (`time.monotonic()`), for an object placed in the cell at
    `placement` (None: abstract). With `moves`, the plan composed of those motions is tried first (a failing
    joint turned the other way round)."""

    obj: ArticulatedObject
    init: State
    goal: State
    deadline_at: float
    placement: Placement | None = None
    moves: tuple[Move, ...] | None = None


@dataclass(frozen=True)
class PlannedTurn:
    """The new plan as planned, and the handle on VAL's verdict on it (`verdict.outcome(...)`: the plan checked)."""

    outcome: PlanOutcome
    verdict: VerdictHandle


def plan_for_service(request: ReplanRequest, config: PlanningConfig, validator: Validator,
                     pool: LargeTaskPlanning | None = None) -> PlannedTurn:
    """The new plan and VAL on it (see the module's note). A failing stage ends in an `error` outcome, never an
    exception: the perception still gets a decision."""
    outcome, started, first = _planned(request, config, validator, pool)
    return PlannedTurn(outcome, validator.check(request.obj, outcome, request.deadline_at, started, first))


def _planned(request: ReplanRequest, config: PlanningConfig, validator: Validator, pool: LargeTaskPlanning | None
             ) -> tuple[PlanOutcome, ValCheck | None, FirstPieces | None]:
    obj, init, goal, deadline_at = request.obj, request.init, request.goal, request.deadline_at
    if request.moves is not None:
        try:
            return stages.plan_moves(obj, init, goal, request.moves, config, placement=request.placement,
                                     defer_validation=True), None, None
        except Exception as exc:  # the composed plan does not hold: let the planner try
            log.warning("the other way round failed for %s: %s", obj.ident, exc)
    if pool is not None and pool.takes(obj):
        return _planned_in_pool(request, config, validator, pool)
    found = _guarded(obj, config, lambda: stages.find_plan(obj, init, goal, config, placement=request.placement,
                                                           deadline_at=deadline_at))
    if isinstance(found, PlanOutcome):
        return found, None, None
    started: ValCheck | None = None
    first: FirstPieces | None = None
    if validator.beside(found.task):
        begun = _guarded(obj, config, lambda: validator.start_whole(found.task, found.steps))
        if isinstance(begun, PlanOutcome):
            return begun, None, None
        started = begun
    else:
        first = _first_started(validator, obj, init, found.task, found.steps, deadline_at)
    try:
        return _guarded(obj, config, lambda: stages.expect(obj, init, goal, found, deadline_at)), started, first
    except BaseException:
        if started is not None:
            started.cancel()
        if first is not None:
            first.cancel()
        raise


def _first_started(validator: Validator, obj: ArticulatedObject, init: State, task: PddlTask,
                   steps: tuple[str, ...], deadline_at: float) -> FirstPieces | None:
    """VAL on the plan's first motion started before the rest is replayed (`Validator.start_first`), or None (VAL
    then starts once the outcome is here, `Validator.check`)."""
    try:
        return validator.start_first(obj, init, task, steps, deadline_at)
    except Exception:
        log.exception("VAL on the first motion of a plan of %s could not start early", obj.ident)
        return None


def _planned_in_pool(request: ReplanRequest, config: PlanningConfig, validator: Validator, pool: LargeTaskPlanning
                     ) -> tuple[PlanOutcome, None, FirstPieces | None]:
    """The plan from a worker. With the early answer VAL runs here: on the first motion once the worker has sent
    the plan's steps (`Validator.start_first`), beside the worker's replay; `Validator.check` keeps those runs only
    if the outcome is what they were made from."""
    obj = request.obj
    if not validator.early_answer:
        job = PlanningJob(obj, request.init, request.goal, config, request.placement, request.deadline_at)
        return _guarded(obj, config, lambda: pool.plan(job)), None, None
    job = PlanningJob(obj, request.init, request.goal, replace(config, validate=False), request.placement,
                      request.deadline_at)
    if obj.n_links < EARLY_VAL_MIN_LINKS:  # VAL starts once the outcome is here (`Validator.check`)
        return _guarded(obj, config, lambda: pool.plan(job)), None, None
    begun: list[FirstPieces] = []

    def steps_known(task: PddlTask, steps: tuple[str, ...]) -> None:
        first = _first_started(validator, obj, request.init, task, steps, request.deadline_at)
        if first is not None:
            begun.append(first)

    try:
        outcome = _guarded(obj, config, lambda: pool.plan(job, steps_known))
    except BaseException:
        for first in begun:
            first.cancel()
        raise
    return outcome, None, begun[0] if begun else None


def _guarded(obj: ArticulatedObject, config: PlanningConfig, stage: Callable[[], _T]) -> _T | PlanOutcome:
    try:
        return stage()
    except Exception as exc:  # a crashing stage must not leave the perception without a decision
        log.exception("planning failed for %s", obj.ident)
        return PlanOutcome(PlanningStatus.ERROR, f"{type(exc).__name__}: {exc}", config.planner)

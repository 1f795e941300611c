"""The pipeline's stages, one after another: `find_plan` (translate, plan, order on the table), `expect` (the
expected states, by replaying the plan), and VAL (`validation`); `plan` runs them in order, `plan_moves` checks a
plan composed of motions the same way."""
from __future__ import annotations

import time
from dataclasses import dataclass, replace
from typing import Mapping, Sequence

from planhrc.model import ArticulatedObject, DomainModelSpec, State, is_subsumed
from planhrc.motion_search import Slide
from planhrc.ordering import Move, Placement, order_moves
from planhrc.planner.chain import plan_with_fallback
from planhrc.planner.result import PlannerAttempt, PlanResult, PlanStatus
from planhrc.settings import get_settings
from planhrc.errors import DeadlineExceeded
from planhrc.transition import TransitionError, replay
from planhrc.translator.domain import read_domain_model
from planhrc.translator.translate import PddlTask, translate
from planhrc.vocabulary import PlanningStatus

from .config import (LaterSlide, PlanningConfig, PlanOutcome, config_from_settings, deadline_from, over_deadline,
                     problem_name, time_left)
from .order import Refusal, Straighten, order_steps, steps_of
from .val_runs import validate


def plan(obj: ArticulatedObject, init: State, goal: State, config: PlanningConfig | None = None, *,
         defer_validation: bool = False, placement: Placement | None = None,
         deadline_at: float | None = None) -> PlanOutcome:
    """Translate, plan, order, replay and validate one task; returns a value and stores nothing. Without
    `config`, the settings (`PLANHRC_*` environment variables and their defaults) say how. Planning and VAL end
    by `deadline_at` (`time.monotonic()`; default: `config.deadline_s` from now), else the status is `timeout`.

    `defer_validation` leaves VAL to the caller, who runs `validate(outcome, obj, config, deadline_at)` (e.g.
    beside other work) and must not use the plan before VAL accepted it (`validated`). With a `placement` (where
    the object lies when the plan starts), the plan's actions are put in an order whose every configuration is
    feasible (or the plan is refused, `unsolvable`, with the `help` to ask for); VAL and the replay then see that
    order. The stages one by one: `find_plan`, then `expect` (and VAL: `validate`, or `start_val` beside `expect`)."""
    config = config or config_from_settings(get_settings())
    deadline_at = deadline_from(config) if deadline_at is None else deadline_at
    found = find_plan(obj, init, goal, config, placement=placement, deadline_at=deadline_at)
    if isinstance(found, PlanOutcome):
        return found
    outcome = expect(obj, init, goal, found, deadline_at)
    if config.validate and not defer_validation:
        outcome = validate(outcome, obj, config, deadline_at)
        if outcome.solved:
            outcome = replace(outcome, timings={**outcome.timings,
                                                "pipeline": time.perf_counter() - found.started})
        elif outcome.status is PlanningStatus.INVALID:
            return _next_planner(obj, init, goal, config, outcome, placement, deadline_at)
    return outcome


def _next_planner(obj: ArticulatedObject, init: State, goal: State, config: PlanningConfig, refused: PlanOutcome,
                  placement: Placement | None, deadline_at: float) -> PlanOutcome:
    """A plan VAL refused is not an answer: the planners after the one that made it try the task, within what is
    left of the deadline; the answer's attempts say why the earlier one failed. With none left, the refusal."""
    chain = planner_chain(config)
    rest = chain[chain.index(refused.planner) + 1:] if refused.planner in chain else ()
    if not rest or time.monotonic() >= deadline_at:
        return refused
    later = replace(config, planner=rest[0], fallback_planner=rest[1] if len(rest) > 1 else None)
    retried = plan(obj, init, goal, later, placement=placement, deadline_at=deadline_at)
    why = PlannerAttempt(refused.planner, PlanStatus.INVALID, refused.message, refused.timings.get("planning", 0.0))
    return replace(retried, attempts=(*refused.attempts, why, *retried.attempts))


@dataclass(frozen=True)
class Found:
    """A plan's steps, final (ordered on the table for a placed object), before its expected states: what
    `find_plan` hands to `expect`, and what VAL can start on (`start_val`)."""

    task: PddlTask
    model: DomainModelSpec
    result: PlanResult
    ordering: str
    timings: Mapping[str, float]
    started: float  # time.perf_counter() when the pipeline began
    config: PlanningConfig
    slide: Slide | None = None  # the robot slides the object there before the plan's first turn
    later_slides: tuple[LaterSlide, ...] = ()  # and between its turns

    @property
    def steps(self) -> tuple[str, ...]:
        return tuple(self.result.plan)


def find_plan(obj: ArticulatedObject, init: State, goal: State, config: PlanningConfig, *,
              placement: Placement | None = None, deadline_at: float | None = None) -> Found | PlanOutcome:
    """Translate, plan and (for a placed object) order: the plan's final steps, or the outcome when there is no
    plan to go on with (the goal already holds, nothing solved, no feasible order, the deadline)."""
    deadline_at = deadline_from(config) if deadline_at is None else deadline_at
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    if is_subsumed(init, goal):
        return PlanOutcome(PlanningStatus.SOLVED, "the initial state already satisfies the goal", config.planner,
                           True, timings=timings)
    model = read_domain_model(config.tbox_path, obj.formulation.value)
    task = translate(obj, init, goal, model, problem_name(obj))
    timings["translate"] = time.perf_counter() - t0

    t = time.perf_counter()
    left = time_left(deadline_at)
    if left <= 0:
        return over_deadline(config, "before planning", config.planner, timings, task)
    result = run_planners(task, config, min(config.timeout_s, left))
    timings["plan"] = time.perf_counter() - t
    if not result.solved:
        status = PlanningStatus(result.status.value)
        message = result.message or result.status.value
        if status is PlanningStatus.TIMEOUT and time_left(deadline_at) <= 0:
            message = f"planning deadline of {config.deadline_s:g} s exceeded ({message})"
        return PlanOutcome(status, message, result.planner, None, timings=timings, task=task,
                           attempts=result.attempts)

    ordering, slide = "", None
    later: tuple[LaterSlide, ...] = ()
    if placement is not None:
        t = time.perf_counter()
        ordered = order_steps(obj, model, init, result.plan, placement, deadline_at)
        timings["order"] = time.perf_counter() - t
        if isinstance(ordered, Refusal):
            return PlanOutcome(PlanningStatus.UNSOLVABLE, ordered.message, result.planner, None, timings=timings,
                               task=task, attempts=result.attempts, help=ordered.help)
        if isinstance(ordered, Straighten):  # a plan fits once the robot has straightened the links: that first
            return PlanOutcome(PlanningStatus.UNSOLVABLE, f"no plan fits where the links lie: {ordered.sentence}",
                               result.planner, None, timings=timings, task=task, attempts=result.attempts,
                               straighten=ordered.turns, slide=ordered.slide)
        ordering, slide, later = ordered.sentence, ordered.slide, ordered.later_slides
        result = replace(result, plan=ordered.steps, optimal=None)
    return Found(task, model, result, ordering, timings, t0, config, slide, later)


def expect(obj: ArticulatedObject, init: State, goal: State, found: Found, deadline_at: float) -> PlanOutcome:
    """The expected states of a found plan (replay with the transition equations), checked against the goal: the
    solved outcome, not yet validated."""
    timings = dict(found.timings)
    result = found.result
    t = time.perf_counter()
    try:
        actions, states = replay(found.model, init, result.plan, deadline_at)
    except DeadlineExceeded:
        return over_deadline(found.config, f"while replaying the plan of {len(result.plan)} steps", result.planner,
                              timings, found.task)
    except TransitionError as exc:
        return PlanOutcome(PlanningStatus.INVALID, f"plan does not replay: {exc}", result.planner,
                           timings=timings, task=found.task)
    if not is_subsumed(states[-1], goal):
        return PlanOutcome(PlanningStatus.INVALID, "the last expected state is not subsumed by the goal",
                           result.planner, timings=timings, task=found.task)
    timings["expected_states"] = time.perf_counter() - t
    timings["pipeline"] = time.perf_counter() - found.started
    return PlanOutcome(PlanningStatus.SOLVED, result.message, result.planner, result.optimal, actions, states,
                       timings, found.task, result.attempts, tuple(result.plan), ordering=found.ordering,
                       slide=found.slide, later_slides=found.later_slides)


def plan_moves(obj: ArticulatedObject, init: State, goal: State, moves: Sequence[Move],
               config: PlanningConfig | None = None, *, placement: Placement | None = None,
               defer_validation: bool = False, planner: str = "other_way") -> PlanOutcome:
    """A plan the caller composed from motions (e.g. a joint turned the other way round), checked like a planner's:
    ordered on the table for a placed object, grounded, VAL (or deferred, as in `plan`), replayed and its last
    state checked against the goal. Raises TransitionError when the motions do not apply from `init`."""
    config = config or config_from_settings(get_settings())
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    model = read_domain_model(config.tbox_path, obj.formulation.value)
    task = translate(obj, init, goal, model, problem_name(obj))
    ordering = ""
    if placement is not None:
        answer = order_moves(placement, moves)
        timings["order"] = time.perf_counter() - t0
        if answer.moves is None:
            return PlanOutcome(PlanningStatus.UNSOLVABLE, answer.sentence(), planner, None, timings=timings,
                               task=task, help=answer.help)
        ordering = ("the planner's order stays on the table" if list(answer.moves) == list(moves)
                    else "reordered so that every configuration stays on the table")
        moves = answer.moves
    steps = steps_of(obj, model, init, moves)
    outcome = PlanOutcome(PlanningStatus.SOLVED, f"{len(steps)} composed steps", planner, None, task=task,
                          steps=steps, timings=timings, ordering=ordering)
    if config.validate and not defer_validation:
        outcome = validate(outcome)
        if not outcome.solved:
            return outcome
    actions, states = replay(model, init, steps)
    if not is_subsumed(states[-1], goal):
        return PlanOutcome(PlanningStatus.INVALID, "the composed plan's last state is not subsumed by the goal",
                           planner, timings=timings, task=task)
    timings["pipeline"] = time.perf_counter() - t0
    return replace(outcome, actions=tuple(actions), expected_states=states, timings=timings)



def run_planners(task: PddlTask, config: PlanningConfig, timeout_s: float | None = None) -> PlanResult:
    """The configured planner, then the fallback planner when the first cannot answer (the planner package's
    one fallback chain), within `timeout_s` (default: the configured planner time limit)."""
    # The chain's own VAL is off: the pipeline validates the plan as it will be executed (ordered on the table,
    # against the paper's exact domain), and a plan that VAL refuses passes the task on (`_next_planner`).
    return plan_with_fallback(task.domain, task.problem, planner_chain(config),
                              config.timeout_s if timeout_s is None else timeout_s, validate=False)


def planner_chain(config: PlanningConfig) -> tuple[str, ...]:
    """The planners tried in order: the configured one, then the fallback (when set and different)."""
    return tuple(dict.fromkeys(name for name in (config.planner, config.fallback_planner) if name))

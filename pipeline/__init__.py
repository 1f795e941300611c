"""The planning pipeline, one stage after another, from values to a value:

    object, initial and goal states -> translate (TBox domain model -> PDDL domain, states -> PDDL problem)
      -> plan (a planner of the registry, then the fallback)
      -> order (for an object placed in the cell: an order of the actions that stays on the table, `ordering`)
      -> validate (VAL) -> expected states (replay with the paper's transition equations) -> `PlanOutcome`

Every call has a deadline (`PlanningConfig.deadline_s`, or the caller's `deadline_at`) that bounds planning and
VAL together: a task too large for it ends with status `timeout` instead of minutes of work.

`plan(...)` reads nothing from and writes nothing to the knowledge base: the caller (the service's orchestrator,
`planhrc solve`) stores what it returns, in one write. Planners are reached only through the registry.
"""
from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Callable, Mapping, Protocol, Sequence

from planhrc.model import (HAS_ORIENTATION, ActionSpec, ArticulatedObject, DomainModelSpec, Formulation, State,
                           format_atom, is_subsumed, orientation_name)
from planhrc.ordering import HelpItem, Move, Placement, feasible_alternative, order_moves
from planhrc.planner.armed import ArmedValidators
from planhrc.planner.chain import plan_with_fallback
from planhrc.planner.errors import PlannerError
from planhrc.planner.fast_downward import has_conditional_effects
from planhrc.planner.result import PlannerAttempt, PlanResult
from planhrc.planner.validate import ValidationResult, start_validation, validate_pieces, validate_plan
from planhrc.errors import DeadlineExceeded
from planhrc.settings import Settings, get_settings
from planhrc.transition import StateIndex, TransitionError, apply, ground_action, parse_step, replay
from planhrc.translator.domain import read_domain_model
from planhrc.translator.translate import PddlTask, translate
from planhrc.vocabulary import PlanningStatus

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class PlanningConfig:
    """How plans are made; built from the settings (`config_from_settings`), which hold every default."""

    tbox_path: Path
    planner: str
    timeout_s: float
    validate: bool
    fallback_planner: str | None
    deadline_s: float = 10.0  # planning and VAL of one request together
    val_pieces: int = 1  # VAL runs on this many pieces of a long plan at once (see `validate`)


def config_from_settings(settings: Settings) -> PlanningConfig:
    return PlanningConfig(
        tbox_path=Path(settings.tbox_path),
        planner=settings.planner,
        timeout_s=float(settings.planner_timeout_s),
        validate=bool(settings.validate_plans),
        fallback_planner=settings.fallback_planner or None,
        deadline_s=float(settings.planning_deadline_s),
        val_pieces=int(settings.val_pieces),
    )


@dataclass(frozen=True)
class PlanOutcome:
    """What one run of the pipeline produced.

    When solved, `actions` are the ground actions a_1 .. a_N and `expected_states` the states s^e_1 .. s^e_{N+1}
    (s^e_1 is the initial state); both are empty when the initial state already satisfies the goal or when
    nothing was solved. `task` is the PDDL the planner saw (None when no planner ran)."""

    status: PlanningStatus
    message: str
    planner: str
    optimal: bool | None = None
    actions: tuple[ActionSpec, ...] = ()
    expected_states: tuple[State, ...] = ()
    timings: Mapping[str, float] = field(default_factory=dict)
    task: PddlTask | None = None
    attempts: tuple[PlannerAttempt, ...] = ()
    steps: tuple[str, ...] = ()  # the planner's plan as VAL reads it, one "(action arg ...)" per step
    validated: bool = False  # VAL accepted the plan
    validated_steps: int = 0  # VAL accepted the first steps a_1 .. a_k so far (the early answer; see `validate_first`)
    help: tuple[HelpItem, ...] = ()  # no feasible order: what the human could do instead
    ordering: str = ""  # what the ordering did, in words (empty when the object is not placed)

    @property
    def solved(self) -> bool:
        return self.status is PlanningStatus.SOLVED


def problem_name(obj: ArticulatedObject) -> str:
    """The name of an object's PDDL problem (the same for every re-plan, so the text depends on states only)."""
    return f"{obj.ident}-task"


def deadline_from(config: PlanningConfig) -> float:
    """The `time.monotonic()` by which a request planned now must be done."""
    return time.monotonic() + config.deadline_s


def _left(deadline_at: float) -> float:
    return deadline_at - time.monotonic()


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
    return outcome


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
    left = _left(deadline_at)
    if left <= 0:
        return _over_deadline(config, "before planning", config.planner, timings, task)
    result = run_planners(task, config, min(config.timeout_s, left))
    timings["plan"] = time.perf_counter() - t
    if not result.solved:
        status = PlanningStatus(result.status.value)
        message = result.message or result.status.value
        if status is PlanningStatus.TIMEOUT and _left(deadline_at) <= 0:
            message = f"planning deadline of {config.deadline_s:g} s exceeded ({message})"
        return PlanOutcome(status, message, result.planner, None, timings=timings, task=task,
                           attempts=result.attempts)

    ordering = ""
    if placement is not None:
        t = time.perf_counter()
        ordered = order_steps(obj, model, init, result.plan, placement)
        timings["order"] = time.perf_counter() - t
        if isinstance(ordered, Refusal):
            return PlanOutcome(PlanningStatus.UNSOLVABLE, ordered.message, result.planner, None, timings=timings,
                               task=task, attempts=result.attempts, help=ordered.help)
        ordering = ordered.sentence
        result = replace(result, plan=ordered.steps)
    return Found(task, model, result, ordering, timings, t0, config)


def expect(obj: ArticulatedObject, init: State, goal: State, found: Found, deadline_at: float) -> PlanOutcome:
    """The expected states of a found plan (replay with the transition equations), checked against the goal: the
    solved outcome, not yet validated."""
    timings = dict(found.timings)
    result = found.result
    t = time.perf_counter()
    try:
        actions, states = replay(found.model, init, result.plan, deadline_at)
    except DeadlineExceeded:
        return _over_deadline(found.config, f"while replaying the plan of {len(result.plan)} steps", result.planner,
                              timings, found.task)
    except TransitionError as exc:
        return PlanOutcome(PlanningStatus.INVALID, f"plan does not replay: {exc}", result.planner,
                           timings=timings, task=found.task)
    if not is_subsumed(states[-1], goal):
        return PlanOutcome(PlanningStatus.INVALID, "the last expected state is not subsumed by the goal",
                           result.planner, timings=timings, task=found.task)
    timings["expected_states"] = time.perf_counter() - t
    timings["pipeline"] = time.perf_counter() - found.started
    return PlanOutcome(PlanningStatus.SOLVED, result.message, result.planner, result.optimal, tuple(actions),
                       tuple(states), timings, found.task, result.attempts, tuple(result.plan),
                       ordering=found.ordering)


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
    return replace(outcome, actions=tuple(actions), expected_states=tuple(states), timings=timings)


# -- an order that stays on the table ---------------------------------------------------------------------------
@dataclass(frozen=True)
class Ordered:
    """The plan's steps in a feasible order, and what the ordering did in words."""

    steps: tuple[str, ...]
    sentence: str


@dataclass(frozen=True)
class Refusal:
    """No feasible order: why, and what to ask the human."""

    message: str
    help: tuple[HelpItem, ...]


def order_steps(obj: ArticulatedObject, model: DomainModelSpec, init: State, steps: Sequence[str],
                placement: Placement) -> Ordered | Refusal:
    """The planner's steps in an order whose every configuration is feasible (`ordering.feasible_alternative`:
    the same steps, else a longer plan turning one joint the other way round), grounded again in that order (in
    the absolute formulation an action's from/to orientations depend on the turns before it)."""
    moves = [move_of(obj, step) for step in steps]
    answer, added = feasible_alternative(placement, moves, obj.orientations)
    if answer.moves is None:
        return Refusal(answer.sentence(), answer.help)
    room = f" ({answer.clearance_m * 100:.1f} cm from its edges at rest)"
    if list(answer.moves) == moves:
        return Ordered(tuple(steps), f"the planner's order of {len(moves)} actions stays on the table{room}")
    what = (f"{added} steps longer: one joint turns the other way round" if added
            else f"reordered {len(moves)} actions")
    return Ordered(steps_of(obj, model, init, answer.moves),
                   f"{what} so that every configuration stays on the table{room}")


def move_of(obj: ArticulatedObject, step: str | ActionSpec) -> Move:
    """The motion of one plan step (a PDDL step or a ground action)."""
    name = step.name if isinstance(step, ActionSpec) else parse_step(step)[0]
    m = action_motion(obj, step)
    return Move(name, m["turned_link_index"], m["held_link_index"], m["joint_index"], m["delta_deg"])


def steps_of(obj: ArticulatedObject, model: DomainModelSpec, init: State, moves: Sequence[Move]) -> tuple[str, ...]:
    """PDDL steps for `moves` in this order from `init`: each from the joint's orientation at that point."""
    state, steps = frozenset(init), []
    index = StateIndex(state)
    for move in moves:
        joint = obj.joint(move.joint)
        now = next(int(a[1].split("_", 1)[1]) for a in state if a[0] == HAS_ORIENTATION and a[2] == joint)
        after = (now + (obj.step if move.name == "rotateclockwise" else -obj.step)) % 360
        step = (f"({move.name} {obj.link(move.turned)} {obj.link(move.held)} {joint} {orientation_name(now)} "
                f"{orientation_name(after)})")
        state = apply(state, ground_action(model, step, state, index))
        index.moved(state)
        steps.append(step)
    return tuple(steps)


def _over_deadline(config: PlanningConfig, where: str, planner: str, timings: Mapping[str, float],
                   task: PddlTask | None) -> PlanOutcome:
    return PlanOutcome(PlanningStatus.TIMEOUT, f"planning deadline of {config.deadline_s:g} s exceeded {where}",
                       planner, timings=timings, task=task)


def validate(outcome: PlanOutcome, obj: ArticulatedObject | None = None, config: PlanningConfig | None = None,
             deadline_at: float | None = None) -> PlanOutcome:
    """VAL on the plan of an outcome made with `defer_validation`: the outcome, now `validated`, or an invalid
    outcome saying why VAL refused it, or a `timeout` outcome when VAL does not finish by `deadline_at`.
    Outcomes without a plan to check come back unchanged.

    With `obj` and `config.val_pieces` > 1, a long plan is checked in pieces at once (one VAL process each, see
    `validation_pieces`); the answer is the one a single run on the whole plan gives."""
    if not outcome.solved or not outcome.actions or outcome.validated or outcome.task is None:
        return outcome
    n_pieces = config.val_pieces if config is not None and obj is not None else 1
    return _checked(outcome, config, deadline_at, lambda left: _run_val(outcome, obj, n_pieces, left),
                    lambda: replace(outcome, validated=True, validated_steps=len(outcome.steps)), "the plan")


def validate_first(outcome: PlanOutcome, pieces: Sequence[ValPiece], config: PlanningConfig | None = None,
                   deadline_at: float | None = None, armed: ArmedValidators | None = None) -> PlanOutcome:
    """VAL on the plan's first pieces only (`early_pieces`: the first motion, in one or more pieces checked at
    once): the outcome with `validated_steps` = the last piece's last step (the rest of the plan is *not*
    validated: the caller checks the later pieces before using their steps), or an invalid or `timeout` outcome
    as in `validate`. `start_pieces` then `finish_first`, for a caller with work to do meanwhile."""
    if not outcome.solved or not outcome.actions or outcome.validated or outcome.task is None:
        return outcome
    checks = start_pieces(outcome.task, pieces, armed)
    return finish_first(outcome, pieces, checks, config, deadline_at)


def start_pieces(task: PddlTask, pieces: Sequence[ValPiece], armed: ArmedValidators | None = None
                 ) -> tuple[ValCheck, ...]:
    """One VAL run per piece, all started now (on armed processes when given), against the paper's exact domain."""
    checks: list[ValCheck] = []
    try:
        for piece in pieces:
            checks.append(armed.start(task.validation_domain, piece.problem, piece.steps) if armed is not None
                          else start_validation(task.validation_domain, piece.problem, piece.steps))
    except BaseException:
        for check in checks:
            check.cancel()
        raise
    return tuple(checks)


def finish_first(outcome: PlanOutcome, pieces: Sequence[ValPiece], checks: Sequence[ValCheck],
                 config: PlanningConfig | None, deadline_at: float | None) -> PlanOutcome:
    """The outcome once VAL has answered on every first piece (`start_pieces`): `validated_steps` up to the last
    one when all accepted, else invalid naming the piece VAL refused (the others stopped), or `timeout` at the
    deadline."""
    deadline_at = deadline_at if deadline_at is not None else (
        deadline_from(config) if config is not None else time.monotonic() + 60.0)
    what = f"its first {pieces[-1].last} steps"
    t = time.perf_counter()
    try:
        for i, check in enumerate(checks, start=1):
            verdict = _wait_verdict(check, deadline_at)
            if verdict is None:
                return _val_timeout(outcome, config, what, "VAL did not answer in time", time.perf_counter() - t)
            if not verdict.valid:
                reason = verdict.reason if len(checks) == 1 else f"piece {i} of {len(checks)}: {verdict.reason}"
                return _judged(outcome, ValidationResult(False, reason, verdict.seconds), time.perf_counter() - t,
                               lambda: outcome, what)
    finally:
        for check in checks:
            check.cancel()  # a run that answered is only cleaned up; one still running is stopped
    return _judged(outcome, ValidationResult(True, "Plan valid", 0.0), time.perf_counter() - t,
                   lambda: replace(outcome, validated_steps=pieces[-1].last), what)


def _wait_verdict(check: ValCheck, until: float) -> ValidationResult | None:
    """VAL's answer, waited for until `until` (`time.monotonic()`), else None."""
    verdict = check.verdict(max(0.0, until - time.monotonic()))
    while verdict is None and time.monotonic() < until:  # a wait may end a little early
        verdict = check.verdict(max(0.0, until - time.monotonic()))
    return verdict


def _checked(outcome: PlanOutcome, config: PlanningConfig | None, deadline_at: float | None,
             run: Callable[[float], ValidationResult], accepted: Callable[[], PlanOutcome], what: str
             ) -> PlanOutcome:
    deadline_at = deadline_at if deadline_at is not None else (
        deadline_from(config) if config is not None else time.monotonic() + 60.0)
    t = time.perf_counter()
    try:
        left = _left(deadline_at)
        if left <= 0:
            raise PlannerError("no time left for VAL")
        check = run(left)
    except PlannerError as exc:  # VAL's time limit: the request's deadline
        return _val_timeout(outcome, config, what, str(exc), time.perf_counter() - t)
    return _judged(outcome, check, time.perf_counter() - t, accepted, what)


def _judged(outcome: PlanOutcome, check: ValidationResult, seconds: float, accepted: Callable[[], PlanOutcome],
            what: str) -> PlanOutcome:
    """The outcome VAL's answer makes of a plan: `accepted()` when VAL accepted it, else invalid with VAL's
    reason (the time VAL took in the timings, as `validate`)."""
    timings = {**outcome.timings, "validate": seconds}
    if check.valid:
        return replace(accepted(), timings=timings)
    log.warning("plan of %s rejected by VAL: %s", outcome.planner, check.reason)
    return PlanOutcome(PlanningStatus.INVALID, f"VAL rejected {what}: {check.reason}", outcome.planner,
                       timings=timings, task=outcome.task, attempts=outcome.attempts)


def _val_timeout(outcome: PlanOutcome, config: PlanningConfig | None, what: str, why: str, seconds: float
                 ) -> PlanOutcome:
    limit = f"{config.deadline_s:g} s" if config is not None else "its time limit"
    return PlanOutcome(PlanningStatus.TIMEOUT, f"planning deadline of {limit} exceeded while VAL checked "
                       f"{what} ({why})", outcome.planner, timings={**outcome.timings, "validate": seconds},
                       task=outcome.task, attempts=outcome.attempts)


class ValCheck(Protocol):
    """A VAL run under way (`planner.validate.ValRun`): its verdict once there is one, and a way to stop it."""

    def verdict(self, timeout_s: float | None = None) -> ValidationResult | None: ...

    def cancel(self) -> None: ...


def start_val(task: PddlTask, steps: Sequence[str], armed: ArmedValidators | None = None) -> ValCheck:
    """VAL started on a plan's steps as one run on the whole plan against the paper's exact domain, e.g. as soon
    as `find_plan` has them, before the expected states are replayed: it runs in its own process (on the other
    core) beside `expect` and whatever the caller does next, and `finish_val` reads its verdict. With `armed`
    (a service's), on a VAL process that has already read the domain. For domains whose plans VAL checks in one
    short run (no conditional effects); the others go through `validate`."""
    if armed is not None:
        return armed.start(task.validation_domain, task.problem, steps)
    return start_validation(task.validation_domain, task.problem, steps)


def finish_val(outcome: PlanOutcome, check: ValCheck, config: PlanningConfig | None, deadline_at: float,
               timeout_s: float | None = None) -> PlanOutcome | None:
    """The outcome of `expect` once the VAL run `start_val` began on its plan has answered (as `validate` would
    make it), waiting up to `timeout_s` (None: until VAL answers or the deadline passes); None while VAL still
    runs within the deadline. At the deadline VAL is stopped and the outcome is a `timeout`. An outcome that is
    not a plan to check stops VAL and comes back unchanged."""
    if not outcome.solved or not outcome.actions:
        check.cancel()
        return outcome
    t = time.perf_counter()
    until = deadline_at if timeout_s is None else min(deadline_at, time.monotonic() + timeout_s)
    verdict = _wait_verdict(check, until)
    if verdict is None:
        if _left(deadline_at) > 0:
            return None
        check.cancel()
        return _val_timeout(outcome, config, "the plan", "VAL did not answer in time", time.perf_counter() - t)
    return _judged(outcome, verdict, verdict.seconds,
                   lambda: replace(outcome, validated=True, validated_steps=len(outcome.steps)), "the plan")


def _run_val(outcome: PlanOutcome, obj: ArticulatedObject | None, n_pieces: int, timeout_s: float
             ) -> ValidationResult:
    assert outcome.task is not None
    if obj is None or n_pieces <= 1 or len(outcome.steps) < 2 * MIN_PIECE_STEPS or not has_conditional_effects(
            outcome.task.validation_domain):
        return validate_plan(outcome.task.validation_domain, outcome.task.problem, outcome.steps, timeout_s)
    return validate_pieces(outcome.task.validation_domain, validation_pieces(obj, outcome, n_pieces), timeout_s)


# VAL's fixed cost (start, parse, ground the problem) is several ms: a piece shorter than this is not worth a
# process of its own. Without conditional effects a step costs VAL next to nothing (a 57-step relative 20 x 12
# plan: 4.0 ms in one run, 7.4 ms in two pieces), so only plans of domains with conditional effects are cut
# (absolute 20 x 12: 249 ms in one run, 156 ms in two pieces, on the 2-core machine under load).
MIN_PIECE_STEPS = 8


def validation_pieces(obj: ArticulatedObject, outcome: PlanOutcome, n_pieces: int, first_steps: int | None = None
                      ) -> list[tuple[str, tuple[str, ...]]]:
    """Cut a solved outcome's plan into at most `n_pieces` consecutive pieces of nearly equal length, each a
    (problem, steps) pair for VAL: piece i starts from the expected state s^e_(c_i) and its goal is the *exact*
    next cut state s^e_(c_(i+1)) (every hasorientation atom of it, and the negation of every other one); the
    last piece's goal is the task's own goal (the first piece starts from the task's initial state). With
    `first_steps`, the first piece is the plan's first `first_steps` steps and the rest is cut as above
    (`piece_bounds`).

    Why the pieces say what one run says: hasorientation is the only predicate any action changes, and every
    piece's problem has the task's objects and static facts. Induction over the pieces: VAL's state before
    piece i is s^e_(c_i) (for i = 1 the task's init); VAL accepts piece i only if each of its steps is
    applicable in turn and the state it ends in satisfies the exact goal, i.e. *is* s^e_(c_(i+1)); so one run
    on the whole plan applies the same steps to the same states and ends where the last piece ends, in a state
    satisfying the goal. When the pieces are accepted, the whole plan is. (A piece can only be refused
    wrongly if an expected state is wrong, which makes the plan unusable anyway.) The same induction makes an
    accepted *first* piece mean: from the perceived state, its steps apply one after the other and end exactly
    in the expected state after them, whatever the later pieces' verdicts."""
    return [(p.problem, p.steps) for p in early_pieces(obj, outcome, n_pieces, first_steps)]


@dataclass(frozen=True)
class ValPiece:
    """One piece of a plan for VAL: steps a_first .. a_last (1-based, inclusive) and the problem they solve."""

    first: int
    last: int
    problem: str
    steps: tuple[str, ...]


def piece_bounds(n_steps: int, n_pieces: int, first_steps: int | None = None, first_parts: int = 1
                 ) -> list[tuple[int, int]]:
    """The pieces of a plan of `n_steps` steps as 0-based half-open (start, end) step ranges: `n_pieces` of
    nearly equal length, none shorter than MIN_PIECE_STEPS unless the plan is; with `first_steps`, the first
    `first_steps` steps as `first_parts` pieces of nearly equal length (at least one step each: they are checked
    at once before an answer, where VAL's cost per step matters more than its fixed cost), then the rest cut the
    same way."""
    if first_steps is not None and 0 < first_steps < n_steps:
        rest = piece_bounds(n_steps - first_steps, n_pieces)
        parts = max(1, min(first_parts, first_steps))
        cuts = [round(i * first_steps / parts) for i in range(parts + 1)]
        return ([(cuts[i], cuts[i + 1]) for i in range(parts)]
                + [(first_steps + a, first_steps + b) for a, b in rest])
    n = min(n_pieces, max(1, n_steps // MIN_PIECE_STEPS))
    cuts = [round(i * n_steps / n) for i in range(n + 1)]
    return [(cuts[i], cuts[i + 1]) for i in range(n)]


def early_pieces(obj: ArticulatedObject, outcome: PlanOutcome, n_pieces: int, first_steps: int | None = None,
                 first_parts: int = 1) -> tuple[ValPiece, ...]:
    """The pieces of `validation_pieces` (the first `first_steps` in `first_parts` pieces), with their step
    ranges."""
    assert outcome.task is not None
    bounds = piece_bounds(len(outcome.steps), n_pieces, first_steps, first_parts)
    return tuple(piece_of(obj, outcome.task.problem, outcome.steps, outcome.expected_states, a + 1, b)
                 for a, b in bounds)


def piece_of(obj: ArticulatedObject, task_problem: str, steps: Sequence[str], states: Sequence[State],
             first: int, last: int) -> ValPiece:
    """The piece of a plan (`steps`, expected states `states`, task problem text) holding steps a_first .. a_last:
    from s^e_first (the task's own init for the first piece) to exactly s^e_(last+1), or to the task's goal for
    the last piece."""
    a, b = first - 1, last
    if b == len(steps):
        problem = task_problem if a == 0 else _problem_text(obj, states[a], None, task_problem)
    else:
        problem = _problem_text(obj, states[a], states[b], task_problem)
    return ValPiece(first, last, problem, tuple(steps[a:b]))


def step_text(action: ActionSpec) -> str:
    """A ground action as a plan step for VAL: "(name arg ...)"."""
    return "(" + " ".join((action.name,) + tuple(action.params)) + ")"


def first_motion_steps(obj: ArticulatedObject, actions: Sequence[ActionSpec], merge: bool) -> int:
    """How many plan steps the robot's first motion covers: 1, or with macro steps merged (`merge_macro_steps`)
    the first run of steps on one joint, one turned link and one direction, short of a full turn."""
    if not actions:
        return 0
    if not merge:
        return 1
    first = action_motion(obj, actions[0])
    total, n = first["delta_deg"], 1
    for action in actions[1:]:
        m = action_motion(obj, action)
        if ((m["joint_index"], m["turned_link_index"]) != (first["joint_index"], first["turned_link_index"])
                or (m["delta_deg"] > 0) != (total > 0) or abs(total + m["delta_deg"]) >= 360):
            break
        total += m["delta_deg"]
        n += 1
    return n


def early_answer_first_piece(obj: ArticulatedObject, outcome: PlanOutcome, merge: bool) -> int | None:
    """The length of the first piece to validate before answering, or None when the whole plan is checked
    before the answer: plans of domains without conditional effects (VAL checks them whole in a few ms) and
    plans whose rest after the first motion is shorter than MIN_PIECE_STEPS."""
    if outcome.task is None or not outcome.steps or not has_conditional_effects(outcome.task.validation_domain):
        return None
    first = first_motion_steps(obj, outcome.actions, merge)
    if len(outcome.steps) - first < MIN_PIECE_STEPS:
        return None
    return first


def _problem_text(obj: ArticulatedObject, start: State, exact_goal: State | None, task_problem: str) -> str:
    """A VAL problem with the task's objects and static facts, starting from `start`, whose goal is
    `exact_goal` exactly (each of its hasorientation atoms, and the negation of every other one) or, when it
    is None, the task's own goal. Written from the task's text (only the hasorientation lines of its init and
    its goal change): the static facts are not sorted and written again for every piece."""
    head, rest = task_problem.split(_INIT, 1)
    init, goal = rest.split(_GOAL, 1)
    static = "".join(line for line in init.splitlines(keepends=True)
                     if not line.startswith(_FLUENT) and line != _CLOSE)
    fluents = "".join(f"    {format_atom(a)}\n" for a in sorted(_fluents(start)))
    if exact_goal is None:
        goal_text = _GOAL + goal
    else:
        wanted = _fluents(exact_goal)
        goal_text = (_GOAL + "".join(f"    {format_atom(a)}\n" for a in sorted(wanted))
                     + "".join(f"    (not {format_atom((HAS_ORIENTATION, o, j))})\n" for j in obj.joints
                               for o in obj.orientation_names if (HAS_ORIENTATION, o, j) not in wanted)
                     + "  ))\n)\n")
    return head + _INIT + static + fluents + _CLOSE + goal_text


# The parts of a problem written by `translator.problem.write_problem` that `_problem_text` cuts at.
_INIT, _GOAL, _CLOSE, _FLUENT = "  (:init\n", "  (:goal (and\n", "  )\n", f"    ({HAS_ORIENTATION} "


def _fluents(state: State) -> frozenset:
    return frozenset(a for a in state if a[0] == HAS_ORIENTATION)


def run_planners(task: PddlTask, config: PlanningConfig, timeout_s: float | None = None) -> PlanResult:
    """The configured planner, then the fallback planner when the first cannot answer (the planner package's
    one fallback chain), within `timeout_s` (default: the configured planner time limit)."""
    return plan_with_fallback(task.domain, task.problem, planner_chain(config),
                              config.timeout_s if timeout_s is None else timeout_s)


def planner_chain(config: PlanningConfig) -> tuple[str, ...]:
    """The planners tried in order: the configured one, then the fallback (when set and different)."""
    return tuple(dict.fromkeys(name for name in (config.planner, config.fallback_planner) if name))


class PlanStep(Protocol):
    """A stored plan step: its id, 1-based position and ground action (e.g. the store's `StoredAction`)."""

    @property
    def id(self) -> str: ...

    @property
    def step(self) -> int: ...

    @property
    def spec(self) -> ActionSpec: ...


# -- what an action means for the robot -----------------------------------------------------------------------
def _index(name: str) -> int:
    return int(name.rsplit("_", 1)[1][1:])


def action_motion(obj: ArticulatedObject, action: PlanStep | ActionSpec | Sequence[str] | str) -> dict[str, int]:
    """Which link turns, which is held (0 = the table), about which joint and by how many degrees
    (+ clockwise seen from above) for one plan step."""
    if isinstance(action, ActionSpec):
        name, params = action.name, action.params
    elif isinstance(action, str):
        name, params = parse_step(action)
    elif isinstance(action, Sequence):
        name, params = action[0], tuple(action[1:])
    else:
        name, params = action.spec.name, action.spec.params
    turned, held, joint = _index(params[0]), _index(params[1]), _index(params[2])
    sign = 1 if name == "rotateclockwise" else -1
    delta = sign * obj.step
    if obj.formulation is Formulation.RELATIVE and turned == joint:
        # jK joins lK and lK+1 and carries lK+1 relative to lK: turning lK instead of lK+1 is the opposite turn
        delta = -delta
    return {"joint_index": joint, "turned_link_index": turned, "held_link_index": held, "delta_deg": delta,
            "macro_steps": 1}


@dataclass(frozen=True)
class MacroStep:
    """Consecutive steps on the same joint, turned link and direction, merged for execution."""

    first_step: int
    last_step: int
    joint_index: int
    turned_link_index: int
    held_link_index: int
    delta_deg: int
    action_ids: tuple[str, ...]

    @property
    def expected_state_step(self) -> int:
        """Index (1-based, s^e_i) of the expected state after the merged step."""
        return self.last_step + 1


def merge_macro_steps(obj: ArticulatedObject, actions: Sequence[PlanStep], first_only: bool = False
                      ) -> tuple[MacroStep, ...]:
    """The paper's consolidation: e.g. two 45° steps of one joint become one 90° step. With `first_only`, only the
    first macro step (the actions after it are not looked at: the motion to dispatch next)."""
    merged: list[MacroStep] = []
    for action in sorted(actions, key=lambda a: a.step):
        if first_only and len(merged) > 1:
            break
        m = action_motion(obj, action)
        prev = merged[-1] if merged else None
        same = (
            prev is not None
            and prev.joint_index == m["joint_index"]
            and prev.turned_link_index == m["turned_link_index"]
            and (prev.delta_deg > 0) == (m["delta_deg"] > 0)
            and abs(prev.delta_deg + m["delta_deg"]) < 360
        )
        if same and prev is not None:
            merged[-1] = MacroStep(prev.first_step, action.step, prev.joint_index, prev.turned_link_index,
                                   prev.held_link_index, prev.delta_deg + m["delta_deg"],
                                   prev.action_ids + (action.id,))
        else:
            merged.append(MacroStep(action.step, action.step, m["joint_index"], m["turned_link_index"],
                                    m["held_link_index"], m["delta_deg"], (action.id,)))
    return tuple(merged[:1]) if first_only else tuple(merged)

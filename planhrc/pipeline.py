"""The planning pipeline, one stage after another, from values to a value:

    object, initial and goal states -> translate (TBox domain model -> PDDL domain, states -> PDDL problem)
      -> plan (a planner of the registry, then the fallback) -> validate (VAL)
      -> expected states (replay with the paper's transition equations) -> `PlanOutcome`

`plan(...)` reads nothing from and writes nothing to the knowledge base: the caller (the service's orchestrator,
`planhrc solve`) stores what it returns, in one write. Planners are reached only through the registry.
"""
from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Mapping, Protocol, Sequence

from planhrc.model import ActionSpec, ArticulatedObject, Formulation, State, is_subsumed
from planhrc.planner.chain import plan_with_fallback
from planhrc.planner.result import PlannerAttempt, PlanResult
from planhrc.planner.validate import validate_plan
from planhrc.settings import Settings, get_settings
from planhrc.transition import TransitionError, parse_step, replay
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


def config_from_settings(settings: Settings) -> PlanningConfig:
    return PlanningConfig(
        tbox_path=Path(settings.tbox_path),
        planner=settings.planner,
        timeout_s=float(settings.planner_timeout_s),
        validate=bool(settings.validate_plans),
        fallback_planner=settings.fallback_planner or None,
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

    @property
    def solved(self) -> bool:
        return self.status is PlanningStatus.SOLVED


def problem_name(obj: ArticulatedObject) -> str:
    """The name of an object's PDDL problem (the same for every re-plan, so the text depends on states only)."""
    return f"{obj.ident}-task"


def plan(obj: ArticulatedObject, init: State, goal: State, config: PlanningConfig | None = None, *,
         defer_validation: bool = False) -> PlanOutcome:
    """Translate, plan, validate and replay one task; returns a value and stores nothing. Without `config`, the
    settings (`PLANHRC_*` environment variables and their defaults) say how.

    `defer_validation` leaves VAL to the caller, who runs `validate(outcome)` (e.g. while it stores the plan) and
    must not use the plan before VAL accepted it (`validated`)."""
    config = config or config_from_settings(get_settings())
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    if is_subsumed(init, goal):
        return PlanOutcome(PlanningStatus.SOLVED, "the initial state already satisfies the goal", config.planner,
                           True, timings=timings)
    model = read_domain_model(config.tbox_path, obj.formulation.value)
    task = translate(obj, init, goal, model, problem_name(obj))
    timings["translate"] = time.perf_counter() - t0

    t = time.perf_counter()
    result = run_planners(task, config)
    timings["plan"] = time.perf_counter() - t
    if not result.solved:
        status = PlanningStatus(result.status.value)
        return PlanOutcome(status, result.message or result.status.value, result.planner, None,
                           timings=timings, task=task, attempts=result.attempts)

    if config.validate and not defer_validation:
        t = time.perf_counter()
        check = validate_plan(task.validation_domain, task.problem, result.plan)
        timings["validate"] = time.perf_counter() - t
        if not check.valid:
            log.warning("plan of %s rejected by VAL: %s", result.planner, check.reason)
            return PlanOutcome(PlanningStatus.INVALID, f"VAL rejected the plan: {check.reason}", result.planner,
                               timings=timings, task=task)

    t = time.perf_counter()
    try:
        actions, states = replay(model, init, result.plan)
    except TransitionError as exc:
        return PlanOutcome(PlanningStatus.INVALID, f"plan does not replay: {exc}", result.planner,
                           timings=timings, task=task)
    if not is_subsumed(states[-1], goal):
        return PlanOutcome(PlanningStatus.INVALID, "the last expected state is not subsumed by the goal",
                           result.planner, timings=timings, task=task)
    timings["expected_states"] = time.perf_counter() - t
    timings["pipeline"] = time.perf_counter() - t0
    return PlanOutcome(PlanningStatus.SOLVED, result.message, result.planner, result.optimal, tuple(actions),
                       tuple(states), timings, task, result.attempts, tuple(result.plan),
                       validated=config.validate and not defer_validation)


def validate(outcome: PlanOutcome) -> PlanOutcome:
    """VAL on the plan of an outcome made with `defer_validation`: the outcome, now `validated`, or an invalid
    outcome saying why VAL refused it. Outcomes without a plan to check come back unchanged."""
    if not outcome.solved or not outcome.actions or outcome.validated or outcome.task is None:
        return outcome
    t = time.perf_counter()
    check = validate_plan(outcome.task.validation_domain, outcome.task.problem, outcome.steps)
    timings = {**outcome.timings, "validate": time.perf_counter() - t}
    if check.valid:
        return replace(outcome, validated=True, timings=timings)
    log.warning("plan of %s rejected by VAL: %s", outcome.planner, check.reason)
    return PlanOutcome(PlanningStatus.INVALID, f"VAL rejected the plan: {check.reason}", outcome.planner,
                       timings=timings, task=outcome.task, attempts=outcome.attempts)


def run_planners(task: PddlTask, config: PlanningConfig) -> PlanResult:
    """The configured planner, then the fallback planner when the first cannot answer (the planner package's
    one fallback chain)."""
    return plan_with_fallback(task.domain, task.problem, planner_chain(config), config.timeout_s)


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


def merge_macro_steps(obj: ArticulatedObject, actions: Sequence[PlanStep]) -> tuple[MacroStep, ...]:
    """The paper's consolidation: e.g. two 45° steps of one joint become one 90° step."""
    merged: list[MacroStep] = []
    for action in sorted(actions, key=lambda a: a.step):
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
    return tuple(merged)

"""The planning pipeline, one stage after another:

    Problem in the ABox -> translate (TBox -> domain, ABox -> problem) -> plan -> validate (VAL)
      -> expected states (replay with the paper's transition equations) -> plan + expected States in the ABox

`Planning` owns what lives across calls: the settings and, for the in-process planner, one grounded task
per object, so a re-plan from a new perceived state does not parse or ground again.
"""
from __future__ import annotations

from typing import TYPE_CHECKING

import logging
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Sequence

from planhrc.kb.records import StoredAction, StoredPlan
from planhrc.model import ArticulatedObject, Formulation, State, is_subsumed
from planhrc.transition import TransitionError, parse_step, replay
from planhrc.planner.errors import PlannerError
from planhrc.planner.inproc import GroundTask, ground_task
from planhrc.planner.registry import get_planner
from planhrc.planner.result import PlanResult, PlanStatus
from planhrc.planner.validate import validate_plan
from planhrc.translator.domain import read_domain_model
from planhrc.translator.translate import PddlTask, translate

if TYPE_CHECKING:  # the store is only a type here: the stage works on any object with its read methods
    from planhrc.kb.store import KnowledgeBase

log = logging.getLogger(__name__)

SOLVED, UNSOLVABLE, TIMEOUT, ERROR, INVALID = "solved", "unsolvable", "timeout", "error", "invalid"


@dataclass(frozen=True)
class PlanOutcome:
    """What one planning request produced. `plan` is stored (with its expected states) only when solved."""

    status: str
    plan: StoredPlan | None
    message: str
    timings: dict[str, float] = field(default_factory=dict)
    planner: str = ""
    optimal: bool | None = None
    problem_id: str | None = None


@dataclass(frozen=True)
class PlanningConfig:
    tbox_path: Path
    planner: str = "inproc"
    timeout_s: float = 5.0
    validate: bool = True
    fallback_planner: str | None = "fd-lama"  # used when the in-process planner cannot take the task


def config_from_settings(settings: Any) -> PlanningConfig:
    return PlanningConfig(
        tbox_path=Path(settings.tbox_path),
        planner=getattr(settings, "planner", "inproc"),
        timeout_s=float(getattr(settings, "planner_timeout_s", 5.0)),
        validate=bool(getattr(settings, "validate_plans", True)),
        fallback_planner=getattr(settings, "fallback_planner", "fd-lama") or None,
    )


class Planning:
    """Runs the pipeline; keeps one grounded in-process task per object (keyed by its PDDL objects)."""

    def __init__(self, config: PlanningConfig) -> None:
        self.config = config
        self._ground: dict[str, tuple[str, GroundTask]] = {}
        self._lock = threading.Lock()

    def _grounded(self, task: PddlTask) -> GroundTask:
        # The grounded task depends on the domain and the problem's objects and static facts, not on init/goal.
        key = task.object_id
        signature = task.domain + "\n" + _static_part(task.problem)
        with self._lock:
            cached = self._ground.get(key)
            if cached is not None and cached[0] == signature:
                return cached[1]
        grounded = ground_task(task.domain, task.problem)
        with self._lock:
            self._ground[key] = (signature, grounded)
        return grounded

    def run_planner(self, task: PddlTask, init: State, goal: State) -> PlanResult:
        if self.config.planner != "inproc":
            return get_planner(self.config.planner).solve(task.domain, task.problem, self.config.timeout_s)
        start = time.perf_counter()
        try:
            result = self._grounded(task).solve(init, goal)
        except PlannerError as exc:  # the task is outside the rotation family the in-process planner knows
            result = PlanResult(PlanStatus.ERROR, (), 0.0, "inproc", str(exc))
        if result.status is PlanStatus.ERROR and self.config.fallback_planner:
            log.warning("in-process planner cannot take %s (%s); using %s", task.problem_id, result.message,
                        self.config.fallback_planner)
            remaining = max(0.1, self.config.timeout_s - (time.perf_counter() - start))
            return get_planner(self.config.fallback_planner).solve(task.domain, task.problem, remaining)
        return PlanResult(result.status, result.plan, time.perf_counter() - start, result.planner,
                          result.message, result.optimal)

    def make_plan(self, kb: KnowledgeBase, object_id: str, init_state_id: str, goal_state_id: str) -> PlanOutcome:
        """Store a Problem (init, goal), plan it, validate the plan and store it with its expected states."""
        timings: dict[str, float] = {}
        t0 = time.perf_counter()
        init = kb.get_state(init_state_id)
        goal = kb.get_state(goal_state_id)
        problem = kb.add_problem(object_id, init_state_id, goal_state_id)
        if is_subsumed(init.atoms, goal.atoms):
            return PlanOutcome(SOLVED, None, "the initial state already satisfies the goal", timings,
                               self.config.planner, True, problem.id)
        task = translate(kb, problem.id, self.config.tbox_path)
        timings["translate"] = time.perf_counter() - t0

        t = time.perf_counter()
        result = self.run_planner(task, init.atoms, goal.atoms)
        timings["plan"] = time.perf_counter() - t
        if not result.solved:
            status = {PlanStatus.UNSOLVABLE: UNSOLVABLE, PlanStatus.TIMEOUT: TIMEOUT}.get(result.status, ERROR)
            return PlanOutcome(status, None, result.message or result.status.value, timings, result.planner,
                               None, problem.id)

        if self.config.validate:
            t = time.perf_counter()
            check = validate_plan(task.validation_domain, task.problem, result.plan)
            timings["validate"] = time.perf_counter() - t
            if not check.valid:
                log.warning("plan of %s rejected by VAL: %s", result.planner, check.reason)
                return PlanOutcome(INVALID, None, f"VAL rejected the plan: {check.reason}", timings,
                                   result.planner, None, problem.id)

        t = time.perf_counter()
        domain = read_domain_model(self.config.tbox_path, kb.get_object(object_id).formulation.value)
        try:
            actions, states = replay(domain, init.atoms, result.plan)
        except TransitionError as exc:
            return PlanOutcome(INVALID, None, f"plan does not replay: {exc}", timings, result.planner, None,
                               problem.id)
        if not is_subsumed(states[-1], goal.atoms):
            return PlanOutcome(INVALID, None, "the last expected state is not subsumed by the goal", timings,
                               result.planner, None, problem.id)
        timings["expected_states"] = time.perf_counter() - t

        t = time.perf_counter()
        stored = kb.add_plan(problem.id, result.planner, actions, states)
        timings["store"] = time.perf_counter() - t
        timings["total"] = time.perf_counter() - t0
        return PlanOutcome(SOLVED, stored, result.message, timings, result.planner, result.optimal, problem.id)


def _static_part(problem_text: str) -> str:
    """The problem text without its hasorientation facts and goal: what grounding depends on."""
    lines = [ln for ln in problem_text.splitlines() if "(hasorientation" not in ln and "(problem " not in ln]
    return "\n".join(lines)


def make_plan(kb: KnowledgeBase, object_id: str, init_state_id: str, goal_state_id: str, settings: Any,
              planning: Planning | None = None) -> PlanOutcome:
    """One-shot form of `Planning.make_plan` (pass `planning` to reuse grounded tasks across calls)."""
    planning = planning or Planning(config_from_settings(settings))
    return planning.make_plan(kb, object_id, init_state_id, goal_state_id)


# -- what an action means for the robot -----------------------------------------------------------------------
def _index(name: str) -> int:
    return int(name.rsplit("_", 1)[1][1:])


def action_motion(obj: ArticulatedObject, action: StoredAction | Sequence[str] | str) -> dict[str, int]:
    """Which link turns, which is held (0 = the table), about which joint and by how many degrees
    (+ clockwise seen from above) for one plan step."""
    if isinstance(action, StoredAction):
        name, params = action.spec.name, action.spec.params
    elif isinstance(action, str):
        name, params = parse_step(action)
    else:
        name, params = action[0], tuple(action[1:])
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


def merge_macro_steps(obj: ArticulatedObject, actions: Sequence[StoredAction]) -> tuple[MacroStep, ...]:
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

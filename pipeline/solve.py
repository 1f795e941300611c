"""One problem through the pipeline, as values: the request, its object and states, and the report `planhrc solve`
prints. Storing the result in the knowledge base is the service's job (`planhrc.kb_service.solve`)."""
from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from typing import Any, Mapping

from planhrc.model import ActionSpec, ArticulatedObject, ModelError, State, make_object
from planhrc.pipeline import PlanningConfig, PlanOutcome, deadline_from, merge_macro_steps, plan, validate
from planhrc.vocabulary import PlanningStatus

ANY = {"*", "_", "-", "?"}


@dataclass(frozen=True)
class SolveRequest:
    formulation: str
    orientations: int
    init: tuple[int, ...]
    goal: tuple[int | None, ...]  # None = unconstrained (partial goal)
    link_length_m: float = 0.155


@dataclass(frozen=True)
class Solution:
    """A request's object, initial and goal states, and what the pipeline made of them."""

    obj: ArticulatedObject
    init: State
    goal: State
    outcome: PlanOutcome
    timings: Mapping[str, float] = field(default_factory=dict)


def parse_angles(text: str, field: str, allow_any: bool = False) -> tuple[int | None, ...]:
    values: list[int | None] = []
    for i, item in enumerate(x.strip() for x in text.split(",")):
        if allow_any and item in ANY:
            values.append(None)
            continue
        try:
            number = float(item)
        except ValueError:
            raise ModelError(f"{field}[{i}]: {item!r} is not a number of degrees") from None
        if not number.is_integer():
            raise ModelError(f"{field}[{i}]: {item} is not an allowed orientation (integer degrees)")
        values.append(int(number) % 360)
    return tuple(values)


def object_for(request: SolveRequest, ident: str) -> ArticulatedObject:
    n_values = len(request.init)
    n_links = n_values if request.formulation == "absolute" else n_values + 1
    return make_object(ident, request.formulation, [request.link_length_m] * n_links, request.orientations)


def solve(request: SolveRequest, config: PlanningConfig, ident: str = "obj1") -> Solution:
    """The request's object (named `ident`) and states, planned, validated and replayed; nothing is stored."""
    t0 = time.perf_counter()
    obj = object_for(request, ident)
    init = obj.state(obj.check_joint_values(request.init, field="init"))
    goal = obj.partial_configuration_atoms(request.goal, field="goal")
    timings = {"model": time.perf_counter() - t0}
    deadline_at = deadline_from(config)
    found = plan(obj, init, goal, config, defer_validation=True, deadline_at=deadline_at)
    outcome = checked(obj, init, goal, config, found, deadline_at)
    return Solution(obj, init, goal, outcome, {**timings, **outcome.timings})


def checked(obj: ArticulatedObject, init: State, goal: State, config: PlanningConfig, found: PlanOutcome,
            deadline_at: float) -> PlanOutcome:
    """The found plan with VAL's verdict. "solved" means validated: a plan no validator gave a verdict on (VAL not
    asked, or not finished by the deadline) is kept `unvalidated` with the reason, never answered as a timeout; a
    plan VAL refused goes to the next planners, as the pipeline does."""
    if not found.solved or not found.actions:
        return found
    if not config.validate:
        return replace(found, status=PlanningStatus.UNVALIDATED, message="not validated: VAL was not asked "
                       "(--no-validate)")
    outcome = validate(found, obj, config, deadline_at)
    if outcome.status is PlanningStatus.INVALID:
        return plan(obj, init, goal, config, deadline_at=deadline_at)
    if outcome.status is PlanningStatus.TIMEOUT:
        return replace(found, status=PlanningStatus.UNVALIDATED, message=f"not validated: {outcome.message}",
                       timings=outcome.timings)
    return outcome


def report(solution: Solution, ids: Mapping[str, str | None], timings: Mapping[str, float]) -> dict[str, Any]:
    """The JSON-ready report of a solution; `ids` names what the store made of it (object, problem, plan)."""
    obj, outcome = solution.obj, solution.outcome
    out: dict[str, Any] = {
        "status": outcome.status.value,
        "planner": outcome.planner,
        "optimal": outcome.optimal,
        "message": outcome.message,
        "object_id": ids.get("object_id"),
        "problem_id": ids.get("problem_id"),
        "plan_id": ids.get("plan_id"),
        "plan": ["(" + " ".join((a.name,) + a.params) + ")" for a in outcome.actions],
        "expected_states": [],
        "macro_steps": [],
        "timings_s": {k: round(v, 6) for k, v in timings.items()},
    }
    if outcome.actions:
        for atoms in outcome.expected_states:
            values = obj.joint_values_of(atoms)
            out["expected_states"].append([values[k] for k in obj.joint_indices])
        steps = [_Step(f"a{i}", i, a) for i, a in enumerate(outcome.actions, start=1)]
        out["macro_steps"] = [
            {"steps": [m.first_step, m.last_step], "joint_index": m.joint_index,
             "turned_link_index": m.turned_link_index, "held_link_index": m.held_link_index,
             "delta_deg": m.delta_deg}
            for m in merge_macro_steps(obj, steps)
        ]
    return out


@dataclass(frozen=True)
class _Step:
    id: str
    step: int
    spec: ActionSpec

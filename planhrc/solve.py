"""`planhrc solve`: one problem end to end through the ontology.

object -> initial and goal States in the ABox -> translation -> planning -> VAL -> expected States stored;
prints the time of each stage and the plan with its expected states.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import dataclass, replace
from typing import Any

from planhrc.cli_args import int_in, positive_float, writable_file
from planhrc.kb.errors import KBError
from planhrc.kb.store import KnowledgeBase
from planhrc.model import ArticulatedObject, ModelError, make_object
from planhrc.pipeline import PlanningConfig, config_from_settings, merge_macro_steps, plan
from planhrc.settings import get_settings
from planhrc.planner.errors import PlannerError
from planhrc.planner.registry import PLANNERS
from planhrc.translator.errors import TranslationError

ANY = {"*", "_", "-", "?"}


@dataclass(frozen=True)
class SolveRequest:
    formulation: str
    orientations: int
    init: tuple[int, ...]
    goal: tuple[int | None, ...]  # None = unconstrained (partial goal)
    link_length_m: float = 0.155


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


def solve(request: SolveRequest, kb: KnowledgeBase, config: PlanningConfig) -> dict[str, Any]:
    """Run the whole pipeline for one request and store its states, problem and plan; returns the JSON-ready
    report."""
    t0 = time.perf_counter()
    ident = kb.new_object_id()
    obj = object_for(request, ident)
    init_atoms = obj.state(obj.check_joint_values(request.init, field="init"))
    goal_atoms = obj.partial_configuration_atoms(request.goal, field="goal")
    timings = {"model": time.perf_counter() - t0}
    outcome = plan(obj, init_atoms, goal_atoms, config)
    timings.update(outcome.timings)
    t = time.perf_counter()
    with kb.transaction():
        kb.create_object(obj)
        init_state = kb.add_state(ident, "initial", init_atoms)
        goal_state = kb.add_state(ident, "goal", goal_atoms)
        problem = kb.add_problem(ident, init_state.id, goal_state.id)
        stored = (kb.add_plan(problem.id, outcome.planner, outcome.actions, outcome.expected_states)
                  if outcome.solved and outcome.actions else None)
    timings["store"] = time.perf_counter() - t
    timings["total"] = time.perf_counter() - t0
    report: dict[str, Any] = {
        "status": outcome.status.value,
        "planner": outcome.planner,
        "optimal": outcome.optimal,
        "message": outcome.message,
        "object_id": ident,
        "problem_id": problem.id,
        "plan_id": stored.id if stored else None,
        "plan": ["(" + " ".join((a.name,) + a.params) + ")" for a in outcome.actions],
        "expected_states": [],
        "macro_steps": [],
        "timings_s": {k: round(v, 6) for k, v in timings.items()},
    }
    if stored is not None:
        for atoms in outcome.expected_states:
            values = obj.joint_values_of(atoms)
            report["expected_states"].append([values[k] for k in obj.joint_indices])
        report["macro_steps"] = [
            {"steps": [m.first_step, m.last_step], "joint_index": m.joint_index,
             "turned_link_index": m.turned_link_index, "held_link_index": m.held_link_index,
             "delta_deg": m.delta_deg}
            for m in merge_macro_steps(obj, stored.actions)
        ]
    return report


def add_solve_parser(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("solve", help="solve one problem end to end through the ontology",
                              description=__doc__)
    p.add_argument("--formulation", choices=["relative", "absolute"], required=True)
    p.add_argument("--orientations", type=int_in(2, 360), required=True, metavar="K", help="allowed orientations (360 %% K == 0)")
    p.add_argument("--init", required=True, help="degrees, comma separated (absolute: per link; relative: per joint)")
    p.add_argument("--goal", required=True, help="degrees, comma separated; '*' leaves a joint unconstrained")
    p.add_argument("--planner", default=None, choices=list(PLANNERS),
                   help="planner backend (default: the settings' planner)")
    p.add_argument("--timeout", type=positive_float, default=None, metavar="S",
                   help="time limit of one planner call (default: the settings' planner_timeout_s)")
    p.add_argument("--no-validate", action="store_true", help="skip VAL (not recommended)")
    p.add_argument("--db", type=writable_file, default=None, help="SQLite store (default: in memory)")
    p.add_argument("--json", action="store_true", help="print the report as JSON")
    p.set_defaults(func=run_solve)


def run_solve(args: argparse.Namespace) -> int:
    try:
        request = SolveRequest(
            formulation=args.formulation,
            orientations=args.orientations,
            init=tuple(v for v in parse_angles(args.init, "init") if v is not None),
            goal=parse_angles(args.goal, "goal", allow_any=True),
        )
        config = config_from_settings(get_settings())
        config = replace(config, planner=args.planner or config.planner,
                         timeout_s=config.timeout_s if args.timeout is None else args.timeout,
                         validate=config.validate and not args.no_validate)
        with KnowledgeBase(args.db, config.tbox_path) as kb:
            report = solve(request, kb, config)
    except (ModelError, KBError, TranslationError, PlannerError) as exc:
        print(f"planhrc solve: {exc}", file=sys.stderr)
        return 2
    if args.json:
        print(json.dumps(report, indent=2))
    else:
        _print_report(report)
    return 0 if report["status"] == "solved" else 1


def _print_report(report: dict) -> None:
    print(f"status: {report['status']}  planner: {report['planner']}  optimal: {report['optimal']}")
    if report["message"]:
        print(f"message: {report['message']}")
    for i, state in enumerate(report["expected_states"], start=1):
        step = report["plan"][i - 1] if i <= len(report["plan"]) else ""
        print(f"  s^e_{i}: {state}  {('-> ' + step) if step else '(goal)'}")
    print("timings (s): " + ", ".join(f"{k} {v:.4f}" for k, v in report["timings_s"].items()))

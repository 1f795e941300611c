"""`planhrc solve`: one problem end to end through the ontology.

object -> translation -> planning -> VAL -> expected states (`planhrc.pipeline.solve`, values) -> the object, its initial
and goal States, the Problem and the Plan with its expected States stored in the ABox in one write; prints the
time of each stage and the plan with its expected states.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import replace
from typing import Any

from planhrc.cli_args import int_in, positive_float, writable_file
from planhrc.model import Formulation, ModelError
from planhrc.pipeline import PlanningConfig, config_from_settings
from planhrc.planner.errors import PlannerError
from planhrc.planner.registry import PLANNERS
from planhrc.settings import get_settings
from planhrc.pipeline.solve import SolveRequest, parse_angles, report, solve
from planhrc.translator.errors import TranslationError

from .store import KBError, SqliteStore


def solve_and_store(request: SolveRequest, kb: SqliteStore, config: PlanningConfig) -> dict[str, Any]:
    """Plan one request and store the object, its states, the problem and the plan in one write; the report."""
    t0 = time.perf_counter()
    ident = kb.new_object_id()
    solution = solve(request, config, ident)
    outcome = solution.outcome
    t = time.perf_counter()
    with kb.transaction():
        kb.create_object(solution.obj)
        init_state = kb.add_state(ident, "initial", solution.init)
        goal_state = kb.add_state(ident, "goal", solution.goal)
        problem = kb.add_problem(ident, init_state.id, goal_state.id)
        stored = (kb.add_plan(problem.id, outcome.planner, outcome.actions, outcome.expected_states)
                  if outcome.solved and outcome.actions else None)
    timings = {**solution.timings, "store": time.perf_counter() - t, "total": time.perf_counter() - t0}
    ids = {"object_id": ident, "problem_id": problem.id, "plan_id": stored.id if stored else None}
    return report(solution, ids, timings)


def add_solve_parser(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = subparsers.add_parser("solve", help="solve one problem end to end through the ontology",
                              description=__doc__)
    p.add_argument("--formulation", choices=[f.value for f in Formulation], required=True,
                   help="bimanual: two grippers turn one joint at a time at the centre; the robot starts with both "
                   "grippers free and the middle joint at the centre")
    p.add_argument("--orientations", type=int_in(2, 360), required=True, metavar="K",
                   help="allowed orientations (360 %% K == 0)")
    p.add_argument("--init", required=True, help="degrees, comma separated (absolute: per link; relative: per joint; "
                   "bimanual: per joint, each link's orientation from link 1)")
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
        with SqliteStore(args.db, config.tbox_path) as kb:
            result = solve_and_store(request, kb, config)
    except (ModelError, KBError, TranslationError, PlannerError) as exc:
        print(f"planhrc solve: {exc}", file=sys.stderr)
        return 2
    if args.json:
        print(json.dumps(result, indent=2))
    else:
        _print_report(result)
    return 0 if result["status"] == "solved" else 1


def _print_report(result: dict[str, Any]) -> None:
    print(f"status: {result['status']}  planner: {result['planner']}  optimal: {result['optimal']}")
    if result["message"]:
        print(f"message: {result['message']}")
    for i, state in enumerate(result["expected_states"], start=1):
        step = result["plan"][i - 1] if i <= len(result["plan"]) else ""
        print(f"  s^e_{i}: {state}  {('-> ' + step) if step else '(goal)'}")
    print("timings (s): " + ", ".join(f"{k} {v:.4f}" for k, v in result["timings_s"].items()))

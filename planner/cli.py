"""`planhrc plan DOMAIN PROBLEM [--planner NAME] [--no-fallback] [--no-validate] --timeout S --json`.

The files go through the one fallback chain (`planner.chain`): `--planner` picks the first planner, the
default chain (in-process, then Fast Downward LAMA) follows unless `--no-fallback` is given. Every plan printed
as solved was accepted by VAL against the files as given: on the plan itself, or on its expansion into the actions
its macros stand for when the domain's macros are proved faithful (`planner.checking`; the answer says which).
A plan no validator gave a verdict on (VAL did not finish in time, or `--no-validate`) is printed with status
`unvalidated` and the reason, and exit status `EXIT_UNVALIDATED`.
"""
from __future__ import annotations

import argparse
import json
import sys
from dataclasses import replace
from typing import Any

from planhrc.cli_args import OneLineParser, SubParsers, existing_file, positive_float

from .chain import DEFAULT_CHAIN, plan_with_fallback
from .errors import PlannerError
from .files import read_pddl
from .registry import PLANNERS
from .result import PlanResult, PlanStatus


def add_plan_parser(subparsers: SubParsers) -> argparse.ArgumentParser:
    parser = subparsers.add_parser("plan", help="plan for a PDDL domain and problem")
    parser.add_argument("domain", type=existing_file, help="PDDL domain file")
    parser.add_argument("problem", type=existing_file, help="PDDL problem file")
    parser.add_argument("--planner", default=DEFAULT_CHAIN[0], choices=list(PLANNERS),
                        help=f"first planner to try (default chain: {', '.join(DEFAULT_CHAIN)})")
    parser.add_argument("--no-fallback", action="store_true", help="run only --planner, no fallback")
    parser.add_argument("--no-validate", action="store_true",
                        help="do not check the plan with VAL (faster; the answer's status is unvalidated, exit 3)")
    parser.add_argument("--timeout", type=positive_float, default=60.0, help="time limit in seconds")
    parser.add_argument("--json", action="store_true", help="print the result as JSON")
    parser.set_defaults(func=run_plan)
    return parser


EXIT_SOLVED, EXIT_NOT_SOLVED, EXIT_UNVALIDATED = 0, 1, 3  # (2 is a usage error, as for every command)


def run_plan(args: argparse.Namespace) -> int:
    """Exit status 0 when solved (a validated plan), 3 when a plan is printed unvalidated, 1 otherwise (including
    bad input, reported on stderr)."""
    try:
        domain, problem = read_pddl(args.domain, "domain"), read_pddl(args.problem, "problem")
        result = plan_with_fallback(domain, problem, plan_chain(args.planner, args.no_fallback), args.timeout,
                                    validate=not args.no_validate)
        result = answered(result)
    except PlannerError as exc:
        if args.json:
            print(json.dumps({"status": "error", "plan": [], "seconds": 0.0, "planner": args.planner,
                              "message": str(exc), "optimal": None, "validated": False, "checked_by": None,
                              "check_note": "", "attempts": [], "warnings": []}))
        print(f"planhrc plan: {exc}", file=sys.stderr)
        return 1
    if args.json:
        print(json.dumps(result_json(result)))
    else:
        for warning in result.warnings:
            print(f"; warning: {warning}")
        for attempt in result.attempts[:-1]:
            print(f"; {attempt.planner} declined: {attempt.status.value}"
                  + (f" ({attempt.message})" if attempt.message else ""))
        print(f"; {result.planner}: {result.status.value} in {result.seconds:.3f} s"
              + (f" ({result.message})" if result.message else ""))
        if result.solved:
            print(f"; validated by {result.check_note}")
        for step in result.plan:
            print(step)
    if result.status is PlanStatus.UNVALIDATED:
        return EXIT_UNVALIDATED
    return EXIT_SOLVED if result.status is PlanStatus.SOLVED else EXIT_NOT_SOLVED


def answered(result: PlanResult) -> PlanResult:
    """The chain's result as the command answers it: a plan solved without a validator's verdict (`--no-validate`)
    is `unvalidated`, saying so ("solved" means validated)."""
    if result.status is PlanStatus.SOLVED and result.plan and not result.validated:
        why = "not checked: --no-validate asks no validator"
        return replace(result, status=PlanStatus.UNVALIDATED,
                       message=f"{result.message}; {why}" if result.message else why)
    return result


def plan_chain(first: str, no_fallback: bool = False) -> tuple[str, ...]:
    """`first`, then the default chain's other planners (none with `no_fallback`)."""
    if no_fallback:
        return (first,)
    return (first, *(name for name in DEFAULT_CHAIN if name != first))


def result_json(result: PlanResult) -> dict[str, Any]:
    return {"status": result.status.value, "plan": list(result.plan), "seconds": round(result.seconds, 6),
            "planner": result.planner, "message": result.message, "optimal": result.optimal,
            "validated": result.validated, "checked_by": result.checked_by or None, "check_note": result.check_note,
            "warnings": list(result.warnings),
            "attempts": [{"planner": a.planner, "status": a.status.value, "message": a.message,
                          "seconds": round(a.seconds, 6)} for a in result.attempts]}


def main(argv: list[str] | None = None) -> int:
    parser = OneLineParser(prog="planhrc")
    add_plan_parser(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(argv)
    return int(args.func(args))


if __name__ == "__main__":
    sys.exit(main())

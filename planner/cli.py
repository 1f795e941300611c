"""`planhrc plan DOMAIN PROBLEM --planner NAME --timeout S --json` (wired into planhrc.cli by the lead)."""
from __future__ import annotations

import argparse
import json
import sys
from typing import Any

from .errors import PlannerError
from .files import plan_files
from .registry import PLANNERS
from .result import PlanStatus


def add_plan_parser(subparsers: Any) -> argparse.ArgumentParser:
    parser = subparsers.add_parser("plan", help="plan for a PDDL domain and problem")
    parser.add_argument("domain", help="PDDL domain file")
    parser.add_argument("problem", help="PDDL problem file")
    parser.add_argument("--planner", default="inproc", choices=list(PLANNERS), help="planner backend")
    parser.add_argument("--timeout", type=float, default=60.0, help="time limit in seconds")
    parser.add_argument("--json", action="store_true", help="print the result as JSON")
    parser.set_defaults(func=run_plan)
    return parser


def run_plan(args: argparse.Namespace) -> int:
    """Exit status 0 when solved, 1 otherwise (including bad input, reported on stderr)."""
    try:
        result = plan_files(args.domain, args.problem, args.planner, args.timeout)
    except PlannerError as exc:
        if args.json:
            print(json.dumps({"status": "error", "plan": [], "seconds": 0.0, "planner": args.planner,
                              "message": str(exc)}))
        print(f"planhrc plan: {exc}", file=sys.stderr)
        return 1
    if args.json:
        print(json.dumps({"status": result.status.value, "plan": list(result.plan),
                          "seconds": round(result.seconds, 6), "planner": result.planner,
                          "message": result.message, "optimal": result.optimal}))
    else:
        print(f"; {result.planner}: {result.status.value} in {result.seconds:.3f} s"
              + (f" ({result.message})" if result.message else ""))
        for step in result.plan:
            print(step)
    return 0 if result.status is PlanStatus.SOLVED else 1


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="planhrc")
    add_plan_parser(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(argv)
    return args.func(args)


if __name__ == "__main__":
    sys.exit(main())

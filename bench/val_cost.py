"""`python -m planhrc.bench.val_cost`: what VAL costs on a re-plan's plan, by formulation, run by run.

For `--tasks` random tasks of LINKS x K (default 20 x 12) in each formulation, the pipeline's plan (in-process
planner, replayed, not validated), then VAL's CPU on it (its processes' user + system time, read from this
process's reaped children: no other process is counted) for each way of checking it:

* ``whole``: one run on the whole plan against the validation domain (the paper's exact domain), as `planhrc solve`;
* ``service``: the runs the service makes with the early answer: the first motion's pieces, then the later pieces
  on problems narrowed to the joints their steps reach (`pipeline.validation`'s cut), all of them;
* ``first motion``: those of the service's runs that come before its answer.

The relative formulation has no quantified effect: its plan of the same size is what a check without one costs,
the floor any equivalent check of the absolute formulation could reach. Results: val-cost.json and .md in `--out`.
"""
from __future__ import annotations

import argparse
import os
import random
import resource
import statistics
import sys
from dataclasses import replace
from pathlib import Path
from typing import Any, Sequence

from planhrc.bench.grid import machine_info, write_json_and_table
from planhrc.model import ArticulatedObject, make_object
from planhrc.pipeline import PlanOutcome, early_answer_first_piece, piece_bounds, piece_of, plan
from planhrc.pipeline.config import config_from_settings
from planhrc.pipeline.validation import LATER_PIECE_STEPS
from planhrc.planner.validate import validate_plan
from planhrc.settings import make_settings

WAYS = ("whole", "service", "first motion")


def _children_cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def _val_cpu(domain: str, runs: Sequence[tuple[str, Sequence[str]]]) -> tuple[float, bool]:
    """VAL's CPU seconds over `runs` (problem, steps), one after another, and whether it accepted them all."""
    before, valid = _children_cpu(), True
    for problem, steps in runs:
        valid = validate_plan(domain, problem, steps, 300.0).valid and valid
    return _children_cpu() - before, valid


def service_runs(obj: ArticulatedObject, outcome: PlanOutcome, val_pieces: int
                 ) -> tuple[list[tuple[str, Sequence[str]]], int]:
    """The service's VAL runs on a plan with the early answer (its cut, `Validator._check_first`), and how many of
    them come before the answer; a plan it checks whole is one run, before the answer."""
    task = outcome.task
    assert task is not None
    first = early_answer_first_piece(obj, outcome, merge=True)
    if first is None:
        return [(task.problem, outcome.steps)], 1
    rest = len(outcome.steps) - first
    bounds = piece_bounds(len(outcome.steps), val_pieces, first, max(1, val_pieces),
                          max(val_pieces, rest // LATER_PIECE_STEPS))
    pieces = [piece_of(obj, task.problem, outcome.steps, outcome.expected_states, a + 1, b, task.validation_domain)
              for a, b in bounds]
    return [(p.problem, p.steps) for p in pieces], sum(1 for _, b in bounds if b <= first)


def measure(formulation: str, links: int, k: int, tasks: int, seed: int) -> list[dict[str, Any]]:
    settings = make_settings()
    config = replace(config_from_settings(settings), validate=False, deadline_s=300.0)
    rng = random.Random(seed)
    rows = []
    for i in range(tasks):
        obj = make_object(f"obj{i}", formulation, links, k)
        start = obj.state([rng.choice(obj.orientation_degrees) for _ in range(obj.n_joints)])
        goal = obj.configuration_atoms([rng.choice(obj.orientation_degrees) for _ in range(obj.n_joints)])
        outcome = plan(obj, start, goal, config)
        if not outcome.solved or not outcome.steps or outcome.task is None:
            continue
        domain = outcome.task.validation_domain
        runs, before = service_runs(obj, outcome, settings.val_pieces)
        whole, ok_whole = _val_cpu(domain, [(outcome.task.problem, outcome.steps)])
        first, ok_first = _val_cpu(domain, runs[:before])
        later, ok_later = _val_cpu(domain, runs[before:])
        rows.append({"formulation": formulation, "steps": len(outcome.steps), "runs": len(runs),
                     "before_answer": before, "whole_ms": round(whole * 1000, 2),
                     "service_ms": round((first + later) * 1000, 2), "first_motion_ms": round(first * 1000, 2),
                     "valid": ok_whole and ok_first and ok_later})
    return rows


def summarise(rows: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    out = []
    for formulation in dict.fromkeys(r["formulation"] for r in rows):
        sel = [r for r in rows if r["formulation"] == formulation]
        out.append({"formulation": formulation, "plans": len(sel), "valid": sum(r["valid"] for r in sel),
                    "median_steps": statistics.median(r["steps"] for r in sel),
                    **{f"{key}_median_ms": round(statistics.median(r[key] for r in sel), 2)
                       for key in ("whole_ms", "service_ms", "first_motion_ms")}})
    return out


def markdown(report: dict[str, Any]) -> str:
    m = report["machine"]
    lines = [f"`{report['command']}`: {m['cpu']}, {m['cores']} cores; load average {report['load_at_start']} at the "
             f"start, {report['load_at_end']} at the end; VAL's CPU (user + system of its processes), medians.", "",
             "| formulation | plans (all VAL-valid) | steps | whole plan, ms | the service's runs, ms | of them before "
             "the answer, ms |", "|---|---|---|---|---|---|"]
    for s in report["summary"]:
        lines.append(f"| {s['formulation']} | {s['plans']} ({s['valid']}) | {s['median_steps']} | "
                     f"{s['whole_ms_median_ms']} | {s['service_ms_median_ms']} | {s['first_motion_ms_median_ms']} |")
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    from planhrc.cli_args import OneLineParser, int_in, positive_int, writable_dir

    parser = OneLineParser(prog="python -m planhrc.bench.val_cost", description=__doc__,
                           formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--links", type=int_in(2), default=20)
    parser.add_argument("--orientations", type=int_in(3), default=12)
    parser.add_argument("--tasks", type=positive_int, default=10, help="random tasks per formulation")
    parser.add_argument("--seed", type=int, default=7)
    parser.add_argument("--out", type=writable_dir, default=None, help="folder for val-cost.json and .md")
    args = parser.parse_args(argv)
    if 360 % args.orientations:
        parser.error(f"--orientations: must divide 360, got {args.orientations}")
    load = round(os.getloadavg()[0], 2)
    rows = [row for formulation in ("absolute", "relative")
            for row in measure(formulation, args.links, args.orientations, args.tasks, args.seed)]
    report = {"command": "python -m planhrc.bench.val_cost " + " ".join(argv if argv is not None else sys.argv[1:]),
              "machine": machine_info(), "load_at_start": load, "load_at_end": round(os.getloadavg()[0], 2),
              "rows": rows, "summary": summarise(rows)}
    table = markdown(report)
    print(table)
    if args.out:
        write_json_and_table(Path(args.out), "val-cost", report, table)
    return 0 if all(r["valid"] for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())

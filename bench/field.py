"""`python -m planhrc.bench.field`: files in the styles of the paper's benchmark, planned in-process and checked by VAL.

Three styles, each on links x orientations (default 4, 8, ..., 20 x 4, 6, ..., 12, two random tasks per cell):

* ``relative``: the paper's relative domain exactly (`translator.domain.get_domain(..., paper_exact=True)`);
* ``absolute``: the paper's absolute domain exactly, the problems listing the upstream `affected` facts too (turning
  l(K-1) about jK "moves" j1 .. j(K-1)), as the benchmark's problems do;
* ``oriented``: a relative domain whose typed lists write ``?j -joint`` and whose two actions are declared twice,
  the later declarations with other parameter lists (VAL reads the first).

Each file goes through the chain with the in-process planner alone (`plan_with_fallback(..., ["inproc"])`, VAL
included); the report counts the tasks whose plan VAL accepted against the files as written, and prints a
Markdown table (with `--out`, field.json and field.md too).
"""
from __future__ import annotations

import argparse
import random
import statistics
import sys
from pathlib import Path
from typing import Any, Sequence

from planhrc.bench.grid import Instance, instance_pddl, machine_info, make_instances, write_json_and_table
from planhrc.paths import default_tbox_path
from planhrc.planner.chain import plan_with_fallback
from planhrc.planner.result import PlanStatus
from planhrc.translator.domain import get_domain

STYLES = ("relative", "absolute", "oriented")
LINKS = (4, 8, 12, 16, 20)
ORIENTATIONS = (4, 6, 8, 10, 12)


def oriented_domain() -> str:
    def action(name: str, params: str, links: str, order: str) -> str:
        return (f"(:action {name}\n :parameters ({params} ?j -joint ?a1 ?a2 -angle)\n"
                f" :precondition (and {links} (angle-of ?j ?a1) (next-angle {order}))\n"
                " :effect (and (not (angle-of ?j ?a1)) (angle-of ?j ?a2)))\n")

    both = "(connected ?j ?l1) (connected ?j ?l2) (not (= ?l1 ?l2))"
    return ("(define (domain oriented)\n(:requirements :strips :typing :adl :equality)\n(:types link joint angle)\n"
            "(:predicates (connected ?j -joint ?l -link) (angle-of ?j -joint ?a -angle) (next-angle ?a1 ?a2 -angle))\n"
            + action("increase_angle", "?l1 ?l2 -link", both, "?a1 ?a2")
            + action("decrease_angle", "?l1 ?l2 -link", both, "?a2 ?a1")
            + action("increase_angle", "?l1 -link", "(connected ?j ?l1)", "?a1 ?a2")
            + action("decrease_angle", "?l1 -link", "(connected ?j ?l1)", "?a2 ?a1") + ")\n")


def oriented_problem(inst: Instance) -> str:
    n, k = inst.links, inst.orientations
    step = 360 // k
    rng = random.Random(f"planhrc-field-oriented-{inst.name}")
    facts = [f"(connected j{i} l{i}) (connected j{i} l{i + 1})" for i in range(1, n)]
    facts += [f"(next-angle a{s * step} a{((s + 1) % k) * step})" for s in range(k)]
    facts += [f"(angle-of j{i} a{rng.randrange(k) * step})" for i in range(1, n)]
    goal = [f"(angle-of j{i} a{rng.randrange(k) * step})" for i in range(1, n)]
    objects = (" ".join(f"l{i}" for i in range(1, n + 1)) + " -link " + " ".join(f"j{i}" for i in range(1, n))
               + " -joint " + " ".join(f"a{s * step}" for s in range(k)) + " -angle")
    return (f"(define (problem {inst.name})\n(:domain oriented)\n(:objects {objects})\n(:init\n  "
            + "\n  ".join(facts) + ")\n(:goal (and " + " ".join(goal) + ")))\n")


def with_upstream_affected(problem: str, links: int) -> str:
    """The benchmark's upstream facts added to one of our absolute problems (object names o_lK, o_jK)."""
    extra = "".join(f"    (affected o_j{m} o_l{k - 1} o_j{k})\n" for k in range(2, links + 1) for m in range(1, k))
    return problem.replace("  (:init\n", "  (:init\n" + extra, 1)


def field_files(style: str, inst: Instance) -> tuple[str, str]:
    if style == "oriented":
        return oriented_domain(), oriented_problem(inst)
    domain = get_domain(default_tbox_path(), style, paper_exact=True)
    problem = instance_pddl(style, inst)[1]
    return domain, with_upstream_affected(problem, inst.links) if style == "absolute" else problem


def run(styles: Sequence[str], links: Sequence[int], orientations: Sequence[int], per_cell: int,
        timeout_s: float) -> dict[str, Any]:
    rows: list[dict[str, Any]] = []
    for style in styles:
        for inst in make_instances(links, orientations, per_cell):
            domain, problem = field_files(style, inst)
            result = plan_with_fallback(domain, problem, ["inproc"], timeout_s)
            rows.append({"style": style, "instance": inst.name, "status": result.status.value,
                         "validated": result.validated, "optimal": result.optimal, "plan_length": len(result.plan),
                         "seconds": round(result.seconds, 4),
                         "planning_seconds": round(result.attempts[-1].seconds if result.attempts else 0.0, 4),
                         "warnings": len(result.warnings), "message": result.message[:200]})
    summary = []
    for style in styles:
        sel = [r for r in rows if r["style"] == style]
        good = [r for r in sel if r["status"] == PlanStatus.SOLVED.value and r["validated"]]
        summary.append({"style": style, "files": len(sel), "val_valid_in_process": len(good),
                        "proved_shortest": sum(1 for r in good if r["optimal"]),
                        "median_with_val_s": statistics.median(float(r["seconds"]) for r in good) if good else None})
    return {"machine": machine_info(), "timeout_s": timeout_s, "summary": summary, "rows": rows}


def markdown(report: dict[str, Any]) -> str:
    lines = [f"machine: {report['machine']['cpu']}, {report['machine']['cores']} cores; the in-process planner, "
             "VAL on every plan", "", "| style | files | VAL-valid in-process | proved shortest | median s (with VAL) |",
             "|---|---|---|---|---|"]
    for s in report["summary"]:
        median = "-" if s["median_with_val_s"] is None else f"{s['median_with_val_s']:.3f}"
        lines.append(f"| {s['style']} | {s['files']} | {s['val_valid_in_process']} | {s['proved_shortest']} | "
                     f"{median} |")
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    from planhrc.cli_args import OneLineParser, int_list, name_list, positive_float, positive_int, writable_dir

    parser = OneLineParser(prog="python -m planhrc.bench.field", description=__doc__,
                           formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--styles", type=name_list(list(STYLES)), default=",".join(STYLES))
    parser.add_argument("--links", type=int_list(2), default=",".join(map(str, LINKS)))
    parser.add_argument("--orientations", type=int_list(2, 360), default=",".join(map(str, ORIENTATIONS)))
    parser.add_argument("--instances", type=positive_int, default=2, help="random tasks per cell")
    parser.add_argument("--timeout", type=positive_float, default=60.0, metavar="S", help="per task, VAL included")
    parser.add_argument("--out", type=writable_dir, default=None, help="folder for field.json and field.md")
    args = parser.parse_args(argv)
    report = run(args.styles, args.links, args.orientations, args.instances, args.timeout)
    table = markdown(report)
    print(table)
    if args.out:
        write_json_and_table(Path(args.out), "field", report, table)
    return 0 if all(s["val_valid_in_process"] == s["files"] for s in report["summary"]) else 1


if __name__ == "__main__":
    sys.exit(main())

"""How long the robot's plan takes to find: `python -m planhrc.bench.motion [--tasks 20] [--seed 1000]`.

The demo's random tasks (`robot_sim.demo.random_scenario`: 5 links x 8 orientations, placed, a goal reachable in the
plane), each formulation, searched from their start by `motion_search.plan_work` with no deadline: per task whether
the exhaustive search proved the least robot time, the configurations it expanded, its CPU time, the plan's turns
and slides beside the unconstrained shortest. Prints one JSON object (the tasks and, per formulation, the medians and
maxima); a benchmark, not a test.
"""
from __future__ import annotations

import argparse
import json
import statistics
import time
from typing import Any, Sequence

from planhrc.geometry import ObjectGeometry
from planhrc.model import make_object, perceive
from planhrc.motion_search import Work, alphabet_of, offsets_between, plan_work
from planhrc.ordering import Placement
from planhrc.pipeline.order import hands_of
from planhrc.robot_sim.demo import RANDOM_FORMULATIONS, random_scenario


def run(tasks: int = 20, seed: int = 1000, formulations: Sequence[str] = RANDOM_FORMULATIONS) -> dict[str, Any]:
    rows: list[dict[str, Any]] = []
    for formulation in formulations:
        for i in range(tasks):
            scenario = random_scenario(seed + i, formulation=formulation, interventions=0)
            obj = make_object("task", formulation, len(scenario.initial_deg), scenario.orientations)
            base = scenario.base_point_xy or (0.6, 0.0)
            placement = Placement(ObjectGeometry.of(obj, base), scenario.initial_deg, grid_deg=obj.step)
            target = offsets_between(obj, scenario.initial_deg, scenario.goal_deg)
            hands = hands_of(obj, perceive(obj, list(scenario.initial_deg), control=obj.initial_control()).atoms)
            cpu = time.process_time()
            work = plan_work(placement, alphabet_of(obj), target, obj.orientations, hands=hands, expansions=10**6)
            cpu = time.process_time() - cpu
            row: dict[str, Any] = {"formulation": formulation, "seed": seed + i, "found": isinstance(work, Work),
                                   "exact": False, "expansions": work.expansions, "cpu_s": round(cpu, 3)}
            if isinstance(work, Work):
                row.update(exact=work.exact, turns=len(work.turns), slides=len(work.slides), robot_s=work.cost_s,
                           unconstrained_steps=work.unconstrained_steps)
            rows.append(row)
    summary: dict[str, Any] = {}
    for formulation in formulations:
        mine = [r for r in rows if r["formulation"] == formulation]
        summary[formulation] = {
            "tasks": len(mine), "found": sum(r["found"] for r in mine), "exact": sum(r["exact"] for r in mine),
            "expansions_median": statistics.median(r["expansions"] for r in mine),
            "expansions_max": max(r["expansions"] for r in mine),
            "cpu_s_median": round(statistics.median(r["cpu_s"] for r in mine), 3),
            "cpu_s_max": round(max(r["cpu_s"] for r in mine), 3),
            "ms_per_expansion": round(1000 * sum(r["cpu_s"] for r in mine) / max(1, sum(r["expansions"] for r in mine)),
                                      3)}
    return {"tasks": tasks, "seed": seed, "summary": summary, "rows": rows}


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m planhrc.bench.motion", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--tasks", type=int, default=20, help="random tasks per formulation")
    parser.add_argument("--seed", type=int, default=1000, help="the first task's seed")
    parser.add_argument("--formulations", default=",".join(RANDOM_FORMULATIONS))
    args = parser.parse_args(argv)
    formulations = [f for f in args.formulations.split(",") if f]
    if args.tasks < 1 or any(f not in RANDOM_FORMULATIONS for f in formulations):
        parser.error(f"--tasks must be at least 1 and --formulations some of {', '.join(RANDOM_FORMULATIONS)}")
    print(json.dumps(run(args.tasks, args.seed, formulations), indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

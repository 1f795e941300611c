"""Benchmark (not a test): `python -m planhrc.planner.bench [--links 20] [--orientations 12] [--fd-timeout 60]`.

Reports in-process grounding time and median re-planning time, Fast Downward whole-process times and VAL
time, for both formulations and the paper's exact absolute domain; the domains come from the translator.
"""
from __future__ import annotations

import argparse
import json
import logging
import random
import statistics
import time
from pathlib import Path

from planhrc.model import make_object
from planhrc.paths import default_tbox_path
from planhrc.translator.domain import get_domain
from planhrc.translator.problem import get_problem

from .inproc import ground_task
from .registry import get_planner
from .validate import validate_plan

log = logging.getLogger(__name__)


CASES = {  # case -> (formulation, the paper's exact schema?, problem's domain name)
    "relative": ("relative", False, None),
    "absolute": ("absolute", False, None),
    "absolute-paper": ("absolute", True, "planhrc-absolute-paper"),
}


def make_problem(formulation: str, links: int, k: int, seed: int, domain_name: str | None = None
                 ) -> tuple[object, str]:
    rng = random.Random(seed)
    obj = make_object("obj1", formulation, links, k)
    init = [rng.choice(obj.orientation_degrees) for _ in obj.joint_indices]
    goal = obj.configuration_atoms([rng.choice(obj.orientation_degrees) for _ in obj.joint_indices])
    return obj, get_problem(obj, obj.configuration_atoms(init), goal, f"bench-{formulation}", domain_name)


def bench(tbox: Path, links: int, k: int, fd_timeout: float, replans: int = 100) -> dict:
    out: dict = {}
    paper = {f: get_domain(tbox, f, paper_exact=True) for f in ("relative", "absolute")}
    for case, (formulation, paper_exact, domain_name) in CASES.items():
        domain = get_domain(tbox, formulation, paper_exact=paper_exact)
        obj, problem = make_problem(formulation, links, k, seed=1, domain_name=domain_name)
        grounds = []
        for _ in range(5):
            t0 = time.perf_counter()
            task = ground_task(domain, problem)
            grounds.append(time.perf_counter() - t0)
        rng = random.Random(2)
        times = []
        for _ in range(replans):
            init = obj.configuration_atoms([rng.choice(obj.orientation_degrees) for _ in obj.joint_indices])
            t0 = time.perf_counter()
            task.solve(init, task.goal)
            times.append(time.perf_counter() - t0)
        plan = task.solve_problem()
        check = validate_plan(paper[formulation], problem, plan.plan)
        row = {
            "inproc_ground_s_median_of_5": statistics.median(grounds),
            f"inproc_replan_s_median_of_{replans}": statistics.median(times),
            "inproc_replan_s_max": max(times),
            "inproc_plan_len": len(plan.plan),
            "inproc_message": plan.message,
            "val_s": check.seconds,
            "val_valid": check.valid,
        }
        for name in ("fd-lama", "fd-opt"):
            res = get_planner(name).solve(domain, problem, fd_timeout)
            row[f"{name}_s"] = res.seconds
            row[f"{name}_status"] = res.status.value
            row[f"{name}_plan_len"] = len(res.plan) if res.plan else None
            log.info("%s %s: %s in %.3f s", case, name, res.status.value, res.seconds)
        out[f"{case} {links}x{k}"] = row
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m planhrc.planner.bench")
    parser.add_argument("--links", type=int, default=20)
    parser.add_argument("--orientations", type=int, default=12)
    parser.add_argument("--fd-timeout", type=float, default=60.0)
    parser.add_argument("--tbox", type=Path, default=default_tbox_path())
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO)
    result = bench(args.tbox, args.links, args.orientations, args.fd_timeout)
    print(json.dumps(result, indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

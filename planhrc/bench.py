"""`planhrc bench`: the paper's planning grid and the re-planning latency.

Grid: links 4..20, orientations {4, 6, 8, 10, 12}, 2 random instances each (fixed seeds) = 170 instances
per formulation. An instance is a random initial and goal configuration of the links (absolute
orientations); each formulation plans the same change of configuration. For every planner and formulation:
status, time, plan length, the optimal length (computed independently, by the formula below) and VAL's
verdict against the paper's domain. Results go to JSON and CSV, with box plots like the paper's Figs 15-18.

Optimal lengths. Relative: each action changes one joint's relative angle by one step, independently, so
the optimum is the sum over joints of the cyclic distance. Absolute (turning lK moves lK..lN): an action at
joint K changes the difference theta_K - theta_(K-1) (theta_0 = the table) by one step and no other
difference, so the optimum is the sum over K of the cyclic distance of the change of that difference. The
relative formulation does not track where l1 lies on the table, so the same change of configuration costs
the absolute formulation the relative optimum plus the cyclic distance of l1's rotation; the report gives
both.

`--replan` measures the re-planning loop on 20 links x 12 orientations: a new perceived state in the ABox ->
translation -> planning -> VAL -> expected states stored, median of repeated runs (`--replan-runs`), beside the whole-process
time of Fast Downward on the same problem.
"""
from __future__ import annotations

import argparse
import csv
import json
import logging
import platform
import random
import statistics
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Iterable, Sequence

from planhrc.cli_args import int_list, name_list, positive_float, positive_int, writable_dir
from planhrc.model import ArticulatedObject, Formulation, make_object, relative_from_absolute
from planhrc.paths import default_tbox_path
from planhrc.plots import plot_times
from planhrc.planner.registry import PLANNERS, available_planners, get_planner
from planhrc.planner.result import PlanStatus
from planhrc.planner.validate import validate_plan
from planhrc.translator.domain import get_domain
from planhrc.translator.problem import get_problem

log = logging.getLogger(__name__)

LINKS = tuple(range(4, 21))
ORIENTATIONS = (4, 6, 8, 10, 12)
INSTANCES = 2


@dataclass(frozen=True)
class Instance:
    links: int
    orientations: int
    index: int
    init_links_deg: tuple[int, ...]
    goal_links_deg: tuple[int, ...]

    @property
    def label(self) -> str:
        return f"{self.links}-{self.orientations}"

    @property
    def name(self) -> str:
        return f"bench-{self.links}-{self.orientations}-{self.index}"


@dataclass(frozen=True)
class Row:
    formulation: str
    planner: str
    instance: str
    label: str
    links: int
    orientations: int
    status: str
    seconds: float
    plan_length: int | None
    optimal_length: int
    relative_equivalent_length: int
    valid: bool | None
    validate_seconds: float | None
    message: str


def make_instances(links: Iterable[int] = LINKS, orientations: Iterable[int] = ORIENTATIONS,
                   per_cell: int = INSTANCES) -> tuple[Instance, ...]:
    out = []
    for n in links:
        for k in orientations:
            step = 360 // k
            for i in range(per_cell):
                rng = random.Random(f"planhrc-bench-{n}-{k}-{i}")
                init = tuple(rng.randrange(k) * step for _ in range(n))
                goal = tuple(rng.randrange(k) * step for _ in range(n))
                out.append(Instance(n, k, i, init, goal))
    return tuple(out)


def _cyc(a: int, b: int, step: int, k: int) -> int:
    d = ((b - a) // step) % k
    return min(d, k - d)


def optimal_length(formulation: str, inst: Instance) -> int:
    step = 360 // inst.orientations
    k = inst.orientations
    if formulation == "relative":
        ri, rg = relative_from_absolute(inst.init_links_deg), relative_from_absolute(inst.goal_links_deg)
        return sum(_cyc(a, b, step, k) for a, b in zip(ri, rg))
    di = relative_from_absolute((0,) + inst.init_links_deg)
    dg = relative_from_absolute((0,) + inst.goal_links_deg)
    return sum(_cyc(a, b, step, k) for a, b in zip(di, dg))


def relative_equivalent(inst: Instance) -> int:
    step = 360 // inst.orientations
    return optimal_length("relative", inst) + _cyc(inst.init_links_deg[0], inst.goal_links_deg[0], step,
                                                   inst.orientations)


def instance_pddl(formulation: str, inst: Instance) -> tuple[ArticulatedObject, str]:
    obj = make_object("o", formulation, inst.links, inst.orientations)
    init = obj.state(obj.joint_values_from_links(inst.init_links_deg))
    goal = obj.configuration_atoms(obj.joint_values_from_links(inst.goal_links_deg))
    return obj, get_problem(obj, init, goal, inst.name)


def run_grid(planners: Sequence[str], formulations: Sequence[str], instances: Sequence[Instance],
             timeout_s: float, validate: bool = True, progress: bool = True) -> list[Row]:
    from tqdm import tqdm

    tbox = default_tbox_path()
    domains = {f: get_domain(tbox, f) for f in formulations}
    val_domains = {f: get_domain(tbox, f, paper_exact=True) for f in formulations}
    jobs = [(f, p, inst) for f in formulations for p in planners for inst in instances]
    rows: list[Row] = []
    bar = tqdm(jobs, disable=not progress, unit="run", file=sys.stderr, dynamic_ncols=True)
    for formulation, planner_name, inst in bar:
        bar.set_description(f"{formulation} {planner_name} {inst.label}")
        planner = get_planner(planner_name)
        _, problem = instance_pddl(formulation, inst)
        result = planner.solve(domains[formulation], problem, timeout_s)
        valid = vsec = None
        if validate and result.status is PlanStatus.SOLVED:
            check = validate_plan(val_domains[formulation], problem, result.plan)
            valid, vsec = check.valid, check.seconds
        rows.append(Row(
            formulation=formulation, planner=planner_name, instance=inst.name, label=inst.label,
            links=inst.links, orientations=inst.orientations, status=result.status.value,
            seconds=result.seconds, plan_length=len(result.plan) if result.status is PlanStatus.SOLVED else None,
            optimal_length=optimal_length(formulation, inst), relative_equivalent_length=relative_equivalent(inst),
            valid=valid, validate_seconds=vsec, message=result.message[:200],
        ))
    return rows


def summarise(rows: Sequence[Row]) -> list[dict]:
    out = []
    keys = sorted({(r.formulation, r.planner) for r in rows})
    for formulation, planner in keys:
        sel = [r for r in rows if r.formulation == formulation and r.planner == planner]
        solved = [r for r in sel if r.status == "solved" and r.valid is not False]
        times = [r.seconds for r in solved]
        out.append({
            "formulation": formulation,
            "planner": planner,
            "instances": len(sel),
            "solved_valid": len(solved),
            "within_1s": sum(1 for r in solved if r.seconds <= 1.0),
            "optimal_length_plans": sum(1 for r in solved if r.plan_length == r.optimal_length),
            "not_longer_than_relative_equivalent": sum(
                1 for r in solved if r.plan_length is not None and r.plan_length <= r.relative_equivalent_length),
            "invalid": sum(1 for r in sel if r.valid is False),
            "median_s": statistics.median(times) if times else None,
            "max_s": max(times) if times else None,
            "mean_length_ratio": (statistics.fmean(r.plan_length / r.optimal_length for r in solved if r.optimal_length)
                                  if any(r.optimal_length for r in solved) else None),
        })
    return out


def write_results(rows: Sequence[Row], summary: list[dict], out_dir: Path, extra: dict | None = None) -> list[Path]:
    out_dir.mkdir(parents=True, exist_ok=True)
    written = []
    data = {"machine": machine_info(), "summary": summary, "rows": [asdict(r) for r in rows], **(extra or {})}
    p = out_dir / "bench.json"
    p.write_text(json.dumps(data, indent=2))
    written.append(p)
    p = out_dir / "bench.csv"
    with p.open("w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(Row.__dataclass_fields__))
        writer.writeheader()
        for r in rows:
            writer.writerow(asdict(r))
    written.append(p)
    written += plot_times(rows, out_dir)
    return written


def machine_info() -> dict:
    import os

    cpu = platform.processor() or ""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return {"cpu": cpu, "cores": os.cpu_count(), "python": platform.python_version(), "system": platform.platform()}


# -- re-planning latency -------------------------------------------------------------------------------------
def measure_replan(formulation: str, links: int = 20, orientations: int = 12, runs: int = 10,
                   fd_runs: int = 10, seed: int = 7) -> dict:
    """Median time from a new perceived state to a validated plan with expected states stored."""
    from planhrc.kb_service.store import KnowledgeBase
    from planhrc.pipeline import config_from_settings, plan
    from planhrc.settings import make_settings

    tbox = default_tbox_path()
    rng = random.Random(seed)
    step = 360 // orientations
    n_values = links if formulation == "absolute" else links - 1
    out: dict = {"formulation": formulation, "links": links, "orientations": orientations}
    with KnowledgeBase(None, tbox) as kb:
        ident = kb.new_object_id()
        obj = make_object(ident, formulation, links, orientations)
        kb.create_object(obj)
        goal_vals = [rng.randrange(orientations) * step for _ in range(n_values)]
        goal = kb.add_state(ident, "goal", obj.configuration_atoms(goal_vals))
        config = config_from_settings(make_settings(tbox_path=str(tbox), planner="inproc"))
        times, stages, lengths = [], [], []
        for _ in range(runs + 1):  # the first run grounds the task; it is reported apart
            vals = [rng.randrange(orientations) * step for _ in range(n_values)]
            t = time.perf_counter()
            outcome = plan(obj, obj.state(vals), goal.atoms, config)
            t_store = time.perf_counter()
            with kb.transaction():  # what the service writes after a re-plan, in one transaction
                perceived = kb.add_state(ident, "perceived", obj.state(vals))
                problem = kb.add_problem(ident, perceived.id, goal.id)
                if outcome.actions:
                    kb.add_plan(problem.id, outcome.planner, outcome.actions, outcome.expected_states)
            times.append(time.perf_counter() - t)
            stages.append({**outcome.timings, "store": time.perf_counter() - t_store})
            lengths.append(len(outcome.actions))
            if outcome.status != "solved":
                raise RuntimeError(f"re-plan failed: {outcome.status} {outcome.message}")
        out["first_run_s"] = times[0]
        out["replan_median_s"] = statistics.median(times[1:])
        out["replan_p90_s"] = sorted(times[1:])[int(0.9 * (runs - 1))]
        out["stage_medians_s"] = {k: statistics.median(s.get(k, 0.0) for s in stages[1:]) for k in stages[1]}
        out["median_plan_length"] = statistics.median(lengths[1:])
        problem_text = get_problem(obj, obj.state(vals), obj.configuration_atoms(goal_vals), "replan")
    domain = get_domain(tbox, formulation)
    if "fd-lama" in available_planners():
        fd = get_planner("fd-lama")
        fd_times = []
        for _ in range(fd_runs):
            t = time.perf_counter()
            res = fd.solve(domain, problem_text, 60.0)
            fd_times.append(time.perf_counter() - t)
        out["fd_lama_whole_process_median_s"] = statistics.median(fd_times)
        out["fd_lama_status"] = res.status.value
    return out


def add_bench_parser(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("bench", help="the paper's planning grid and re-planning latency",
                              description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--planners", type=name_list(list(PLANNERS)), default="inproc,fd-lama",
                   help="comma separated planner names")
    p.add_argument("--formulations", type=name_list([f.value for f in Formulation]), default="relative,absolute")
    p.add_argument("--links", type=int_list(2), default="4-20", help="range A-B or list")
    p.add_argument("--orientations", type=orientation_list, default="4,6,8,10,12", help="range A-B or list")
    p.add_argument("--instances", type=positive_int, default=INSTANCES, help="random instances per cell")
    p.add_argument("--timeout", type=positive_float, default=10.0, metavar="S", help="per planner call")
    p.add_argument("--no-validate", action="store_true")
    p.add_argument("--replan", action="store_true", help="also measure the re-planning loop on 20 x 12")
    p.add_argument("--replan-only", action="store_true", help="only measure the re-planning loop")
    p.add_argument("--replan-runs", type=positive_int, default=30, help="re-plans measured per formulation (median)")
    p.add_argument("--out", type=writable_dir, default="bench-results", help="output folder")
    p.add_argument("--no-progress", action="store_true")
    p.set_defaults(func=run_bench)


def orientation_list(text: str) -> list[int]:
    """Orientation counts K: each divides 360 and is at least 2."""
    values = int_list(2, 360)(text)
    bad = [k for k in values if 360 % k]
    if bad:
        raise argparse.ArgumentTypeError(f"360 must be divisible by each K, not by {', '.join(map(str, bad))}")
    return values


def run_bench(args: argparse.Namespace) -> int:
    out_dir = Path(args.out)
    formulations, planners = args.formulations, args.planners
    usable = set(available_planners())
    missing = [p for p in planners if p not in usable]
    if missing and not args.replan_only:
        print(f"planhrc bench: --planners: not available here: {', '.join(missing)}", file=sys.stderr)
        return 2
    extra: dict = {}
    if args.replan or args.replan_only:
        extra["replan"] = [measure_replan(f, runs=args.replan_runs) for f in formulations]
        for r in extra["replan"]:
            print(json.dumps(r))
    if args.replan_only:
        out_dir.mkdir(parents=True, exist_ok=True)
        (out_dir / "replan.json").write_text(json.dumps({"machine": machine_info(), **extra}, indent=2))
        return 0
    instances = make_instances(args.links, args.orientations, args.instances)
    rows = run_grid(planners, formulations, instances, args.timeout, not args.no_validate, not args.no_progress)
    summary = summarise(rows)
    paths = write_results(rows, summary, out_dir, extra)
    print(f"{'formulation':<10} {'planner':<10} {'solved':>8} {'<=1s':>6} {'optimal':>8} {'median s':>10} {'max s':>9}")
    for s in summary:
        med = f"{s['median_s']:.4f}" if s["median_s"] is not None else "-"
        mx = f"{s['max_s']:.4f}" if s["max_s"] is not None else "-"
        print(f"{s['formulation']:<10} {s['planner']:<10} {s['solved_valid']:>4}/{s['instances']:<3} "
              f"{s['within_1s']:>6} {s['optimal_length_plans']:>8} {med:>10} {mx:>9}")
    print("wrote " + ", ".join(str(p) for p in paths))
    return 0 if all(s["invalid"] == 0 for s in summary) else 1

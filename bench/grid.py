"""The paper's planning grid and the re-planning measurements of `planhrc bench` (`bench.command` runs them).

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
from typing import Any, Iterable, Sequence

from planhrc.cli_args import int_list
from planhrc.model import ArticulatedObject, make_object, relative_from_absolute
from planhrc.paths import default_tbox_path
from planhrc.bench.cpu import cpu_row, cpu_text
from planhrc.bench.errors import BenchError
from planhrc.bench.plots import plot_times
from planhrc.planner.errors import PlannerError
from planhrc.planner.registry import available_planners, get_planner
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
    status: PlanStatus
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
            links=inst.links, orientations=inst.orientations, status=result.status,
            seconds=result.seconds, plan_length=len(result.plan) if result.status is PlanStatus.SOLVED else None,
            optimal_length=optimal_length(formulation, inst), relative_equivalent_length=relative_equivalent(inst),
            valid=valid, validate_seconds=vsec, message=result.message[:200],
        ))
    return rows


def summarise(rows: Sequence[Row]) -> list[dict[str, Any]]:
    out = []
    keys = sorted({(r.formulation, r.planner) for r in rows})
    for formulation, planner in keys:
        sel = [r for r in rows if r.formulation == formulation and r.planner == planner]
        solved = [r for r in sel if r.status is PlanStatus.SOLVED and r.valid is not False]
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
            "mean_length_ratio": (statistics.fmean(r.plan_length / r.optimal_length for r in solved
                                                  if r.optimal_length and r.plan_length is not None)
                                  if any(r.optimal_length for r in solved) else None),
        })
    return out


def write_results(rows: Sequence[Row], summary: list[dict[str, Any]], out_dir: Path, extra: dict[str, Any] | None = None) -> list[Path]:
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


def write_json_and_table(out_dir: Path, stem: str, report: dict[str, Any], table: str) -> list[Path]:
    """`report` as `<stem>.json` and its markdown `table` as `<stem>.md` in `out_dir` (made when missing)."""
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = [out_dir / f"{stem}.json", out_dir / f"{stem}.md"]
    paths[0].write_text(json.dumps(report, indent=2))
    paths[1].write_text(table + "\n")
    return paths


def machine_info() -> dict[str, Any]:
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
def stats_ms(values: Sequence[float]) -> dict[str, Any]:
    """Count, median and p90 in milliseconds (the one percentile helper: `planhrc.stats.percentile`)."""
    from planhrc.stats import percentile

    return {"n": len(values), "median_ms": round(percentile(list(values), 0.5) * 1000, 3),
            "p90_ms": round(percentile(list(values), 0.9) * 1000, 3)}


def _random_case(formulation: str, links: int, orientations: int, rng: random.Random
                 ) -> tuple[ArticulatedObject, list[int], list[int]]:
    obj = make_object("obj1", formulation, links, orientations)
    degs = obj.orientation_degrees
    return obj, [rng.choice(degs) for _ in obj.joint_indices], [rng.choice(degs) for _ in obj.joint_indices]


def measure_planner(formulation: str, links: int = 20, orientations: int = 12, runs: int = 30, seed: int = 7,
                    val_timeout_s: float = 60.0, validate: bool = True, val_runs: int | None = None) -> dict[str, Any]:
    """The in-process stages on PDDL text: grounding (parse, ground, recognise; once per object), re-planning
    on the ground task from new initial states, VAL against the paper's exact domain, and the whole
    in-process loop (problem text -> `InprocPlanner.solve` with its memoised grounding -> VAL). With
    `val_runs`, only the first that many plans are validated (VAL is slow on large absolute tasks); the loop
    figure then covers those runs."""
    from planhrc.planner.inproc import InprocPlanner, ground_task

    tbox = default_tbox_path()
    domain = get_domain(tbox, formulation)
    paper = get_domain(tbox, formulation, paper_exact=True)
    rng = random.Random(seed)
    obj, init, goal = _random_case(formulation, links, orientations, rng)
    goal_atoms = obj.configuration_atoms(goal)
    problem = get_problem(obj, obj.configuration_atoms(init), goal_atoms, "bench")
    t = time.perf_counter()
    task = ground_task(domain, problem)
    ground_s = time.perf_counter() - t
    plan_s, lengths, problems = [], [], []
    for _ in range(runs):
        values = [rng.choice(obj.orientation_degrees) for _ in obj.joint_indices]
        atoms = obj.configuration_atoms(values)
        t = time.perf_counter()
        result = task.solve(atoms, task.goal)
        plan_s.append(time.perf_counter() - t)
        lengths.append(len(result.plan))
        problems.append(get_problem(obj, atoms, goal_atoms, "bench"))
    out: dict[str, Any] = {"formulation": formulation, "links": links, "orientations": orientations,
                 "ground_ms": round(ground_s * 1000, 3), "plan": stats_ms(plan_s),
                 "median_plan_length": statistics.median(lengths), "optimal": result.optimal}
    planner = InprocPlanner()
    planner.solve(domain, problem, 60.0)  # the loop re-plans a known object: its grounding is memoised
    loop_s, val_s, solve_s, status = [], [], [], "valid"
    for i, text in enumerate(problems):
        t = time.perf_counter()
        result = planner.solve(domain, text, 60.0)
        solve_s.append(time.perf_counter() - t)
        if validate and val_runs is not None and i >= val_runs:
            continue
        if validate:
            try:
                check = validate_plan(paper, text, result.plan, timeout_s=val_timeout_s)
            except PlannerError as exc:  # VAL's own time limit
                status = f"VAL timeout ({exc})"
                break
            val_s.append(check.seconds)
            if not check.valid:
                status = f"VAL rejected a plan: {check.reason}"
                break
        loop_s.append(time.perf_counter() - t)
    out["solve_from_text"] = stats_ms(solve_s)
    if validate:
        out["validate"] = stats_ms(val_s)
        out["validation"] = status
    out["inproc_loop"] = stats_ms(loop_s)
    return out


def measure_fast_downward(formulation: str, links: int = 20, orientations: int = 12, runs: int = 3,
                          timeout_s: float = 10.0, seed: int = 7, planner: str = "fd-lama") -> dict[str, Any]:
    """Fast Downward's whole process (driver, translator, search, plan file) on the same kind of problem.
    A run that hits `timeout_s` is reported as a timeout and not repeated."""
    tbox = default_tbox_path()
    domain = get_domain(tbox, formulation)
    rng = random.Random(seed)
    obj, init, goal = _random_case(formulation, links, orientations, rng)
    problem = get_problem(obj, obj.configuration_atoms(init), obj.configuration_atoms(goal), "bench")
    fd = get_planner(planner)
    times: list[float] = []
    statuses: list[PlanStatus] = []
    for _ in range(runs):
        result = fd.solve(domain, problem, timeout_s)
        statuses.append(result.status)
        if result.status is PlanStatus.TIMEOUT:
            break
        times.append(result.seconds)
    out = {"planner": planner, "formulation": formulation, "links": links, "orientations": orientations,
           "runs": len(statuses), "statuses": statuses, "time_limit_s": timeout_s, **stats_ms(times)}
    if statuses and statuses[-1] is PlanStatus.TIMEOUT:
        out["note"] = f"no plan within {timeout_s} s; not repeated"
    return out


# A robot's next perception follows its action: seconds on a cell, this long in the bench (the store's writer
# thread writes the last plan's triples 50 ms after its commit, and is done by then).
ROBOT_PAUSE_S = 0.25


def measure_http(formulation: str, links: int = 20, orientations: int = 12, runs: int = 30, seed: int = 7) -> dict[str, Any]:
    """A re-planning `POST /objects/{id}/perceptions` to a real `planhrc serve` process, request to answer, each
    `ROBOT_PAUSE_S` after the last answer as from a robot; and, meanwhile, `GET /health` from another connection
    every 20 ms (its slowest answer: does a re-plan stall the service?). Then the same number back to back
    (`back_to_back`: each request meets the store's writer busy with the last plan)."""
    import tempfile
    import threading

    import httpx

    from planhrc.bench.service_calls import (TOKEN, create_object, random_angles, replanning_latencies,
                                             running_service, set_goal)

    rng = random.Random(seed)
    with tempfile.TemporaryDirectory(prefix="planhrc-bench-http-") as tmp, running_service(Path(tmp)) as server, \
            httpx.Client(base_url=server.url, timeout=120,
                         headers={"Authorization": f"Bearer {TOKEN}"}) as client:
        ident = create_object(client, links, orientations, formulation, f"bench-{formulation}")
        set_goal(client, ident, random_angles(rng, links, orientations))
        replanning_latencies(client, ident, links, orientations, 3, rng)  # the first one grounds the task
        health: list[float] = []
        done = threading.Event()

        def poll() -> None:
            with httpx.Client(base_url=server.url, timeout=120) as other:
                other.get("/health").raise_for_status()  # the connection's first request is not the service's
                while not done.wait(0.02):
                    t = time.perf_counter()
                    other.get("/health").raise_for_status()
                    health.append(time.perf_counter() - t)

        poller = threading.Thread(target=poll, daemon=True)
        poller.start()
        try:
            times = replanning_latencies(client, ident, links, orientations, runs, rng, ROBOT_PAUSE_S)
        finally:
            done.set()
            poller.join(10)
        back_to_back = replanning_latencies(client, ident, links, orientations, runs, rng)
    return {"formulation": formulation, "links": links, "orientations": orientations, "pause_s": ROBOT_PAUSE_S,
            **stats_ms(times), "back_to_back": stats_ms(back_to_back),
            "health_during": {"n": len(health), **stats_ms(health),
                              "max_ms": round(max(health) * 1000, 3) if health else None}}


def measure_replan(formulation: str, links: int = 20, orientations: int = 12, runs: int = 10, seed: int = 7) -> dict[str, Any]:
    """The library pipeline in this process: a new perceived state -> translation -> planning -> expected
    states -> VAL (in pieces where the service cuts them), then what the service writes after a re-plan
    (perceived state, problem, plan journal row) in one transaction, on a SQLite file like the service's; medians
    per stage, and apart (`write_out`, not in the loop's time) the plan's triples, which the store's writer thread
    writes behind the answer."""
    import tempfile

    from planhrc.kb_service.store import SqliteStore
    from planhrc.pipeline import config_from_settings, plan
    from planhrc.settings import make_settings

    tbox = default_tbox_path()
    rng = random.Random(seed)
    step = 360 // orientations
    n_values = links if formulation == "absolute" else links - 1
    out: dict[str, Any] = {"formulation": formulation, "links": links, "orientations": orientations}
    with tempfile.TemporaryDirectory(prefix="planhrc-bench-kb-") as tmp, \
            SqliteStore(str(Path(tmp) / "kb.sqlite3"), tbox) as kb:
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
            t_out = time.perf_counter()
            kb.settle()  # the plan's triples, which the store's writer thread writes behind the answer
            stages.append({**outcome.timings, "store": t_out - t_store, "write_out": time.perf_counter() - t_out})
            lengths.append(len(outcome.actions))
            if outcome.status is not PlanStatus.SOLVED:
                raise BenchError(f"re-plan failed: {outcome.status} {outcome.message}")
    out["first_run_ms"] = round(times[0] * 1000, 3)
    out.update(stats_ms(times[1:]))
    out["stage_medians_ms"] = {k: stats_ms([s.get(k, 0.0) for s in stages[1:]])["median_ms"] for k in stages[1]}
    out["median_plan_length"] = statistics.median(lengths[1:])
    return out


def replan_report(formulations: Sequence[str], runs: int, fd_runs: int, fd_timeout_s: float,
                  http: bool = True) -> dict[str, Any]:
    """Everything `--replan-only` measures, in one run, on 20 links x 12 orientations."""
    report: dict[str, Any] = {"machine": machine_info(), "links": 20, "orientations": 12, "formulations": {}}
    for f in formulations:
        row: dict[str, Any] = {"planner": measure_planner(f, runs=runs)}
        log.info("%s: in-process stages done", f)
        row["pipeline"] = measure_replan(f, runs=runs)
        if "fd-lama" in available_planners():
            row["fast_downward"] = measure_fast_downward(f, runs=fd_runs, timeout_s=fd_timeout_s)
        if http:
            row["http"] = measure_http(f, runs=runs)
            row["cpu"] = cpu_row(f, runs, anchor_runs=fd_runs, anchor_timeout_s=fd_timeout_s)
        report["formulations"][f] = row
    return report


def replan_table(report: dict[str, Any]) -> str:
    lines = [f"machine: {report['machine']['cpu']}, {report['machine']['cores']} cores; "
             f"{report['links']} links x {report['orientations']} orientations; medians (p90) in ms",
             "| formulation | ground (once) | plan | VAL | in-process loop | pipeline (KB) | its VAL | its store | "
             "written out behind | Fast Downward process | HTTP perception | back to back | /health meanwhile, max | "
             "service CPU per re-plan | anchor's whole process CPU |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for f, row in report["formulations"].items():
        p = row["planner"]
        fd = row.get("fast_downward")
        fd_text = "-" if fd is None else (
            f"{fd['median_ms']} ({fd['p90_ms']}), {fd['runs']} runs" if not fd.get("note")
            else f"timeout at {fd['time_limit_s']} s")
        http = row.get("http")
        stages = row["pipeline"].get("stage_medians_ms", {})
        health = (http or {}).get("health_during") or {}
        lines.append(
            f"| {f} | {p['ground_ms']} | {p['plan']['median_ms']} ({p['plan']['p90_ms']}) | "
            f"{p['validate']['median_ms']} ({p['validate']['p90_ms']}) | "
            f"{p['inproc_loop']['median_ms']} ({p['inproc_loop']['p90_ms']}) | "
            f"{row['pipeline']['median_ms']} ({row['pipeline']['p90_ms']}) | {stages.get('validate', '-')} | "
            f"{stages.get('store', '-')} | {stages.get('write_out', '-')} | {fd_text} | "
            + (f"{http['median_ms']} ({http['p90_ms']}) | {http['back_to_back']['median_ms']} "
               f"({http['back_to_back']['p90_ms']}) |" if http else "- | - |")
            + (f" {health['max_ms']} |" if health.get("max_ms") is not None else " - |")
            + f" {cpu_text(row.get('cpu'))}")
    return "\n".join(lines)


def orientation_list(text: str) -> list[int]:
    """Orientation counts K: each divides 360 and is at least 2."""
    values = int_list(2, 360)(text)
    bad = [k for k in values if 360 % k]
    if bad:
        raise argparse.ArgumentTypeError(f"360 must be divisible by each K, not by {', '.join(map(str, bad))}")
    return values

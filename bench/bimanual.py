"""`planhrc bench --bimanual[-only]`: the bimanual family on a grid, the chain beside packaged planners, in one run.

Instances are random tasks of `bench.bimanual_tasks` (both variants: ``basic`` and ``macros``), seeded per cell,
on links x orientations (default 3-8 x 8, 12, 24). For every instance and planner: status, planning time, plan
length, the length formula's optimum, the planner's own optimality claim, and VAL's verdict on the plan against
the domain and problem as written, with VAL's time apart (VAL expands the macros' forall over four angles: K^4
instances per joint, seconds at K = 24, so it is never inside a planning time here).

* ``chain`` is the one fallback chain (`planner.chain.DEFAULT_CHAIN`: in-process, then Fast Downward LAMA) with
  its memoised stages emptied before each task (`planner.inproc.forget`): it reads, grounds and plans from the
  text, as the other planners do in their own processes;
* any other name is a registry planner (``fd-lama``, ``symk``, ``bfws``, ...), its whole process timed.

Then the whole command, as a user runs it: ``planhrc plan DOMAIN PROBLEM --json --no-validate`` as a process, on
the instances of the links x orientations cell `command_cell` (default 4 x 24). Results: bimanual.json, .csv and
.md in `--out`.
"""
from __future__ import annotations

import argparse
import csv
import json
import logging
import statistics
import subprocess
import sys
import tempfile
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Mapping, Sequence

from planhrc.bench.bimanual_tasks import (VARIANTS, BimanualInstance, domain_text, make_instances, optimal_length,
                                          problem_text)
from planhrc.planner.chain import DEFAULT_CHAIN, plan_with_fallback, val_crashed
from planhrc.planner.errors import PlannerError
from planhrc.planner.inproc import forget
from planhrc.planner.registry import PLANNERS as REGISTRY, get_planner
from planhrc.planner.result import PlanResult, PlanStatus
from planhrc.planner.validate import validate_plan
from planhrc.stats import percentile

log = logging.getLogger(__name__)

CHAIN = "chain"
LINKS = tuple(range(3, 9))
ORIENTATIONS = (8, 12, 24)
PLANNERS = (CHAIN, "fd-lama", "symk", "bfws")


@dataclass(frozen=True)
class BimanualRow:
    variant: str
    planner: str
    instance: str
    links: int
    orientations: int
    status: PlanStatus
    seconds: float
    plan_length: int | None
    optimal_length: int
    claimed_optimal: bool | None
    decided_by: str
    valid: bool | None  # None: not checked, or VAL ended without a verdict (val_reason says which)
    validate_seconds: float | None
    val_reason: str
    message: str


def plan_once(planner: str, domain: str, problem: str, timeout_s: float) -> PlanResult:
    if planner == CHAIN:
        forget()
        return plan_with_fallback(domain, problem, DEFAULT_CHAIN, timeout_s, validate=False)
    return get_planner(planner).solve(domain, problem, timeout_s)


def val_expansion(inst: BimanualInstance) -> int:
    """How many instances of a turn's conditional effect VAL expands: a joint and four angles for the macros,
    a joint and two for the single steps. VAL held about 3.7 GB for one macro plan of 4 links x 24 (3 x 24^4
    instances); the kernel killed it at 23-24 GB on 7 and 8 links."""
    return inst.joints * inst.orientations ** (4 if inst.variant == "macros" else 2)


VAL_LIMIT = 1_500_000  # expansions VAL is given: about 5 GB on the macros, so a shared machine keeps its memory


def run_grid(planners: Sequence[str], instances: Sequence[BimanualInstance], timeout_s: float,
             validate: bool = True, val_timeout_s: float = 300.0, progress: bool = True,
             val_limit: int = VAL_LIMIT) -> list[BimanualRow]:
    from tqdm import tqdm

    jobs = [(p, inst) for inst in instances for p in planners]
    rows = []
    bar = tqdm(jobs, disable=not progress, unit="run", file=sys.stderr, dynamic_ncols=True)
    for planner, inst in bar:
        bar.set_description(f"{inst.variant} {planner} {inst.label}")
        domain, problem = domain_text(inst.variant), problem_text(inst)
        result = plan_once(planner, domain, problem, timeout_s)
        valid = vsec = None
        reason = ""
        if validate and result.solved and val_expansion(inst) > val_limit:
            reason = f"not run: VAL would expand {val_expansion(inst)} effect instances (limit {val_limit})"
        elif validate and result.solved:
            try:
                check = validate_plan(domain, problem, result.plan, timeout_s=val_timeout_s)
                vsec, reason = check.seconds, check.reason
                valid = None if val_crashed(check.reason) else check.valid
            except PlannerError as exc:  # VAL's own time limit: no verdict
                reason = str(exc)
        if reason and valid is None:
            log.warning("VAL gave no verdict on %s's plan of %s: %s", planner, inst.name, reason)
        rows.append(BimanualRow(inst.variant, planner, inst.name, inst.links, inst.orientations, result.status,
                                result.seconds, len(result.plan) if result.solved else None, optimal_length(inst),
                                result.optimal, result.planner, valid, vsec, reason[:200], result.message[:200]))
    return rows


def measure_command(instances: Sequence[BimanualInstance], timeout_s: float) -> list[dict[str, Any]]:
    """`planhrc plan ... --json --no-validate` as a process on each instance: wall time, planner, plan length."""
    out = []
    with tempfile.TemporaryDirectory(prefix="planhrc-bench-bimanual-") as tmp:
        for inst in instances:
            d, p = Path(tmp, f"domain-{inst.variant}.pddl"), Path(tmp, f"{inst.name}.pddl")
            d.write_text(domain_text(inst.variant))
            p.write_text(problem_text(inst))
            t = time.perf_counter()
            done = subprocess.run([sys.executable, "-m", "planhrc.cli", "plan", str(d), str(p), "--json",
                                   "--no-validate", "--timeout", str(timeout_s)], capture_output=True, text=True)
            seconds = time.perf_counter() - t
            answer = json.loads(done.stdout) if done.stdout.strip() else {}
            out.append({"variant": inst.variant, "instance": inst.name, "seconds": round(seconds, 4),
                        "status": planned_status(answer), "planner": answer.get("planner"),
                        "plan_length": len(answer.get("plan", [])), "optimal_length": optimal_length(inst)})
    return out


def planned_status(answer: Mapping[str, Any]) -> str | None:
    """The planner's status in an answer of `planhrc plan --no-validate`: a plan it found is printed `unvalidated`
    (only a validated plan is `solved` there), which for the planner is solved."""
    status = answer.get("status")
    return "solved" if status == "unvalidated" and answer.get("plan") else status


def summarise(rows: Sequence[BimanualRow]) -> list[dict[str, Any]]:
    out = []
    for variant in sorted({r.variant for r in rows}):
        for planner in dict.fromkeys(r.planner for r in rows):
            sel = [r for r in rows if r.variant == variant and r.planner == planner]
            good = [r for r in sel if r.status is PlanStatus.SOLVED and r.valid is not False]
            times = [r.seconds for r in good]
            ratios = [r.plan_length / r.optimal_length for r in good if r.plan_length is not None and r.optimal_length]
            checked = [r.validate_seconds for r in good if r.validate_seconds is not None]
            out.append({
                "variant": variant, "planner": planner, "instances": len(sel), "solved": len(good),
                "val_valid": sum(1 for r in good if r.valid), "invalid": sum(1 for r in sel if r.valid is False),
                "no_verdict": sum(1 for r in good if r.valid is None),
                "timeouts": sum(1 for r in sel if r.status is PlanStatus.TIMEOUT),
                "median_s": statistics.median(times) if times else None,
                "p95_s": percentile(times, 0.95) if times else None,
                "max_s": max(times) if times else None,
                "shortest": sum(1 for r in good if r.plan_length == r.optimal_length),
                "claimed_optimal": sum(1 for r in good if r.claimed_optimal),
                "mean_length_ratio": statistics.fmean(ratios) if ratios else None,
                "val_median_s": statistics.median(checked) if checked else None,
            })
    return out


def _num(value: float | None, digits: int = 3) -> str:
    return "-" if value is None else f"{value:.{digits}f}"


def markdown(report: dict[str, Any]) -> str:
    machine = report["machine"]
    lines = [f"machine: {machine['cpu']}, {machine['cores']} cores; per planner call {report['timeout_s']} s; "
             f"links {report['links']}, orientations {report['orientations']}, {report['per_cell']} random "
             "instances per cell and variant; VAL where it expands at most "
             f"{report.get('val_limit', 'any number of')} effect instances", "",
             "| variant | planner | solved, VAL-valid | VAL: invalid, no verdict | timeouts | median s | p95 s | "
             "max s | shortest | claimed optimal | mean length / optimum | VAL median s |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for s in report["summary"]:
        lines.append(f"| {s['variant']} | {s['planner']} | {s['val_valid']}/{s['instances']} | "
                     f"{s['invalid']}, {s.get('no_verdict', 0)} | {s['timeouts']} | "
                     f"{_num(s['median_s'], 4)} | {_num(s['p95_s'], 4)} | {_num(s['max_s'], 4)} | {s['shortest']} | "
                     f"{s['claimed_optimal']} | {_num(s['mean_length_ratio'])} | {_num(s['val_median_s'])} |")
    rows = [BimanualRow(**{"val_reason": "", **r, "status": PlanStatus(r["status"])}) for r in report["rows"]]
    planners = list(dict.fromkeys(r.planner for r in rows))
    lines += ["", "Per cell: solved and not refused by VAL / instances (* some plans VAL did not check), median "
              "planning s", "",
              "| variant | links x K | " + " | ".join(planners) + " |", "|---|---|" + "---|" * len(planners)]
    for variant in sorted({r.variant for r in rows}):
        for links, k in sorted({(r.links, r.orientations) for r in rows if r.variant == variant}):
            cells = []
            for planner in planners:
                sel = [r for r in rows if (r.variant, r.planner, r.links, r.orientations) == (variant, planner, links, k)]
                good = [r for r in sel if r.status is PlanStatus.SOLVED and r.valid is not False]
                times = [r.seconds for r in good]
                unchecked = "*" if any(r.valid is None for r in good) else ""
                cells.append(f"{len(good)}/{len(sel)}{unchecked}, {_num(statistics.median(times), 3) if times else '-'}")
            lines.append(f"| {variant} | {links} x {k} | " + " | ".join(cells) + " |")
    if report.get("command"):
        lines += ["", f"Whole command, `planhrc plan DOMAIN PROBLEM --json --no-validate` as a process, "
                  f"{report['command_cell'][0]} links x {report['command_cell'][1]}:", "",
                  "| variant | runs | solved | shortest | median s | max s |", "|---|---|---|---|---|---|"]
        for variant in sorted({c["variant"] for c in report["command"]}):
            runs = [c for c in report["command"] if c["variant"] == variant]
            times = [c["seconds"] for c in runs]
            lines.append(f"| {variant} | {len(runs)} | {sum(c['status'] == 'solved' for c in runs)} | "
                         f"{sum(c['plan_length'] == c['optimal_length'] for c in runs)} | "
                         f"{_num(statistics.median(times))} | {_num(max(times))} |")
    return "\n".join(lines)


def bimanual_report(planners: Sequence[str], links: Sequence[int], orientations: Sequence[int], per_cell: int,
                    timeout_s: float, validate: bool, val_timeout_s: float, command_cell: tuple[int, int],
                    progress: bool, variants: Sequence[str] = VARIANTS, val_limit: int = VAL_LIMIT) -> dict[str, Any]:
    from planhrc.bench.grid import machine_info

    instances = [inst for v in variants for inst in make_instances(links, orientations, per_cell, v)]
    rows = run_grid(planners, instances, timeout_s, validate, val_timeout_s, progress, val_limit)
    command = measure_command([i for i in instances if (i.links, i.orientations) == command_cell], timeout_s)
    return {"machine": machine_info(), "timeout_s": timeout_s, "links": list(links),
            "orientations": list(orientations), "per_cell": per_cell, "planners": list(planners),
            "command_cell": list(command_cell), "val_limit": val_limit, "summary": summarise(rows),
            "rows": [{**asdict(r), "status": r.status.value} for r in rows], "command": command}


def write_report(report: dict[str, Any], out_dir: Path) -> list[Path]:
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = [out_dir / "bimanual.json", out_dir / "bimanual.csv", out_dir / "bimanual.md"]
    paths[0].write_text(json.dumps(report, indent=2))
    with paths[1].open("w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(BimanualRow.__dataclass_fields__))
        writer.writeheader()
        writer.writerows(report["rows"])
    paths[2].write_text(markdown(report) + "\n")
    return paths


def add_bimanual_arguments(parser: argparse.ArgumentParser) -> None:
    from planhrc.cli_args import int_list, name_list, positive_float, positive_int

    parser.add_argument("--bimanual", action="store_true",
                        help="also the bimanual grid, after the paper's grid and in the same run")
    parser.add_argument("--bimanual-only", action="store_true",
                        help="only the bimanual grid (the chain beside packaged planners; bimanual.json/.csv/.md)")
    parser.add_argument("--bimanual-planners", type=name_list([CHAIN, *REGISTRY]), default=",".join(PLANNERS),
                        help="'chain' (the fallback chain) and registry planner names")
    parser.add_argument("--bimanual-links", type=int_list(3), default=f"{LINKS[0]}-{LINKS[-1]}")
    parser.add_argument("--bimanual-orientations", type=int_list(2, 360), default=",".join(map(str, ORIENTATIONS)))
    parser.add_argument("--bimanual-instances", type=positive_int, default=2, help="random instances per cell")
    parser.add_argument("--bimanual-variants", type=name_list(list(VARIANTS)), default=",".join(VARIANTS))
    parser.add_argument("--bimanual-val-timeout", type=positive_float, default=300.0, metavar="S",
                        help="VAL's limit per plan (the macros' conditional effects make VAL slow at K = 24)")
    parser.add_argument("--bimanual-val-limit", type=positive_int, default=VAL_LIMIT, metavar="N",
                        help="run VAL only where it expands at most N conditional-effect instances (its memory)")


def unavailable_planners(args: argparse.Namespace) -> list[str]:
    """The `--bimanual-planners` this machine cannot run (checked before a run starts anything)."""
    from planhrc.planner.registry import available_planners

    usable = set(available_planners()) | {CHAIN}
    return [p for p in args.bimanual_planners if p not in usable]


def run_bimanual(args: argparse.Namespace, run: dict[str, Any]) -> int:
    """The bimanual grid of `args`, its files written with the `run` they belong to (`bench.tables`)."""
    report = bimanual_report(args.bimanual_planners, args.bimanual_links, args.bimanual_orientations,
                             args.bimanual_instances, args.timeout, not args.no_validate, args.bimanual_val_timeout,
                             (4, 24), not args.no_progress, args.bimanual_variants, args.bimanual_val_limit)
    paths = write_report({**report, "run": run}, Path(args.out))
    print(markdown(report))
    print("wrote " + ", ".join(str(p) for p in paths))
    return 0 if all(s["invalid"] == 0 for s in report["summary"]) else 1

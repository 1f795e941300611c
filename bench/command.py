"""`planhrc bench`: the paper's planning grid, the re-planning latency and its CPU, and the bimanual grid.

Grid: links 4..20, orientations {4, 6, 8, 10, 12}, 2 random instances each (fixed seeds) = 170 instances
per formulation, every planner's plan checked by VAL against the paper's domain, its length beside the optimum
(`bench.grid`). Results go to bench.json and bench.csv, with box plots like the paper's Figs 15-18.

`--replan` (before the grid) or `--replan-only` measures re-planning on 20 links x 12 orientations: the
in-process stages on PDDL text (grounding once, planning, VAL, the whole in-process loop), the library pipeline
with the knowledge base (new perceived state -> translation -> planning -> VAL -> expected states stored), Fast
Downward's whole process (bounded by `--fd-timeout` and `--fd-runs`; a timeout is reported as such and not
repeated) and a re-planning `POST /objects/{id}/perceptions` to a real `planhrc serve` process; medians and p90.
Beside them, the CPU a re-plan costs, whole (`bench.cpu`): the service's process, its reaped VAL children and the
work behind each answer, per re-plan over paced re-plans, and the anchor planner's whole process on tasks of the
same size measured right after it in the same run. Files: replan.json and replan.md.

`--bimanual` (after the grid) or `--bimanual-only` runs the bimanual grid (`bench.bimanual`): the chain beside
packaged planners on random tasks with two hands, a centre, grasp and release. Files: bimanual.json, .csv, .md.

Every file a run writes carries the same `run` record (its id, when it started, the parts it ran), so
`python -m planhrc.bench.tables --check` can tell that the README's planning, re-planning and bimanual tables
come from one run (`bench.tables` writes them from the files).

`--scale` measures how grounding, planning, VAL and the in-process loop grow with links (20..200) and
orientations (12..72); a table and a plot go to `--out`.

An interrupted bench (Ctrl-C or SIGTERM) kills the process group of every planner and validator it started.
"""
from __future__ import annotations

import argparse
import json
import os
import signal
import sys
import time
import uuid
from pathlib import Path
from typing import Any

from planhrc.bench.bimanual import add_bimanual_arguments, run_bimanual, unavailable_planners
from planhrc.bench.grid import (INSTANCES, make_instances, orientation_list, replan_report, replan_table, run_grid,
                                summarise, write_results)
from planhrc.bench.scale import SCALE_LINKS, SCALE_ORIENTATIONS, scale_plot, scale_report, scale_table
from planhrc.cli_args import SubParsers, int_list, name_list, positive_float, positive_int, writable_dir
from planhrc.model import Formulation
from planhrc.planner.registry import PLANNERS, available_planners

def add_bench_parser(subparsers: SubParsers) -> None:
    p = subparsers.add_parser("bench", help="the paper's planning grid, re-planning latency and its CPU, the bimanual grid",
                              description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--planners", type=name_list(list(PLANNERS)), default="inproc,fd-lama",
                   help="comma separated planner names")
    p.add_argument("--formulations", type=name_list([f.value for f in Formulation]), default="relative,absolute")
    p.add_argument("--links", type=int_list(2), default="4-20", help="range A-B or list")
    p.add_argument("--orientations", type=orientation_list, default="4,6,8,10,12", help="range A-B or list")
    p.add_argument("--instances", type=positive_int, default=INSTANCES, help="random instances per cell")
    p.add_argument("--timeout", type=positive_float, default=10.0, metavar="S", help="per planner call")
    p.add_argument("--no-validate", action="store_true")
    p.add_argument("--replan", action="store_true", help="also measure re-planning on 20 x 12")
    p.add_argument("--replan-only", action="store_true", help="only measure re-planning on 20 x 12")
    p.add_argument("--replan-runs", type=positive_int, default=60,
                   help="re-plans measured per formulation and stage (the CPU column wants some 60 to settle)")
    p.add_argument("--fd-runs", type=positive_int, default=3, help="Fast Downward runs in the re-planning comparison")
    p.add_argument("--fd-timeout", type=positive_float, default=10.0, metavar="S",
                   help="Fast Downward's limit in the re-planning comparison (a timeout is not repeated)")
    p.add_argument("--no-http", action="store_true", help="skip the planhrc serve measurement")
    p.add_argument("--scale", action="store_true", help="only measure how the in-process stages grow")
    p.add_argument("--scale-links", type=int_list(2), default=",".join(map(str, SCALE_LINKS)))
    p.add_argument("--scale-orientations", type=orientation_list, default=",".join(map(str, SCALE_ORIENTATIONS)))
    p.add_argument("--scale-runs", type=positive_int, default=5, help="re-plans per cell")
    p.add_argument("--val-timeout", type=positive_float, default=20.0, metavar="S",
                   help="VAL's limit per plan in --scale")
    add_bimanual_arguments(p)
    p.add_argument("--out", type=writable_dir, default="bench-results", help="output folder")
    p.add_argument("--no-progress", action="store_true")
    p.set_defaults(func=run_bench)


def _interrupt(signum: int, frame: object) -> None:
    raise KeyboardInterrupt(f"signal {signum}")


def run_bench(args: argparse.Namespace) -> int:
    """SIGTERM is turned into KeyboardInterrupt while the bench runs, so every planner process group and the
    service process are killed on the way out, as on Ctrl-C."""
    previous = signal.signal(signal.SIGTERM, _interrupt)
    try:
        return _run_bench(args)
    except KeyboardInterrupt:
        print("planhrc bench: interrupted; planner processes stopped", file=sys.stderr)
        return 130
    finally:
        signal.signal(signal.SIGTERM, previous)


def run_record(args: argparse.Namespace) -> dict[str, Any]:
    """What every file of one run carries: its id, when it started and the parts it runs."""
    parts = (["replan"] if args.replan or args.replan_only else []) \
        + ([] if args.replan_only or args.bimanual_only else ["grid"]) \
        + (["bimanual"] if args.bimanual or args.bimanual_only else [])
    return {"id": uuid.uuid4().hex[:12], "started_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
            "parts": parts, "load_at_start": [round(x, 2) for x in os.getloadavg()]}


def _run_bench(args: argparse.Namespace) -> int:
    out_dir = Path(args.out)
    formulations, planners = args.formulations, args.planners
    if args.scale:
        report = scale_report(formulations, args.scale_links, args.scale_orientations, args.scale_runs,
                              args.val_timeout)
        out_dir.mkdir(parents=True, exist_ok=True)
        (out_dir / "scale.json").write_text(json.dumps(report, indent=2))
        table = scale_table(report)
        (out_dir / "scale.md").write_text(table + "\n")
        print(table)
        print(f"wrote {out_dir / 'scale.json'}, {out_dir / 'scale.md'}, {scale_plot(report, out_dir / 'scale.png')}")
        return 0
    usable = set(available_planners())
    missing = [p for p in planners if p not in usable] if "grid" in run_record(args)["parts"] else []
    missing_bimanual = unavailable_planners(args) if args.bimanual or args.bimanual_only else []
    for option, names in (("--planners", missing), ("--bimanual-planners", missing_bimanual)):
        if names:
            print(f"planhrc bench: {option}: not available here: {', '.join(names)}", file=sys.stderr)
            return 2
    run = run_record(args)
    if args.bimanual_only:
        return run_bimanual(args, run)
    extra: dict[str, Any] = {"run": run}
    if args.replan or args.replan_only:  # its own files too: docs/results.md's re-planning table is read from them
        extra["replan"] = {**replan_report(formulations, args.replan_runs, args.fd_runs, args.fd_timeout,
                                           http=not args.no_http), "run": run}
        table = replan_table(extra["replan"])
        print(table)
        out_dir.mkdir(parents=True, exist_ok=True)
        (out_dir / "replan.json").write_text(json.dumps(extra["replan"], indent=2))
        (out_dir / "replan.md").write_text(table + "\n")
        print(f"wrote {out_dir / 'replan.json'}, {out_dir / 'replan.md'}")
    if args.replan_only:
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
    code = 0 if all(s["invalid"] == 0 for s in summary) else 1
    if args.bimanual:
        code = max(code, run_bimanual(args, run))
    return code

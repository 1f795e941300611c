"""The README's planning, re-planning and bimanual tables, written from the files of one `planhrc bench` run.

`python -m planhrc.bench.tables` renders the three tables from `docs/results/one-run/{bench,replan,bimanual}.json` and
puts them between the README's `<!-- bench:begin -->` and `<!-- bench:end -->` lines; `--check` only says whether
the README holds what the files give. Files of different runs (their `run` records differ, or a file has none)
are refused: the tables are one run's, or none.
"""
from __future__ import annotations

import argparse
import json
import statistics
import sys
from pathlib import Path
from typing import Any, Mapping, Sequence

from planhrc.bench.errors import BenchError

COMMAND = ("planhrc bench --planners inproc,fd-lama --timeout 10 --replan --bimanual --bimanual-instances 1 "
           "--out docs/results/one-run")
FILES = ("bench.json", "replan.json", "bimanual.json")
BEGIN, END = "<!-- bench:begin -->", "<!-- bench:end -->"
TIMED_CELL = (4, 24)  # the bimanual cell: 4 links x 24 orientations


def load_run(results: Path) -> dict[str, dict[str, Any]]:
    """The three files by name; BenchError unless they exist and carry one and the same run record."""
    reports: dict[str, dict[str, Any]] = {}
    for name in FILES:
        path = results / name
        try:
            reports[name] = json.loads(path.read_text())
        except (OSError, ValueError) as exc:
            raise BenchError(f"{path}: not readable as a bench report ({exc})") from None
    runs = {name: report.get("run") for name, report in reports.items()}
    if any(run is None for run in runs.values()):
        raise BenchError("no run record in " + ", ".join(n for n, r in runs.items() if r is None)
                         + f": made before the files carried one; run `{COMMAND}`")
    ids = {run["id"] for run in runs.values() if run}
    if len(ids) != 1:
        raise BenchError("the files come from different runs (" + ", ".join(
            f"{n}: {r['id'] if r else '-'}" for n, r in runs.items()) + f"); run `{COMMAND}`")
    return reports


def _s(value: float | None, digits: int = 3) -> str:
    return "-" if value is None else f"{value:.{digits}f}"


def planning_table(report: Mapping[str, Any]) -> list[str]:
    lines = ["| formulation | planner | solved, VAL-valid | within 1 s | shortest | median s | max s |",
             "|---|---|---|---|---|---|---|"]
    for s in report["summary"]:
        lines.append(f"| {s['formulation']} | {s['planner']} | {s['solved_valid']}/{s['instances']} | "
                     f"{s['within_1s']} | {s['optimal_length_plans']} | {_s(s['median_s'], 4)} | "
                     f"{_s(s['max_s'], 3)} |")
    return lines


def _ms(value: Any) -> str:
    return "-" if value is None else f"{float(value):.1f}"


def replanning_table(report: Mapping[str, Any]) -> list[str]:
    lines = ["| formulation | HTTP perception, median (p90) ms | back to back, median ms | service CPU per re-plan, "
             "ms (VAL's part) | anchor's whole process CPU, ms | ratio |", "|---|---|---|---|---|---|"]
    for name, row in report["formulations"].items():
        http, cpu = row.get("http") or {}, row.get("cpu") or {}
        service, anchor = cpu.get("service") or {}, cpu.get("anchor") or {}
        anchor_text = (f"{anchor['planner']} {_ms(anchor['cpu_median_ms'])}"
                       if anchor.get("cpu_median_ms") is not None
                       else f"{anchor.get('planner', '-')}: no plan within its limit")
        lines.append(f"| {name} | {_ms(http.get('median_ms'))} ({_ms(http.get('p90_ms'))}) | "
                     f"{_ms((http.get('back_to_back') or {}).get('median_ms'))} | "
                     f"{_ms(service.get('per_replan_ms'))} ({_ms(service.get('val_children_ms'))}) | {anchor_text} | "
                     f"{_s(cpu.get('ratio'), 2)} |")
    return lines


def _cell_median(rows: Sequence[Mapping[str, Any]], variant: str, planner: str) -> str:
    times = [r["seconds"] for r in rows if (r["variant"], r["planner"], r["links"], r["orientations"])
             == (variant, planner, *TIMED_CELL) and r["status"] == "solved" and r["valid"] is not False]
    return _s(statistics.median(times), 3) if times else "-"


def bimanual_table(report: Mapping[str, Any]) -> list[str]:
    links, k = TIMED_CELL
    lines = [f"| variant | planner | solved, not refused by VAL | VAL: valid, no verdict | shortest | median s | "
             f"median s on {links} x {k} |", "|---|---|---|---|---|---|---|"]
    for s in report["summary"]:
        solved = s["val_valid"] + s.get("no_verdict", 0)
        lines.append(f"| {s['variant']} | {s['planner']} | {solved}/{s['instances']} | {s['val_valid']}, "
                     f"{s.get('no_verdict', 0)} | {s['shortest']} | {_s(s['median_s'], 4)} | "
                     f"{_cell_median(report['rows'], s['variant'], s['planner'])} |")
    command = report.get("command") or []
    if command:
        times = [c["seconds"] for c in command]
        lines += ["", f"The whole command, `planhrc plan DOMAIN PROBLEM --json --no-validate` as a process on "
                  f"{links} x {k}: {sum(c['status'] == 'solved' for c in command)}/{len(command)} solved, median "
                  f"{_s(statistics.median(times), 3)} s."]
    return lines


def render(reports: Mapping[str, Mapping[str, Any]]) -> str:
    bench, replan, bimanual = (reports[name] for name in FILES)
    run, machine = bench["run"], bench["machine"]
    load = run.get("load_at_start")
    per_cell = bimanual["per_cell"]
    lines = [f"`{COMMAND}`: run {run['id']}, started {run['started_utc']}, {machine['cpu']}, {machine['cores']} "
             f"cores, Python {machine['python']}" + (f", load average {load[0]} at its start" if load else "") + ".",
             "", f"**Planning**, the paper's grid: {bench['summary'][0]['instances']} random tasks per formulation "
             "(4–20 links × 4–12 orientations), 10 s per call, every plan checked by VAL.", "",
             *planning_table(bench), "",
             f"**Re-planning**, {replan['links']} links × {replan['orientations']}: a perception that leaves the plan, "
             "over HTTP to a real `planhrc serve`; the service's whole CPU (its process, its VAL children, the work "
             "behind the answer) beside the anchor planner's whole process on tasks of the same size.", "",
             *replanning_table(replan), "",
             f"**Bimanual**: two grippers, a centre, grasp and release; {bimanual['links'][0]}–{bimanual['links'][-1]}"
             f" links × {', '.join(map(str, bimanual['orientations']))} orientations, {per_cell} random "
             f"task{'s' if per_cell > 1 else ''} per cell and variant, {bimanual['timeout_s']:g} s per call.", "",
             *bimanual_table(bimanual)]
    return "\n".join(lines)


def replace_block(text: str, block: str) -> str:
    """`text` with the lines between BEGIN and END replaced by `block`; BenchError without both markers."""
    if text.count(BEGIN) != 1 or text.count(END) != 1 or text.index(BEGIN) > text.index(END):
        raise BenchError(f"the README needs one {BEGIN} line followed by one {END} line")
    head, rest = text.split(BEGIN, 1)
    tail = rest.split(END, 1)[1]
    return f"{head}{BEGIN}\n{block}\n{END}{tail}"


def main(argv: Sequence[str] | None = None) -> int:
    from planhrc.cli_args import OneLineParser

    parser = OneLineParser(prog="python -m planhrc.bench.tables", description=__doc__,
                           formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--results", default="docs/results/one-run", help="the folder of the run's files")
    parser.add_argument("--readme", default="README.md")
    parser.add_argument("--check", action="store_true", help="only say whether the README holds these tables")
    args = parser.parse_args(argv)
    readme = Path(args.readme)
    try:
        block = render(load_run(Path(args.results)))
        text = readme.read_text()
        updated = replace_block(text, block)
    except (BenchError, OSError) as exc:
        print(f"python -m planhrc.bench.tables: {exc}", file=sys.stderr)
        return 2
    if args.check:
        if updated != text:
            print(f"{readme}: its tables are not those of {args.results}", file=sys.stderr)
            return 1
        return 0
    readme.write_text(updated)
    print(f"wrote the tables of run {json.loads((Path(args.results) / FILES[0]).read_text())['run']['id']} "
          f"into {readme}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

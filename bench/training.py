"""`python -m planhrc.bench.training --data DIR`: the planning bench on the bimanual authors' published training
problems, in both of their domain files, with same-run anchors.

`DIR` holds their problems (`problems/batchB_*.pddl`), the plans they published for them (`plans/`, for the macro
domain) and both domain files (`domains/domain_m_0.pddl`, without macros; `domains/domain_m_25_B.pddl`, with them):
the project's `bimanual-train` sample of their `dataset/batches`. Their `dataset/test` set is never read here (a
folder whose path names it is refused): the project is measured on it from outside, not tuned on it.

A stratified sample: `--per-stratum` problems of each stratum (batch x whether both grippers start holding links),
seeded. For each problem and domain file:

* **the whole command**, `planhrc plan DOMAIN PROBLEM --json --timeout T` as a process, validated as a user gets
  it: wall time, status, which check gave the verdict (`val` or `val-expansion`), plan length beside the authors'
  (for the macro-free domain: their plan's expansion into its actions);
* **anchors** in the same run (`--anchors`, default Fast Downward LAMA, SymK, BFWS: the `bench` extra), each
  planner's whole process timed, its plan then checked the same way (not on its time);
* **VAL on the plan as given** (`--as-given-timeout`, 0: never), for an answer checked through its expansion: its
  verdict beside the expansion's, off the answer's path; and a **broken copy** of each answered plan (its first
  turn started from the wrong angle), which both checks must refuse.

Results: training.json and training.md in `--out`.
"""
from __future__ import annotations

import argparse
import json
import os
import random
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Any, Sequence

from planhrc.bench.grid import machine_info, write_json_and_table
from planhrc.planner.checking import check_as_given, check_plan
from planhrc.planner.errors import PlannerError
from planhrc.planner.macros import macro_report
from planhrc.planner.pddl import format_sexpr, parse_sexpr
from planhrc.planner.plan_file import parse_plan_text
from planhrc.planner.registry import get_planner
from planhrc.stats import percentile

DOMAINS = ("domain_m_25_B", "domain_m_0")
ANCHORS = ("fd-lama", "symk", "bfws")
COMMAND = "planhrc plan"


def sample(data: Path, per_stratum: int, seed: int) -> list[Path]:
    """`per_stratum` problems of each (batch, start) stratum, drawn with `seed`, in name order."""
    strata: dict[tuple[str, str], list[Path]] = {}
    for path in sorted((data / "problems").glob("*.pddl")):
        start = "holding" if "(grasp " in path.read_text() else "free"
        strata.setdefault((path.name.split("_", 1)[0], start), []).append(path)
    rng = random.Random(seed)
    chosen = [p for key in sorted(strata) for p in rng.sample(strata[key], min(per_stratum, len(strata[key])))]
    return sorted(chosen)


def with_actions_of(base: str, other: str) -> str:
    """`base`'s text with the actions of `other` it lacks added (so that a plan of `other` expands into `base`'s
    actions where `other`'s are faithful macros of them)."""
    define = parse_sexpr(base, "domain")
    names = {sec[1] for sec in define[2:] if isinstance(sec, tuple) and sec[0] == ":action"}
    extra = [sec for sec in parse_sexpr(other, "domain")[2:]
             if isinstance(sec, tuple) and sec[0] == ":action" and sec[1] not in names]
    assert isinstance(define, tuple)
    return format_sexpr((*define, *extra))


def run_command(domain: Path, problem: Path, timeout_s: float) -> dict[str, Any]:
    t = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "planhrc.cli", "plan", str(domain), str(problem), "--json",
                           "--timeout", str(timeout_s)], capture_output=True, text=True, timeout=timeout_s + 120)
    seconds = time.perf_counter() - t
    answer = json.loads(done.stdout) if done.stdout.strip() else {}
    return {"planner": COMMAND, "seconds": round(seconds, 4), "exit": done.returncode,
            "status": answer.get("status", "error"), "checked_by": answer.get("checked_by"),
            "plan": answer.get("plan", []), "message": str(answer.get("message", done.stderr))[:200]}


def run_anchor(name: str, domain: str, problem: str, timeout_s: float, check_s: float) -> dict[str, Any]:
    try:
        result = get_planner(name).solve(domain, problem, timeout_s)
    except PlannerError as exc:
        return {"planner": name, "seconds": None, "status": "error", "checked_by": None, "plan": [],
                "message": str(exc)[:200]}
    row: dict[str, Any] = {"planner": name, "seconds": round(result.seconds, 4), "status": result.status.value,
                           "checked_by": None, "plan": list(result.plan), "message": result.message[:200]}
    if result.solved:
        try:
            checked = check_plan(domain, problem, result.plan, check_s)
        except PlannerError as exc:
            row.update(status="unvalidated", message=str(exc)[:200])
        else:
            row.update(status="solved" if checked.valid else "invalid", checked_by=checked.by.value)
    return row


def broken(plan: Sequence[str]) -> tuple[str, ...] | None:
    """The plan with its first turn started one angle on (its precondition then fails): None without a turn."""
    for i, step in enumerate(plan):
        parts = step.strip("()").split()
        if "angle" in parts[0]:
            angles = [k for k, a in enumerate(parts) if a.startswith("angle") and k > 0]
            parts[angles[0]] = "angle15" if parts[angles[0]] != "angle15" else "angle30"
            return (*plan[:i], "(" + " ".join(parts) + ")", *plan[i + 1:])
    return None


def both_checks(domain: str, problem: str, plan: Sequence[str], as_given_s: float) -> dict[str, Any]:
    """The expansion's verdict (its route) beside VAL's on the plan as given, on the plan and on a broken copy."""
    out: dict[str, Any] = {}
    for label, steps in (("plan", tuple(plan)), ("broken", broken(plan))):
        if steps is None:
            continue
        checked = check_plan(domain, problem, steps, 120.0)
        t = time.perf_counter()
        given = check_as_given(domain, problem, steps, as_given_s)
        out[label] = {"by": checked.by.value, "valid": checked.valid,
                      "as_given": None if given is None else given.valid,
                      "as_given_s": round(time.perf_counter() - t, 3)}
    return out


def measure(data: Path, problems: Sequence[Path], anchors: Sequence[str], timeout_s: float, anchor_s: float,
            as_given_s: float, progress: bool) -> list[dict[str, Any]]:
    texts = {name: (data / "domains" / f"{name}.pddl").read_text() for name in DOMAINS}
    combined = with_actions_of(texts["domain_m_0"], texts["domain_m_25_B"])
    rows = []
    for n, problem in enumerate(problems, start=1):
        problem_text = problem.read_text()
        theirs = parse_plan_text((data / "plans" / f"{problem.stem}.plan").read_text())
        expanded = macro_report(combined).expand(theirs)
        lengths = {"domain_m_25_B": len(theirs), "domain_m_0": len(expanded.steps if expanded else theirs)}
        for domain in DOMAINS:
            path = data / "domains" / f"{domain}.pddl"
            runs = [run_command(path, problem, timeout_s)]
            runs += [run_anchor(a, texts[domain], problem_text, anchor_s, 120.0) for a in anchors]
            for run in runs:
                run.update(problem=problem.stem, domain=domain, published_length=lengths[domain],
                           length=len(run["plan"]) if run["status"] == "solved" else None)
                if run["planner"] == COMMAND and run["status"] == "solved" and as_given_s > 0:
                    run["both_checks"] = both_checks(texts[domain], problem_text, run["plan"], as_given_s)
                run.pop("plan")
                rows.append(run)
        if progress:
            print(f"[{n}/{len(problems)}] {problem.stem}", file=sys.stderr, flush=True)
    return rows


def summarise(rows: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    out = []
    for domain in DOMAINS:
        ours = {r["problem"]: r["length"] for r in rows
                if r["domain"] == domain and r["planner"] == COMMAND and r["status"] == "solved"}
        for planner in dict.fromkeys(r["planner"] for r in rows):
            sel = [r for r in rows if r["domain"] == domain and r["planner"] == planner]
            good = [r for r in sel if r["status"] == "solved"]
            both = [(r["length"], ours[r["problem"]]) for r in good if r["problem"] in ours]
            times = [r["seconds"] for r in sel if r["seconds"] is not None]
            pairs = [c for r in sel for c in (r.get("both_checks") or {}).values()]
            ran = [c for c in pairs if c["as_given"] is not None]
            out.append({
                "domain": domain, "planner": planner, "problems": len(sel), "solved_validated": len(good),
                "by_expansion": sum(r["checked_by"] == "val-expansion" for r in good),
                "by_val": sum(r["checked_by"] == "val" for r in good),
                "unvalidated": sum(r["status"] == "unvalidated" for r in sel),
                "invalid": sum(r["status"] == "invalid" for r in sel),
                "not_longer": sum(r["length"] <= r["published_length"] for r in good),
                "mean_length": round(statistics.fmean(r["length"] for r in good), 2) if good else None,
                "vs_command": [sum(a < b for a, b in both), sum(a == b for a, b in both), sum(a > b for a, b in both)],
                "published_mean_length": round(statistics.fmean(r["published_length"] for r in sel), 2),
                "median_s": round(statistics.median(times), 3) if times else None,
                "p95_s": round(percentile(times, 0.95), 3) if times else None,
                "max_s": round(max(times), 3) if times else None,
                "as_given_agree": sum(c["as_given"] == c["valid"] for c in ran), "as_given_ran": len(ran),
                "as_given_unfinished": len(pairs) - len(ran),
                "broken_refused_by_both": sum(1 for r in sel for k, c in (r.get("both_checks") or {}).items()
                                              if k == "broken" and not c["valid"] and c["as_given"] is False),
            })
    return out


def markdown(report: dict[str, Any]) -> str:
    m = report["machine"]
    lines = [f"`{report['command']}`: {m['cpu']}, {m['cores']} cores, Python {m['python']}; load average "
             f"{report['load_at_start']} at the start, {report['load_at_end']} at the end; {report['problems']} "
             f"problems ({report['per_stratum']} per batch x start stratum, seed {report['seed']}), "
             f"{report['timeout_s']:g} s per call ({report['anchor_timeout_s']:g} s per anchor call).", "",
             "| domain | planner | solved, validated | by expansion / VAL | unvalidated | invalid | not longer "
             "than the authors' | mean length (theirs) | shorter / same / longer than the command's | median s | "
             "p95 s | max s | VAL as given agrees |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for s in report["summary"]:
        agree = (f"{s['as_given_agree']}/{s['as_given_ran']}"
                 + (f" ({s['as_given_unfinished']} unfinished)" if s["as_given_unfinished"] else "")
                 if s["as_given_ran"] or s["as_given_unfinished"] else "-")
        lines.append(f"| {s['domain']} | {s['planner']} | {s['solved_validated']}/{s['problems']} | "
                     f"{s['by_expansion']} / {s['by_val']} | {s['unvalidated']} | {s['invalid']} | "
                     f"{s['not_longer']} | {s['mean_length'] if s['mean_length'] is not None else '-'} "
                     f"({s['published_mean_length']}) | {' / '.join(map(str, s['vs_command']))} | {s['median_s']} | "
                     f"{s['p95_s']} | {s['max_s']} | {agree} |")
    lines += ["", f"{COMMAND}: the whole command as a process (interpreter start-up included); the anchors: each "
              "planner's whole process; a plan counts as solved once it is validated (VAL on the plan, or on its "
              "expansion into the actions its proved macros stand for). VAL as given: the answer's plan and a "
              "broken copy of it, both checks side by side (the broken copies refused by both: "
              f"{sum(s['broken_refused_by_both'] for s in report['summary'])})."]
    return "\n".join(lines)


def _data_dir(text: str) -> str:
    """A training sample's folder (`--data`): problems/, plans/ and both domain files; never the authors' test set."""
    path = Path(text)
    if "dataset/test" in path.resolve().as_posix():
        raise argparse.ArgumentTypeError("the authors' test set is measured on from outside, never benched here")
    for part in ("problems", "plans", *(f"domains/{name}.pddl" for name in DOMAINS)):
        if not (path / part).exists():
            raise argparse.ArgumentTypeError(f"no {part} in {text}")
    return text


def main(argv: Sequence[str] | None = None) -> int:
    from planhrc.cli_args import OneLineParser, non_negative_float, positive_float, positive_int, writable_dir

    parser = OneLineParser(prog="python -m planhrc.bench.training", description=__doc__,
                           formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--data", type=_data_dir, required=True,
                        help="the training sample: problems/, plans/, domains/")
    parser.add_argument("--per-stratum", type=positive_int, default=2, help="problems per batch x start stratum")
    parser.add_argument("--seed", type=int, default=7)
    parser.add_argument("--timeout", type=positive_float, default=10.0, help="seconds per call")
    parser.add_argument("--anchors", default=",".join(ANCHORS), help="registry planners run beside the command")
    parser.add_argument("--anchor-timeout", type=positive_float, default=None,
                        help="seconds per anchor call (default: --timeout)")
    parser.add_argument("--as-given-timeout", type=non_negative_float, default=60.0,
                        help="seconds for VAL on an answer's plan as given (0: never)")
    parser.add_argument("--out", type=writable_dir, default=None, help="folder for training.json and .md")
    parser.add_argument("--no-progress", action="store_true")
    args = parser.parse_args(argv)
    data = Path(args.data)
    anchors = [a for a in args.anchors.split(",") if a]
    for name in anchors:
        try:
            get_planner(name)
        except PlannerError as exc:
            parser.error(f"--anchors: {exc}")
    problems = sample(data, args.per_stratum, args.seed)
    load = round(os.getloadavg()[0], 2)
    rows = measure(data, problems, anchors, args.timeout, args.anchor_timeout or args.timeout, args.as_given_timeout,
                   not args.no_progress)
    report = {"command": "python -m planhrc.bench.training " + " ".join(argv if argv is not None else sys.argv[1:]),
              "machine": machine_info(), "load_at_start": load, "load_at_end": round(os.getloadavg()[0], 2),
              "problems": len(problems), "per_stratum": args.per_stratum, "seed": args.seed,
              "timeout_s": args.timeout, "anchor_timeout_s": args.anchor_timeout or args.timeout, "anchors": anchors, "rows": rows, "summary": summarise(rows)}
    table = markdown(report)
    print(table)
    if args.out:
        write_json_and_table(Path(args.out), "training", report, table)
    return 0


if __name__ == "__main__":
    sys.exit(main())

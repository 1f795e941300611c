"""`python -m planhrc.bench.large`: re-planning perceptions of large objects over HTTP: the time to the first
validated action.

For each size (default 50 links x 36 and 200 x 12, absolute), a fresh `planhrc serve` (its planning pool on, the
planning deadline the settings', or `--deadline`) gets one object with a random goal and `--runs` perceptions at
random configurations, one after the other once the last plan's later VAL pieces have their verdicts (the first
`--first-after` seconds after the goal was set: a camera's first frame comes some time after the goal, time in
which the service warms its planning up for the object; default 0, the first perception at once). Per
perception: the HTTP status, the wall time to the answer, which is the time to the first validated action when the
answer names one (a re-plan is answered once VAL accepted its first motion, and the store checked it), the plan's
length and how many of its steps were checked before the answer (the first motion, or the whole plan when it was
checked in one piece) against how many behind it, and the re-plan's stages as the service timed them (translate,
plan, expected states: the replay of every step, which the store needs whole; VAL before the answer), and the
service process's own CPU seconds to the answer and behind it, until the later pieces have their verdicts (VAL's
and the planning worker's CPU are theirs, not counted). A 503 is the deadline passing; it is reported, never
retried.

With `--stage-cpu`, each size's re-plan stages on the answer's path are first run once in the bench's own process
and their CPU seconds reported (`stage_cpu`: the planning worker's translation, planning, replay and packing, the
service's unpacking, first VAL pieces' problems and journal row), which the machine's other work moves less than
the answers' wall time.
"""
from __future__ import annotations

import argparse
import random
import sys
import tempfile
import time
from pathlib import Path
from typing import Any, Sequence

import httpx

from planhrc.bench.cpu import Settle, process_cpu_s
from planhrc.bench.grid import machine_info, write_json_and_table
from planhrc.bench.service_calls import TOKEN, create_object, random_angles, running_service, set_goal
from planhrc.event_log import DecisionData, data_of
from planhrc.settings import make_settings

SIZES = ((50, 36), (200, 12))


def _size(text: str) -> tuple[int, int]:
    links, sep, k = text.partition("x")
    if not sep or not links.isdigit() or not k.isdigit() or 360 % int(k):
        raise argparse.ArgumentTypeError(f"expected LINKSxK with K dividing 360, got {text!r}")
    return int(links), int(k)


STAGES = ("translate", "plan", "expected_states", "validate")


def measure_size(links: int, orientations: int, formulation: str, runs: int, seed: int,
                 deadline_s: float | None = None, first_after_s: float = 0.0) -> dict[str, Any]:
    rng = random.Random(seed)
    rows = []
    env = {"PLANHRC_PLANNING_DEADLINE_S": str(deadline_s)} if deadline_s is not None else None
    with tempfile.TemporaryDirectory(prefix="planhrc-bench-large-") as tmp, running_service(Path(tmp), env) as server, \
            httpx.Client(base_url=server.url, timeout=120, headers={"Authorization": f"Bearer {TOKEN}"}) as client:
        ident = create_object(client, links, orientations, formulation, f"large-{links}x{orientations}")
        set_goal(client, ident, random_angles(rng, links, orientations))
        settle = Settle(client, ident)
        time.sleep(first_after_s)
        for _ in range(runs):
            before = process_cpu_s(server.pid)[0]
            t = time.perf_counter()
            r = client.post(f"/objects/{ident}/perceptions",
                            json={"link_orientations_deg": random_angles(rng, links, orientations)})
            row: dict[str, Any] = {"status": r.status_code, "seconds": round(time.perf_counter() - t, 3)}
            answered = process_cpu_s(server.pid)[0]
            if r.status_code == 200:
                answer = r.json()
                row["decision"] = answer["decision"]
                events = client.get(f"/objects/{ident}/events").json()
                decisions = [data_of(e["kind"], e["data"]) for e in events if e["kind"] == "replan"]
                data = next((d for d in reversed(decisions) if isinstance(d, DecisionData)
                             and d.plan_id == answer.get("plan_id")), DecisionData())
                pieces = data.val_pieces
                accepted = [pieces[i - 1] for i in data.val_accepted]
                if pieces:  # answered once VAL accepted the first pieces, the rest checked behind the answer
                    row["plan_steps"] = pieces[-1][1]
                    row["accepted_before_answer"] = accepted[-1][1] if accepted else 0
                else:  # a plan without pieces was checked whole before the answer
                    steps = len(client.get(f"/objects/{ident}/plan").json()["steps"])
                    row["plan_steps"] = row["accepted_before_answer"] = steps
                row["first_action_last_step"] = (answer.get("next_action") or {}).get("last_step")
                if row["first_action_last_step"] is not None and row["accepted_before_answer"] >= \
                        row["first_action_last_step"]:
                    row["first_validated_action_s"] = row["seconds"]
                timings = (data.timings or {}) if answer["decision"] == "replan" else {}
                row["stages_s"] = {k: round(float(timings[k]), 3) for k in STAGES if k in timings}
            else:
                row["detail"] = str(r.json().get("detail", ""))[:160]
            settle.wait(limit_s=600.0)
            # the service's own CPU (not VAL's, nor the planning worker's), to the answer and then behind it until
            # the plan's later pieces have their verdicts (the bench's own probes of `settle` included)
            row["service_cpu_s"] = {"to_answer": round(answered - before, 2),
                                    "behind": round(process_cpu_s(server.pid)[0] - answered, 2)}
            rows.append(row)
    return {"links": links, "orientations": orientations, "formulation": formulation, "first_after_s": first_after_s,
            "rows": rows}


CPU_STAGES = ("translate and plan (the object's first)", "translate and plan (a later one)",
              "expected states (the replay)", "the outcome packed (worker)", "the outcome unpacked (service)",
              "the first VAL pieces' problems", "the journal row's body")


def stage_cpu(links: int, orientations: int, seed: int) -> dict[str, Any]:
    """The CPU seconds (`time.process_time()`) of an absolute re-plan's stages on the answer's path, each once, in this
    process, without a service: what the planning worker and the service each spend of a random task of this size
    (the garbage collector off, as the worker and the unpacking run). Less at the mercy of other work on the
    machine than the answers' wall time."""
    import gc
    from dataclasses import replace

    from planhrc.kb_service.planning_pool import pack_outcome, unpack_outcome
    from planhrc.kb_service.store.journal import encode_body
    from planhrc.model import HAS_ORIENTATION, make_object, perceive
    from planhrc.pipeline import config_from_settings, stages
    from planhrc.pipeline.pieces import early_answer_first_piece, piece_bounds, piece_of

    rng = random.Random(seed)
    obj = make_object("o1", "absolute", links, orientations)
    goal = frozenset(a for a in perceive(obj, random_angles(rng, links, orientations)).atoms if a[0] == HAS_ORIENTATION)
    init = perceive(obj, random_angles(rng, links, orientations)).atoms
    config = replace(config_from_settings(make_settings()), validate=False, deadline_s=3600.0)
    cpu: dict[str, float] = {}

    def timed(stage: str, work: Any) -> Any:
        started = time.process_time()
        done = work()
        cpu[stage] = round(time.process_time() - started, 3)
        return done

    enabled = gc.isenabled()
    gc.disable()
    try:
        for stage in CPU_STAGES[:2]:
            found = timed(stage, lambda: stages.find_plan(obj, init, goal, config, deadline_at=time.monotonic() + 3600))
        if not isinstance(found, stages.Found):
            return {"links": links, "orientations": orientations, "status": found.status.value, "cpu_s": cpu}
        outcome = timed(CPU_STAGES[2], lambda: stages.expect(obj, init, goal, found, time.monotonic() + 3600))
        frames = timed(CPU_STAGES[3], lambda: list(pack_outcome(outcome)))
        back = timed(CPU_STAGES[4], lambda: unpack_outcome(iter(frames), init))
        task, first = back.task, early_answer_first_piece(obj, back, True)
        bounds = piece_bounds(len(back.steps), 2, first, 2, 2) if first is not None else []
        timed(CPU_STAGES[5], lambda: [piece_of(obj, task.problem, back.steps, back.expected_states, a + 1, b,
                                               task.validation_domain) for a, b in bounds if first and b <= first])
        timed(CPU_STAGES[6], lambda: encode_body(back.actions, back.expected_states))
    finally:
        if enabled:
            gc.enable()
    return {"links": links, "orientations": orientations, "steps": len(outcome.actions), "cpu_s": cpu}


def markdown(report: dict[str, Any]) -> str:
    m = report["machine"]
    lines = [f"machine: {m['cpu']}, {m['cores']} cores; planning deadline {report['deadline_s']} s; "
             f"first perception {report.get('first_after_s', 0)} s after the goal; "
             f"load average {report['load_at_start']} at the start, {report.get('load_at_end', '-')} at the end", ""]
    if report.get("stage_cpu"):
        lines += ["CPU seconds of an absolute re-plan's stages, in process (`stage_cpu`):", "",
                  "| object | steps | " + " | ".join(CPU_STAGES) + " |", "|---|---|" + "---|" * len(CPU_STAGES)]
        for row in report["stage_cpu"]:
            lines.append(f"| {row['links']} x {row['orientations']} | {row.get('steps', row.get('status'))} | "
                         + " | ".join(str(row["cpu_s"].get(k, "-")) for k in CPU_STAGES) + " |")
        lines.append("")
    lines += ["| object | perception | HTTP | seconds | first validated action s | decision | plan steps | "
              "checked before the answer | translate / plan / expected states / VAL s | "
              "service CPU s: to the answer / behind it |",
              "|---|---|---|---|---|---|---|---|---|---|"]
    for size in report["sizes"]:
        for i, row in enumerate(size["rows"], start=1):
            stages = row.get("stages_s") or {}
            said = " / ".join(str(stages.get(k, "-")) for k in STAGES) if stages else "-"
            lines.append(f"| {size['links']} x {size['orientations']} {size['formulation']} | {i} | {row['status']} | "
                         f"{row['seconds']} | {row.get('first_validated_action_s', '-')} | "
                         f"{row.get('decision', row.get('detail', '-'))} | {row.get('plan_steps', '-')} | "
                         f"{row.get('accepted_before_answer', '-')} | {said} | {_cpu(row)} |")
    return "\n".join(lines)


def _cpu(row: dict[str, Any]) -> str:
    cpu = row.get("service_cpu_s")
    return f"{cpu['to_answer']} / {cpu['behind']}" if cpu else "-"


def main(argv: Sequence[str] | None = None) -> int:
    import os

    from planhrc.cli_args import OneLineParser, non_negative_float, positive_float, positive_int, writable_dir

    parser = OneLineParser(prog="python -m planhrc.bench.large", description=__doc__,
                           formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--sizes", type=lambda t: [_size(s) for s in t.split(",")],
                        default=[SIZES[0], SIZES[1]], help="LINKSxK,… (default 50x36,200x12)")
    parser.add_argument("--formulation", choices=["relative", "absolute"], default="absolute")
    parser.add_argument("--runs", type=positive_int, default=3, help="perceptions per size")
    parser.add_argument("--seed", type=int, default=7)
    parser.add_argument("--deadline", type=positive_float, default=None,
                        help="the service's planning deadline in seconds (default: the settings')")
    parser.add_argument("--first-after", type=non_negative_float, default=0.0,
                        help="seconds between setting the goal and the first perception (default 0)")
    parser.add_argument("--stage-cpu", action="store_true",
                        help="first, each size's absolute re-plan stages in this process: their CPU seconds")
    parser.add_argument("--out", type=writable_dir, default=None, help="folder for large.json and large.md")
    args = parser.parse_args(argv)
    report: dict[str, Any] = {"machine": machine_info(),
                              "deadline_s": args.deadline or make_settings().planning_deadline_s,
                              "first_after_s": args.first_after, "load_at_start": round(os.getloadavg()[0], 2)}
    if args.stage_cpu:
        report["stage_cpu"] = [stage_cpu(links, k, args.seed) for links, k in args.sizes]
    report["sizes"] = [measure_size(links, k, args.formulation, args.runs, args.seed, args.deadline, args.first_after)
                       for links, k in args.sizes]
    report["load_at_end"] = round(os.getloadavg()[0], 2)
    table = markdown(report)
    print(table)
    if args.out:
        write_json_and_table(Path(args.out), "large", report, table)
    return 0 if all(r["status"] == 200 for s in report["sizes"] for r in s["rows"]) else 1


if __name__ == "__main__":
    sys.exit(main())

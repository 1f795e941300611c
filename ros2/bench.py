"""`planhrc ros2-bench`: perception -> decision over ROS 2 against the same over HTTP, in one run (not a test).

One `planhrc serve` on a fresh store, one object (20 links x 12 orientations, relative, by default) and one
bridge serving it. Each round sends, through both doors (the one that goes first alternating), a random
configuration that forces a new plan (the measure) and one with a link not seen, which the service answers without
planning or storing anything (so the difference is the way there and back). Over HTTP, the time of
`POST /objects/{id}/perceptions`; over ROS 2, from publishing the JointState to the decision's arrival on the
decision topic. The same work follows either: the action is dispatched (the HTTP caller takes it, the bridge does
over ROS 2), the bridge publishes the decision, and a pause lets what the request set going settle.

Prints one JSON document; `--out DIR` also writes `ros2-bench.json` and `ros2-bench.md` there.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import random
import secrets
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from planhrc.cli_args import int_in, non_negative_int, SubParsers, writable_dir
from planhrc.stats import cpu_model, percentile

TARGET_MS = 5.0  # the target: ROS 2 adds at most this much at the median
# a pause after each request and what follows it: the bridge's reads and markers, the service's writing of the
# plan, do not delay the next (measured) request, whichever door it takes
PAUSE_S = 0.3
DOORS = ("http", "ros2")
# re-planning perceptions (the measure: a new plan each), and perceptions with a link not seen, which the service
# answers without planning or storing anything: the difference between the doors is then the way there and back
KINDS = ("replan", "unseen")
EXPECTED = {"replan": "replan", "unseen": "incomplete_perception"}


def add_ros2_bench_parser(subparsers: SubParsers) -> None:
    p = subparsers.add_parser("ros2-bench", help="perception to decision over ROS 2 and over HTTP, in one run",
                              description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--samples", type=int_in(5), default=60, help="perceptions through each door")
    p.add_argument("--links", type=int_in(2, 200), default=20)
    p.add_argument("--orientations", type=int_in(2, 360), default=12)
    p.add_argument("--seed", type=non_negative_int, default=0)
    p.add_argument("--out", type=writable_dir, default=None, help="write ros2-bench.json and ros2-bench.md here")
    p.set_defaults(func=run_ros2_bench_cli)


def run_ros2_bench_cli(args: argparse.Namespace) -> int:
    from .cli import rclpy_problem

    if problem := rclpy_problem("ros2-bench"):
        print(f"planhrc ros2-bench: {problem}", file=sys.stderr)
        return 2
    report = run_ros2_bench(args.samples, args.links, args.orientations, args.seed)
    text = json.dumps(report, indent=2)
    print(text)
    if args.out:
        out = Path(args.out)
        (out / "ros2-bench.json").write_text(text + "\n")
        (out / "ros2-bench.md").write_text(markdown(report))
    return 0


def run_ros2_bench(samples: int, links: int, orientations: int, seed: int) -> dict[str, Any]:
    from planhrc.client import KBClient
    from planhrc.service_process import running_service

    from .cli import running_bridge
    from .link import Ros2Link

    rng = random.Random(seed)
    step = 360 // orientations

    def angles() -> list[float]:
        return [float(rng.randrange(orientations) * step) for _ in range(links)]

    token = secrets.token_urlsafe(16)
    load_start = os.getloadavg()[0]
    times: dict[tuple[str, str], list[float]] = {(kind, door): [] for kind in KINDS for door in DOORS}
    other: dict[tuple[str, str], int] = {key: 0 for key in times}
    with tempfile.TemporaryDirectory(prefix="planhrc-ros2-bench-") as tmp, \
            running_service(Path(tmp) / "kb.sqlite3", args=("--log-level", "warning"), clean_env=True,
                            env={"PLANHRC_TOKEN": token}, cwd=Path(tmp)) as server, \
            KBClient(server.url, token=token) as kb:
        oid = kb.create_object("ros2-bench", links, orientations, "relative")["id"]
        kb.set_goal(oid, link_orientations_deg=angles())
        with running_bridge(server.url, token, (oid,), Path(tmp) / "bridge.log"), Ros2Link(oid) as link:
            for round_ in range(samples + 1):  # round 0 warms up both doors' connections and is left out
                # each round: both kinds through both doors, the door that goes first alternating
                doors = DOORS if round_ % 2 == 0 else DOORS[::-1]
                for kind in KINDS:
                    for door in doors:
                        values: list[float | None] = list(angles())
                        if kind == "unseen":
                            values[-1] = None
                        decision, seconds = _perceive(door, kb, link, oid, values)
                        time.sleep(PAUSE_S)  # what the request set going (plan writing, checks) settles
                        if round_ == 0:
                            continue
                        if str(decision.decision) == EXPECTED[kind]:
                            times[(kind, door)].append(seconds)
                        else:
                            other[(kind, door)] += 1
    parts: dict[str, dict[str, Any]] = {
        kind: {door: summary_ms(times[(kind, door)]) | {"other_decisions": other[(kind, door)]} for door in DOORS}
        for kind in KINDS}
    for kind in KINDS:
        parts[kind]["median_added_ms"] = round(
            (percentile(times[(kind, "ros2")], 0.5) - percentile(times[(kind, "http")], 0.5)) * 1000, 2)
    return {
        "command": f"planhrc ros2-bench --samples {samples} --links {links} --orientations {orientations} "
                   f"--seed {seed}",
        "object": {"links": links, "orientations": orientations, "formulation": "relative"},
        "machine": {"cpu": cpu_model(), "cores": os.cpu_count(), "python": platform.python_version(),
                    "load_start": round(load_start, 2), "load_end": round(os.getloadavg()[0], 2)},
        **parts,
        "median_added_ms": parts["replan"]["median_added_ms"],
        "target_ms": TARGET_MS,
    }


def _perceive(door: str, kb: Any, link: Any, oid: str, values: list[float | None]) -> tuple[Any, float]:
    """One perception through `door`, and its seconds to the decision; the same work follows either: the action
    dispatched (by the caller over HTTP, by the bridge over ROS 2) and the decision published on ROS 2."""
    t0 = time.perf_counter()
    if door == "http":
        seen = link.other_decisions
        decision = kb.post_perception(oid, values)
        seconds = time.perf_counter() - t0
        if decision.next_action is not None:
            kb.next_action(oid)
        # the bridge publishes this decision too (from the event stream): let it finish first
        link._wait(lambda: link.other_decisions > seen, "the HTTP decision on ROS 2", 10.0)
        return decision, seconds
    decision = link.post_perception(oid, values)  # returns once the bridge has dispatched
    return decision, link.received_at[link.last_perception] - t0


def summary_ms(values: list[float]) -> dict[str, Any]:
    return {"n": len(values), "p50_ms": round(percentile(values, 0.5) * 1000, 2),
            "p90_ms": round(percentile(values, 0.9) * 1000, 2), "p95_ms": round(percentile(values, 0.95) * 1000, 2),
            "max_ms": round(max(values) * 1000, 2) if values else None}


def markdown(report: dict[str, Any]) -> str:
    m, o = report["machine"], report["object"]
    what = {"replan": "re-planning", "unseen": "a link not seen (no planning)"}
    rows = [f"| {what[kind]} | {door} | {report[kind][door]['n']} | {report[kind][door]['p50_ms']} ms | "
            f"{report[kind][door]['p90_ms']} ms | {report[kind][door]['p95_ms']} ms | {report[kind][door]['max_ms']} ms |"
            for kind in KINDS for door in DOORS]
    met = "met" if report["median_added_ms"] <= report["target_ms"] else "missed"
    return "\n".join([
        f"Perception -> decision on one object of {o['links']} links x {o['orientations']} orientations "
        f"({o['formulation']}), the two doors alternating in one run: `{report['command']}`.",
        "",
        f"Machine: {m['cpu']}, {m['cores']} cores, Python {m['python']}; load average {m['load_start']} at the start, "
        f"{m['load_end']} at the end.",
        "",
        "| perception | door | n | p50 | p90 | p95 | max |",
        "|---|---|---|---|---|---|---|",
        *rows,
        "",
        f"ROS 2 adds {report['median_added_ms']} ms at the median of re-planning perceptions (target <= "
        f"{report['target_ms']:g} ms: {met}); {report['unseen']['median_added_ms']} ms where the service does not "
        "plan.",
        "",
    ])

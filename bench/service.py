"""`planhrc service-bench`: the KB service as a cell uses it for weeks, measured over HTTP (not a test).

Each part starts its own `planhrc serve` process on a fresh SQLite file and drives it with real requests:

* **objects** — p50/p95 of a re-planning perception on one object while 1, 200, 1,000 … objects are stored;
* **history** — one object receives thousands of perceptions (each forces a new plan); at each checkpoint: the
  re-planning perception's p50/p95, every read route's latency, `/ontology`'s size, the server's RSS and the
  worst wait of `/health` while the slowest read runs;
* **contention** — another object's worst perception latency while a large absolute object plans;
* **refusal** — the time to refuse a 150 MB body without the token, and over the size limit with it;
* **knowledge** — SPARQL, subsumption over HTTP and reasoning jobs after a long history (`bench.knowledge`);
* **scale-out** — perceptions per second, latency and CPU per perception of SQLite against 1, 2, 4 replicas on one
  PostgreSQL database (`--db`), 10 and 100 objects (`bench.scale_out`);
* **observability** — the server's CPU per re-planning perception with metrics and tracing off and on, two services
  side by side (`bench.observability`).

Prints one JSON document on stdout (`--out DIR` also writes `service-bench.json` and a Markdown table).
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import random
import socket
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any, Callable

import httpx

from planhrc.cli_args import SubParsers
from planhrc.service_process import RunningService as Server
from planhrc.stats import cpu_model, percentile

from .errors import BenchError
from .knowledge import bench_knowledge, knowledge_markdown
from .observability import bench_observability, observability_markdown
from .scale_out import bench_scale_out, scale_out_markdown
from .service_calls import (TOKEN, Side, client_of, create_object, perceive, random_angles,
                            replanning_latencies, replanning_with_cpu, rss_mb, running_service, set_goal, summary_ms)

READ_ROUTES = ("object", "plan", "events", "pddl_problem", "ontology")


# -- parts ----------------------------------------------------------------------------------------------------
def bench_objects(counts: list[int], samples: int, links: int, orientations: int, seed: int) -> list[dict[str, Any]]:
    rng = random.Random(seed)
    rows = []
    with tempfile.TemporaryDirectory(prefix="planhrc-sbench-") as tmp, running_service(Path(tmp)) as server, \
            client_of(server, 120) as client:
        stored = 0
        probe = create_object(client, links, orientations, "relative", "probe")
        set_goal(client, probe, random_angles(rng, links, orientations))
        stored = 1
        for count in sorted(counts):
            while stored < count:
                create_object(client, links, orientations, "relative", f"filler{stored}")
                stored += 1
            lat, cpu_ms = replanning_with_cpu(client, server, probe, links, orientations, samples, rng)
            rows.append({"objects": count, **summary_ms(lat), "server_cpu_ms": cpu_ms,
                         "rss_mb": round(rss_mb(server.pid), 1)})
            print(f"[service-bench] objects={count}: {rows[-1]}", file=sys.stderr, flush=True)
    return rows


def _timed_get(client: httpx.Client, path: str, headers: dict[str, str] | None = None) -> tuple[float, int, int]:
    t = time.perf_counter()
    try:
        r = client.get(path, headers=headers)
    except httpx.TimeoutException:
        return float("inf"), 0, 0
    return time.perf_counter() - t, r.status_code, len(r.content)


def _last_seq(client: httpx.Client, object_id: str, after_seq: int) -> int:
    """The object's last event seq, paging through the log from `after_seq`."""
    while True:
        page = client.get(f"/objects/{object_id}/events", params={"after_seq": after_seq}).json()
        if not page:
            return after_seq
        after_seq = int(page[-1]["seq"])


def _read_paths(object_id: str, last_seq: int) -> dict[str, str]:
    return {"object": f"/objects/{object_id}", "plan": f"/objects/{object_id}/plan",
            "events": f"/objects/{object_id}/events?after_seq={max(0, last_seq - 50)}",
            "pddl_problem": f"/objects/{object_id}/pddl/problem", "ontology": "/ontology"}


def _health_worst_wait(server: Server, during: Callable[[], Any]) -> tuple[float, Any]:
    """Run `during` while polling /health from another connection; the worst /health latency seen."""
    stop = threading.Event()
    worst = [0.0]

    def poll() -> None:
        with httpx.Client(base_url=server.url, timeout=120) as c:
            while not stop.is_set():
                t = time.perf_counter()
                try:
                    c.get("/health")
                except httpx.TransportError:
                    pass
                worst[0] = max(worst[0], time.perf_counter() - t)
                time.sleep(0.01)

    thread = threading.Thread(target=poll, daemon=True)
    thread.start()
    try:
        result = during()
    finally:
        stop.set()
        thread.join(timeout=130)
    return worst[0], result


def bench_history(checkpoints: list[int], samples: int, links: int, orientations: int, formulation: str,
                  read_timeout: float, seed: int, validate: bool = True) -> list[dict[str, Any]]:
    """The history part; `validate` False: the service with VAL off (`PLANHRC_VALIDATE_PLANS=false`), what a
    re-plan costs without its check, to set the check's share apart (not a product's figure: no plan is checked)."""
    rng = random.Random(seed)
    rows = []
    env = {} if validate else {"PLANHRC_VALIDATE_PLANS": "false"}
    with tempfile.TemporaryDirectory(prefix="planhrc-sbench-") as tmp, running_service(Path(tmp), env) as server, \
            client_of(server, read_timeout) as client:
        obj = create_object(client, links, orientations, formulation, "history")
        set_goal(client, obj, random_angles(rng, links, orientations))
        sent = last_seq = 0
        for checkpoint in sorted(checkpoints):
            while sent < checkpoint - samples:
                perceive(client, obj, random_angles(rng, links, orientations))
                sent += 1
            lat, cpu_ms = replanning_with_cpu(client, server, obj, links, orientations, samples, rng,
                                               acting=formulation == "bimanual")
            sent += samples
            last_seq = _last_seq(client, obj, last_seq)
            reads: dict[str, Any] = {}
            for name, path in _read_paths(obj, last_seq).items():
                times = []
                size = 0
                for _ in range(3 if name == "ontology" else 20):
                    seconds, status, size = _timed_get(client, path)
                    times.append(seconds)
                    if status != 200:
                        break
                reads[name] = {"p50_ms": round(percentile(times, 0.5) * 1000, 2),
                               "p95_ms": round(percentile(times, 0.95) * 1000, 2),
                               "max_ms": round(max(times) * 1000, 2), "bytes": size,
                               "status": status if times[-1] != float("inf") else "timeout"}
            slowest = max(READ_ROUTES, key=lambda n: reads[n]["max_ms"])
            worst_health, _ = _health_worst_wait(server, lambda: _timed_get(client, _read_paths(obj, last_seq)[slowest]))
            row: dict[str, Any] = {"perceptions": checkpoint, "validated": validate,
                                   "replan": {**summary_ms(lat), "server_cpu_ms": cpu_ms},
                   "reads": reads,
                   "slowest_read": slowest, "health_worst_ms_during_slowest_read": round(worst_health * 1000, 2),
                   "rss_mb": round(rss_mb(server.pid), 1)}
            rows.append(row)
            print(f"[service-bench] history {checkpoint}: replan p50 {row['replan']['p50_ms']} ms, "
                  f"rss {row['rss_mb']} MB, slowest read {slowest} {reads[slowest]['max_ms']} ms",
                  file=sys.stderr, flush=True)
    return rows


def bench_history_side_by_side(short: int, long: int, samples: int, links: int, orientations: int,
                               formulation: str, seed: int, round_size: int = 20) -> dict[str, Any]:
    """The history part's growth figure with the machine's load taken out: two services side by side, one object
    each, one given `short` perceptions and the other `long`; then re-planning perceptions in alternating rounds
    of `round_size` on each, until each has `samples`, so whatever else the machine runs falls on both alike."""
    rng = random.Random(seed)
    with tempfile.TemporaryDirectory(prefix="planhrc-sbench-") as tmp_a, \
            tempfile.TemporaryDirectory(prefix="planhrc-sbench-") as tmp_b, \
            running_service(Path(tmp_a)) as server_a, running_service(Path(tmp_b)) as server_b, \
            client_of(server_a, 120) as client_a, client_of(server_b, 120) as client_b:
        sides = []
        for server, client, history in ((server_a, client_a, short), (server_b, client_b, long)):
            obj = create_object(client, links, orientations, formulation, "history")
            set_goal(client, obj, random_angles(rng, links, orientations))
            for _ in range(history):
                perceive(client, obj, random_angles(rng, links, orientations))
            sides.append(Side(server, client, obj, history, []))
        while any(side.posted < samples for side in sides):
            for side in sides:
                count = min(round_size, samples - side.posted)
                if count <= 0:
                    continue
                lat, cpu_ms = replanning_with_cpu(side.client, side.server, side.object_id, links, orientations,
                                                   count, rng, acting=formulation == "bimanual")
                side.latencies += lat
                side.cpu_s += cpu_ms * count / 1000
                side.posted += count
        rows = [{"perceptions": side.history, **summary_ms(side.latencies),
                 "server_cpu_ms": round(side.cpu_s / side.posted * 1000, 2),
                 "rss_mb": round(rss_mb(side.server.pid), 1)} for side in sides]
    print(f"[service-bench] side by side: {rows}", file=sys.stderr, flush=True)
    return {"round_size": round_size, "rows": rows}


def bench_contention(big_links: int, big_orientations: int, small_samples: int, seed: int,
                     planning_workers: int | None = None) -> dict[str, Any]:
    """The latency of a small object's perceptions, and of `/health` polled every 20 ms from another connection,
    while a large absolute object plans (`planning_workers`: the service's setting, e.g. 0 to plan everything
    in the service's process; default: the service's default)."""
    rng = random.Random(seed)
    env = {} if planning_workers is None else {"PLANHRC_PLANNING_WORKERS": str(planning_workers)}
    with tempfile.TemporaryDirectory(prefix="planhrc-sbench-") as tmp, running_service(Path(tmp), env) as server, \
            client_of(server, 600) as client:
        small = create_object(client, 8, 12, "relative", "small")
        set_goal(client, small, random_angles(rng, 8, 12))
        big = create_object(client, big_links, big_orientations, "absolute", "big")
        set_goal(client, big, random_angles(rng, big_links, big_orientations))
        quiet = replanning_latencies(client, small, 8, 12, small_samples, rng)
        big_answer: dict[str, Any] = {}

        def plan_big() -> None:
            """The large object's perception, whatever it answers (a service with a planning deadline refuses a
            task it cannot plan in time: 503 with the reason)."""
            with client_of(server, 600) as c:
                t = time.perf_counter()
                r = c.post(f"/objects/{big}/perceptions",
                           json={"link_orientations_deg": random_angles(rng, big_links, big_orientations)})
                big_answer.update(seconds=time.perf_counter() - t, status=r.status_code,
                                  answer=r.json().get("decision") if r.is_success else r.json().get("detail"))

        health: list[float] = []

        def poll_health() -> None:
            with client_of(server, 600) as c:
                c.get("/health").raise_for_status()  # a new connection's first answer is not the service's
                while thread.is_alive():
                    t = time.perf_counter()
                    c.get("/health").raise_for_status()
                    health.append(time.perf_counter() - t)
                    time.sleep(0.02)

        thread = threading.Thread(target=plan_big)
        poller = threading.Thread(target=poll_health)
        thread.start()
        poller.start()
        busy: list[float] = []
        time.sleep(0.05)
        while thread.is_alive() and len(busy) < 10 * small_samples:
            busy.extend(replanning_latencies(client, small, 8, 12, 1, rng))
        thread.join()
        poller.join()
        return {"big_object": f"{big_links} links x {big_orientations} orientations, absolute",
                "planning_workers": planning_workers if planning_workers is not None else "default",
                "big_perception_s": round(big_answer["seconds"], 2) if big_answer else None,
                "big_status": big_answer.get("status"), "big_answer": big_answer.get("answer"),
                "small_quiet": summary_ms(quiet), "small_while_big_plans": summary_ms(busy),
                "health_while_big_plans": summary_ms(health)}


def bench_refusal() -> dict[str, Any]:
    """Seconds to answer a request announcing a 150 MB body, with only its first KB sent."""
    out: dict[str, Any] = {}
    with tempfile.TemporaryDirectory(prefix="planhrc-sbench-") as tmp, running_service(Path(tmp)) as server:
        host, port = server.url.rsplit(":", 1)
        for label, auth in (("no_token", ""), ("token_over_limit", f"Authorization: Bearer {TOKEN}\r\n")):
            head = (f"POST /objects HTTP/1.1\r\nHost: x\r\n{auth}Content-Type: application/json\r\n"
                    f"Content-Length: {150 * 1024 * 1024}\r\n\r\n").encode()
            with socket.create_connection(("127.0.0.1", int(port)), timeout=30) as sock:
                t = time.perf_counter()
                sock.sendall(head + b"{" + b" " * 1023)
                first = sock.recv(4096)
                seconds = time.perf_counter() - t
            status = int(first.split(b" ")[1]) if first else 0
            out[label] = {"status": status, "ms": round(seconds * 1000, 2)}
        out["rss_mb_after"] = round(rss_mb(server.pid), 1)
    return out


# -- command --------------------------------------------------------------------------------------------------
def _int_list(text: str) -> list[int]:
    try:
        values = [int(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected whole numbers separated by commas, got {text!r}") from None
    if not values or min(values) < 1:
        raise argparse.ArgumentTypeError(f"expected positive whole numbers, got {text!r}")
    return values


def _int_at_least(minimum: int, words: str) -> Callable[[str], int]:
    """An argparse type: a whole number >= `minimum` (`words` names the bound in the error)."""
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
        if value < minimum:
            raise argparse.ArgumentTypeError(f"expected {words}, got {text!r}")
        return value
    return parse


_positive_int = _int_at_least(1, "a positive whole number")
_non_negative_int = _int_at_least(0, "a whole number >= 0")


def add_service_bench_parser(subparsers: SubParsers) -> argparse.ArgumentParser:
    p = subparsers.add_parser("service-bench", help="measure the KB service with a long history (not a test)",
                              description=__doc__.splitlines()[0] if __doc__ else None)
    p.add_argument("--parts", default="objects,history,contention,refusal",
                   help="comma-separated: objects, history, side-by-side, contention, refusal, knowledge, scale-out, "
                   "observability "
                   "(side-by-side: the first and last --checkpoints on two services at once, measured in alternating "
                   "rounds; knowledge: after the last --checkpoints perceptions; scale-out: needs --db)")
    p.add_argument("--objects", type=_int_list, default=[1, 200, 1000], help="stored-object counts (1,200,1000)")
    p.add_argument("--checkpoints", type=_int_list, default=[100, 1000, 10000],
                   help="perception counts on one object at which to measure (100,1000,10000)")
    p.add_argument("--samples", type=_positive_int, default=30, help="re-planning perceptions per measurement")
    p.add_argument("--links", type=_positive_int, default=8)
    p.add_argument("--orientations", type=_positive_int, default=12)
    p.add_argument("--formulation", choices=["relative", "absolute", "bimanual"], default="relative",
                   help="the history parts' object (bimanual: the robot executes the next action before each "
                   "re-planning perception, the server's CPU per perception counting its calls)")
    p.add_argument("--big-links", type=_positive_int, default=200, help="links of the large object (contention)")
    p.add_argument("--big-orientations", type=_positive_int, default=12)
    p.add_argument("--planning-workers", type=_non_negative_int, default=None,
                   help="the service's planning pool size for the contention part (default: the service's; 0: "
                   "plan everything in the service's process, to compare)")
    p.add_argument("--db", default=None, help="scale-out: a PostgreSQL database the bench may fill and empty "
                   "(postgresql://user@host:port/database)")
    p.add_argument("--scale-replicas", type=_int_list, default=[1, 2, 4], help="scale-out: replica counts (1,2,4)")
    p.add_argument("--scale-objects", type=_int_list, default=[10, 100], help="scale-out: object counts (10,100)")
    p.add_argument("--scale-size", type=_int_list, default=[20, 12], help="scale-out: links,orientations (20,12)")
    p.add_argument("--scale-clients", type=_positive_int, default=8, help="scale-out: closed-loop clients (8)")
    p.add_argument("--scale-seconds", type=float, default=20.0, help="scale-out: seconds per configuration (20)")
    p.add_argument("--without-val", action="store_true",
                   help="history: the service with VAL off, no plan checked (what a re-plan costs without its "
                   "check, beside a run with it; not a product's figure)")
    p.add_argument("--read-timeout", type=float, default=120.0, help="seconds before a read counts as a timeout")
    p.add_argument("--seed", type=int, default=7)
    p.add_argument("--out", type=Path, default=None, help="also write service-bench.json and .md here")
    p.set_defaults(func=run_service_bench)
    return p


def run_service_bench(args: argparse.Namespace) -> int:
    parts = {p.strip() for p in args.parts.split(",") if p.strip()}
    unknown = parts - {"objects", "history", "side-by-side", "contention", "refusal", "knowledge", "scale-out",
                       "observability"}
    if unknown:
        print(f"planhrc service-bench: --parts: unknown part(s) {', '.join(sorted(unknown))}", file=sys.stderr)
        return 2
    if len(args.scale_size) != 2:
        print("planhrc service-bench: --scale-size: expected links,orientations (two numbers)", file=sys.stderr)
        return 2
    report: dict[str, Any] = {"machine": {"cpu": cpu_model(), "cores": os.cpu_count(),
                                          "python": platform.python_version(),
                                          "load_at_start": round(os.getloadavg()[0], 2)}}
    try:
        if "refusal" in parts:
            report["refusal"] = bench_refusal()
        if "objects" in parts:
            report["objects"] = bench_objects(args.objects, args.samples, args.links, args.orientations, args.seed)
        if "history" in parts:
            report["history"] = bench_history(args.checkpoints, args.samples, args.links, args.orientations,
                                              args.formulation, args.read_timeout, args.seed, not args.without_val)
        if "side-by-side" in parts:
            checkpoints = sorted(args.checkpoints)
            report["side_by_side"] = bench_history_side_by_side(
                checkpoints[0], checkpoints[-1], args.samples, args.links, args.orientations, args.formulation,
                args.seed)
        if "contention" in parts:
            report["contention"] = bench_contention(args.big_links, args.big_orientations, args.samples, args.seed,
                                                    args.planning_workers)
        if "knowledge" in parts:
            report["knowledge"] = bench_knowledge(max(args.checkpoints), args.samples, args.links, args.orientations,
                                                  args.seed)
        if "scale-out" in parts:
            report["scale_out"] = bench_scale_out(
                args.db, args.scale_replicas, args.scale_objects, args.scale_clients, args.scale_seconds,
                args.scale_size[0], args.scale_size[-1], args.seed,
                log=lambda line: print(f"[service-bench] {line}", file=sys.stderr, flush=True))
        if "observability" in parts:
            report["observability"] = bench_observability(args.samples, args.links, args.orientations, args.seed)
    except (RuntimeError, httpx.HTTPError, BenchError) as exc:
        print(f"planhrc service-bench: {exc}", file=sys.stderr)
        return 1
    report["machine"]["load_at_end"] = round(os.getloadavg()[0], 2)
    text = json.dumps(report, indent=2)
    print(text)
    if args.out:
        args.out.mkdir(parents=True, exist_ok=True)
        (args.out / "service-bench.json").write_text(text + "\n")
        (args.out / "service-bench.md").write_text(markdown(report))
    return 0


def markdown(report: dict[str, Any]) -> str:
    m = report["machine"]
    lines = [f"Machine: {m['cpu']}, {m['cores']} cores, Python {m['python']}; load average "
             f"{m.get('load_at_start', '?')} at the start, {m.get('load_at_end', '?')} at the end. *Server CPU* is "
             "the service process's CPU time per perception posted (user + system), which the machine's load does "
             "not inflate.", ""]
    if "objects" in report:
        lines += ["| objects stored | re-planning perception p50 | p95 | server CPU | server RSS |",
                  "|---|---|---|---|---|"]
        lines += [f"| {r['objects']} | {r['p50_ms']} ms | {r['p95_ms']} ms | {r.get('server_cpu_ms', '?')} ms "
                  f"| {r['rss_mb']} MB |" for r in report["objects"]]
        lines.append("")
    if "history" in report:
        if not all(r.get("validated", True) for r in report["history"]):
            lines += ["**VAL off** (`--without-val`): no plan of these re-plans was checked; what a re-plan costs "
                      "without its check, not a product's figure.", ""]
        lines += ["Reads: p95 of 20 requests each (`ontology`, the current ABox as RDF/XML: the worst of 3).", "",
                  "| perceptions on one object | re-plan p50 | p95 | server CPU | " + " | ".join(READ_ROUTES)
                  + " | /health worst wait | RSS |", "|---" * (6 + len(READ_ROUTES)) + "|"]
        for r in report["history"]:
            reads = " | ".join(f"{r['reads'][n].get('p95_ms', r['reads'][n]['max_ms'])} ms" if n != "ontology"
                               else f"{r['reads'][n]['max_ms']} ms" for n in READ_ROUTES)
            lines.append(f"| {r['perceptions']} | {r['replan']['p50_ms']} ms | {r['replan']['p95_ms']} ms "
                         f"| {r['replan'].get('server_cpu_ms', '?')} ms | {reads} "
                         f"| {r['health_worst_ms_during_slowest_read']} ms | {r['rss_mb']} MB |")
        lines.append("")
    if "side_by_side" in report:
        sbs = report["side_by_side"]
        lines += [f"Side by side: two services at once, re-planning perceptions in alternating rounds of "
                  f"{sbs['round_size']}, so the machine's load falls on both alike.", "",
                  "| perceptions on the object | re-planning perception p50 | p95 | server CPU | server RSS |",
                  "|---|---|---|---|---|"]
        lines += [f"| {r['perceptions']} | {r['p50_ms']} ms | {r['p95_ms']} ms | {r['server_cpu_ms']} ms "
                  f"| {r['rss_mb']} MB |" for r in sbs["rows"]]
        lines.append("")
    if "knowledge" in report:
        lines += knowledge_markdown(report["knowledge"])
    if "scale_out" in report:
        lines += scale_out_markdown(report["scale_out"])
    if "observability" in report:
        lines += observability_markdown(report["observability"])
    lines += [f"* {line}" for line in targets(report)] + [""]
    if "contention" in report:
        c = report["contention"]
        lines.append(f"Contention: while a {c['big_object']} object planned ({c['big_perception_s']} s, answered "
                     f"{c.get('big_status')}: {c.get('big_answer')}), another "
                     f"object's perceptions took p50 {c['small_while_big_plans']['p50_ms']} ms, worst "
                     f"{c['small_while_big_plans']['max_ms']} ms (alone: p50 {c['small_quiet']['p50_ms']} ms); "
                     + (f"/health meanwhile p50 {c['health_while_big_plans']['p50_ms']} ms, worst "
                        f"{c['health_while_big_plans']['max_ms']} ms; " if c.get("health_while_big_plans") else "")
                     + f"planning workers: {c.get('planning_workers', 'default')}.")
        lines.append("")
    if "refusal" in report:
        r = report["refusal"]
        lines.append(f"Refusing a 150 MB body: without the token {r['no_token']['ms']} ms "
                     f"({r['no_token']['status']}), over the limit with it {r['token_over_limit']['ms']} ms "
                     f"({r['token_over_limit']['status']}).")
    return "\n".join(lines) + "\n"


def targets(report: dict[str, Any]) -> list[str]:
    """The growth targets, each with its measured value: p95 of a re-planning perception from the fewest to the
    most objects (< 20 % growth), RSS after the most perceptions against the fewest (<= 1.5x), every read's p95
    (< 50 ms) and the current-ABox export (< 1 s) at the last checkpoint, /health's worst wait (< 50 ms)."""
    out = []
    if report.get("objects"):
        first, last = report["objects"][0], report["objects"][-1]
        out.append(f"re-planning p95, {first['objects']} -> {last['objects']} objects: {first['p95_ms']} -> "
                   f"{last['p95_ms']} ms ({last['p95_ms'] / first['p95_ms'] - 1:+.0%}; target < +20 %); server CPU "
                   f"per perception {_growth(first.get('server_cpu_ms'), last.get('server_cpu_ms'))}")
    if report.get("history"):
        first, last = report["history"][0], report["history"][-1]
        a, b = first["replan"], last["replan"]
        out.append(f"re-planning p95, {first['perceptions']} -> {last['perceptions']} perceptions: {a['p95_ms']} -> "
                   f"{b['p95_ms']} ms ({b['p95_ms'] / a['p95_ms'] - 1:+.0%}; target < +20 %); server CPU per "
                   f"perception {_growth(a.get('server_cpu_ms'), b.get('server_cpu_ms'))}")
        out.append(f"RSS, {first['perceptions']} -> {last['perceptions']} perceptions: {first['rss_mb']} -> "
                   f"{last['rss_mb']} MB ({last['rss_mb'] / first['rss_mb']:.2f}x; target <= 1.5x)")
        reads = {n: v for n, v in last["reads"].items() if n != "ontology"}
        worst = max(reads, key=lambda n: reads[n].get("p95_ms", reads[n]["max_ms"]))
        out.append(f"after {last['perceptions']} perceptions: slowest read {worst} p95 "
                   f"{reads[worst].get('p95_ms', reads[worst]['max_ms'])} ms (target < 50 ms); current-ABox "
                   f"export {last['reads']['ontology']['max_ms']} ms (target < 1 s); /health's worst wait during "
                   f"the slowest read {last['health_worst_ms_during_slowest_read']} ms (target < 50 ms)")
    if report.get("side_by_side"):
        a, b = report["side_by_side"]["rows"]
        out.append(f"side by side, re-planning p95, {a['perceptions']} -> {b['perceptions']} perceptions: "
                   f"{a['p95_ms']} -> {b['p95_ms']} ms ({b['p95_ms'] / a['p95_ms'] - 1:+.0%}; target < +20 %); "
                   f"p50 {a['p50_ms']} -> {b['p50_ms']} ms; server CPU per perception "
                   f"{_growth(a['server_cpu_ms'], b['server_cpu_ms'])}")
    return out


def _growth(first: float | None, last: float | None) -> str:
    if not first or not last:
        return "not measured"
    return f"{first} -> {last} ms ({last / first - 1:+.0%})"

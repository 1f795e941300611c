"""`planhrc service-bench --parts observability`: what metrics and tracing cost the service, side by side.

Services at once on fresh SQLite stores, one object each (the history parts' object): two with metrics and tracing
off (`PLANHRC_METRICS=false`, no OTLP endpoint; the second a control of the bench's own noise), one with metrics
alone, and two with both on (every request traced, and one in ten), their spans sent over OTLP/HTTP to a collector
in this process that decodes nothing and answers at once, and their `/metrics` scraped every 15 s as Prometheus
usually does (the scrapes' cost counts; a scrape's own cost, which a site pays per scrape whatever its rate of
perceptions, is measured apart at the end). Re-planning perceptions go to each in alternating rounds, so whatever
else the machine runs falls on all alike; the figure is the server's CPU time (user + system of its process) per
perception posted, and its ratio to the service with both off: over the whole run, and the median of the rounds'
ratios (each round against the off service's round of the same turn: a burst of other work on the machine moves a
few rounds, not the median). A round is 50 perceptions: about 0.3 s of CPU, read in 10 ms ticks. Target: at most
3 % more.
"""
from __future__ import annotations

import random
import sys
import tempfile
import threading
from contextlib import ExitStack, contextmanager
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from typing import Any, Iterator

import httpx

from planhrc.stats import percentile

from .service_calls import (Side, client_of, cpu_seconds, create_object, random_angles, replanning_with_cpu,
                            rss_mb, running_service, set_goal, summary_ms)

SCRAPE_S = 15.0  # Prometheus' usual scrape interval; a scrape's own cost is measured apart (`scrape_cpu_ms`)
SCRAPES_TIMED = 20
TARGET_PCT = 3.0


@contextmanager
def span_sink() -> Iterator[tuple[str, list[int]]]:
    """An OTLP/HTTP endpoint on loopback that reads each export and answers 200; its URL and [exports, bytes]."""
    counts = [0, 0]

    class Sink(BaseHTTPRequestHandler):
        def do_POST(self) -> None:  # noqa: N802 (the handler's name)
            body = self.rfile.read(int(self.headers.get("Content-Length", 0)))
            counts[0] += 1
            counts[1] += len(body)
            self.send_response(200)
            self.send_header("Content-Length", "0")
            self.end_headers()

        def log_message(self, *args: Any) -> None:
            pass

    server = ThreadingHTTPServer(("127.0.0.1", 0), Sink)
    thread = threading.Thread(target=server.serve_forever, name="otlp-sink", daemon=True)
    thread.start()
    try:
        yield f"http://127.0.0.1:{server.server_address[1]}", counts
    finally:
        server.shutdown()
        server.server_close()


@contextmanager
def scraping(url: str, headers: dict[str, str]) -> Iterator[list[int]]:
    """`GET /metrics` every `SCRAPE_S` until the block ends; [scrapes] done."""
    done = [0]
    stop = threading.Event()

    def scrape() -> None:
        with httpx.Client(base_url=url, timeout=30, headers=headers) as http:
            while not stop.wait(SCRAPE_S):
                http.get("/metrics").raise_for_status()
                done[0] += 1

    thread = threading.Thread(target=scrape, name="scrape", daemon=True)
    thread.start()
    try:
        yield done
    finally:
        stop.set()
        thread.join(30)


SIDES = ("off", "off, again", "metrics only", "on", "on, 1 in 10 traced")


def bench_observability(samples: int, links: int, orientations: int, seed: int,
                        round_size: int = 50) -> dict[str, Any]:
    """Five services side by side: off, off again (a control: what the bench reads between two equal services is
    its noise), metrics alone, metrics and tracing on (every request traced), and on with one request in ten traced
    (`--trace-ratio 0.1`). They get the same goal and the same perceptions, in the same order (one random sequence
    each, from the same seed): the only difference between them is metrics and tracing."""
    with span_sink() as (sink, exported), ExitStack() as stack:
        environments = {"off": {"PLANHRC_METRICS": "false"}, "off, again": {"PLANHRC_METRICS": "false"},
                        "metrics only": {"PLANHRC_METRICS": "true"},
                        "on": {"PLANHRC_METRICS": "true", "PLANHRC_OTLP_ENDPOINT": sink},
                        "on, 1 in 10 traced": {"PLANHRC_METRICS": "true", "PLANHRC_OTLP_ENDPOINT": sink,
                                               "PLANHRC_TRACE_RATIO": "0.1"}}
        sides, rngs, scrapes = {}, {}, {}
        for name in SIDES:
            folder = Path(stack.enter_context(tempfile.TemporaryDirectory(prefix="planhrc-sbench-")))
            server = stack.enter_context(running_service(folder, environments[name]))
            client = stack.enter_context(client_of(server, 120))
            if environments[name]["PLANHRC_METRICS"] == "true":
                scrapes[name] = stack.enter_context(scraping(server.url, dict(client.headers)))
            rngs[name] = random.Random(seed)
            obj = create_object(client, links, orientations, "relative", "observed")
            set_goal(client, obj, random_angles(rngs[name], links, orientations))
            sides[name] = Side(server, client, obj, 0, [])
        rounds: dict[str, list[float]] = {name: [] for name in sides}  # CPU ms per perception, round by round
        while any(side.posted < samples for side in sides.values()):
            for name, side in sides.items():
                count = min(round_size, samples - side.posted)
                if count <= 0:
                    continue
                lat, cpu_ms = replanning_with_cpu(side.client, side.server, side.object_id, links, orientations,
                                                   count, rngs[name])
                side.latencies += lat
                side.cpu_s += cpu_ms * count / 1000
                side.posted += count
                rounds[name].append(cpu_ms)
        on = sides["on"]
        before = cpu_seconds(on.server.pid)
        for _ in range(SCRAPES_TIMED):
            on.client.get("/metrics").raise_for_status()
        scrape_cpu_ms = (cpu_seconds(on.server.pid) - before) / SCRAPES_TIMED * 1000
        cpu = {name: side.cpu_s / side.posted * 1000 for name, side in sides.items()}
        rows: list[dict[str, Any]] = [
            {"metrics_and_tracing": name, **summary_ms(side.latencies), "server_cpu_ms": round(cpu[name], 3),
             "rss_mb": round(rss_mb(side.server.pid), 1)} for name, side in sides.items()]
    for row in rows[1:]:
        name = row["metrics_and_tracing"]
        row["cpu_increase_pct"] = round((cpu[name] / cpu["off"] - 1) * 100, 2)
        # each round against the off service's round beside it: the machine's load in that moment falls on both
        paired = [on / off - 1 for on, off in zip(rounds[name], rounds["off"]) if off > 0]
        row["cpu_increase_pct_median_of_rounds"] = round(percentile(paired, 0.5) * 100, 2)
    report = {"round_size": round_size, "rows": rows, "scrapes": sum(s[0] for s in scrapes.values()),
              "scrape_cpu_ms": round(scrape_cpu_ms, 2),
              "span_exports": exported[0], "span_bytes": exported[1], "target_pct": TARGET_PCT}
    print(f"[service-bench] observability: {report}", file=sys.stderr, flush=True)
    return report


def observability_markdown(report: dict[str, Any]) -> list[str]:
    lines = [f"Metrics and tracing, off and on side by side (alternating rounds of {report['round_size']} "
             f"re-planning perceptions; on: /metrics scraped every {SCRAPE_S:g} s, {report['scrapes']} scrapes, "
             f"spans exported over OTLP/HTTP in {report['span_exports']} batches, {report['span_bytes']} bytes).", "",
             "| metrics and tracing | re-planning perception p50 | p95 | server CPU per perception | against off "
             "| against off, median of the rounds | server RSS |", "|---|---|---|---|---|---|---|"]
    lines += [f"| {r['metrics_and_tracing']} | {r['p50_ms']} ms | {r['p95_ms']} ms | {r['server_cpu_ms']} ms "
              f"| {'' if 'cpu_increase_pct' not in r else format(r['cpu_increase_pct'], '+.2f') + ' %'} "
              f"| {'' if 'cpu_increase_pct' not in r else format(r['cpu_increase_pct_median_of_rounds'], '+.2f') + ' %'} "
              f"| {r['rss_mb']} MB |" for r in report["rows"]]
    lines.append("")
    for row in report["rows"][1:]:
        if row["metrics_and_tracing"] == "off, again":
            lines.append(f"* the control, off against off: {row['cpu_increase_pct']:+.2f} % over the run, "
                         f"{row['cpu_increase_pct_median_of_rounds']:+.2f} % the median round: the bench's noise")
            continue
        verdict = "met" if row["cpu_increase_pct"] <= report["target_pct"] else "missed"
        lines.append(f"* server CPU per re-planning perception, {row['metrics_and_tracing']} against off: "
                     f"{row['cpu_increase_pct']:+.2f} % over the run, {row['cpu_increase_pct_median_of_rounds']:+.2f} % "
                     f"the median round (target at most +{report['target_pct']:g} %: {verdict} over the run)")
    lines.append(f"* one scrape of /metrics: {report['scrape_cpu_ms']} ms of the service's CPU (mean of "
                 f"{SCRAPES_TIMED}, after the run), whatever the rate of perceptions")
    return lines + [""]

"""`planhrc service-bench --parts observability`: what metrics and tracing cost the service, side by side.

Services at once on fresh SQLite stores, one object each (the history parts' object): two with metrics and tracing
off (`PLANHRC_METRICS=false`, no OTLP endpoint; the second a control of the bench's own noise), one with metrics
alone, and two with both on (every request traced, and one in ten), their spans sent over OTLP/HTTP to a collector
in this process that decodes nothing and answers at once, and their `/metrics` scraped every 15 s as Prometheus
usually does (the scrapes' cost counts; a scrape's own cost, which a site pays per scrape whatever its rate of
perceptions, is measured apart). Re-planning perceptions go to each in alternating rounds, so whatever else the
machine runs falls on all alike; the figure is the server's CPU time (user + system of its process: its request
threads, its span exporter's thread, everything) per perception posted, and its ratio to the service with both
off: over the whole run, and the median of the rounds' ratios (each round against the off service's round of the
same turn: a burst of other work on the machine moves a few rounds, not the median). A round is 50 perceptions:
about 0.3 s of CPU, read in 10 ms ticks. The run is cut into blocks, each with fresh services (two equal processes
differ by a few per cent; each figure is over as many processes as blocks). Target: at most 3 % more.

One more service, with tracing on, gives tracing's cost per request within one process, where two processes'
difference cannot blur it: its two objects' perceptions alternate, one's traced, the other's carrying a client's
`traceparent` that says "not sampled", which the service follows (no span recorded, none exported).
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

from .service_calls import (Side, client_of, cpu_seconds, create_object, random_angles, replanning_latencies,
                            replanning_with_cpu, rss_mb, running_service, set_goal, summary_ms)

SCRAPE_S = 15.0  # Prometheus' usual scrape interval; a scrape's own cost is measured apart (`scrape_cpu_ms`)
SCRAPES_TIMED = 20
WARM_UP = 20  # perceptions to each object before its measured ones
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
SINK = ""  # in ENVIRONMENTS: the bench's span collector
ENVIRONMENTS = {"off": {"PLANHRC_METRICS": "false"}, "off, again": {"PLANHRC_METRICS": "false"},
                "metrics only": {"PLANHRC_METRICS": "true"},
                "on": {"PLANHRC_METRICS": "true", "PLANHRC_OTLP_ENDPOINT": SINK},
                "on, 1 in 10 traced": {"PLANHRC_METRICS": "true", "PLANHRC_OTLP_ENDPOINT": SINK,
                                       "PLANHRC_TRACE_RATIO": "0.1"}}
# one more service, on, with two objects: one's perceptions traced, the other's carrying a client's trace context
# that says "not sampled" (which the service follows): tracing's cost per request, read within one process
PAIRED = ("traced", "not traced")
NOT_SAMPLED = {"traceparent": "00-5eb0a1f2c3d4e5f60718293a4b5c6d7e-0102030405060708-00"}


def bench_observability(samples: int, links: int, orientations: int, seed: int, round_size: int = 50,
                        blocks: int = 3) -> dict[str, Any]:
    """Five services side by side: off, off again (a control: what the bench reads between two equal services is
    its noise), metrics alone, metrics and tracing on (every request traced), and on with one request in ten traced
    (`--trace-ratio 0.1`). They get the same goal and the same perceptions, in the same order (one random sequence
    each, from the same seed): the only difference between them is metrics and tracing. Two equal services differ
    by a few per cent in CPU per perception whatever they run (their memory's layout, where the system placed
    them), so the run is cut into `blocks`, each with fresh services: each figure is over as many processes.

    Beside them, one more service with tracing on reads tracing's cost within one process: two objects in it, one
    whose perceptions it traces and one whose perceptions carry a client's trace context that is not sampled (the
    service follows it: no span is recorded or exported), in alternating rounds."""
    names = (*SIDES, *PAIRED)
    cpu_s = dict.fromkeys(names, 0.0)
    posted = dict.fromkeys(names, 0)
    latencies: dict[str, list[float]] = {name: [] for name in names}
    rounds: dict[str, list[float]] = {name: [] for name in names}  # CPU ms per perception, round by round
    rss: dict[str, float] = {}
    scrape_cpu_ms, exported, scrapes = float("nan"), [0, 0], 0
    with span_sink() as (sink, exported):
        for block in range(blocks):
            share = samples * (block + 1) // blocks - samples * block // blocks  # this block's perceptions
            scrape_ms, scraped = _block(sink, share, links, orientations, seed + block, round_size, block == 0,
                                        cpu_s, posted, latencies, rounds, rss)
            scrapes += scraped
            if block == 0:
                scrape_cpu_ms = scrape_ms
    cpu = {name: cpu_s[name] / posted[name] * 1000 for name in names}
    rows: list[dict[str, Any]] = [
        {"metrics_and_tracing": name, **summary_ms(latencies[name]), "server_cpu_ms": round(cpu[name], 3),
         "rss_mb": round(rss[name], 1)} for name in SIDES]
    for row in rows[1:]:
        row.update(_against(row["metrics_and_tracing"], "off", cpu, rounds))
    paired = [{"requests": name, **summary_ms(latencies[name]), "server_cpu_ms": round(cpu[name], 3)}
              for name in PAIRED]
    paired[0].update(_against("traced", "not traced", cpu, rounds))
    report = {"round_size": round_size, "blocks": blocks, "rows": rows, "paired": paired, "scrapes": scrapes,
              "scrape_cpu_ms": round(scrape_cpu_ms, 2), "span_exports": exported[0], "span_bytes": exported[1],
              "target_pct": TARGET_PCT}
    print(f"[service-bench] observability: {report}", file=sys.stderr, flush=True)
    return report


def _against(name: str, base: str, cpu: dict[str, float], rounds: dict[str, list[float]]) -> dict[str, float]:
    """`name`'s CPU per perception against `base`'s: over the run, and the median of the rounds' ratios (each round
    against `base`'s round of the same turn: a burst of other work on the machine moves a few rounds, not the
    median)."""
    paired = [one / other - 1 for one, other in zip(rounds[name], rounds[base]) if other > 0]
    return {"cpu_increase_pct": round((cpu[name] / cpu[base] - 1) * 100, 2),
            "cpu_increase_pct_median_of_rounds": round(percentile(paired, 0.5) * 100, 2)}


def _block(sink: str, samples: int, links: int, orientations: int, seed: int, round_size: int, time_scrape: bool,
           cpu_s: dict[str, float], posted: dict[str, int], latencies: dict[str, list[float]],
           rounds: dict[str, list[float]], rss: dict[str, float]) -> tuple[float, int]:
    """One block: fresh services, `samples` perceptions to each side, added to the run's counts; a scrape's CPU
    (measured when `time_scrape`, else nan) and the scrapes done."""
    with ExitStack() as stack:
        sides: dict[str, Side] = {}
        rngs: dict[str, random.Random] = {}
        scrapes: dict[str, list[int]] = {}
        for name in (*SIDES, "paired"):
            environment = {k: v or sink for k, v in ENVIRONMENTS.get(name, ENVIRONMENTS["on"]).items()}
            folder = Path(stack.enter_context(tempfile.TemporaryDirectory(prefix="planhrc-sbench-")))
            server = stack.enter_context(running_service(folder, environment))
            client = stack.enter_context(client_of(server, 120))
            if environment["PLANHRC_METRICS"] == "true":
                scrapes[name] = stack.enter_context(scraping(server.url, dict(client.headers)))
            for label in ((name,) if name != "paired" else PAIRED):
                if label == "not traced":
                    client = stack.enter_context(client_of(server, 120))
                    client.headers.update(NOT_SAMPLED)
                rngs[label] = random.Random(seed)
                obj = create_object(client, links, orientations, "relative", "observed")
                set_goal(client, obj, random_angles(rngs[label], links, orientations))
                # not measured: a process's and an object's first perceptions (caches filled, code paths warm)
                replanning_latencies(client, obj, links, orientations, WARM_UP, random.Random(-seed))
                sides[label] = Side(server, client, obj, 0, [])
        turn = 0
        while any(side.posted < samples for side in sides.values()):
            order = list(sides.items())
            if turn % 2:  # the pair's two objects take turns going first
                order[-2], order[-1] = order[-1], order[-2]
            turn += 1
            for name, side in order:
                count = min(round_size, samples - side.posted)
                if count <= 0:
                    continue
                lat, cpu_ms = replanning_with_cpu(side.client, side.server, side.object_id, links, orientations,
                                                   count, rngs[name])
                side.posted += count
                latencies[name] += lat
                cpu_s[name] += cpu_ms * count / 1000
                posted[name] += count
                rounds[name].append(cpu_ms)
        for name, side in sides.items():
            rss[name] = rss_mb(side.server.pid)
        scrape_cpu_ms = float("nan")
        if time_scrape:
            on = sides["on"]
            before = cpu_seconds(on.server.pid)
            for _ in range(SCRAPES_TIMED):
                on.client.get("/metrics").raise_for_status()
            scrape_cpu_ms = (cpu_seconds(on.server.pid) - before) / SCRAPES_TIMED * 1000
    return scrape_cpu_ms, sum(s[0] for s in scrapes.values())


def observability_markdown(report: dict[str, Any]) -> list[str]:
    lines = [f"Metrics and tracing, off and on side by side (alternating rounds of {report['round_size']} "
             f"re-planning perceptions, in {report['blocks']} blocks of fresh services; on: /metrics scraped every "
             f"{SCRAPE_S:g} s, {report['scrapes']} scrapes, spans exported over OTLP/HTTP in "
             f"{report['span_exports']} batches, {report['span_bytes']} bytes).", "",
             "| metrics and tracing | re-planning perception p50 | p95 | server CPU per perception | against off "
             "| against off, median of the rounds | server RSS |", "|---|---|---|---|---|---|---|"]
    lines += [f"| {r['metrics_and_tracing']} | {r['p50_ms']} ms | {r['p95_ms']} ms | {r['server_cpu_ms']} ms "
              f"| {_pct(r, 'cpu_increase_pct')} | {_pct(r, 'cpu_increase_pct_median_of_rounds')} | {r['rss_mb']} MB |"
              for r in report["rows"]]
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
    traced, untraced = report["paired"]
    lines.append(f"* within one service with tracing on, a traced request against one not sampled (alternating "
                 f"rounds): {traced['server_cpu_ms']} ms against {untraced['server_cpu_ms']} ms of CPU per "
                 f"perception, {traced['cpu_increase_pct']:+.2f} % over the run, "
                 f"{traced['cpu_increase_pct_median_of_rounds']:+.2f} % the median round")
    lines.append(f"* one scrape of /metrics: {report['scrape_cpu_ms']} ms of the service's CPU (mean of "
                 f"{SCRAPES_TIMED}, after the first block), whatever the rate of perceptions")
    return lines + [""]


def _pct(row: dict[str, Any], key: str) -> str:
    return f"{row[key]:+.2f} %" if key in row else ""

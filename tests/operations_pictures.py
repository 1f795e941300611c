"""The pictures of docs/operations.md, made from a running site (not a test; run by hand):

    .venv/bin/python -m tests.operations_pictures docs

A throwaway PostgreSQL cluster, two replicas planning through its queue, a planning worker, Debian's Prometheus
scraping all three and the OTLP collector of tests/test_observability.py; perceptions at a robot's pace for
`--seconds`, sent to each replica in turn. Then:

* `operations-prometheus.png`: Prometheus' own graph page (headless Chromium, Debian's) for a query of the
  re-planning stages' 90th percentiles;
* `operations-trace.png`: the spans of one re-plan, drawn from what the collector received (matplotlib);
* `operations-trace.json`: those spans, as received.
"""
from __future__ import annotations

import argparse
import json
import random
import sys
import time
from contextlib import ExitStack
from pathlib import Path
from tempfile import TemporaryDirectory
from typing import Any
from urllib.parse import urlencode

import httpx

from tests.pg_cluster import Cluster
from tests.replica_tools import replicas
from tests.test_console import CHROMIUM, DESKTOP
from tests.test_observability import QUEUED, Collector, add_key, planning_worker, prometheus

QUERY = ('histogram_quantile(0.9, sum by (le, stage) (rate(planhrc_replan_stage_seconds_bucket'
         '{stage=~"plan|validate|store"}[30s])))')


def drive(clients: list[httpx.Client], seconds: float, seed: int = 7) -> None:
    """An absolute 12 x 8 object, its goal, and a perception every 0.3 s or so, each replica in turn; every few a
    person's hand undoes the plan (a re-plan)."""
    rng = random.Random(seed)
    first = clients[0]
    oid = first.post("/objects", json={"name": "rod", "links": 12, "orientations": 8,
                                       "formulation": "absolute"}).json()["id"]
    goal = [45.0 * rng.randrange(8) for _ in range(12)]
    first.put(f"/objects/{oid}/goal", json={"link_orientations_deg": goal}).raise_for_status()
    end, k = time.monotonic() + seconds, 0
    while time.monotonic() < end:
        links = [45.0 * rng.randrange(8) for _ in range(12)]
        clients[k % len(clients)].post(f"/objects/{oid}/perceptions",
                                       json={"link_orientations_deg": links}).raise_for_status()
        k += 1
        time.sleep(0.3)


def screenshot(prom: str, out: Path) -> None:
    from playwright.sync_api import sync_playwright

    url = f"{prom}/graph?" + urlencode({"g0.expr": QUERY, "g0.tab": "0", "g0.range_input": "2m",
                                        "g0.stacked": "0", "g0.show_exemplars": "0"})
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=str(CHROMIUM), headless=True)
        try:
            page = browser.new_page(viewport=DESKTOP)
            page.goto(url)
            page.wait_for_selector(".rickshaw_graph svg path", timeout=30000)
            time.sleep(2.0)  # the chart drawn
            page.screenshot(path=str(out), full_page=False)
        finally:
            browser.close()


def draw_trace(spans: list[dict[str, Any]], out: Path) -> None:
    """One bar per span, children under their parent, time from the root's start in milliseconds."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    by_parent: dict[str | None, list[dict[str, Any]]] = {}
    for s in spans:
        by_parent.setdefault(s["parent"], []).append(s)
    ordered: list[tuple[int, dict[str, Any]]] = []

    def walk(parent: str | None, depth: int) -> None:
        for s in sorted(by_parent.get(parent, []), key=lambda s: s["start"]):
            ordered.append((depth, s))
            walk(s["id"], depth + 1)

    walk(None, 0)
    t0 = ordered[0][1]["start"]
    colours = {"planhrc-service": "#3b6ea8", "planhrc-planning-worker": "#c0612b", "planhrc-planning-pool": "#7a9a3a"}
    fig, ax = plt.subplots(figsize=(10, 0.55 * len(ordered) + 1.2))
    for row, (depth, s) in enumerate(ordered):
        start, width = (s["start"] - t0) / 1e6, (s["end"] - s["start"]) / 1e6
        ax.barh(row, width, left=start, color=colours.get(s["service"], "#777"), height=0.6)
        ax.text(start, row - 0.38, f"{'  ' * depth}{s['name']}  ({s['service']}, {width:.1f} ms)", fontsize=8,
                va="bottom")
    ax.set_yticks([])
    ax.invert_yaxis()
    ax.set_xlabel("ms since the request arrived")
    ax.set_title(f"one re-plan: trace {ordered[0][1]['trace'][:16]}…")
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    plt.close(fig)


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    parser.add_argument("out", type=Path)
    parser.add_argument("--seconds", type=float, default=90.0)
    args = parser.parse_args(argv)
    cluster = Cluster()
    collector = Collector()
    try:
        with TemporaryDirectory() as tmp, ExitStack() as stack:
            folder = Path(tmp)
            db = str(cluster.database())
            reader = add_key(db, "prometheus", "reader")
            worker_port = __import__("planhrc.service_process", fromlist=["free_port"]).free_port()
            stack.enter_context(planning_worker(db, folder, "--metrics-port", str(worker_port), "--otlp-endpoint",
                                                collector.url))
            running = stack.enter_context(replicas(
                db, folder, count=2, args=("--planning-queue", "--protect-reads", "--otlp-endpoint", collector.url),
                env=QUEUED))
            prom = stack.enter_context(prometheus(folder, [s.url for s, _ in running], worker_port, reader))
            clients = [c for _, c in running]
            drive(clients, args.seconds)
            answer = clients[0].post("/objects/obj1/perceptions", json={"link_orientations_deg": [0.0] * 12},
                                     headers={"X-Request-ID": "the-pictured-replan"})
            answer.raise_for_status()
            time.sleep(3)  # the last scrapes and span batches
            root = next(s for s in collector.spans if s["name"] == "POST /objects/{object_id}/perceptions"
                        and s["attributes"].get("planhrc.request_id") is not None
                        and s["attributes"]["planhrc.request_id"].string_value == "the-pictured-replan")
            spans = collector.trace(root["trace"])
            draw_trace(spans, args.out / "operations-trace.png")
            (args.out / "operations-trace.json").write_text(json.dumps(
                [{k: v for k, v in s.items() if k != "attributes"} for s in spans], indent=1) + "\n")
            print(f"decision of the pictured perception: {answer.json()['decision']}; {len(spans)} spans")
            screenshot(prom, args.out / "operations-prometheus.png")
    finally:
        collector.close()
        cluster.close()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

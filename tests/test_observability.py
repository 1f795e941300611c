"""A site an operator can watch, with real parts: a PostgreSQL database, two `planhrc serve` replicas planning
through its queue, a `planhrc planning-worker`, Debian's Prometheus scraping all three, and an OTLP/HTTP collector
(a loopback HTTP server decoding OpenTelemetry's protobuf) receiving their spans.

* Prometheus scrapes both replicas (with a reader's key: reads are protected) and the worker; after perceptions
  sent to both replicas, its query API gives every series back: requests by replica, decisions, re-plan stages
  measured where they ran (the worker's planning, the service's VAL and store), VAL's verdicts and their CPU, the
  queue's depth, the worker's jobs.
* One perception is one trace, across processes: the route's server span, the use case, the planning span whose
  job crosses the PostgreSQL queue to the worker (its span a child of the service's), VAL and the store; each span's
  parent is in the same trace, the worker's span comes from the worker's process.
* `--log-format json`: each line one JSON object; the perception's lines carry its request id, object id and the
  trace's id.
"""
from __future__ import annotations

import json
import shutil
import subprocess
import sys
import threading
import time
from contextlib import contextmanager
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from typing import Any, Iterator

import httpx
import pytest

from planhrc.service_process import die_with_parent, free_port, stop_process_group
from tests.replica_tools import replicas
from tests.servers import TOKEN, serve_env, store_location

psycopg = pytest.importorskip("psycopg", reason="the planning queue is a PostgreSQL store's (psycopg 3)")
pytestmark = pytest.mark.integration

PROMETHEUS = Path("/usr/bin/prometheus")
QUEUED = {"PLANHRC_PLANNING_POOL_MIN_ATOMS": "1", "OTEL_BSP_SCHEDULE_DELAY": "100"}  # every task through the queue
GOAL = [0, 90, 180, 270]
PERCEPTIONS = ([0, 0, 0, 0], [0, 90, 0, 0], [0, 0, 0, 0], [0, 90, 0, 0])  # a person keeps undoing the plan


@pytest.fixture
def db(pg_cluster, tmp_path, request) -> str:
    return store_location("postgresql", tmp_path, request)


@contextmanager
def planning_worker(db: str, folder: Path, *args: str) -> Iterator[subprocess.Popen[bytes]]:
    log_path = folder / "worker.log"
    with open(log_path, "wb") as log:
        proc = subprocess.Popen([sys.executable, "-m", "planhrc.cli", "planning-worker", "--db", db, *args],
                                env=serve_env(QUEUED), stdout=log, stderr=subprocess.STDOUT, start_new_session=True,
                                preexec_fn=die_with_parent)
    try:
        yield proc
    finally:
        stop_process_group(proc)


def add_key(db: str, name: str, role: str) -> str:
    made = subprocess.run([sys.executable, "-m", "planhrc.cli", "keys", "add", name, "--role", role, "--db", db],
                          env=serve_env(), capture_output=True, text=True, timeout=120)
    assert made.returncode == 0, made.stderr
    return made.stdout.strip()


def drive(clients: list[httpx.Client]) -> list[str]:
    """An object, its goal, and perceptions sent to each replica in turn; their decisions."""
    first = clients[0]
    oid = first.post("/objects", json={"name": "rod", "links": 4, "orientations": 4,
                                       "formulation": "relative"}).json()["id"]
    assert first.put(f"/objects/{oid}/goal", json={"link_orientations_deg": GOAL}).status_code == 200
    decisions = []
    for k, links in enumerate(PERCEPTIONS):
        answer = clients[k % len(clients)].post(f"/objects/{oid}/perceptions", json={"link_orientations_deg": links})
        assert answer.status_code == 200, answer.text
        decisions.append(answer.json()["decision"])
    return decisions


# -- Prometheus -----------------------------------------------------------------------------------------------------
@contextmanager
def prometheus(folder: Path, replicas_urls: list[str], worker_port: int, key: str) -> Iterator[str]:
    """Debian's Prometheus scraping the replicas (with `key`) and the worker every second; its URL."""
    if not PROMETHEUS.exists():
        reason = f"{PROMETHEUS} is not installed (Debian: apt-get install prometheus; python3 ./run.py test does)"
        if __import__("os").environ.get("CI"):
            pytest.fail(reason)
        pytest.skip(reason)
    port = free_port()
    config = folder / "prometheus.yml"
    config.write_text(json.dumps({  # YAML is a superset of JSON
        "global": {"scrape_interval": "1s", "scrape_timeout": "900ms"},
        "scrape_configs": [
            {"job_name": "planhrc", "authorization": {"credentials": key},
             "static_configs": [{"targets": [u.removeprefix("http://") for u in replicas_urls]}]},
            {"job_name": "planhrc-planning-worker",
             "static_configs": [{"targets": [f"127.0.0.1:{worker_port}"]}]},
        ]}))
    data = folder / "prometheus-data"
    data.mkdir()
    log = open(folder / "prometheus.log", "wb")
    proc = subprocess.Popen([str(PROMETHEUS), f"--config.file={config}", f"--storage.tsdb.path={data}",
                             f"--web.listen-address=127.0.0.1:{port}"], stdout=log, stderr=subprocess.STDOUT,
                            start_new_session=True, preexec_fn=die_with_parent)
    url = f"http://127.0.0.1:{port}"
    try:
        deadline = time.monotonic() + 60
        while True:
            try:
                if httpx.get(f"{url}/-/ready", timeout=2).status_code == 200:
                    break
            except httpx.HTTPError:
                pass
            assert proc.poll() is None, (folder / "prometheus.log").read_text()[-3000:]
            assert time.monotonic() < deadline, "Prometheus did not get ready"
            time.sleep(0.2)
        yield url
    finally:
        stop_process_group(proc)
        log.close()
        shutil.rmtree(data, ignore_errors=True)


def query(url: str, promql: str) -> list[dict[str, Any]]:
    answer = httpx.get(f"{url}/api/v1/query", params={"query": promql}, timeout=10).json()
    assert answer["status"] == "success", answer
    result: list[dict[str, Any]] = answer["data"]["result"]
    return result


def value_of(url: str, promql: str) -> float | None:
    result = query(url, promql)
    return float(result[0]["value"][1]) if result else None


def until(check: Any, within_s: float = 60.0) -> Any:
    """`check()`'s first truthy answer, asked every half second (scrapes come each second)."""
    deadline = time.monotonic() + within_s
    while time.monotonic() < deadline:
        got = check()
        if got:
            return got
        time.sleep(0.5)
    return check()


def test_prometheus_scrapes_two_replicas_and_a_planning_worker(db, tmp_path):
    reader = add_key(db, "prometheus", "reader")
    worker_port = free_port()
    with planning_worker(db, tmp_path, "--metrics-port", str(worker_port)), \
            replicas(db, tmp_path, count=2, args=("--planning-queue", "--protect-reads"), env=QUEUED) as running:
        urls = [server.url for server, _ in running]
        assert httpx.get(f"{urls[0]}/metrics").status_code == 401  # a read: reads are protected
        with prometheus(tmp_path, urls, worker_port, reader) as prom:
            assert until(lambda: value_of(prom, 'count(up == 1)') == 3), query(prom, "up")
            decisions = drive([client for _, client in running])
            replans = decisions.count("replan")
            assert replans >= 2, decisions
            perceived = 'sum by (instance) (planhrc_http_requests_total{route="/objects/{object_id}/perceptions",' \
                        'status="200"})'
            by_replica = until(lambda: (r := query(prom, perceived)) and sum(float(x["value"][1]) for x in r) == 4
                               and r)
            assert sorted(x["metric"]["instance"] for x in by_replica) == sorted(u[7:] for u in urls)
            assert all(float(x["value"][1]) == 2 for x in by_replica)  # two perceptions each
            assert until(lambda: value_of(prom, 'sum(planhrc_decisions_total)') == len(decisions))
            assert value_of(prom, 'sum(planhrc_decisions_total{kind="replan"})') == replans
            for stage in ("plan", "validate", "store"):  # the worker's planning, the service's VAL and write
                count = value_of(prom, f'sum(planhrc_replan_stage_seconds_count{{stage="{stage}"}})')
                assert count == replans, (stage, count)
            assert value_of(prom, 'sum(planhrc_val_verdicts_total{verdict="accepted"})') == replans
            assert value_of(prom, 'sum(planhrc_val_cpu_seconds_count)') == replans  # VAL's CPU per verdict
            assert value_of(prom, 'sum(planhrc_val_cpu_seconds_sum)') > 0
            assert until(lambda: value_of(prom, 'sum(planhrc_planning_jobs_total{job="planhrc-planning-worker",'
                                                'status="solved"})') == replans)
            assert value_of(prom, 'max(planhrc_planning_queue_depth{state="queued"})') == 0
            assert value_of(prom, 'sum(planhrc_store_transaction_seconds_count)') >= 4
            # the 90th percentile of a re-plan's planning stage since the start (docs/operations.md takes a rate)
            p90 = value_of(prom, 'histogram_quantile(0.9, sum by (le) (planhrc_replan_stage_seconds_bucket'
                                 '{stage="plan"}))')
            assert p90 is not None and p90 > 0


# -- traces ---------------------------------------------------------------------------------------------------------
class Collector:
    """An OTLP/HTTP traces receiver on loopback: the spans it was sent, decoded from protobuf."""

    def __init__(self) -> None:
        from opentelemetry.proto.collector.trace.v1.trace_service_pb2 import ExportTraceServiceRequest

        spans: list[dict[str, Any]] = []
        lock = threading.Lock()

        class Handler(BaseHTTPRequestHandler):
            def do_POST(self) -> None:  # noqa: N802 (the handler's name)
                body = self.rfile.read(int(self.headers.get("Content-Length", 0)))
                request = ExportTraceServiceRequest.FromString(body)
                with lock:
                    for resource in request.resource_spans:
                        service = next(a.value.string_value for a in resource.resource.attributes
                                       if a.key == "service.name")
                        for scope in resource.scope_spans:
                            for s in scope.spans:
                                spans.append({"trace": s.trace_id.hex(), "id": s.span_id.hex(),
                                              "parent": s.parent_span_id.hex() or None, "name": s.name,
                                              "service": service, "start": s.start_time_unix_nano,
                                              "end": s.end_time_unix_nano,
                                              "attributes": {a.key: a.value for a in s.attributes}})
                self.send_response(200)
                self.send_header("Content-Type", "application/x-protobuf")
                self.send_header("Content-Length", "0")
                self.end_headers()

            def log_message(self, *args: Any) -> None:
                pass

        self.spans, self._lock = spans, lock
        self.server = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self.url = f"http://127.0.0.1:{self.server.server_address[1]}"
        threading.Thread(target=self.server.serve_forever, daemon=True).start()

    def trace(self, trace_id: str) -> list[dict[str, Any]]:
        with self._lock:
            return [s for s in self.spans if s["trace"] == trace_id]

    def close(self) -> None:
        self.server.shutdown()
        self.server.server_close()


def test_one_perception_is_one_trace_across_the_service_the_queue_and_the_worker(db, tmp_path):
    pytest.importorskip("opentelemetry.sdk", reason="tracing needs the `tracing` extra")
    collector = Collector()
    try:
        with planning_worker(db, tmp_path, "--otlp-endpoint", collector.url), \
                replicas(db, tmp_path, count=1, args=("--planning-queue", "--otlp-endpoint", collector.url,
                                                      "--log-format", "json", "--log-level", "info"),
                         env=QUEUED) as [(server, client)]:
            oid = client.post("/objects", json={"name": "rod", "links": 4, "orientations": 4,
                                                "formulation": "relative"}).json()["id"]
            assert client.put(f"/objects/{oid}/goal", json={"link_orientations_deg": GOAL}).status_code == 200
            answer = client.post(f"/objects/{oid}/perceptions", json={"link_orientations_deg": PERCEPTIONS[0]},
                                 headers={"X-Request-ID": "perception-1"})
            assert answer.status_code == 200 and answer.json()["decision"] == "replan", answer.text
            assert answer.headers["x-request-id"] == "perception-1"
            wanted = {"POST /objects/{object_id}/perceptions", "perceive", "plan", "planning_job", "val", "store"}

            def whole() -> list[dict[str, Any]] | None:
                roots = [s for s in collector.spans if s["name"] == "POST /objects/{object_id}/perceptions"]
                if not roots:
                    return None
                spans = collector.trace(roots[0]["trace"])
                return spans if wanted <= {s["name"] for s in spans} else None

            spans = until(whole, 30)
            assert spans, sorted({(s["name"], s["service"]) for s in collector.spans})
            log_text = (tmp_path / f"serve-{server.url.rsplit(':', 1)[1]}.log").read_text()
    finally:
        collector.close()
    by_name = {s["name"]: s for s in spans}
    by_id = {s["id"]: s for s in spans}
    root = by_name["POST /objects/{object_id}/perceptions"]
    assert root["parent"] is None and root["service"] == "planhrc-service"
    assert all(s["parent"] in by_id for s in spans if s is not root), "a span whose parent is not in the trace"

    def parent(name: str) -> str:
        return by_id[by_name[name]["parent"]]["name"]

    assert parent("perceive") == root["name"]
    assert parent("plan") == "perceive" and parent("val") == "perceive"
    assert parent("store") == "val"  # the write reads VAL's verdict in its transaction
    job = by_name["planning_job"]
    assert parent("planning_job") == "plan" and job["service"] == "planhrc-planning-worker"  # across the queue
    assert by_name["plan"]["start"] <= job["start"] and job["end"] <= by_name["plan"]["end"]
    # the log lines of the perception carry its request id, its object and its trace
    lines = [json.loads(line) for line in log_text.splitlines() if line.startswith("{")]
    assert lines and all({"time", "level", "logger", "message"} <= set(line) for line in lines)
    mine = [line for line in lines if line.get("request_id") == "perception-1"]
    assert mine and all(line["object_id"] == oid and line["trace_id"] == root["trace"] for line in mine), mine

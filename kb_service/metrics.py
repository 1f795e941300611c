"""What the service measures, in Prometheus' text format at `/metrics` (`prometheus_client`), every name under
`planhrc_`.

Each service process keeps its own registry (`ServiceMetrics`, made with the app; nothing at import time), and each
replica serves its own numbers: Prometheus scrapes every replica and adds them up (`sum by (...)` over the
`instance` label it gives each target). Work done in other processes is counted where its result arrives: a large
task planned by the service's planning pool or by a `planhrc planning-worker` comes back with its stage times
(`PlanOutcome.timings`), which the service observes when it answers. A `planhrc planning-worker` also serves its own
`/metrics` (`WorkerMetrics`: the jobs it planned, the leases it took over).

| name | kind | labels | what |
|---|---|---|---|
| `planhrc_http_requests_total` | counter | route, method, status | requests answered (a refusal too) |
| `planhrc_http_request_seconds` | histogram | route, method | time to the response's start |
| `planhrc_decisions_total` | counter | kind | perceptions decided, by decision |
| `planhrc_replan_stage_seconds` | histogram | stage | a re-plan's stages: translate, plan, order, expected_states, pipeline, validate, store |
| `planhrc_val_verdicts_total` | counter | verdict | VAL's verdicts on new plans and on later pieces |
| `planhrc_val_seconds` | histogram | | VAL's time per verdict |
| `planhrc_store_transaction_seconds` | histogram | | a perception's one write (the unit of work) |
| `planhrc_event_streams_open` | gauge | | Server-Sent Events streams open now |
| `planhrc_planning_queue_depth` | gauge | state | the database's planning jobs, queued or running (the same on every replica: take `max`) |
| `planhrc_planning_jobs_total` | counter | status | jobs a planning worker finished (worker) |
| `planhrc_planning_leases_taken_over_total` | counter | | jobs a worker took from a worker whose lease expired (worker) |
| `planhrc_planning_job_seconds` | histogram | stage | a worker's pipeline stages (worker) |
"""
from __future__ import annotations

import logging
from typing import Any, Callable, Iterable, Mapping

from prometheus_client import CollectorRegistry, Counter, Gauge, Histogram, Info
from prometheus_client.core import GaugeMetricFamily
from prometheus_client.exposition import generate_latest
from prometheus_client.registry import Collector

import planhrc

log = logging.getLogger(__name__)

CONTENT_TYPE = "text/plain; version=0.0.4; charset=utf-8"
# from a millisecond (a /health) to a minute (a large re-plan at its deadline)
SECONDS = (0.001, 0.0025, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5, 5.0, 10.0, 30.0, 60.0)
STAGES = ("translate", "plan", "order", "expected_states", "pipeline", "validate")


class ServiceMetrics:
    """The service process's measurements (one per app)."""

    def __init__(self) -> None:
        self.registry = r = CollectorRegistry()
        Info("planhrc_build", "The planhrc version serving.", registry=r).info({"version": planhrc.__version__})
        self.requests = Counter("planhrc_http_requests", "HTTP requests answered, refusals included.",
                                ("route", "method", "status"), registry=r)
        self.request_seconds = Histogram("planhrc_http_request_seconds", "Time from a request's arrival to the "
                                         "start of its response.", ("route", "method"), buckets=SECONDS, registry=r)
        self.decisions = Counter("planhrc_decisions", "Perceptions decided, by the decision taken.", ("kind",),
                                 registry=r)
        self.stage_seconds = Histogram("planhrc_replan_stage_seconds", "A re-planning perception's stages, wherever "
                                       "they ran (this process, its planning pool or a planning worker).",
                                       ("stage",), buckets=SECONDS, registry=r)
        self.val_verdicts = Counter("planhrc_val_verdicts", "VAL's verdicts on plans and pieces of plans.",
                                    ("verdict",), registry=r)
        self.val_seconds = Histogram("planhrc_val_seconds", "VAL's time per verdict.", buckets=SECONDS, registry=r)
        self.store_seconds = Histogram("planhrc_store_transaction_seconds", "A perception's one write to the store "
                                       "(the unit of work).", buckets=SECONDS, registry=r)
        self.event_streams = Gauge("planhrc_event_streams_open", "Server-Sent Events streams open now.", registry=r)
        self._queue = _QueueDepth()
        r.register(self._queue)
        # each label's series, found once (a label lookup cost more than the update): a request's figures then cost
        # their updates only
        self._answers: dict[tuple[str, str, int], tuple[Any, Any]] = {}
        self._stages: dict[str, Any] = {}
        self._kinds: dict[str, Any] = {}
        self._verdicts: dict[bool, Any] = {}

    def answered(self, route: str, method: str, status: int, seconds: float) -> None:
        """A request answered: its count and its time."""
        key = (route, method, status)
        series = self._answers.get(key)
        if series is None:
            series = self._answers.setdefault(key, (self.requests.labels(route, method, str(status)),
                                                    self.request_seconds.labels(route, method)))
        series[0].inc()
        series[1].observe(seconds)

    # -- what the use cases and routes report (`usecases.Observer`) ---------------------------------------------
    def decided(self, kind: str, timings: Mapping[str, float] | None) -> None:
        counter = self._kinds.get(kind)
        if counter is None:
            counter = self._kinds.setdefault(kind, self.decisions.labels(kind))
        counter.inc()
        if timings:
            for stage, seconds in timings.items():
                if stage in STAGES:
                    self._stage(stage).observe(seconds)
            if "validate" in timings:
                self.val_seconds.observe(timings["validate"])

    def validated(self, accepted: bool, seconds: float) -> None:
        counter = self._verdicts.get(accepted)
        if counter is None:
            counter = self._verdicts.setdefault(accepted, self.val_verdicts.labels("accepted" if accepted else
                                                                                   "refused"))
        counter.inc()

    def stored(self, seconds: float, replanned: bool) -> None:
        self.store_seconds.observe(seconds)
        if replanned:
            self._stage("store").observe(seconds)

    def _stage(self, stage: str) -> Any:
        series = self._stages.get(stage)
        if series is None:
            series = self._stages.setdefault(stage, self.stage_seconds.labels(stage))
        return series

    def watch_queue(self, depth: Callable[[], Mapping[str, int]] | None) -> None:
        """Report the planning queue's depth (read from the database at each scrape; None: no queue)."""
        self._queue.depth = depth

    def text(self) -> bytes:
        return generate_latest(self.registry)


class _QueueDepth(Collector):
    def __init__(self) -> None:
        self.depth: Callable[[], Mapping[str, int]] | None = None

    def collect(self) -> Iterable[Any]:
        depth = self.depth
        if depth is None:
            return
        family = GaugeMetricFamily("planhrc_planning_queue_depth", "Planning jobs in the database's queue, by "
                                   "state (the same on every replica).", labels=("state",))
        try:
            counts = depth()
        except Exception as exc:  # a scrape must not fail for a database that is away: the series is missing
            log.warning("planning queue depth: %s", exc)
            return
        for state in ("queued", "running"):
            family.add_metric((state,), counts.get(state, 0))
        yield family


class WorkerMetrics:
    """A `planhrc planning-worker`'s measurements, served on its own port (`serve`)."""

    def __init__(self) -> None:
        self.registry = r = CollectorRegistry()
        Info("planhrc_build", "The planhrc version serving.", registry=r).info({"version": planhrc.__version__})
        self.jobs = Counter("planhrc_planning_jobs", "Planning jobs this worker finished, by outcome.", ("status",),
                            registry=r)
        self.taken_over = Counter("planhrc_planning_leases_taken_over", "Jobs this worker took from a worker whose "
                                  "lease had expired.", registry=r)
        self.stage_seconds = Histogram("planhrc_planning_job_seconds", "This worker's pipeline stages per job.",
                                       ("stage",), buckets=SECONDS, registry=r)

    def finished(self, status: str, timings: Mapping[str, float]) -> None:
        self.jobs.labels(status).inc()
        for stage, seconds in timings.items():
            if stage in STAGES:
                self.stage_seconds.labels(stage).observe(seconds)

    def serve(self, host: str, port: int) -> Any:
        """Serve `/metrics` on (host, port) from a thread of this process; the server, to `shutdown()`."""
        from prometheus_client import start_http_server

        server, _thread = start_http_server(port, host, registry=self.registry)
        return server

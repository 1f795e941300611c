"""What the service measures, in Prometheus' text format at `/metrics` (`prometheus_client`), every name under
`planhrc_`.

Each service process keeps its own registry (`ServiceMetrics`, made with the app; nothing at import time), and each
replica serves its own numbers: Prometheus scrapes every replica and adds them up (`sum by (...)` over the
`instance` label it gives each target). Work done in other processes is counted where its result arrives: a large
task planned by the service's planning pool or by a `planhrc planning-worker` comes back with its stage times
(`PlanOutcome.timings`), which the service observes when it answers. A `planhrc planning-worker` also serves its own
`/metrics` (`WorkerMetrics`: the jobs it planned, the leases it took over).

The series, each with one line on what it measures, are in docs/operations.md ("Metrics").
"""
from __future__ import annotations

import logging
from typing import Any, Callable, Iterable, Mapping

import threading
from bisect import bisect_left

from prometheus_client import CollectorRegistry, Counter, Gauge, Histogram, Info
from prometheus_client.core import GaugeMetricFamily, HistogramMetricFamily
from prometheus_client.exposition import generate_latest
from prometheus_client.registry import Collector
from prometheus_client.utils import floatToGoString

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
        self.request_seconds = Histograms("planhrc_http_request_seconds", "Time from a request's arrival to the "
                                          "start of its response.", ("route", "method"))
        self.decisions = Counter("planhrc_decisions", "Perceptions decided, by the decision taken.", ("kind",),
                                 registry=r)
        self.stage_seconds = Histograms("planhrc_replan_stage_seconds", "A re-planning perception's stages, "
                                        "wherever they ran (this process, its planning pool or a planning worker).",
                                        ("stage",))
        self.val_verdicts = Counter("planhrc_val_verdicts", "VAL's verdicts on plans and pieces of plans.",
                                    ("verdict",), registry=r)
        self.val_seconds = Histograms("planhrc_val_seconds", "VAL's time per verdict.", ())
        self.val_cpu_seconds = Histograms("planhrc_val_cpu_seconds", "The CPU (user + system) of VAL's runs per "
                                          "verdict, wherever they ran (this process's VAL, its planning pool's or a "
                                          "planning worker's).", ())
        self.store_seconds = Histograms("planhrc_store_transaction_seconds", "A perception's one write to the store "
                                        "(the unit of work).", ())
        self.event_streams = Gauge("planhrc_event_streams_open", "Server-Sent Events streams open now.", registry=r)
        self._queue = _QueueDepth()
        r.register(self._queue)
        # each label's series, found once (a label lookup cost more than the update): a request's figures then cost
        # their updates only
        self._answers: dict[tuple[str, str, int], Any] = {}
        self._kinds: dict[str, Any] = {}
        self._verdicts: dict[bool, Any] = {}

    def answered(self, route: str, method: str, status: int, seconds: float) -> None:
        """A request answered: its count and its time."""
        key = (route, method, status)
        counter = self._answers.get(key)
        if counter is None:
            counter = self._answers.setdefault(key, self.requests.labels(route, method, str(status)))
        counter.inc()
        self.request_seconds.observe((route, method), seconds)

    # -- what the use cases and routes report (`usecases.Observer`) ---------------------------------------------
    def decided(self, kind: str, timings: Mapping[str, float] | None) -> None:
        counter = self._kinds.get(kind)
        if counter is None:
            counter = self._kinds.setdefault(kind, self.decisions.labels(kind))
        counter.inc()
        if timings:
            self.stage_seconds.observe_all([((stage,), seconds) for stage, seconds in timings.items()
                                            if stage in STAGES])

    def validated(self, accepted: bool, seconds: float, cpu_s: float | None) -> None:
        """A verdict of VAL (on a new plan or a later piece): counted, its time and, when known, its CPU."""
        counter = self._verdicts.get(accepted)
        if counter is None:
            counter = self._verdicts.setdefault(accepted, self.val_verdicts.labels("accepted" if accepted else
                                                                                   "refused"))
        counter.inc()
        self.val_seconds.observe((), seconds)
        if cpu_s is not None:
            self.val_cpu_seconds.observe((), cpu_s)

    def stored(self, seconds: float, replanned: bool) -> None:
        self.store_seconds.observe((), seconds)
        if replanned:
            self.stage_seconds.observe(("store",), seconds)

    def watch_queue(self, depth: Callable[[], Mapping[str, int]] | None) -> None:
        """Report the planning queue's depth (read from the database at each scrape; None: no queue)."""
        self._queue.depth = depth

    def text(self) -> bytes:
        """`/metrics`: the library's metrics as it writes them, then the histograms (written by themselves: most of
        the lines, at a fraction of the library's cost per line)."""
        histograms = (self.request_seconds, self.stage_seconds, self.val_seconds, self.val_cpu_seconds,
                      self.store_seconds)
        return generate_latest(self.registry) + "".join(h.text() for h in histograms).encode()


class Histograms(Collector):
    """Histograms of one name, one per label values, in `SECONDS`' buckets: what `prometheus_client.Histogram`
    exposes (less its `_created` series), at a fraction of its cost, per observation (one lock and a binary search
    for however many values, where the library's takes two locks and a walk through the buckets for each, and a
    lookup for each label values) and per scrape (`text`: each series' label text written once, where the library
    checks and escapes every label of every line at every scrape). A re-plan makes about ten observations, a scrape
    writes about 250 of their lines (see docs/operations.md, "What it costs"). Registered in `registry` when given
    (the library's exposition then writes them too: tests/test_metrics.py compares the two)."""

    def __init__(self, name: str, documentation: str, labels: tuple[str, ...],
                 registry: CollectorRegistry | None = None) -> None:
        self._name, self._documentation, self._labels = name, documentation, labels
        self._les = [*(_go(bound) for bound in SECONDS), "+Inf"]
        self._lock = threading.Lock()
        self._series: dict[tuple[str, ...], list[float]] = {}  # label values -> a count per bucket, then the sum
        self._heads: dict[tuple[str, ...], tuple[list[str], str, str]] = {}  # their lines' heads, made once
        if registry is not None:
            registry.register(self)

    def observe(self, labels: tuple[str, ...], seconds: float) -> None:
        self.observe_all([(labels, seconds)])

    def observe_all(self, observations: Iterable[tuple[tuple[str, ...], float]]) -> None:
        with self._lock:
            for labels, seconds in observations:
                series = self._series.get(labels)
                if series is None:
                    series = self._series[labels] = [0.0] * (len(SECONDS) + 2)
                series[bisect_left(SECONDS, seconds)] += 1  # the first bucket whose bound is >= seconds
                series[-1] += seconds

    def _snapshot(self) -> dict[tuple[str, ...], list[float]]:
        with self._lock:
            return {labels: list(values) for labels, values in self._series.items()}

    def collect(self) -> Iterable[Any]:
        family = HistogramMetricFamily(self._name, self._documentation, labels=self._labels)
        for labels, values in self._snapshot().items():
            total, buckets = 0.0, []
            for le, count in zip(self._les, values):
                total += count
                buckets.append((le, total))
            family.add_metric(labels, buckets, values[-1])
        yield family

    def text(self) -> str:
        """This family in Prometheus' text format, as `generate_latest` writes it (labels sorted by name, `le`
        among them)."""
        name = self._name
        documentation = self._documentation.replace("\\", r"\\").replace("\n", r"\n")
        out = [f"# HELP {name} {documentation}\n# TYPE {name} histogram\n"]
        for labels, values in self._snapshot().items():
            heads = self._heads.get(labels)
            if heads is None:
                heads = self._heads[labels] = self._line_heads(labels)
            buckets, count, total = heads
            cumulative = 0.0
            for head, value in zip(buckets, values):
                cumulative += value
                out.append(f"{head}{_go(cumulative)}\n")
            out.append(f"{count}{_go(cumulative)}\n{total}{_go(values[-1])}\n")
        return "".join(out)

    def _line_heads(self, values: tuple[str, ...]) -> tuple[list[str], str, str]:
        """The text before each bucket's, the count's and the sum's value."""
        def labelled(pairs: dict[str, str]) -> str:
            if not pairs:
                return ""
            return "{" + ",".join(f'{k}="{_escaped(v)}"' for k, v in sorted(pairs.items())) + "}"

        own = dict(zip(self._labels, values))
        return ([f"{self._name}_bucket{labelled({**own, 'le': le})} " for le in self._les],
                f"{self._name}_count{labelled(own)} ", f"{self._name}_sum{labelled(own)} ")


def _go(value: float) -> str:
    """A value as the text format writes it (as Go formats a float)."""
    return str(floatToGoString(value))  # type: ignore[no-untyped-call]


def _escaped(value: str) -> str:
    """A label value as the text format writes it."""
    return value.replace("\\", r"\\").replace("\n", r"\n").replace('"', r'\"')


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

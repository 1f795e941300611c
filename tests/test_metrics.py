"""The service's histograms (`metrics.Histograms`, cheaper per observation and per scrape than
`prometheus_client.Histogram`) expose what the library's histogram exposes for the same observations, line for line
(less the library's `_created` series), through the library's exposition and through their own `text`: with labels and without, values on a bucket's bound, beyond the last, and from many threads at
once; and what a re-plan reports lands in its series. Prometheus reading them is tests/test_observability.py's."""
from __future__ import annotations

import random
import threading

from prometheus_client import CollectorRegistry, Histogram
from prometheus_client.exposition import generate_latest

from planhrc.kb_service.metrics import SECONDS, Histograms, ServiceMetrics


def exposed(registry: CollectorRegistry) -> list[str]:
    """The text format's lines, less the `_created` series (and their HELP and TYPE lines)."""
    return [line for line in generate_latest(registry).decode().splitlines() if "_created" not in line]


def test_the_same_observations_give_the_library_s_lines():
    ours, theirs = CollectorRegistry(), CollectorRegistry()
    staged = Histograms("planhrc_t_seconds", "A test's stages.", ("stage", "where"), registry=ours)
    reference = Histogram("planhrc_t_seconds", "A test's stages.", ("stage", "where"), buckets=SECONDS,
                          registry=theirs)
    alone = Histograms("planhrc_u_seconds", "Without labels.", (), registry=ours)
    reference_alone = Histogram("planhrc_u_seconds", "Without labels.", buckets=SECONDS, registry=theirs)
    rng = random.Random(4)
    values = [*SECONDS, 0.0, 61.0, 1e9, *(rng.lognormvariate(-5, 2) for _ in range(500))]
    for k, seconds in enumerate(values):
        labels = (("plan", "val", "store")[k % 3], "here" if k % 2 else 'a "quoted" place\n')
        staged.observe(labels, seconds)
        reference.labels(*labels).observe(seconds)
        alone.observe((), seconds)
        reference_alone.observe(seconds)
    assert exposed(ours) == exposed(theirs)
    assert (staged.text() + alone.text()).splitlines() == exposed(theirs)  # as the service's /metrics writes them


def test_threads_observing_at_once_lose_nothing():
    registry = CollectorRegistry()
    staged = Histograms("planhrc_t_seconds", "A test's stages.", ("stage",), registry=registry)

    def observe() -> None:
        for k in range(2000):
            staged.observe_all([(("plan",), 0.002), (("val",), 0.5 * (k % 2))])

    threads = [threading.Thread(target=observe) for _ in range(8)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    lines = exposed(registry)
    assert 'planhrc_t_seconds_count{stage="plan"} 16000.0' in lines
    assert 'planhrc_t_seconds_bucket{le="0.001",stage="val"} 8000.0' in lines
    assert 'planhrc_t_seconds_sum{stage="val"} 4000.0' in lines


def test_a_re_plan_s_figures_land_in_their_series():
    metrics = ServiceMetrics()
    metrics.answered("/objects/{object_id}/perceptions", "POST", 200, 0.02)
    metrics.decided("replan", {"translate": 0.001, "plan": 0.004, "validate": 0.003, "not a stage": 1.0})
    metrics.validated(True, 0.003)
    metrics.stored(0.002, replanned=True)
    metrics.decided("continue", None)
    text = metrics.text().decode()
    assert len([line for line in text.splitlines() if line.startswith("# TYPE")]) == len(set(
        line for line in text.splitlines() if line.startswith("# TYPE")))  # each family once
    for line in ('planhrc_http_requests_total{method="POST",route="/objects/{object_id}/perceptions",status="200"} 1.0',
                 'planhrc_http_request_seconds_count{method="POST",route="/objects/{object_id}/perceptions"} 1.0',
                 'planhrc_decisions_total{kind="replan"} 1.0', 'planhrc_decisions_total{kind="continue"} 1.0',
                 'planhrc_replan_stage_seconds_count{stage="plan"} 1.0',
                 'planhrc_replan_stage_seconds_count{stage="store"} 1.0',
                 'planhrc_val_seconds_count 1.0', 'planhrc_val_verdicts_total{verdict="accepted"} 1.0',
                 'planhrc_store_transaction_seconds_bucket{le="0.0025"} 1.0'):
        assert line in text.splitlines(), line
    assert "not a stage" not in text

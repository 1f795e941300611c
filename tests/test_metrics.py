"""The service's histograms (`metrics.Histograms`, cheaper per observation and per scrape than
`prometheus_client.Histogram`) expose what the library's histogram exposes for the same observations, line for line
(less the library's `_created` series), through the library's exposition and through their own `text`: with labels
and without, values on a bucket's bound, beyond the last, and from many threads at once; and what a re-plan reports
lands in its series. VAL's CPU per verdict, from real re-plans: in a real `planhrc serve`, the CPU the kernel
counted for VAL's runs (those of its fork server and those it started itself); VAL run in the planning pool's
process, and on later pieces behind the answer. Prometheus reading them is tests/test_observability.py's."""
from __future__ import annotations

import contextlib
import os
import random
import threading
import time
from pathlib import Path
from typing import Any, Iterator

import httpx
import pytest
from prometheus_client import CollectorRegistry, Histogram
from prometheus_client.exposition import generate_latest

from planhrc.kb_service import usecases
from planhrc.kb_service.metrics import SECONDS, Histograms, ServiceMetrics
from planhrc.kb_service.observe import Observation
from planhrc.kb_service.planning_pool import PlanningPool
from planhrc.kb_service.store import SqliteStore
from planhrc.kb_service.tracing import Tracing
from planhrc.paths import default_tbox_path
from planhrc.settings import make_settings
from tests.processes import reaped_cpu_s
from tests.servers import served
from tests.test_val_gate import GOAL, K, LINKS, START, adoption, kinds, new_object, perceived


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
    metrics.validated(True, 0.003, 0.002)
    metrics.validated(False, 0.001, None)  # a verdict whose CPU is not known: counted, its CPU not
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
                 'planhrc_val_seconds_count 2.0', 'planhrc_val_verdicts_total{verdict="accepted"} 1.0',
                 'planhrc_val_verdicts_total{verdict="refused"} 1.0', 'planhrc_val_cpu_seconds_count 1.0',
                 'planhrc_val_cpu_seconds_sum 0.002', 'planhrc_val_cpu_seconds_bucket{le="0.0025"} 1.0',
                 'planhrc_store_transaction_seconds_bucket{le="0.0025"} 1.0'):
        assert line in text.splitlines(), line
    assert "not a stage" not in text


# -- VAL's CPU per verdict, from real re-plans ------------------------------------------------------------------------
def val_series(text: str) -> dict[str, float]:
    """VAL's verdicts (all kinds), and the count and sum of VAL's CPU per verdict, in a `/metrics` text."""
    found = {"verdicts": 0.0, "cpu_count": 0.0, "cpu_sum": 0.0}
    for line in text.splitlines():
        name, _, value = line.rpartition(" ")
        if name.startswith("planhrc_val_verdicts_total{"):
            found["verdicts"] += float(value)
        elif name == "planhrc_val_cpu_seconds_count":
            found["cpu_count"] = float(value)
        elif name == "planhrc_val_cpu_seconds_sum":
            found["cpu_sum"] = float(value)
    return found


def val_fork_servers(pid: int) -> list[int]:
    """The VAL fork servers among process `pid`'s children (a `Validate` whose runs are its own children)."""
    servers = []
    for entry in Path("/proc").iterdir():
        with contextlib.suppress(OSError, IndexError, ValueError):
            if entry.name.isdigit() and (entry / "comm").read_text().strip() == "Validate" and \
                    int((entry / "stat").read_text().rsplit(")", 1)[1].split()[1]) == pid:
                servers.append(int(entry.name))
    return servers


def val_runs_cpu_s(service: int, servers: list[int]) -> float:
    """The CPU the kernel counted for the VAL runs the service and its fork servers have waited for."""
    return reaped_cpu_s(service) + sum(reaped_cpu_s(server) for server in servers)


@pytest.mark.integration
def test_val_s_cpu_is_what_the_kernel_counted_for_val_s_runs(tmp_path):
    """A real `planhrc serve` (the whole plan checked before the answer) re-planning a relative object, whose checks
    are runs of its VAL fork servers (from the start-up, then past the domain), and an absolute one, whose checks
    are VAL processes it starts and waits for itself (cold runs). After each re-plan `/metrics` counts one more
    verdict and one more observation of VAL's CPU, whose sum has grown. And the sum is the CPU the kernel counted
    for those runs, not the service's own: what the fork servers and the service itself waited for grew by as much
    (within the kernel's clock ticks; the service's planners run in its own process here, so VAL's are the only
    children it waits for)."""
    with served(tmp_path / "kb.sqlite3", env={"PLANHRC_VAL_EARLY_ANSWER": "false"}) as server, \
            httpx.Client(base_url=server.url, timeout=60) as client:
        before = val_series(client.get("/metrics").text)
        assert before == {"verdicts": 0.0, "cpu_count": 0.0, "cpu_sum": 0.0}
        assert val_fork_servers(server.pid) == []  # started on the first check
        kernel_before = reaped_cpu_s(server.pid)
        replans = 0
        for formulation in ("relative", "absolute"):
            oid = client.post("/objects", json={"name": formulation, "links": LINKS, "orientations": K,
                                                "formulation": formulation}).json()["id"]
            assert client.put(f"/objects/{oid}/goal", json={"link_orientations_deg": GOAL}).status_code == 200
            for turn in range(6):  # a person undoing the plan, again and again
                links = START if turn % 2 == 0 else [START[0] + 90, *START[1:]]
                answer = client.post(f"/objects/{oid}/perceptions", json={"link_orientations_deg": links})
                assert answer.status_code == 200, answer.text
                now = val_series(client.get("/metrics").text)
                if answer.json()["decision"] == "replan":
                    replans += 1
                    assert now["cpu_count"] == before["cpu_count"] + 1 and now["cpu_sum"] > before["cpu_sum"], now
                else:
                    assert now == before
                assert now["cpu_count"] == now["verdicts"]
                before = now
        assert replans >= 10
        servers = val_fork_servers(server.pid)
        assert 1 <= len(servers) <= 2  # the fork server, and the one past the relative domain once it is up
        counted = val_runs_cpu_s(server.pid, servers) - kernel_before
        tick = 1 / os.sysconf("SC_CLK_TCK")  # user and system of the service and each server, each in whole ticks
        assert abs(before["cpu_sum"] - counted) <= 2 * (1 + len(servers)) * tick + 0.001, (before, counted)
        assert 'planhrc_val_cpu_seconds_bucket{le="+Inf"}' in client.get("/metrics").text


@contextlib.contextmanager
def observed(db: Path, metrics: ServiceMetrics, pool: PlanningPool | None = None, **settings: Any
             ) -> Iterator[tuple[SqliteStore, usecases.Context]]:
    """The service's use cases in process on a store file, reporting to `metrics`."""
    tbox = default_tbox_path()
    with SqliteStore(str(db), tbox) as kb:
        cell = usecases.open_context(kb, make_settings(tbox_path=str(tbox), **settings), pool=pool,
                                     observer=Observation(metrics, Tracing.off()))
        try:
            yield kb, cell
        finally:
            usecases.close_context(cell)


def test_a_verdict_of_the_planning_pool_comes_back_with_its_cpu(tmp_path):
    """With the early answer off, a task planned in the planning pool is checked by VAL there too: its CPU comes
    back with the plan and is counted here, where no VAL ran."""
    metrics = ServiceMetrics()
    with PlanningPool(1, min_atoms=1) as pool, \
            observed(tmp_path / "kb.sqlite3", metrics, pool, val_early_answer=False) as (kb, cell):
        oid = new_object(cell, "relative")
        assert perceived(cell, oid, START).decision == "replan" and pool.pids()
        assert cell.validator.armed is not None and sum(cell.validator.armed.counts.values()) == 0  # none here
    found = val_series(metrics.text().decode())
    assert found["cpu_count"] == found["verdicts"] == 1 and found["cpu_sum"] > 0, found


def test_each_later_piece_s_verdict_has_its_cpu(tmp_path):
    """The early answer on an absolute object: the first motion's verdict before the answer and each later piece's
    behind it, each with its CPU."""
    metrics = ServiceMetrics()
    with observed(tmp_path / "kb.sqlite3", metrics) as (kb, cell):
        oid = new_object(cell)
        answer = perceived(cell, oid, START)
        assert answer.decision == "replan"
        event = adoption(kb, oid, answer.plan_id).data
        later = len(event["val_pieces"]) - len(event["val_accepted"])
        assert later > 0
        deadline = time.monotonic() + 60
        while len(kinds(kb, oid, "val_verdict")) < later:
            assert time.monotonic() < deadline, "the later pieces' verdicts did not come"
            time.sleep(0.05)
        found = until_counted(metrics, 1 + later)
    assert found["cpu_count"] == found["verdicts"] == 1 + later and found["cpu_sum"] > 0, found


def until_counted(metrics: ServiceMetrics, verdicts: int) -> dict[str, float]:
    """The VAL series once `verdicts` verdicts are counted (a later piece's is counted just after it is recorded)."""
    deadline = time.monotonic() + 10
    while (found := val_series(metrics.text().decode()))["verdicts"] < verdicts and time.monotonic() < deadline:
        time.sleep(0.01)
    return found

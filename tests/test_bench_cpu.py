"""The CPU column of `planhrc bench --replan-only` (`planhrc.bench.cpu`): a process's CPU from /proc with its reaped
children's, the service's whole CPU per re-plan on a real `planhrc serve`, a planner's whole process beside it, and
the cells of the re-planning table."""
from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pytest

from planhrc.bench.cpu import anchor_planner, cpu_text, measure_process_cpu, measure_service_cpu, process_cpu_s
from planhrc.bench.grid import replan_table

BURN = "import time\nend = time.process_time() + 0.3\nwhile time.process_time() < end: pass"


def test_a_running_childs_cpu_is_counted_among_the_live_descendants():
    from planhrc.bench.cpu import live_descendants_cpu_s

    before = live_descendants_cpu_s(os.getpid())
    child = subprocess.Popen([sys.executable, "-c", BURN + "\nimport sys\nsys.stdin.read()"],
                             stdin=subprocess.PIPE)
    try:
        deadline = time.monotonic() + 10
        while live_descendants_cpu_s(os.getpid()) - before < 0.25 and time.monotonic() < deadline:
            time.sleep(0.05)
        assert live_descendants_cpu_s(os.getpid()) - before >= 0.25  # still running: not reaped yet
    finally:
        child.communicate(b"")


def test_live_descendants_are_told_apart_by_their_command_name():
    from planhrc.bench.cpu import live_children_cpu_s

    child = subprocess.Popen([sys.executable, "-c", BURN + "\nimport sys\nsys.stdin.read()"], stdin=subprocess.PIPE)
    try:
        name = open(f"/proc/{child.pid}/comm").read().strip()
        deadline = time.monotonic() + 10
        while live_children_cpu_s(os.getpid()).get(name, 0.0) < 0.25 and time.monotonic() < deadline:
            time.sleep(0.05)
        assert live_children_cpu_s(os.getpid()).get(name, 0.0) >= 0.25
        assert "Validate" not in live_children_cpu_s(os.getpid())
    finally:
        child.communicate(b"")


def test_the_runs_of_vals_fork_server_count_as_vals():
    """VAL's fork server reaps its runs itself: their CPU is in its children's, read while it lives, as VAL's."""
    from planhrc.bench.cpu import _Reading
    from planhrc.planner.valfork import ForkServer
    from planhrc.planner.validate import ValRun
    from tests.test_val_fork import _files
    from tests.test_val_runs import PAPER_ABSOLUTE, _task

    forks = ForkServer.start()
    if forks is None:
        pytest.skip("no fork server here (no C compiler)")
    problem, plan = _task("absolute", 12, 8)  # about 20 ms of VAL each
    try:
        with tempfile.TemporaryDirectory() as tmp:
            before = _Reading(os.getpid())
            for i in range(25):
                files = _files(Path(tmp) / str(i), PAPER_ABSOLUTE, problem, plan)
                assert ValRun(forks.run(files), files, None).result(60).valid
            time.sleep(0.1)  # the server reaps the last run
            after = _Reading(os.getpid())
    finally:
        forks.close()
    assert after.val - before.val >= 0.2
    assert after.live - before.live < 0.05  # nothing else ran meanwhile


def test_a_reaped_childs_cpu_is_counted_as_the_childrens_not_the_process_own():
    own, children = process_cpu_s(os.getpid())
    subprocess.run([sys.executable, "-c", BURN], check=True)
    own_after, children_after = process_cpu_s(os.getpid())
    assert children_after - children >= 0.25
    assert own_after - own < 0.25


@pytest.mark.integration
def test_the_services_cpu_per_replan_is_measured_on_a_real_server():
    result = measure_service_cpu("relative", links=20, orientations=12, runs=4, pause_s=0.05)
    assert sum(result["decisions"].values()) == 4 and result["decisions"].get("replan", 0) >= 1
    assert result["per_replan_ms"] > 0 and result["val_children_ms"] >= 0  # in clock ticks: 0 in so short a run
    assert abs(result["per_replan_ms"] - result["own_ms"] - result["val_children_ms"]
               - result["descendants_ms"]) <= 0.03
    assert result["probes"] >= 4 and result["latency_median_ms"] > 0


@pytest.mark.skipif(anchor_planner() is None, reason="needs Fast Downward (or Madagascar) for the anchor")
def test_the_anchor_is_a_planners_whole_process_and_a_timeout_is_not_repeated():
    anchor = anchor_planner()
    assert anchor is not None
    result = measure_process_cpu(anchor, "relative", links=6, orientations=4, runs=2)
    assert result["status"] == "solved" and result["runs"] == 2 and result["cpu_median_ms"] > 0
    result = measure_process_cpu(anchor, "relative", links=20, orientations=12, runs=3, timeout_s=0.01)
    assert result["status"] != "solved" and result["runs"] == 1 and "not repeated" in result["note"]


def test_the_replanning_table_shows_the_cpu_column():
    stats = {"median_ms": 1.0, "p90_ms": 2.0}
    service = {"per_replan_ms": 12.5, "val_children_ms": 4.0}
    row = {"planner": {"ground_ms": 1, "plan": stats, "validate": stats, "inproc_loop": stats},
           "pipeline": {**stats, "stage_medians_ms": {}},
           "cpu": {"service": service, "anchor": {"planner": "fd-lama", "status": "solved", "cpu_median_ms": 250.0},
                   "ratio": 0.05}}
    report = {"machine": {"cpu": "x", "cores": 2}, "links": 20, "orientations": 12, "formulations": {"relative": row}}
    lines = replan_table(report).splitlines()
    assert lines[1].count("|") == lines[2].count("|") == lines[3].count("|")
    assert lines[3].endswith("| 12.5 (VAL 4.0) | fd-lama 250.0, ratio 0.05 |")
    assert cpu_text(None) == "- | - |"
    assert cpu_text({"service": service}) == "12.5 (VAL 4.0) | - |"

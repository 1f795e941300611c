"""`planhrc bench` on a small slice of the grid: results, optimal lengths and files."""
import csv
import json
import os
import signal
import subprocess
import sys
import time

import pytest

from planhrc.bench.grid import make_instances, optimal_length, relative_equivalent, run_grid, summarise, write_results
from planhrc.cli import main
from tests.scenarios import SCENARIOS, Scenario
from planhrc.bench.grid import Instance


def test_instances_are_fixed_by_seed():
    a = make_instances([4, 5], [4, 12], 2)
    b = make_instances([4, 5], [4, 12], 2)
    assert a == b and len(a) == 8
    assert a[0].init_links_deg != a[1].init_links_deg or a[0].goal_links_deg != a[1].goal_links_deg


def _instance(s: Scenario) -> Instance:
    return Instance(s.links, s.orientations, 0, s.init_links_deg, s.goal_links_deg)


def test_optimal_length_formula_on_named_scenarios():
    for s in SCENARIOS.values():
        inst = _instance(s)
        assert optimal_length("relative", inst) == s.optimal_relative, s.name
        assert optimal_length("absolute", inst) == s.optimal_absolute, s.name
        assert optimal_length("absolute", inst) <= relative_equivalent(inst)


def test_grid_slice_solved_optimal_and_valid(tmp_path):
    instances = make_instances([4, 7], [4, 6], 1)
    rows = run_grid(["inproc"], ["relative", "absolute"], instances, timeout_s=5, validate=True, progress=False)
    assert len(rows) == 8
    assert all(r.status == "solved" and r.valid for r in rows)
    assert all(r.plan_length == r.optimal_length for r in rows)
    summary = summarise(rows)
    assert {(s["formulation"], s["solved_valid"]) for s in summary} == {("relative", 4), ("absolute", 4)}
    paths = write_results(rows, summary, tmp_path)
    data = json.loads((tmp_path / "bench.json").read_text())
    assert len(data["rows"]) == 8 and data["machine"]["cores"]
    with (tmp_path / "bench.csv").open() as fh:
        assert len(list(csv.DictReader(fh))) == 8
    assert any(p.suffix == ".png" and p.stat().st_size > 1000 for p in paths)


def test_bench_command_refuses_unknown_planner(tmp_path, capsys):
    code = main(["bench", "--planners", "nosuchplanner", "--links", "4", "--orientations", "4",
                 "--out", str(tmp_path), "--no-progress"])
    assert code == 2
    assert "nosuchplanner" in capsys.readouterr().err


def test_replan_measurement_reports_every_stage():
    from planhrc.bench.grid import measure_replan

    result = measure_replan("absolute", links=5, orientations=4, runs=3)
    assert result["median_ms"] > 0 and result["first_run_ms"] > 0 and result["n"] == 3
    assert {"translate", "plan", "validate", "expected_states", "store"} <= set(result["stage_medians_ms"])


def test_planner_stages_on_a_size_beyond_the_paper():
    from planhrc.bench.grid import measure_planner

    result = measure_planner("relative", links=100, orientations=72, runs=2)
    assert result["validation"] == "valid" and result["optimal"] is True
    assert result["ground_ms"] > 0 and result["plan"]["n"] == 2 and result["inproc_loop"]["n"] == 2
    assert result["inproc_loop"]["median_ms"] >= result["validate"]["median_ms"]
    # VAL needs minutes on large absolute tasks: the planner's share alone
    result = measure_planner("absolute", links=50, orientations=36, runs=2, validate=False)
    assert result["optimal"] is True and result["median_plan_length"] > 0 and "validate" not in result


def test_fast_downward_timeout_is_reported_and_not_repeated():
    from planhrc.bench.grid import measure_fast_downward

    result = measure_fast_downward("relative", links=5, orientations=4, runs=3, timeout_s=0.01)
    assert result["statuses"] == ["timeout"] and result["runs"] == 1 and "not repeated" in result["note"]


def test_http_perception_is_measured_on_a_real_server():
    from planhrc.bench.grid import measure_http

    result = measure_http("relative", links=4, orientations=4, runs=4)
    assert 1 <= result["n"] <= 4 and result["median_ms"] > 0 and result["pause_s"] > 0
    assert 1 <= result["back_to_back"]["n"] <= 4 and result["back_to_back"]["median_ms"] > 0


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM])
def test_an_interrupted_bench_leaves_no_planner_process(tmp_path, signum):
    """Interrupt the bench while Fast Downward runs (LAMA does not solve the absolute 20 x 12 task quickly),
    then look with ps for anything left in Fast Downward's process group."""
    log = tmp_path / "bench.err"
    bench = subprocess.Popen([sys.executable, "-m", "planhrc.cli", "bench", "--replan-only", "--formulations",
                              "absolute", "--no-http", "--replan-runs", "1", "--fd-runs", "1", "--fd-timeout", "120",
                              "--out", str(tmp_path)], stdout=subprocess.DEVNULL, stderr=log.open("w"))
    group = None
    try:
        deadline = time.monotonic() + 120
        while group is None and time.monotonic() < deadline and bench.poll() is None:
            for pid, ppid, pgid, command in _processes():
                if ppid == bench.pid and "fast-downward" in command:
                    group = pgid
            time.sleep(0.2)
        assert group is not None, (f"Fast Downward never started (bench exit {bench.poll()}): "
                                   f"{[r for r in _processes() if r[1] == bench.pid]} {log.read_text()[-2000:]}")
        time.sleep(0.5)  # let the driver start its translator
        assert any(g == group for _, _, g, _ in _processes())
        bench.send_signal(signum)
        assert bench.wait(timeout=30) == 130
        assert "interrupted" in log.read_text()
        time.sleep(0.2)
        assert not [cmd for _, _, g, cmd in _processes() if g == group]
    finally:
        if bench.poll() is None:
            bench.kill()
            bench.wait()
        if group is not None and any(g == group for _, _, g, _ in _processes()):
            os.killpg(group, signal.SIGKILL)  # only when the check above failed: leave nothing running


def _processes() -> list[tuple[int, int, int, str]]:
    """(pid, ppid, pgid, command) of every live process; zombies (killed, waiting for init to reap them) are
    not running and are left out."""
    out = subprocess.run(["ps", "-ww", "-eo", "pid=,ppid=,pgid=,stat=,args="], capture_output=True, text=True,
                         check=True).stdout
    rows = []
    for line in out.splitlines():
        parts = line.split(None, 4)
        if len(parts) == 5 and not parts[3].startswith("Z"):
            rows.append((int(parts[0]), int(parts[1]), int(parts[2]), parts[4]))
    return rows


def test_the_grounding_bench_reports_both_paths_for_both_formulations(capsys):
    from planhrc.bench.replay import main as replay_main

    assert replay_main(["--links", "4", "--orientations", "4", "--repeat", "2"]) == 0
    report = json.loads(capsys.readouterr().out)
    for formulation in ("relative", "absolute"):
        numbers = report[formulation]
        assert numbers["plan_length"] > 0
        assert all(numbers[key] > 0 for key in ("replay_cold_ms", "replay_warm_ms", "ground_task_ms"))

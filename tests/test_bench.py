"""`planhrc bench` on a small slice of the grid: results, optimal lengths and files."""
import csv
import json

from planhrc.bench import make_instances, optimal_length, relative_equivalent, run_grid, summarise, write_results
from planhrc.cli import main
from tests.scenarios import SCENARIOS, Scenario
from planhrc.bench import Instance


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
    from planhrc.bench import measure_replan

    result = measure_replan("absolute", links=5, orientations=4, runs=3, fd_runs=1)
    assert result["replan_median_s"] > 0 and result["first_run_s"] > 0
    assert {"translate", "plan", "validate", "expected_states", "store"} <= set(result["stage_medians_s"])
    assert result.get("fd_lama_status", "solved") == "solved"

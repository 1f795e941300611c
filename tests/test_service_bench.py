"""`planhrc service-bench` runs end to end on tiny sizes and reports what it says it measures."""
from __future__ import annotations

import json
import subprocess
import sys

import pytest

from planhrc.bench.service import percentile

pytestmark = pytest.mark.integration


def test_percentile_interpolates():
    assert percentile([3.0, 1.0, 2.0], 0.5) == 2.0
    assert percentile([0.0, 10.0], 0.95) == pytest.approx(9.5)
    assert percentile([5.0], 0.95) == 5.0


def test_service_bench_reports_numbers(tmp_path):
    out = subprocess.run([sys.executable, "-m", "planhrc.cli", "service-bench", "--parts", "refusal,objects,history",
                          "--objects", "1,3", "--checkpoints", "4", "--samples", "3", "--links", "4",
                          "--orientations", "4", "--out", str(tmp_path)],
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    report = json.loads(out.stdout)
    assert report["refusal"]["no_token"]["status"] == 401
    assert report["refusal"]["token_over_limit"]["status"] == 413
    assert [row["objects"] for row in report["objects"]] == [1, 3]
    assert all(row["p50_ms"] > 0 and row["rss_mb"] > 0 for row in report["objects"])
    # the server's CPU per perception, read from /proc (10 ms ticks: a few tiny perceptions may round to 0)
    assert all(0 <= row["server_cpu_ms"] < 60_000 for row in report["objects"])
    assert report["machine"]["load_at_start"] >= 0 and report["machine"]["load_at_end"] >= 0
    (row,) = report["history"]
    assert row["perceptions"] == 4 and set(row["reads"]) == {"object", "plan", "events", "pddl_problem", "ontology"}
    assert 0 <= row["replan"]["server_cpu_ms"] < 60_000
    assert (tmp_path / "service-bench.md").read_text().count("|") > 10


def test_service_bench_re_plans_a_bimanual_object_with_the_robot_acting(tmp_path):
    """A bimanual plan begins with grasps: without the robot acting, every random perception lets the plan go on.
    With it (the next action taken and done before each perception) the perceptions re-plan."""
    out = subprocess.run([sys.executable, "-m", "planhrc.cli", "service-bench", "--parts", "history",
                          "--checkpoints", "12", "--samples", "10", "--links", "4", "--orientations", "8",
                          "--formulation", "bimanual"], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    (row,) = json.loads(out.stdout)["history"]
    assert row["replan"]["n"] >= 3 and row["replan"]["p50_ms"] > 0


def test_service_bench_without_val_says_so_in_its_rows_and_its_table(tmp_path):
    """`--without-val` (what a re-plan costs without its check) is never mistaken for a product's figure: each
    history row says the plans were not validated, and the table opens with it; a run with VAL says nothing."""
    for flag in ([], ["--without-val"]):
        out = subprocess.run([sys.executable, "-m", "planhrc.cli", "service-bench", "--parts", "history",
                              "--checkpoints", "6", "--samples", "5", "--links", "4", "--orientations", "8",
                              *flag, "--out", str(tmp_path / str(len(flag)))],
                             capture_output=True, text=True, timeout=300)
        assert out.returncode == 0, out.stderr
        (row,) = json.loads(out.stdout)["history"]
        table = (tmp_path / str(len(flag)) / "service-bench.md").read_text()
        assert row["replan"]["n"] >= 1 and row["validated"] is (not flag)
        assert ("VAL off" in table) is bool(flag)


def test_service_bench_side_by_side_measures_both_histories_in_one_run(tmp_path):
    out = subprocess.run([sys.executable, "-m", "planhrc.cli", "service-bench", "--parts", "side-by-side",
                          "--checkpoints", "2,6", "--samples", "5", "--links", "4", "--orientations", "4",
                          "--out", str(tmp_path)], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    rows = json.loads(out.stdout)["side_by_side"]["rows"]
    assert [row["perceptions"] for row in rows] == [2, 6]
    assert all(0 < row["n"] <= 5 and row["p50_ms"] > 0 and row["server_cpu_ms"] >= 0 for row in rows)
    assert "side by side, re-planning p95, 2 -> 6 perceptions" in (tmp_path / "service-bench.md").read_text()


def test_service_bench_refuses_bad_parts():
    out = subprocess.run([sys.executable, "-m", "planhrc.cli", "service-bench", "--parts", "objects,bogus"],
                         capture_output=True, text=True, timeout=60)
    assert out.returncode == 2
    assert out.stderr.strip().splitlines() == ["planhrc service-bench: --parts: unknown part(s) bogus"]


def test_service_bench_contention_reports_health_and_the_pool(tmp_path):
    out = subprocess.run([sys.executable, "-m", "planhrc.cli", "service-bench", "--parts", "contention",
                          "--big-links", "30", "--samples", "3", "--planning-workers", "1", "--out", str(tmp_path)],
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    c = json.loads(out.stdout)["contention"]
    assert c["planning_workers"] == 1 and c["big_status"] == 200
    assert c["health_while_big_plans"]["n"] >= 1 and c["health_while_big_plans"]["max_ms"] > 0
    assert "/health meanwhile" in (tmp_path / "service-bench.md").read_text()
    bad = subprocess.run([sys.executable, "-m", "planhrc.cli", "service-bench", "--planning-workers", "-1"],
                         capture_output=True, text=True, timeout=60)
    assert bad.returncode == 2 and "--planning-workers" in bad.stderr and "Traceback" not in bad.stderr


def test_service_bench_scale_out_compares_sqlite_and_replicas_in_one_run(tmp_path, pg_cluster, request):
    from tests.servers import store_location

    db = store_location("postgresql", tmp_path, request)
    out = subprocess.run([sys.executable, "-m", "planhrc.cli", "service-bench", "--parts", "scale-out", "--db", db,
                          "--scale-replicas", "1,2", "--scale-objects", "3", "--scale-size", "4,4",
                          "--scale-clients", "2", "--scale-seconds", "2", "--out", str(tmp_path)],
                         capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr
    part = json.loads(out.stdout)["scale_out"]
    assert [(r["backend"], r["replicas"], r["routing"], r["objects"]) for r in part["rows"]] == [
        ("sqlite", 1, "-", 3), ("postgresql", 1, "-", 3), ("postgresql", 2, "turns", 3), ("postgresql", 2, "object", 3)]
    for row in part["rows"]:
        assert row["perceptions"] > 0 and row["per_s"] > 0 and row["not_200"] == 0
        assert 0 < row["p50_ms"] <= row["p95_ms"]
        assert row["cpu_ms"] > 0
    assert all(r["database_cpu_ms"] > 0 for r in part["rows"] if r["backend"] == "postgresql")
    assert [r["throughput_vs_1_replica"] is not None for r in part["ratios"]] == [True] * 4
    assert "| 3 | postgresql | 2 | object |" in (tmp_path / "service-bench.md").read_text()
    refused = subprocess.run([sys.executable, "-m", "planhrc.cli", "service-bench", "--parts", "scale-out"],
                             capture_output=True, text=True, timeout=120)
    assert refused.returncode == 1 and refused.stderr.strip().splitlines() == [
        "planhrc service-bench: --db: the scale-out part needs a PostgreSQL database it may fill "
        "(postgresql://user@host:port/database)"]

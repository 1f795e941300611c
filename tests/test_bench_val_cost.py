"""`python -m planhrc.bench.val_cost`: VAL's CPU on plans of both formulations, each way the pipeline checks them."""
from __future__ import annotations

import json

import pytest

from planhrc.bench.val_cost import main


def test_every_plan_is_checked_each_way_and_the_service_cuts_a_long_absolute_plan(tmp_path):
    assert main(["--links", "12", "--orientations", "8", "--tasks", "2", "--out", str(tmp_path)]) == 0
    report = json.loads((tmp_path / "val-cost.json").read_text())
    rows = report["rows"]
    assert {r["formulation"] for r in rows} == {"absolute", "relative"} and all(r["valid"] for r in rows)
    for r in rows:
        assert 1 <= r["before_answer"] <= r["runs"]
        assert r["whole_ms"] >= 0 and r["service_ms"] >= r["first_motion_ms"] >= 0
    relative = [r for r in rows if r["formulation"] == "relative"]
    assert all(r["runs"] == 1 for r in relative)  # no quantified effect: checked whole, before the answer
    assert any(r["runs"] > r["before_answer"] for r in rows if r["formulation"] == "absolute")
    assert "| absolute |" in (tmp_path / "val-cost.md").read_text()


def test_orientations_that_do_not_divide_360_are_refused_in_one_line(capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(["--orientations", "7"])
    err = capsys.readouterr().err.strip()
    assert exit_info.value.code == 2 and len(err.splitlines()) == 1 and "--orientations" in err

"""The one fallback chain: order, remaining time, attempts, and bad input refused before anything runs."""
import json
from pathlib import Path

import pytest

from planhrc.planner import PlannerError, PlanStatus, plan_with_fallback, validate_plan
from planhrc.planner.cli import main as cli_main

DATA = Path(__file__).parent / "data"
RELATIVE = (DATA / "domain-relative.pddl").read_text()
PROBLEM = (DATA / "problem-relative-3x4.pddl").read_text()
# Orientations in a line, not a cycle: outside the in-process planner's family, easy for Fast Downward.
OPEN_ORDER = PROBLEM.replace("(orientationord deg_270 deg_0)", "")


def test_inproc_answers_alone_when_it_can():
    result = plan_with_fallback(RELATIVE, PROBLEM, ["inproc", "fd-lama"], 10.0)
    assert result.status is PlanStatus.SOLVED and result.planner == "inproc" and result.optimal is True
    assert [a.planner for a in result.attempts] == ["inproc"]
    assert validate_plan(RELATIVE, PROBLEM, result.plan).valid


def test_fallback_says_why_the_first_planner_declined():
    result = plan_with_fallback(RELATIVE, OPEN_ORDER, ["inproc", "fd-lama"], 30.0)
    assert result.status is PlanStatus.SOLVED and result.planner == "fd-lama"
    first, second = result.attempts
    assert (first.planner, first.status) == ("inproc", PlanStatus.ERROR) and "orientationord" in first.message
    assert (second.planner, second.status) == ("fd-lama", PlanStatus.SOLVED)
    assert result.optimal is None  # LAMA proves nothing about length
    assert result.seconds >= first.seconds + second.seconds
    assert validate_plan(RELATIVE, OPEN_ORDER, result.plan).valid


def test_unsolvable_is_a_proof_and_ends_the_chain():
    text = PROBLEM.replace("(connected obj1_j2 obj1_l3)", "")
    head, sep, goal = text.partition("(:goal")
    unsolvable = head + sep + goal.replace("(hasorientation deg_90 obj1_j2)", "(hasorientation deg_0 obj1_j2)")
    result = plan_with_fallback(RELATIVE, unsolvable, ["inproc", "fd-lama"], 10.0)
    assert result.status is PlanStatus.UNSOLVABLE and [a.planner for a in result.attempts] == ["inproc"]


def test_a_planner_without_time_left_is_not_tried():
    result = plan_with_fallback(RELATIVE, PROBLEM, ["fd-lama", "inproc"], 0.001)
    assert result.status is PlanStatus.TIMEOUT and not result.plan
    assert [(a.planner, a.status) for a in result.attempts] == [("fd-lama", PlanStatus.TIMEOUT),
                                                              ("inproc", PlanStatus.TIMEOUT)]
    assert result.attempts[1].message == "not tried: no time left"
    assert "fd-lama: timeout" in result.message


@pytest.mark.parametrize("planners, timeout, field", [
    ([], 5.0, "planners"), ("inproc", 5.0, "planners"), (["inproc", "lama"], 5.0, "unknown planner"),
    (["inproc"], 0.0, "timeout"), (["inproc"], -1.0, "timeout"),
])
def test_bad_chain_is_refused(planners, timeout, field):
    with pytest.raises(PlannerError, match=field):
        plan_with_fallback(RELATIVE, PROBLEM, planners, timeout)


def test_cli_falls_back_and_reports_attempts(capsys, tmp_path):
    path = tmp_path / "p.pddl"
    path.write_text(OPEN_ORDER)
    code = cli_main(["plan", str(DATA / "domain-relative.pddl"), str(path), "--json", "--timeout", "30"])
    out = json.loads(capsys.readouterr().out)
    assert code == 0 and out["status"] == "solved" and out["planner"] == "fd-lama"
    assert [a["planner"] for a in out["attempts"]] == ["inproc", "fd-lama"]
    assert out["attempts"][0]["status"] == "error"
    code = cli_main(["plan", str(DATA / "domain-relative.pddl"), str(path), "--timeout", "30"])
    text = capsys.readouterr().out
    assert code == 0 and text.startswith("; inproc declined: error")

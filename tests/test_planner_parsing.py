"""PDDL reading (our parser and an independent one), plan-file parsing, recognition of the family."""
from pathlib import Path

import pytest

from planhrc.model import make_object
from planhrc.planner.errors import PlannerError
from planhrc.planner.inproc import ground_task
from planhrc.planner.pddl import parse_domain, parse_problem
from planhrc.planner.plan_file import parse_plan_text, read_best_plan
from planhrc.translator.problem import get_problem

DATA = Path(__file__).parent / "data"


def test_parse_golden_problem():
    problem = parse_problem((DATA / "problem-absolute-3x4.pddl").read_text())
    assert problem.domain_name == "planhrc-absolute"
    assert problem.objects_of({"joint"}) == ("obj1_j1", "obj1_j2", "obj1_j3")
    assert ("hasorientation", "deg_90", "obj1_j2") in problem.init
    assert ("affected", "obj1_j3", "obj1_l1", "obj1_j1") in problem.init
    assert problem.goal == {("hasorientation", "deg_0", "obj1_j3"), ("hasorientation", "deg_90", "obj1_j1"),
                            ("hasorientation", "deg_90", "obj1_j2")}


@pytest.mark.parametrize("name", ["relative", "absolute", "absolute-paper"])
def test_golden_domains_ground_to_fixed_vectors(name):
    """Each ground action (up to its orientation arguments) adds a fixed step vector to the joints."""
    formulation = "relative" if name == "relative" else "absolute"
    task = ground_task((DATA / f"domain-{name}.pddl").read_text(),
                       (DATA / f"problem-{formulation}-3x4.pddl").read_text())
    joints = ("obj1_j1", "obj1_j2") + (("obj1_j3",) if formulation == "absolute" else ())
    assert task.joints == joints and task.cycle == ("deg_0", "deg_90", "deg_180", "deg_270")
    vectors = {(a.action, dict(a.binding)["?l1"], dict(a.binding)["?j1"]): {task.names[v]: s for v, s in a.effect}
               for a in task.axes}
    turn_l1 = {"relative": {"obj1_j1": 1}, "absolute": {"obj1_j1": 1, "obj1_j2": 1, "obj1_j3": 1},
               "absolute-paper": {"obj1_j1": 1, "obj1_j2": 1, "obj1_j3": 1}}[name]
    assert vectors[("rotateclockwise", "obj1_l1", "obj1_j1")] == turn_l1
    assert vectors[("rotateanticlockwise", "obj1_l1", "obj1_j1")] == {j: 3 for j in turn_l1}  # -1 mod 4
    # the guard (affected ?j1 ?l1 ?j1) removes turning the table link l0; the paper's schema keeps it
    assert (("rotateclockwise", "obj1_l0", "obj1_j1") in vectors) is (name == "absolute-paper")
    assert all(len(a.values) == 2 for a in task.axes)  # ?o1 pinned, ?o2 one step on


def test_parser_is_case_insensitive_and_ignores_comments():
    text = (DATA / "problem-relative-3x4.pddl").read_text().replace("obj1_j1", "OBJ1_J1")
    text = "; a comment\n" + text.replace("(:init", "(:init ; init follows")
    problem = parse_problem(text)
    assert ("hasorientation", "deg_0", "obj1_j1") in problem.init


@pytest.mark.parametrize("bad,match", [
    ("", "empty"),
    ("(define (problem p) (:domain d) (:objects a - t) (:init (p b)) (:goal (p a)))", "not an object"),
    ("(define (problem p) (:domain d) (:goal (or (p) (q))))", "ground atom"),
    ("(define (problem p) (:domain d) (:init)", "unclosed"),
    ("(define (problem p) (:init) (:goal (and)))", "domain"),
    ("(define (problem p) (:domain d) (:objects a a - t) (:goal (and)))", "twice"),
])
def test_bad_problem_text_raises_with_a_clear_message(bad, match):
    with pytest.raises(PlannerError, match=match):
        parse_problem(bad)


def test_bad_domain_text_raises():
    with pytest.raises(PlannerError, match="no action"):
        parse_domain("(define (domain d) (:predicates (p)))")
    with pytest.raises(PlannerError, match="unbalanced"):
        parse_domain("(define (domain d)))")


@pytest.mark.parametrize("formulation", ["relative", "absolute"])
def test_round_trip_with_unified_planning(formulation):
    """Our domains and generated problems parse with unified-planning's independent PDDLReader and agree
    with our reader on objects, initial orientations and goals."""
    from unified_planning.io import PDDLReader

    obj = make_object("obj1", formulation, 5, 6)
    goal = {("hasorientation", "deg_120", obj.joint(2)), ("hasorientation", "deg_300", obj.joint(4))}
    text = get_problem(obj, obj.configuration_atoms([0, 60, 120, 180, 240][: obj.n_joints]), goal, "rt")
    domain_path = DATA / f"domain-{formulation}.pddl"
    ours = parse_problem(text)
    up_problem = PDDLReader().parse_problem_string(domain_path.read_text(), text)
    assert {o.name for o in up_problem.all_objects} == {name for name, _ in ours.objects}
    up_true = {str(fluent) for fluent, value in up_problem.initial_values.items() if value.bool_constant_value()}
    ours_init = {f"{a[0]}({', '.join(a[1:])})" for a in ours.init}
    assert up_true == ours_init
    up_goals = {str(g) for goal_expr in up_problem.goals for g in (goal_expr.args if goal_expr.is_and() else [goal_expr])}
    assert up_goals == {f"{a[0]}({', '.join(a[1:])})" for a in ours.goal}
    assert {a.name for a in up_problem.actions} == {a.name for a in parse_domain(domain_path.read_text()).actions}


def test_plan_text_parsing_variants():
    text = """; comment line
(ROTATECLOCKWISE Obj1_L2 obj1_l1 obj1_j1 deg_0 deg_90)
0.000: (rotateanticlockwise obj1_l2 obj1_l1 obj1_j1 deg_90 deg_0) [1.000]
STEP 2: (a b) (c d)
3 : e f
; cost = 4 (unit cost)
"""
    assert parse_plan_text(text) == (
        "(rotateclockwise obj1_l2 obj1_l1 obj1_j1 deg_0 deg_90)",
        "(rotateanticlockwise obj1_l2 obj1_l1 obj1_j1 deg_90 deg_0)",
        "(a b)", "(c d)", "(e f)",
    )


def test_read_best_plan_prefers_the_last_numbered_file(tmp_path):
    assert read_best_plan(tmp_path, "plan") is None
    (tmp_path / "plan.1").write_text("(a)\n(b)\n")
    (tmp_path / "plan.2").write_text("(c)\n")
    (tmp_path / "plan.10").write_text("(d)\n")
    assert read_best_plan(tmp_path, "plan") == ("(d)",)

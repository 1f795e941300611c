"""The bimanual family: a cyclic part (joint angles) times a small control (two hands, the joint at the centre,
grasp and release, 3-step macros), in the field's style (`?j -joint`, forall/when, :adl, :equality). The
in-process planner plans it through `planner.product`; plans are VAL-valid and as short as the length formula
of `bench.bimanual_tasks` and Fast Downward's optimal search say."""
import dataclasses
import os
import subprocess
import sys

import pytest

from planhrc.bench.bimanual_tasks import (VARIANTS, domain_text, make_instances, optimal_length, problem_text,
                                          turning_steps)
from planhrc.planner import PlanStatus, get_planner, plan_with_fallback, validate_plan
from planhrc.planner import product
from planhrc.planner.inproc import InprocPlanner, ground_task


def instance(variant, links, orientations, index=0):
    return make_instances([links], [orientations], index + 1, variant)[index]


def test_the_length_formula_counts_turns_and_hands():
    assert turning_steps(6, 24, macros=True) == 2 and turning_steps(6, 24, macros=False) == 6
    assert turning_steps(22, 24, macros=True) == 2  # -1, -1
    inst = dataclasses.replace(instance("macros", 4, 24), init=(0, 0, 0), goal=(3, 3, 3), centre=3)
    assert optimal_length(inst) == 2  # centre-and-grasp at j1, one 3-step turn: it carries j2 and j3 along
    inst = dataclasses.replace(inst, goal=(3, 3, 4))
    assert optimal_length(inst) == 5  # and j3 one step more: release, centre-and-grasp at j3, turn
    basic = dataclasses.replace(inst, variant="basic", goal=(1, 1, 2))
    assert optimal_length(basic) == 6  # j3 first (at the centre): grasp, turn, release; centre j1, grasp, turn


@pytest.mark.parametrize("variant", VARIANTS)
@pytest.mark.parametrize("links, orientations", [(3, 8), (4, 24), (6, 24), (8, 12)])
def test_inproc_plans_are_shortest_and_val_valid(variant, links, orientations):
    domain = domain_text(variant)
    for inst in make_instances([links], [orientations], 2, variant):
        problem = problem_text(inst)
        result = InprocPlanner().solve(domain, problem, 30.0)
        assert result.status is PlanStatus.SOLVED and result.optimal is True, result.message
        assert len(result.plan) == optimal_length(inst)
        if variant == "basic" or orientations <= 12:  # VAL expands the macros' 4-angle forall: K^4 per joint
            assert validate_plan(domain, problem, result.plan).valid


@pytest.mark.slow
def test_a_macro_plan_on_24_orientations_is_val_valid():
    inst = instance("macros", 4, 24)
    domain, problem = domain_text("macros"), problem_text(inst)
    result = plan_with_fallback(domain, problem, ["inproc"], 300.0)
    assert result.solved and result.validated and len(result.plan) == optimal_length(inst)
    assert any("-3 " in step for step in result.plan)  # a 45-degree macro


@pytest.mark.parametrize("variant", VARIANTS)
@pytest.mark.parametrize("links, orientations", [(3, 4), (4, 4)])
def test_fast_downward_optimal_search_agrees_on_length(variant, links, orientations):
    inst = instance(variant, links, orientations)
    domain, problem = domain_text(variant), problem_text(inst)
    ours = InprocPlanner().solve(domain, problem, 30.0)
    theirs = get_planner("fd-opt").solve(domain, problem, 120.0)  # the normalised copy: `-joint` split
    assert theirs.solved, theirs.message
    assert len(ours.plan) == len(theirs.plan) == optimal_length(inst)


def with_goal(problem: str, extra: str) -> str:
    head, goal = problem.split("(:goal (and", 1)
    return head + "(:goal (and\n    " + extra + goal


@pytest.mark.parametrize("variant", VARIANTS)
def test_control_facts_in_the_goal(variant):
    """Hands empty at the end: the plan ends with a release; still as short as Fast Downward's optimum."""
    inst = instance(variant, 3, 4)
    domain, problem = domain_text(variant), with_goal(problem_text(instance(variant, 3, 4)), "(empty left) (empty right)")
    result = InprocPlanner().solve(domain, problem, 30.0)
    assert result.solved and result.optimal is True and result.plan[-1].startswith("(release")
    assert len(result.plan) == optimal_length(inst) + 1
    assert len(get_planner("fd-opt").solve(domain, problem, 120.0).plan) == len(result.plan)
    assert validate_plan(domain, problem, result.plan).valid


def test_a_partial_goal_and_a_goal_at_the_centre():
    domain = domain_text("basic")
    problem = problem_text(instance("basic", 4, 4))
    head, goal = problem.split("(:goal (and", 1)
    partial = head + "(:goal (and (at-angle a90 j2) (centred j1)))\n)\n"
    result = InprocPlanner().solve(domain, partial, 30.0)
    reference = get_planner("fd-opt").solve(domain, partial, 120.0)
    assert result.solved and result.optimal is True and len(result.plan) == len(reference.plan)
    assert validate_plan(domain, partial, result.plan).valid


def test_replanning_from_hands_already_holding():
    """The ground task re-plans from any state of the control part, e.g. the hands holding l2 and l3 at j2."""
    inst = instance("macros", 5, 8)
    domain, problem = domain_text("macros"), problem_text(inst)
    task = ground_task(domain, problem)
    holding = (set(task.init) - {("centred", f"j{inst.centre}"), ("empty", "left"), ("empty", "right")}) | {
        ("centred", "j2"), ("held", "l2"), ("held", "l3"), ("holding", "left", "l3"), ("holding", "right", "l2")}
    result = task.solve(holding, task.goal)
    assert result.solved and result.optimal is True
    text = problem.replace(f"(centred j{inst.centre})", "(centred j2) (held l2) (held l3) (holding left l3) "
                           "(holding right l2)").replace("(empty left)", "").replace("(empty right)", "")
    assert validate_plan(domain, text, result.plan).valid
    assert result.plan == InprocPlanner().solve(domain, text, 30.0).plan


def test_one_hand_cannot_turn_and_that_is_proved():
    inst = dataclasses.replace(instance("basic", 3, 8), init=(0, 0), goal=(1, 1))
    domain, problem = domain_text("basic"), problem_text(inst).replace("(empty right)", "")
    result = InprocPlanner().solve(domain, problem, 30.0)
    assert result.status is PlanStatus.UNSOLVABLE and result.plan == ()
    assert get_planner("fd-opt").solve(domain, problem, 120.0).status is PlanStatus.UNSOLVABLE


def test_a_search_too_large_ends_in_a_greedy_walk_not_claimed_shortest(monkeypatch):
    monkeypatch.setattr(product, "NODE_LIMIT", 1)
    inst = instance("macros", 6, 8)
    domain, problem = domain_text("macros"), problem_text(inst)
    result = ground_task(domain, problem).solve_problem()
    assert result.solved and result.optimal is False and "greedy" in result.message
    assert validate_plan(domain, problem, result.plan).valid
    assert len(result.plan) >= optimal_length(inst)


def test_plans_do_not_depend_on_the_process(tmp_path):
    """Sets of atoms iterate in a hash order that changes with each process: the plan must not."""
    (tmp_path / "d.pddl").write_text(domain_text("macros"))
    (tmp_path / "p.pddl").write_text(problem_text(instance("macros", 6, 24)))
    plans = set()
    for seed in ("1", "2", "3"):
        out = subprocess.run([sys.executable, "-m", "planhrc.cli", "plan", str(tmp_path / "d.pddl"),
                              str(tmp_path / "p.pddl"), "--no-validate"], capture_output=True, text=True,
                             env={**os.environ, "PYTHONHASHSEED": seed})
        assert out.returncode == 3, out.stderr  # printed unvalidated (--no-validate)
        plans.add(tuple(line for line in out.stdout.splitlines() if not line.startswith(";")))
    assert len(plans) == 1

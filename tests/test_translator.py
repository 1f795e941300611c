"""Translator: TBox -> PDDL domain, problem writer, the pure `translate`; checked by independent tools."""
from pathlib import Path

import pytest

from planhrc.model import make_object
from planhrc.paths import default_tbox_path
from planhrc.translator import TranslationError, get_domain, get_problem, read_domain_model, translate

DATA = Path(__file__).parent / "data"


@pytest.mark.parametrize(
    "formulation,paper,golden",
    [("relative", False, "domain-relative"), ("absolute", False, "domain-absolute"),
     ("absolute", True, "domain-absolute-paper")],
)
def test_domain_from_tbox_matches_the_golden_file(formulation, paper, golden):
    assert get_domain(default_tbox_path(), formulation, paper_exact=paper) == (DATA / f"{golden}.pddl").read_text()


def test_unknown_formulation_is_a_translation_error():
    with pytest.raises(TranslationError, match="formulation"):
        get_domain(default_tbox_path(), "sideways")


@pytest.mark.parametrize("formulation", ["relative", "absolute"])
def test_problem_is_deterministic(formulation):
    obj = make_object("obj7", formulation, 6, 8)
    vals = [45 * (i % 8) for i in range(obj.n_joints)]
    init = obj.state(vals)
    goal = obj.configuration_atoms(list(reversed(vals)))
    first = get_problem(obj, init, goal, "p")
    # a different iteration order of the same sets gives the same bytes
    second = get_problem(obj, frozenset(sorted(init, reverse=True)), frozenset(sorted(goal)), "p")
    assert first == second
    assert "(:goal (and" in first


def test_problem_refuses_foreign_names_and_non_orientation_goals():
    obj = make_object("o", "relative", 3, 4)
    with pytest.raises(TranslationError, match="not part of o"):
        get_problem(obj, obj.state([0, 0]), {("hasorientation", "deg_0", "x_j1")}, "p")
    with pytest.raises(TranslationError, match="only hasorientation"):
        get_problem(obj, obj.state([0, 0]), {("connected", "o_j1", "o_l1")}, "p")
    with pytest.raises(TranslationError, match="no predicate"):
        get_problem(obj, obj.state([0, 0]), set(), "p")


@pytest.mark.parametrize("formulation", ["relative", "absolute"])
def test_translate_is_a_function_of_values(formulation):
    """Object, states and the TBox's domain model in, PDDL text out: the same values give the same text."""
    obj = make_object("obj3", formulation, 5, 8)
    model = read_domain_model(default_tbox_path(), formulation)
    init, goal = obj.state([45] * obj.n_joints), obj.configuration_atoms([90] * obj.n_joints)
    task = translate(obj, init, goal, model, "obj3-task")
    assert task == translate(obj, frozenset(sorted(init)), frozenset(goal), model, "obj3-task")
    assert task.domain == get_domain(default_tbox_path(), formulation)
    assert task.validation_domain == get_domain(default_tbox_path(), formulation, paper_exact=True)
    assert task.problem == get_problem(obj, init, goal, "obj3-task")
    assert "(hasorientation deg_45 obj3_j2)" in task.problem and "(hasorientation deg_90 obj3_j2)" in task.problem


@pytest.mark.parametrize("formulation", ["relative", "absolute"])
def test_independent_parser_reads_domain_and_problem(formulation, tmp_path):
    """unified-planning's PDDL reader (an independent parser) accepts what we write."""
    from unified_planning.io import PDDLReader

    obj = make_object("o", formulation, 4, 6)
    vals = [60 * i % 360 for i in range(obj.n_joints)]
    (tmp_path / "d.pddl").write_text(get_domain(default_tbox_path(), formulation))
    (tmp_path / "p.pddl").write_text(get_problem(obj, obj.state(vals), obj.configuration_atoms([0] * obj.n_joints), "p"))
    problem = PDDLReader().parse_problem(str(tmp_path / "d.pddl"), str(tmp_path / "p.pddl"))
    assert {a.name for a in problem.actions} == {"rotateclockwise", "rotateanticlockwise"}
    assert len(problem.all_objects) == len(obj.all_links) + obj.n_joints + 6
    assert len(problem.goals) >= 1
    has_conditional = any(e.is_conditional() for a in problem.actions for e in a.effects)
    assert has_conditional == (formulation == "absolute")


@pytest.mark.slow
@pytest.mark.parametrize("formulation", ["relative", "absolute"])
def test_fast_downward_solves_translated_problem(formulation):
    from planhrc.planner.registry import get_planner
    from planhrc.planner.validate import validate_plan

    obj = make_object("o", formulation, 5, 4)
    init = obj.state([0] * obj.n_joints)
    goal = obj.configuration_atoms([90] * obj.n_joints)
    domain, problem = get_domain(default_tbox_path(), formulation), get_problem(obj, init, goal, "p")
    result = get_planner("fd-lama").solve(domain, problem, 60)
    assert result.status.value == "solved"
    check = validate_plan(get_domain(default_tbox_path(), formulation, paper_exact=True), problem, result.plan)
    assert check.valid, check.reason

"""The bimanual formulation as knowledge: the TBox holds its domain model, the translator writes it (the same
bytes every run, read by an independent parser), the in-process planner solves it shortest, VAL accepts the plans,
and a DL reasoner finds a stored bimanual object consistent."""
from __future__ import annotations

import random
import subprocess
import sys

import pytest

from planhrc.kb_service.check import check_ontology
from planhrc.kb_service.store import SqliteStore
from planhrc.model import make_object
from planhrc.paths import default_tbox_path
from planhrc.pipeline import PlanningConfig, plan
from planhrc.planner.validate import validate_plan
from planhrc.translator import get_domain, get_problem, read_domain_model

TBOX = default_tbox_path()
SCHEMAS = {"movetocentre", "grasplinks", "releaselinks", "rotateclockwise", "rotateanticlockwise",
           "rotateclockwise45", "rotateanticlockwise45"}


def test_the_tbox_holds_the_bimanual_domain_model():
    model = read_domain_model(TBOX, "bimanual")
    assert {s.name for s in model.actions} == SCHEMAS
    for name in ("free", "holding", "incentre", "keeper", "orientationord45"):
        assert f"({name} " in get_domain(TBOX, "bimanual")
    for schema in model.actions:  # turned link, kept link, joint: every schema's head
        assert [name for name, _ in schema.parameters[:3]] == ["?l1", "?l2", "?j1"], schema.name


def test_translation_is_deterministic_and_round_trips(tmp_path):
    from unified_planning.io import PDDLReader

    obj = make_object("o", "bimanual", 5, 24)
    init = obj.state([0, 45, 90, 135])
    goal = obj.configuration_atoms([90, 90, 0, 315])
    shuffled = list(init)
    random.Random(3).shuffle(shuffled)
    domain, problem = get_domain(TBOX, "bimanual"), get_problem(obj, init, goal, "p")
    assert domain == get_domain(TBOX, "bimanual")
    assert problem == get_problem(obj, frozenset(shuffled), frozenset(sorted(goal)), "p")
    assert "(keeper left)" in problem and "(orientationord45 deg_0 deg_45)" in problem  # K = 24 has macros
    (tmp_path / "d.pddl").write_text(domain)
    (tmp_path / "p.pddl").write_text(problem)
    parsed = PDDLReader().parse_problem(str(tmp_path / "d.pddl"), str(tmp_path / "p.pddl"))
    assert {a.name for a in parsed.actions} == SCHEMAS
    assert {o.name for o in parsed.all_objects} >= {"left", "right", "o_j1", "o_l5", "deg_315"}


@pytest.mark.parametrize("links, k, goal", [(4, 4, [90, 90, 180]), (3, 8, [45, 270]), (3, 24, [45, 90])])
def test_the_in_process_planner_solves_it_shortest_and_val_accepts(links, k, goal):
    obj = make_object("o", "bimanual", links, k)
    init, target = obj.state([0] * obj.n_joints), obj.configuration_atoms(goal)
    config = PlanningConfig(tbox_path=TBOX, planner="inproc", timeout_s=60, validate=True, fallback_planner=None,
                            deadline_s=120)
    outcome = plan(obj, init, target, config)
    assert outcome.solved and outcome.validated and outcome.optimal is True, outcome.message
    steps = list(outcome.steps)
    assert validate_plan(outcome.task.domain, outcome.task.problem, steps).valid
    assert not validate_plan(outcome.task.domain, outcome.task.problem, steps[:-1]).valid
    assert target <= outcome.expected_states[-1]
    names = [a.name for a in outcome.actions]
    assert names.count("grasplinks") >= 1 and names.count("releaselinks") == names.count("grasplinks") - 1
    if k == 24:  # 45 degrees are three steps: the macro makes each of them in one action
        assert any(n.endswith("45") for n in names)


def test_planhrc_solve_takes_the_bimanual_formulation():
    run = subprocess.run([sys.executable, "-m", "planhrc.cli", "solve", "--formulation", "bimanual",
                          "--orientations", "4", "--init", "0,0", "--goal", "90,180"],
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    assert "grasplinks" in run.stdout


@pytest.mark.reasoner
@pytest.mark.parametrize("reasoner", ["pellet", "hermit"])
def test_a_stored_bimanual_object_is_consistent(tmp_path, reasoner):
    db = tmp_path / "kb.sqlite3"
    with SqliteStore(str(db), TBOX) as kb:
        obj = make_object("obj1", "bimanual", 4, 8)
        kb.create_object(obj)
        kb.add_state("obj1", "perceived", obj.state([45, 90, 90]), [0.0, 45.0, 90.0, 90.0])
    report = check_ontology(TBOX, str(db), reasoner, timeout_s=300)
    assert report.consistent

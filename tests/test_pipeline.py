"""The planning pipeline end to end through the ontology, and `planhrc solve`."""
import json
from dataclasses import replace

import pytest

from planhrc import pipeline
from planhrc.cli import main
from planhrc.kb_service.store import SqliteStore
from planhrc.model import is_subsumed, make_object
from planhrc.paths import default_tbox_path
from planhrc.pipeline import config_from_settings, plan
from planhrc.planner.result import PlanResult, PlanStatus
from planhrc.settings import make_settings
from planhrc.translator import read_domain_model, translate
from planhrc.vocabulary import PlanningStatus
from tests.scenarios import SCENARIOS


@pytest.fixture
def config():
    return config_from_settings(make_settings())


def _setup(formulation, links, k, init_links, goal_links, ident="obj1"):
    obj = make_object(ident, formulation, links, k)
    init = obj.state(obj.joint_values_from_links(init_links))
    goal = obj.configuration_atoms(obj.joint_values_from_links(goal_links))
    return obj, init, goal


@pytest.mark.parametrize("formulation", ["relative", "absolute"])
@pytest.mark.parametrize("name", sorted(SCENARIOS))
def test_plan_returns_a_value_with_expected_states(config, formulation, name):
    sc = SCENARIOS[name]
    obj, init, goal = _setup(formulation, sc.links, sc.orientations, sc.init_links_deg, sc.goal_links_deg)
    outcome = plan(obj, init, goal, config)
    expected_length = sc.optimal_relative if formulation == "relative" else sc.optimal_absolute
    assert outcome.solved, outcome.message
    if expected_length == 0:
        assert outcome.actions == () and outcome.task is None  # nothing to do, no planner ran
        return
    assert len(outcome.actions) == expected_length and outcome.optimal
    states = outcome.expected_states
    assert len(states) == len(outcome.actions) + 1
    assert states[0] == init  # s^e_1 is the current state
    assert is_subsumed(states[-1], goal)  # s^e_N+1 is subsumed by the goal
    assert not any(is_subsumed(s, goal) for s in states[:-1])  # an optimal plan reaches it only at the end
    assert set(outcome.timings) >= {"translate", "plan", "validate", "expected_states"}


def test_the_value_is_stored_in_one_write_and_reads_back_equal(config, tmp_path):
    sc = SCENARIOS[sorted(SCENARIOS)[0]]
    db = str(tmp_path / "kb.sqlite3")
    with SqliteStore(db, default_tbox_path()) as kb:
        ident = kb.new_object_id()
        obj, init, goal = _setup("absolute", sc.links, sc.orientations, sc.init_links_deg, (90,) * sc.links, ident)
        outcome = plan(obj, init, goal, config)
        with kb.transaction():
            kb.create_object(obj)
            problem = kb.add_problem(ident, kb.add_state(ident, "initial", init).id,
                                     kb.add_state(ident, "goal", goal).id)
            stored = kb.add_plan(problem.id, outcome.planner, outcome.actions, outcome.expected_states)
    with SqliteStore(db, default_tbox_path()) as kb:  # read back from the database, not from a cache
        again = kb.get_plan(stored.id)
        assert tuple(a.spec for a in again.actions) == outcome.actions
        assert tuple(kb.get_state(s).atoms for s in again.expected_state_ids) == outcome.expected_states


def test_a_plan_val_rejects_is_refused(config, monkeypatch):
    obj, init, goal = _setup("relative", 3, 4, (0, 0, 0), (0, 90, 0))
    wrong = ("(rotateanticlockwise obj2_l2 obj2_l1 obj2_j1 deg_0 deg_270)",)  # names another object: VAL refuses
    monkeypatch.setattr(pipeline.stages, "run_planners",
                        lambda task, cfg, timeout_s=None: PlanResult(PlanStatus.SOLVED, wrong, 0.0, "stub"))
    outcome = plan(obj, init, goal, config)
    assert outcome.status == "invalid" and "replay" in outcome.message  # the replay refuses it before VAL
    assert outcome.actions == () and outcome.expected_states == ()
    solved = pipeline.PlanOutcome(PlanningStatus.SOLVED, "", "stub", None, (None,), (init, goal),  # type: ignore
                                  task=translate(obj, init, goal, read_domain_model(
                                      config.tbox_path, "relative"), "t"), steps=wrong)
    checked = pipeline.validate(solved, obj, config)
    assert checked.status == "invalid" and "VAL" in checked.message


def test_solve_command_json(capsys):
    code = main(["solve", "--formulation", "absolute", "--orientations", "4", "--init", "0,90,180",
                 "--goal", "90,90,0", "--json"])
    report = json.loads(capsys.readouterr().out)
    assert code == 0 and report["status"] == "solved" and report["optimal"]
    assert report["expected_states"][0] == [0, 90, 180] and report["expected_states"][-1] == [90, 90, 0]
    assert len(report["plan"]) == len(report["expected_states"]) - 1 == 4
    assert {"translate", "plan", "validate", "store", "total"} <= set(report["timings_s"])


def test_solve_command_partial_goal_and_macro_steps(capsys):
    code = main(["solve", "--formulation", "relative", "--orientations", "8", "--init", "0,0,0",
                 "--goal", "*,90,*", "--json"])
    report = json.loads(capsys.readouterr().out)
    assert code == 0 and len(report["plan"]) == 2
    assert report["expected_states"][-1][1] == 90
    assert report["macro_steps"] == [{"steps": [1, 2], "joint_index": 2, "turned_link_index": 3,
                                      "held_link_index": 2, "delta_deg": 90}]


@pytest.mark.parametrize("args,message", [
    (["--init", "0,45,0", "--goal", "0,0,0"], "init"),
    (["--init", "0,0,0", "--goal", "0,0"], "goal"),
    (["--init", "0,0,x", "--goal", "0,0,0"], "init[2]"),
    (["--init", "0,0,0", "--goal", "*,*,*"], "goal"),
])
def test_solve_command_refuses_bad_input(capsys, args, message):
    code = main(["solve", "--formulation", "absolute", "--orientations", "4", *args])
    assert code == 2
    assert message in capsys.readouterr().err


def test_a_task_the_in_process_planner_refuses_goes_to_the_fallback_planner(config, monkeypatch):
    """Isolates the fallback: the in-process planner is made to refuse the task; Fast Downward (real) plans it."""
    from planhrc.planner.inproc import InprocPlanner

    def refuse(self, domain, problem, timeout_s):
        return PlanResult(PlanStatus.ERROR, (), 0.0, "inproc", "domain: not a member of the rotation family")

    monkeypatch.setattr(InprocPlanner, "solve", refuse)
    obj, init, goal = _setup("relative", 4, 4, (0, 0, 0, 0), (0, 90, 90, 0))
    outcome = plan(obj, init, goal, config)
    assert outcome.solved and outcome.planner == "fd-lama"
    assert len(outcome.actions) == 2
    assert plan(obj, init, goal, replace(config, fallback_planner=None)).status == "error"


def test_a_plan_val_refuses_passes_the_task_to_the_next_planner(config, monkeypatch):
    """Isolates the pipeline's reaction to VAL's refusal: VAL (the real one) is handed a tampered copy of the
    in-process planner's plan; the next planner of the chain (Fast Downward, real) plans the task and VAL accepts it,
    and the answer's attempts say why the first plan was not taken."""
    real_validate = pipeline.stages.validate

    def tampered(outcome, obj, cfg, deadline_at=None):
        if outcome.planner == "inproc":
            outcome = replace(outcome, steps=outcome.steps[1:])  # VAL sees a plan without its first step
        return real_validate(outcome, obj, cfg, deadline_at)

    monkeypatch.setattr(pipeline.stages, "validate", tampered)
    obj, init, goal = _setup("relative", 4, 4, (0, 0, 0, 0), (0, 90, 90, 0))
    outcome = plan(obj, init, goal, config)
    assert outcome.solved and outcome.validated and outcome.planner == "fd-lama"
    refused = [a for a in outcome.attempts if a.status is PlanStatus.INVALID]
    assert [a.planner for a in refused] == ["inproc"] and "VAL" in refused[0].message
    alone = plan(obj, init, goal, replace(config, fallback_planner=None))  # no planner left: the refusal stands
    assert alone.status == "invalid" and not alone.actions

"""The planning pipeline end to end through the ontology, and `planhrc solve`."""
import json

import pytest

from planhrc.cli import main
from planhrc.kb.store import KnowledgeBase
from planhrc.model import is_subsumed, make_object
from planhrc.paths import default_tbox_path
from planhrc.pipeline import Planning, PlanningConfig
from planhrc.planner.result import PlanResult, PlanStatus
from tests.scenarios import SCENARIOS


@pytest.fixture
def kb():
    with KnowledgeBase(None, default_tbox_path()) as kb:
        yield kb


def _setup(kb, formulation, links, k, init_links, goal_links):
    oid = kb.new_object_id()
    obj = make_object(oid, formulation, links, k)
    kb.create_object(obj)
    init = kb.add_state(oid, "initial", obj.state(obj.joint_values_from_links(init_links)))
    goal = kb.add_state(oid, "goal", obj.configuration_atoms(obj.joint_values_from_links(goal_links)))
    return obj, init, goal


@pytest.mark.parametrize("formulation", ["relative", "absolute"])
@pytest.mark.parametrize("name", sorted(SCENARIOS))
def test_plan_is_stored_with_expected_states(kb, formulation, name):
    sc = SCENARIOS[name]
    obj, init, goal = _setup(kb, formulation, sc.links, sc.orientations, sc.init_links_deg, sc.goal_links_deg)
    planning = Planning(PlanningConfig(default_tbox_path()))
    outcome = planning.make_plan(kb, obj.ident, init.id, goal.id)
    expected_length = sc.optimal_relative if formulation == "relative" else sc.optimal_absolute
    if expected_length == 0:
        assert outcome.status == "solved" and outcome.plan is None  # nothing to do
        return
    assert outcome.status == "solved", outcome.message
    plan = kb.get_plan(outcome.plan.id)
    assert len(plan.actions) == expected_length and outcome.optimal
    states = [kb.get_state(s).atoms for s in plan.expected_state_ids]
    assert states[0] == init.atoms  # s^e_1 is the current state
    assert is_subsumed(states[-1], goal.atoms)  # s^e_N+1 is subsumed by the goal
    assert not any(is_subsumed(s, goal.atoms) for s in states[:-1])  # an optimal plan reaches it only at the end
    assert kb.get_problem(outcome.problem_id).init_state_id == init.id
    assert set(outcome.timings) >= {"translate", "plan", "validate", "expected_states", "store"}


def test_a_plan_val_rejects_is_never_stored(kb, monkeypatch):
    obj, init, goal = _setup(kb, "relative", 3, 4, (0, 0, 0), (0, 90, 0))
    planning = Planning(PlanningConfig(default_tbox_path()))
    wrong = ("(rotateanticlockwise o_l2 o_l1 o_j1 deg_0 deg_270)",)  # names another object: VAL refuses it
    wrong = tuple(step.replace("o_", f"{obj.ident}_") for step in wrong)
    monkeypatch.setattr(planning, "run_planner",
                        lambda task, i, g: PlanResult(PlanStatus.SOLVED, wrong, 0.0, "stub"))
    before = kb.triple_count()
    outcome = planning.make_plan(kb, obj.ident, init.id, goal.id)
    assert outcome.status == "invalid" and "VAL" in outcome.message
    assert outcome.plan is None and kb.latest_plan(obj.ident) is None
    assert kb.triple_count() - before < 50  # only the Problem individual was added


def test_replanning_reuses_the_grounded_task(kb):
    obj, init, goal = _setup(kb, "absolute", 6, 8, (0,) * 6, (45, 90, 0, 315, 0, 45))
    planning = Planning(PlanningConfig(default_tbox_path()))
    first = planning.make_plan(kb, obj.ident, init.id, goal.id)
    grounded = planning._ground[obj.ident][1]
    perceived = kb.add_state(obj.ident, "perceived", obj.state((90, 90, 0, 0, 0, 0)),
                             link_orientations_deg=(90, 90, 0, 0, 0, 0))
    second = planning.make_plan(kb, obj.ident, perceived.id, goal.id)
    assert first.status == second.status == "solved"
    assert planning._ground[obj.ident][1] is grounded


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


def test_a_task_the_in_process_planner_refuses_goes_to_the_fallback_planner(kb, monkeypatch):
    """Isolates the fallback: grounding is made to refuse the task; Fast Downward (real) then plans it."""
    import planhrc.pipeline as pipeline
    from planhrc.planner.errors import PlannerError

    def refuse(domain, problem):
        raise PlannerError("domain: not a member of the rotation family")

    monkeypatch.setattr(pipeline, "ground_task", refuse)
    obj, init, goal = _setup(kb, "relative", 4, 4, (0, 0, 0, 0), (0, 90, 90, 0))
    outcome = Planning(PlanningConfig(default_tbox_path())).make_plan(kb, obj.ident, init.id, goal.id)
    assert outcome.status == "solved" and outcome.planner == "fd-lama"
    assert len(outcome.plan.actions) == 2
    none = Planning(PlanningConfig(default_tbox_path(), fallback_planner=None))
    assert none.make_plan(kb, obj.ident, init.id, goal.id).status == "error"

"""A bimanual object in the service: selected at `POST /objects`, planned with its grippers, driven by a
simulated worker to its goal, in process and over HTTP (with a restart in the middle of its plan).

A perception gives only the links' orientations; the grippers and the centre are the robot's own state, which the
service follows from the worker's feedback (`planhrc.control`). The tests check that it does: after a grasp the
next perception matches the expected state that holds the grasp, after a failed turn the worker has let go (the
robot resumes from the state before its grasp), and a human moving the object while the robot holds nothing gives
continue, goal reached or re-plan as for the other formulations.
"""
from __future__ import annotations

import warnings

import httpx
import pytest

with warnings.catch_warnings():
    warnings.simplefilter("ignore")  # starlette's notice about httpx2
    from fastapi.testclient import TestClient

from planhrc.kb_service.app import create_app
from planhrc.planner.validate import validate_plan
from planhrc.settings import make_settings
from tests.servers import serving, store_location
from tests.test_service_api import move, new_object, noisy, perceive

GOAL = [0, 90, 90, 180]  # link orientations: j1..j3 carry 90, 90, 180 from l1
TURNS = ("rotateclockwise", "rotateanticlockwise", "rotateclockwise45", "rotateanticlockwise45")  # the TBox's turns


@pytest.fixture
def client():
    with TestClient(create_app(make_settings(db_path=None, token=None, merge_macro_steps=False))) as c:
        yield c


def act(client, oid: str, links: list[float], outcome: str = "succeeded",
        moved: bool = True) -> tuple[list[float], dict]:
    """The worker takes the next action, turns the links if `moved`, and reports `outcome`."""
    action = client.post(f"/objects/{oid}/actions/next").json()
    assert action is not None
    r = client.post(f"/objects/{oid}/actions/{action['id']}/feedback", json={"outcome": outcome})
    assert r.status_code == 200 and r.json()["accepted"] == "current", r.text
    return (move(links, action) if moved else links), action


def holding(state: dict) -> set[str]:
    return {a for a in state["atoms"] if a.startswith("(holding ")}


def test_a_bimanual_object_is_created_and_its_goal_names_joints_from_link_one(client):
    oid = new_object(client, formulation="bimanual")
    obj = client.get(f"/objects/{oid}").json()
    assert obj["formulation"] == "bimanual" and len(obj["joints"]) == 3
    schema = client.get("/openapi.json").json()["components"]["schemas"]
    assert "bimanual" in schema["Formulation"]["enum"]
    assert client.put(f"/objects/{oid}/goal", json={"link_orientations_deg": [90, 180, 180, 270]}).status_code == 200
    perceive(client, oid, noisy([0, 0, 0, 0]))
    problem = client.get(f"/objects/{oid}/pddl/problem").text
    for fact in ("(hasorientation deg_90 obj1_j1)", "(hasorientation deg_90 obj1_j2)",
                 "(hasorientation deg_180 obj1_j3)", "(free left)", "(free right)"):
        assert fact in problem
    assert "(:requirements" in client.get(f"/objects/{oid}/pddl/domain").text


def test_nominal_bimanual_episode_grasps_turns_releases_and_reaches_the_goal(client):
    oid = new_object(client, formulation="bimanual")
    client.put(f"/objects/{oid}/goal", json={"link_orientations_deg": GOAL})
    links = [0.0, 0.0, 0.0, 0.0]
    answers = [perceive(client, oid, noisy(links))]
    assert answers[0]["decision"] == "replan"
    plan = client.get(f"/objects/{oid}/plan").json()
    names = [s["name"] for s in plan["steps"]]
    assert {"grasplinks", "movetocentre"} <= set(names) and any(n in TURNS for n in names)
    for step in plan["steps"]:  # a turn is made only by a joint both grippers hold
        if step["name"] in TURNS:
            assert holding(plan["expected_states"][step["step"] - 1])
    while answers[-1]["decision"] != "goal_reached":
        assert len(answers) <= len(names) + 1, answers[-1]
        links, action = act(client, oid, links)
        assert (action["delta_deg"] != 0) == (action["name"] in TURNS)
        answers.append(perceive(client, oid, noisy(links)))
        assert answers[-1]["decision"] in ("continue", "goal_reached"), answers[-1]
    # every perception after a step matched the expected state after it: grasps included, which no camera sees
    assert [a["matched_expected_step"] for a in answers[1:-1]] == list(range(2, len(answers)))
    assert [round(v - links[0]) % 360 for v in links] == GOAL
    domain, problem = (client.get(f"/objects/{oid}/pddl/{part}").text for part in ("domain", "problem"))
    steps = [f"({s['name']} {' '.join(s['params'])})" for s in plan["steps"]]
    assert validate_plan(domain, problem, steps).valid
    assert not validate_plan(domain, problem, [s for s in steps if not s.startswith("(grasplinks")]).valid
    assert client.get(f"/objects/{oid}").json()["execution"]["status"] == "goal_reached"


def to_the_first_turn(client) -> tuple[str, list[float], dict]:
    """A bimanual object with the goal, its plan followed until its next action is its first turn: (object id,
    links, the last answer)."""
    oid = new_object(client, formulation="bimanual")
    client.put(f"/objects/{oid}/goal", json={"link_orientations_deg": GOAL})
    links = [0.0, 0.0, 0.0, 0.0]
    answer = perceive(client, oid, noisy(links))
    while answer["next_action"]["name"] not in TURNS:
        links, _ = act(client, oid, links)
        answer = perceive(client, oid, noisy(links))
        assert answer["decision"] == "continue"
    return oid, links, answer


def test_a_failed_turn_lets_go_and_the_robot_resumes_from_its_grasp(client):
    oid, links, answer = to_the_first_turn(client)
    turn = answer["next_action"]
    links, _ = act(client, oid, links, "failed", moved=False)
    answer = perceive(client, oid, noisy(links))
    # nothing turned, but the worker opened its hands: the state before the grasp, so the grasp comes again
    assert answer["decision"] == "resume" and answer["matched_expected_step"] == turn["step"] - 1
    assert answer["next_action"]["name"] == "grasplinks"


def test_a_turn_done_with_the_hands_opened_after_it_continues_past_the_release(client):
    """The worker turned, then opened its hands (they hid a link from every camera): the service counts on open
    hands, so the next perception is the state after the plan's release and the robot goes on from there."""
    oid, links, _ = to_the_first_turn(client)
    plan = client.get(f"/objects/{oid}/plan").json()
    turn = client.post(f"/objects/{oid}/actions/next").json()
    following = [s["name"] for s in plan["steps"][turn["step"]:]]
    r = client.post(f"/objects/{oid}/actions/{turn['id']}/feedback", json={"outcome": "succeeded", "hands_open": True})
    assert r.status_code == 200, r.text
    links = move(links, turn)
    events = client.get(f"/objects/{oid}/events").json()
    feedback = [e for e in events if e["kind"] == "feedback"][-1]
    assert "then the hands opened" in feedback["reason"]
    answer = perceive(client, oid, noisy(links))
    assert following[0] == "releaselinks"  # the plan lets go after this turn: that is done already
    assert answer["decision"] == "resume" and answer["matched_expected_step"] == turn["step"] + 2
    assert answer["next_action"]["name"] in ("movetocentre", "grasplinks")
    # the perceived state holds no grasp: nothing the hands no longer hold
    state = client.get(f"/states/{answer['perceived_state_id']}").json()
    assert not holding(state)


def test_hands_open_is_refused_for_an_object_without_hands_and_changes_nothing(client):
    oid = new_object(client)  # relative
    client.put(f"/objects/{oid}/goal", json={"link_orientations_deg": GOAL})
    perceive(client, oid, noisy([0.0, 0.0, 0.0, 0.0]))
    action = client.post(f"/objects/{oid}/actions/next").json()
    before = client.get(f"/objects/{oid}").json()["execution"]
    r = client.post(f"/objects/{oid}/actions/{action['id']}/feedback", json={"outcome": "succeeded", "hands_open": True})
    assert r.status_code == 409 and r.json()["detail"].startswith("hands_open: ") and "\n" not in r.json()["detail"]
    assert client.get(f"/objects/{oid}").json()["execution"] == before
    r = client.post(f"/objects/{oid}/actions/{action['id']}/feedback", json={"outcome": "succeeded", "hands_open": 3})
    assert r.status_code == 422, r.text


def test_a_human_moving_the_object_while_the_robot_holds_nothing(client):
    oid = new_object(client, formulation="bimanual")
    client.put(f"/objects/{oid}/goal", json={"link_orientations_deg": GOAL})
    links = [0.0, 0.0, 0.0, 0.0]
    answer = perceive(client, oid, noisy(links))
    plan_id = answer["plan_id"]
    while answer["next_action"]["name"] != "releaselinks":
        links, _ = act(client, oid, links)
        answer = perceive(client, oid, noisy(links))
    links, _ = act(client, oid, links)  # released: the robot holds nothing now
    answer = perceive(client, oid, noisy(links))
    assert answer["decision"] == "continue"
    step = answer["matched_expected_step"]

    # the whole object turned by a step: the joints carry the same angles from l1, nothing changed
    links = [(v + 90) % 360 for v in links]
    answer = perceive(client, oid, noisy(links))
    assert (answer["decision"], answer["matched_expected_step"]) == ("continue", step)

    # a human turns l4 by 90 degrees: the last joint's turn is done, so is the plan (the goal names no grippers)
    links[3] = (links[3] + 90) % 360
    answer = perceive(client, oid, noisy(links))
    assert answer["decision"] == "goal_reached"

    # knocked off every expected state: a new plan from the perceived state and the robot's control facts
    links[2] = (links[2] + 180) % 360
    client.put(f"/objects/{oid}/goal", json={"link_orientations_deg": GOAL})
    answer = perceive(client, oid, noisy(links))
    assert answer["decision"] == "replan" and answer["plan_id"] != plan_id
    first = client.get(f"/objects/{oid}/plan").json()["expected_states"][0]
    assert not holding(first)


@pytest.mark.integration
@pytest.mark.parametrize("backend", ["sqlite", "postgresql"])
def test_bimanual_episode_over_http_with_a_restart_in_the_middle(tmp_path, backend, request):
    """Create, goal, perceive, take actions, feedback over HTTP; the service restarts while the robot holds the
    links, and the next perception still matches the expected state with the grasp (the control facts are kept
    with the feedback events it reads back)."""
    db = store_location(backend, tmp_path, request)
    env = {"PLANHRC_MERGE_MACRO_STEPS": "false"}
    links = [0.0, 0.0, 0.0, 0.0]
    with serving(db, env=env, folder=tmp_path) as base, httpx.Client(base_url=base, timeout=60) as c:
        oid = new_object(c, formulation="bimanual")
        assert c.put(f"/objects/{oid}/goal", json={"link_orientations_deg": GOAL}).status_code == 200
        answer = perceive(c, oid, noisy(links))
        assert answer["decision"] == "replan"
        while answer["next_action"]["name"] != "grasplinks":
            links, _ = act(c, oid, links)
            answer = perceive(c, oid, noisy(links))
        links, grasp = act(c, oid, links)
    with serving(db, env=env, folder=tmp_path) as base, httpx.Client(base_url=base, timeout=60) as c:
        answer = perceive(c, oid, noisy(links))
        assert (answer["decision"], answer["matched_expected_step"]) == ("continue", grasp["step"] + 1)
        while answer["decision"] != "goal_reached":
            assert answer["decision"] == "continue", answer
            links, _ = act(c, oid, links)
            answer = perceive(c, oid, noisy(links))
        assert [round(v - links[0]) % 360 for v in links] == GOAL
        assert c.get(f"/objects/{oid}").json()["execution"]["status"] == "goal_reached"

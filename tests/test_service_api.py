"""The knowledge-base service in process (FastAPI TestClient) on an in-memory store.

`move` and `links_of` are a small kinematic simulation shared with the integration tests: they apply a
next_action's motion to the link orientations, as a worker would.
"""
from __future__ import annotations

import json
import re
import warnings

import pytest

with warnings.catch_warnings():
    warnings.simplefilter("ignore")  # starlette's notice about httpx2
    from fastapi.testclient import TestClient

from planhrc.kb_service.app import create_app
from planhrc.kb_service import schemas
from planhrc.model import absolute_from_relative
from planhrc.settings import make_settings
from tests.servers import settled_health

TOKEN = "s3cret"


# -- a kinematic simulation: absolute link orientations, one per link -----------------------------------------
def move(links: list[float], motion: dict) -> list[float]:
    """Turn the link `turned_link_index` by `delta_deg`, with every link beyond it (away from the held one)."""
    turned, held, delta = motion["turned_link_index"], motion["held_link_index"], motion["delta_deg"]
    out = list(links)
    moving = range(turned, len(links) + 1) if turned > held else range(1, turned + 1)
    for k in moving:
        out[k - 1] = (out[k - 1] + delta) % 360
    return out


def links_of(state: dict, formulation: str, first_link_deg: int = 0) -> list[int]:
    """Link orientations of a complete StatePublic (relative: l1 placed at `first_link_deg`)."""
    values = [v for _, v in sorted(state["joint_values_deg"].items(), key=lambda kv: int(kv[0].rsplit("j", 1)[1]))]
    if formulation == "absolute":
        return values
    return list(absolute_from_relative(first_link_deg, values))


def noisy(links: list[float], amplitude: float = 7.0) -> list[float]:
    """Perception noise well below half a step (K <= 8), alternating in sign."""
    return [v + (amplitude if i % 2 else -amplitude) + 0.3 for i, v in enumerate(links)]


# -- fixtures -----------------------------------------------------------------------------------------------
@pytest.fixture
def client():
    """One plan step per dispatched action, so the tests can name every expected state."""
    with TestClient(create_app(make_settings(db_path=None, token=None, merge_macro_steps=False))) as c:
        yield c


@pytest.fixture
def macro_client():
    """The service's default: consecutive steps of one joint in one direction dispatched as one motion."""
    with TestClient(create_app(make_settings(db_path=None, token=None))) as c:
        yield c


@pytest.fixture
def auth_client():
    with TestClient(create_app(make_settings(db_path=None, token=TOKEN))) as c:
        yield c


def new_object(client, links=4, orientations=4, formulation="relative", headers=None) -> str:
    r = client.post("/objects", json={"name": "rod", "links": links, "orientations": orientations,
                                      "formulation": formulation}, headers=headers)
    assert r.status_code == 201, r.text
    return r.json()["id"]


def perceive(client, oid, links, key=None, headers=None) -> dict:
    h = dict(headers or {})
    if key:
        h["Idempotency-Key"] = key
    r = client.post(f"/objects/{oid}/perceptions", json={"link_orientations_deg": links}, headers=h)
    assert r.status_code == 200, r.text
    return r.json()


def kb_size(client, oid) -> tuple[int, int]:
    """(number of events, number of triples): both unchanged when a request is refused."""
    return len(client.get(f"/objects/{oid}/events").json()), settled_health(client)["triples"]


def drive_to_goal(client, oid, links, formulation, max_steps=40) -> tuple[list[float], list[dict]]:
    """Worker loop: perceive, fetch the next action, execute it, report success; until the goal is reached."""
    answers = []
    for _ in range(max_steps):
        answer = perceive(client, oid, noisy(links))
        answers.append(answer)
        if answer["decision"] == "goal_reached":
            return links, answers
        action = client.post(f"/objects/{oid}/actions/next").json()
        assert action is not None and action["id"] == answer["next_action"]["id"]
        links = move(links, action)
        r = client.post(f"/objects/{oid}/actions/{action['id']}/feedback", json={"outcome": "succeeded"})
        assert r.status_code == 200 and r.json()["accepted"] == "current", r.text
    raise AssertionError(f"goal not reached in {max_steps} steps: {answers[-1]}")


# -- objects ------------------------------------------------------------------------------------------------
def test_create_list_and_read_objects(client):
    links = [{"name": "base", "length_m": 0.1}, {"name": "mid", "length_m": 0.2}, {"name": "tip", "length_m": 0.3}]
    oid = new_object(client, links=links, orientations=8, formulation="absolute")
    obj = client.get(f"/objects/{oid}").json()
    assert obj["formulation"] == "absolute" and obj["step_deg"] == 45
    assert [link["length_m"] for link in obj["links"]] == [0.1, 0.2, 0.3]
    assert len(obj["joints"]) == 3
    assert obj["execution"]["status"] == "idle"
    assert [o["id"] for o in client.get("/objects").json()] == [oid]


@pytest.mark.parametrize("body, field", [
    ({"name": "x", "links": 4, "orientations": 7, "formulation": "relative"}, "orientations"),
    ({"name": "x", "links": 1, "orientations": 4, "formulation": "relative"}, "links"),
    ({"name": "x", "links": 3, "orientations": 4, "formulation": "polar"}, "formulation"),
    ({"name": "x", "links": [{"name": "a", "length_m": -1}, {"name": "b", "length_m": 1}], "orientations": 4,
      "formulation": "relative"}, "length_m"),
])
def test_bad_object_is_refused_naming_the_field(client, body, field):
    r = client.post("/objects", json=body)
    assert r.status_code == 422
    assert field in r.json()["detail"]
    assert client.get("/objects").json() == []


def test_unknown_object_is_404(client):
    assert client.get("/objects/nope").status_code == 404
    assert client.put("/objects/nope/goal", json={"joint_angles_deg": [0]}).status_code == 404
    assert client.post("/objects/nope/perceptions", json={"link_orientations_deg": [0, 0]}).status_code == 404
    assert client.post("/objects/nope/actions/next").status_code == 404
    assert client.get("/objects/nope/events").status_code == 404
    assert client.get("/states/nope").status_code == 404
    assert client.get("/plans/nope").status_code == 404
    assert client.get("/problems/nope").status_code == 404


# -- goals ----------------------------------------------------------------------------------------------
def test_goal_before_any_perception_waits_for_the_first_one(client):
    oid = new_object(client)
    r = client.put(f"/objects/{oid}/goal", json={"link_orientations_deg": [0, 90, 90, 180]})
    assert r.status_code == 200
    body = r.json()
    assert body["problem_id"] is None
    goal = client.get(f"/states/{body['goal_state_id']}").json()
    assert goal["kind"] == "goal"
    assert goal["joint_values_deg"] == {f"{oid}_j1": 90, f"{oid}_j2": 0, f"{oid}_j3": 90}
    assert client.get(f"/objects/{oid}").json()["goal_state_id"] == body["goal_state_id"]
    answer = perceive(client, oid, [0, 0, 0, 0])
    assert answer["decision"] == "replan"
    plan = client.get(f"/objects/{oid}/plan").json()
    problem = client.get(f"/problems/{plan['problem_id']}").json()
    assert problem["goal_state_id"] == body["goal_state_id"]
    assert problem["init_state_id"] == answer["perceived_state_id"]


def test_goal_after_a_perception_stores_a_problem(client):
    oid = new_object(client)
    first = perceive(client, oid, [0, 0, 0, 0])
    assert first["decision"] == "no_plan" and "goal" in first["reason"]
    body = client.put(f"/objects/{oid}/goal", json={"joint_angles_deg": [90, None, 90]}).json()
    problem = client.get(f"/problems/{body['problem_id']}").json()
    assert problem["init_state_id"] == first["perceived_state_id"]
    assert len(client.get(f"/states/{body['goal_state_id']}").json()["atoms"]) == 2  # a partial goal


@pytest.mark.parametrize("body, field", [
    ({"link_orientations_deg": [0, 90, 90]}, "link_orientations_deg"),
    ({"link_orientations_deg": [0, 90, 45, 0]}, "link_orientations_deg[2]"),
    ({"joint_angles_deg": [90, 0]}, "joint_angles_deg"),
    ({"joint_angles_deg": [None, None, None]}, "joint_angles_deg"),
    ({"joint_angles_deg": [0, 0, 0], "link_orientations_deg": [0, 0, 0, 0]}, "joint_angles_deg"),
    ({}, "link_orientations_deg"),
])
def test_bad_goal_is_refused_naming_the_field(client, body, field):
    oid = new_object(client)
    before = kb_size(client, oid)
    r = client.put(f"/objects/{oid}/goal", json=body)
    assert r.status_code == 422, r.text
    assert field in r.json()["detail"]
    assert kb_size(client, oid) == before


@pytest.mark.parametrize("raw", [b"NaN", b"Infinity", b"-Infinity", b"1e999"])
def test_nan_and_infinity_are_refused_and_nothing_is_stored(client, raw):
    oid = new_object(client)
    client.put(f"/objects/{oid}/goal", json={"link_orientations_deg": [0, 90, 90, 180]})
    before = kb_size(client, oid)
    body = b'{"link_orientations_deg": [0, 1, ' + raw + b', 2]}'
    r = client.post(f"/objects/{oid}/perceptions", content=body, headers={"content-type": "application/json"})
    assert r.status_code == 422
    assert "link_orientations_deg[2]" in r.json()["detail"]
    r = client.put(f"/objects/{oid}/goal", content=b'{"joint_angles_deg": [' + raw + b', 0, 0]}',
                   headers={"content-type": "application/json"})
    assert r.status_code == 422 and "joint_angles_deg[0]" in r.json()["detail"]
    assert kb_size(client, oid) == before


def test_wrong_number_of_perceived_values_is_refused(client):
    oid = new_object(client)
    before = kb_size(client, oid)
    r = client.post(f"/objects/{oid}/perceptions", json={"link_orientations_deg": [0, 0, 0]})
    assert r.status_code == 422
    assert "link_orientations_deg" in r.json()["detail"] and "4" in r.json()["detail"]
    assert kb_size(client, oid) == before


# -- the cooperation loop ------------------------------------------------------------------------------------
@pytest.mark.parametrize("formulation, k, goal", [
    ("relative", 4, [0, 90, 90, 180]),
    ("absolute", 4, [90, 90, 180, 180]),
    ("relative", 8, [0, 45, 90, 90]),
    ("absolute", 8, [45, 0, 0, 315]),
])
def test_nominal_episode_reaches_the_goal(client, formulation, k, goal):
    oid = new_object(client, orientations=k, formulation=formulation)
    client.put(f"/objects/{oid}/goal", json={"link_orientations_deg": goal})
    links, answers = drive_to_goal(client, oid, [0, 0, 0, 0], formulation)
    assert [a["decision"] for a in answers[1:-1]] == ["continue"] * (len(answers) - 2)
    assert answers[0]["decision"] == "replan"
    assert all(a["matched_expected_step"] == i + 1 for i, a in enumerate(answers[:-1]) if i > 0)
    assert answers[-1]["next_action"] is None
    plan = client.get(f"/objects/{oid}/plan").json()
    assert len(answers) == len(plan["steps"]) + 1
    if formulation == "absolute":
        assert [v % 360 for v in links] == goal
    assert client.get(f"/objects/{oid}").json()["execution"]["status"] == "goal_reached"
    assert client.post(f"/objects/{oid}/actions/next").json() is None
    kinds = [e["kind"] for e in client.get(f"/objects/{oid}/events").json()]
    assert kinds[-1] == "goal_reached" and kinds.count("continue") == len(plan["steps"]) - 1


def test_plan_lists_steps_and_expected_states(client):
    oid = new_object(client)
    client.put(f"/objects/{oid}/goal", json={"link_orientations_deg": [0, 180, 180, 0]})
    answer = perceive(client, oid, [0, 0, 0, 0])
    plan = client.get(f"/objects/{oid}/plan").json()
    assert plan == client.get(f"/plans/{answer['plan_id']}").json()
    n = len(plan["steps"])
    assert n == 4
    assert len(plan["expected_states"]) == n + 1
    assert all(s["kind"] == "expected" for s in plan["expected_states"])
    assert [s["step"] for s in plan["steps"]] == list(range(1, n + 1))
    # s^e_{j+1} = apply(a_j, s^e_j): the orientation a_j adds is in the next expected state.
    for step, after in zip(plan["steps"], plan["expected_states"][1:]):
        assert set(step["eff_pos"]) <= set(after["atoms"])


def test_human_skipping_ahead_resumes_from_a_later_expected_state(client):
    oid = new_object(client)
    client.put(f"/objects/{oid}/goal", json={"link_orientations_deg": [0, 180, 180, 0]})
    first = perceive(client, oid, [0, 0, 0, 0])
    plan = client.get(f"/objects/{oid}/plan").json()
    human = links_of(plan["expected_states"][2], "relative")  # a human did a_1 and a_2
    answer = perceive(client, oid, noisy(human))
    assert answer["decision"] == "resume"
    assert answer["plan_id"] == first["plan_id"]
    assert answer["matched_expected_step"] == 3
    assert answer["next_action"]["step"] == 3
    assert client.post(f"/objects/{oid}/actions/next").json()["step"] == 3


def test_disturbance_forces_a_replan(client):
    oid = new_object(client)
    client.put(f"/objects/{oid}/goal", json={"link_orientations_deg": [0, 90, 90, 180]})
    first = perceive(client, oid, [0, 0, 0, 0])
    # j1 turned by 180: the state is on no expected state and a_1 (turn j1 from 0) is not executable
    answer = perceive(client, oid, noisy([0, 180, 180, 180]))
    assert answer["decision"] == "replan"
    assert answer["plan_id"] != first["plan_id"]
    assert answer["matched_expected_step"] is None
    assert "re-plan" in answer["reason"]
    links, answers = drive_to_goal(client, oid, [0, 180, 180, 180], "relative")
    assert answers[-1]["decision"] == "goal_reached"


def test_failed_action_is_retried_when_nothing_moved(client):
    oid = new_object(client)
    client.put(f"/objects/{oid}/goal", json={"link_orientations_deg": [0, 90, 90, 180]})
    perceive(client, oid, [0, 0, 0, 0])
    action = client.post(f"/objects/{oid}/actions/next").json()
    r = client.post(f"/objects/{oid}/actions/{action['id']}/feedback", json={"outcome": "failed"})
    assert r.json()["execution"] == {"plan_id": action["plan_id"], "next_step": 1, "status": "ready",
                                     "dispatched_action_id": None}
    answer = perceive(client, oid, noisy([0, 0, 0, 0]))
    assert answer["decision"] == "continue" and answer["next_action"]["id"] == action["id"]
    assert "retry" in answer["reason"] and "failed" in answer["reason"]


def test_feedback_for_a_non_current_or_unknown_action(client):
    oid = new_object(client)
    client.put(f"/objects/{oid}/goal", json={"link_orientations_deg": [0, 180, 180, 0]})
    answer = perceive(client, oid, [0, 0, 0, 0])
    plan = client.get(f"/objects/{oid}/plan").json()
    first = plan["steps"][0]["id"]
    # nothing dispatched yet
    assert client.post(f"/objects/{oid}/actions/{first}/feedback", json={"outcome": "succeeded"}).status_code == 409
    client.post(f"/objects/{oid}/actions/next")
    before = kb_size(client, oid)
    r = client.post(f"/objects/{oid}/actions/{plan['steps'][1]['id']}/feedback", json={"outcome": "succeeded"})
    assert r.status_code == 409 and "action_id" in r.json()["detail"]
    r = client.post(f"/objects/{oid}/actions/no_such_action/feedback", json={"outcome": "succeeded"})
    assert r.status_code == 404
    r = client.post(f"/objects/{oid}/actions/{first}/feedback", json={"outcome": "exploded"})
    assert r.status_code == 422 and "outcome" in r.json()["detail"]
    assert kb_size(client, oid) == before
    assert answer["next_action"]["id"] == first


def test_perception_while_dispatched_and_late_feedback(client):
    oid = new_object(client)
    client.put(f"/objects/{oid}/goal", json={"link_orientations_deg": [0, 180, 180, 0]})
    perceive(client, oid, [0, 0, 0, 0])
    action = client.post(f"/objects/{oid}/actions/next").json()
    # the same configuration perceived while the action runs: it stays dispatched
    assert perceive(client, oid, [0, 0, 0, 0])["decision"] == "continue"
    assert client.get(f"/objects/{oid}").json()["execution"]["status"] == "dispatched"
    links = move([0, 0, 0, 0], action)
    after = perceive(client, oid, noisy(links))  # the action's effect is seen before its feedback
    after_motion = action["last_step"] + 1  # the motion may be a macro step covering several plan steps
    assert (after["decision"], after["matched_expected_step"]) == ("resume", after_motion)
    r = client.post(f"/objects/{oid}/actions/{action['id']}/feedback", json={"outcome": "succeeded"})
    assert r.status_code == 200 and r.json()["accepted"] == "late"
    # the perception already moved on; the feedback does not move it again
    assert r.json()["execution"]["next_step"] == after_motion
    assert client.post(f"/objects/{oid}/actions/next").json()["step"] == after_motion


def test_unsolvable_or_failed_planning_answers_no_plan(client, monkeypatch):
    from planhrc import pipeline
    from planhrc.vocabulary import PlanningStatus

    monkeypatch.setattr(pipeline.stages, "find_plan",
                        lambda *a, **k: pipeline.PlanOutcome(PlanningStatus.UNSOLVABLE, "no plan exists", "stub"))
    oid = new_object(client)
    client.put(f"/objects/{oid}/goal", json={"link_orientations_deg": [0, 90, 90, 180]})
    answer = perceive(client, oid, [0, 0, 0, 0])
    assert answer["decision"] == "no_plan" and "unsolvable" in answer["reason"]
    assert client.post(f"/objects/{oid}/actions/next").json() is None
    assert client.get(f"/objects/{oid}").json()["execution"]["status"] == "no_plan"


# -- idempotency ------------------------------------------------------------------------------------------------
def test_idempotent_perception_returns_the_first_answer_and_stores_nothing(client):
    oid = new_object(client)
    client.put(f"/objects/{oid}/goal", json={"link_orientations_deg": [0, 90, 90, 180]})
    first = perceive(client, oid, [0, 0, 0, 0], key="p-1")
    before = kb_size(client, oid)
    again = perceive(client, oid, [0, 0, 0, 0], key="p-1")
    assert again == first
    assert kb_size(client, oid) == before
    r = client.post(f"/objects/{oid}/perceptions", json={"link_orientations_deg": [90, 0, 0, 0]},
                    headers={"Idempotency-Key": "p-1"})
    assert r.status_code == 409 and "Idempotency-Key" in r.json()["detail"]
    assert perceive(client, oid, [0, 0, 0, 0], key="p-2")["perceived_state_id"] != first["perceived_state_id"]


def test_idempotent_feedback(client):
    oid = new_object(client)
    client.put(f"/objects/{oid}/goal", json={"link_orientations_deg": [0, 90, 90, 180]})
    perceive(client, oid, [0, 0, 0, 0])
    action = client.post(f"/objects/{oid}/actions/next").json()
    url = f"/objects/{oid}/actions/{action['id']}/feedback"
    one = client.post(url, json={"outcome": "succeeded"}, headers={"Idempotency-Key": "f-1"})
    two = client.post(url, json={"outcome": "succeeded"}, headers={"Idempotency-Key": "f-1"})
    assert one.status_code == two.status_code == 200 and one.json() == two.json()
    assert client.post(url, json={"outcome": "succeeded"}).status_code == 409


# -- authentication -------------------------------------------------------------------------------------------
def test_token_guards_every_write_and_leaves_reads_open(auth_client):
    c = auth_client
    body = {"name": "rod", "links": 3, "orientations": 4, "formulation": "relative"}
    assert c.post("/objects", json=body).status_code == 401
    assert c.post("/objects", json=body, headers={"Authorization": "Bearer wrong"}).status_code == 401
    assert c.get("/objects").json() == []
    good = {"Authorization": f"Bearer {TOKEN}"}
    oid = new_object(c, links=3, headers=good)
    before = kb_size(c, oid)
    r = c.put(f"/objects/{oid}/goal", json={"joint_angles_deg": [90, 0]})
    assert r.status_code == 401 and r.headers["www-authenticate"] == "Bearer"
    assert c.post(f"/objects/{oid}/perceptions", json={"link_orientations_deg": [0, 0, 0]}).status_code == 401
    assert c.post(f"/objects/{oid}/actions/next").status_code == 401
    assert c.post(f"/objects/{oid}/actions/x/feedback", json={"outcome": "failed"}).status_code == 401
    assert kb_size(c, oid) == before
    assert c.put(f"/objects/{oid}/goal", json={"joint_angles_deg": [90, 0]}, headers=good).status_code == 200
    assert perceive(c, oid, [0, 0, 0], headers=good)["decision"] == "replan"
    for path in (f"/objects/{oid}", f"/objects/{oid}/plan", f"/objects/{oid}/events", "/health",
                 f"/objects/{oid}/pddl/domain", f"/objects/{oid}/pddl/problem"):
        assert c.get(path).status_code == 200, path


# -- records, PDDL, ontology, events, health -------------------------------------------------------------------
def test_pddl_domain_and_problem(client):
    oid = new_object(client, formulation="absolute")
    assert client.get(f"/objects/{oid}/pddl/problem").status_code == 404
    domain = client.get(f"/objects/{oid}/pddl/domain")
    assert domain.status_code == 200 and domain.headers["content-type"].startswith("text/plain")
    assert "(define (domain" in domain.text and "affected" in domain.text
    client.put(f"/objects/{oid}/goal", json={"link_orientations_deg": [90, 90, 0, 0]})
    perceive(client, oid, [0, 0, 0, 0])
    problem = client.get(f"/objects/{oid}/pddl/problem").text
    assert "(:goal" in problem and f"(hasorientation deg_90 {oid}_j1)" in problem


def test_ontology_as_rdf_xml_or_turtle(client):
    new_object(client)
    xml = client.get("/ontology")
    assert xml.headers["content-type"].startswith("application/rdf+xml") and b"<rdf:RDF" in xml.content
    ttl = client.get("/ontology", headers={"Accept": "text/turtle"})
    assert ttl.headers["content-type"].startswith("text/turtle") and b"@prefix" in ttl.content


def test_events_are_oldest_first_and_stream_as_sse(client):
    oid = new_object(client)
    client.put(f"/objects/{oid}/goal", json={"link_orientations_deg": [0, 90, 90, 180]})
    perceive(client, oid, [0, 0, 0, 0])
    events = client.get(f"/objects/{oid}/events").json()
    assert [e["seq"] for e in events] == sorted(e["seq"] for e in events)
    assert [e["kind"] for e in events] == ["object_created", "goal_set", "replan"]
    assert all(e["reason"] for e in events)
    with client.stream("GET", f"/objects/{oid}/events/stream", params={"max_events": 3, "timeout_s": 5}) as r:
        assert r.headers["content-type"].startswith("text/event-stream")
        text = "".join(r.iter_text())
    frames = [f for f in text.split("\n\n") if f.startswith("id:")]
    assert len(frames) == 3
    data = [json.loads(line[len("data: "):]) for f in frames for line in f.splitlines() if line.startswith("data: ")]
    assert [d["kind"] for d in data] == ["object_created", "goal_set", "replan"]
    with client.stream("GET", f"/objects/{oid}/events/stream", params={"after_seq": 2, "timeout_s": 0.5}) as r:
        tail = "".join(r.iter_text())
    assert "event: replan" in tail and "goal_set" not in tail


def test_health(client):
    body = client.get("/health").json()
    assert body["status"] == "ok" and body["objects"] == 0 and body["triples"] > 0 and body["auth"] is False


def test_every_schema_and_field_has_a_description_and_examples(client):
    components = client.get("/openapi.json").json()["components"]["schemas"]
    ours = {name for name in dir(schemas) if name.endswith("Public") or name.endswith(("Create", "Update", "Spec"))}
    checked = 0
    for name in ours:
        schema = components.get(name)
        if schema is None:
            continue
        checked += 1
        assert schema.get("description") and schema.get("examples"), name
        for field, prop in schema["properties"].items():
            assert prop.get("description") and prop.get("examples"), f"{name}.{field}"
    assert checked >= 12


@pytest.mark.parametrize("turned_fraction, decision, step", [(0.4, "continue", 1), (0.6, "resume", 2)])
def test_partial_action_snaps_back_or_forward(client, turned_fraction, decision, step):
    """A partial rotation is seen at the nearest allowed orientation: the start (retry a_1) or the end of
    the step (resume from s^e_2); after a partial action pre(a_1) alone is not normative."""
    oid = new_object(client, orientations=8)
    client.put(f"/objects/{oid}/goal", json={"link_orientations_deg": [0, 90, 90, 90]})
    perceive(client, oid, [0, 0, 0, 0])
    action = client.post(f"/objects/{oid}/actions/next").json()
    part = dict(action, delta_deg=action["delta_deg"] * turned_fraction)
    links = move([0, 0, 0, 0], part)
    r = client.post(f"/objects/{oid}/actions/{action['id']}/feedback", json={"outcome": "partial"})
    assert r.json()["execution"]["next_step"] == 1
    answer = perceive(client, oid, links)
    assert (answer["decision"], answer["next_action"]["step"]) == (decision, step)
    assert "partial" in answer["reason"]


def test_next_action_is_dispatched_once(client):
    oid = new_object(client)
    client.put(f"/objects/{oid}/goal", json={"link_orientations_deg": [0, 90, 90, 180]})
    perceive(client, oid, [0, 0, 0, 0])
    one = client.post(f"/objects/{oid}/actions/next").json()
    events = kb_size(client, oid)
    two = client.post(f"/objects/{oid}/actions/next").json()
    assert one == two and kb_size(client, oid) == events
    assert client.get(f"/objects/{oid}").json()["execution"]["dispatched_action_id"] == one["id"]


def test_object_locks_serialize_one_object_and_not_two():
    import threading

    from planhrc.kb_service.locks import ObjectLocks

    locks = ObjectLocks()
    got: dict[str, bool] = {}
    with locks.hold("a"):
        def other() -> None:
            got["b"] = locks.lock_for("b").acquire(timeout=1)
            got["a"] = locks.lock_for("a").acquire(timeout=0.2)

        t = threading.Thread(target=other)
        t.start()
        t.join()
    assert got == {"b": True, "a": False}


def test_macro_step_covers_consecutive_steps_and_checks_the_state_after_it(macro_client):
    client = macro_client
    oid = new_object(client, links=3, orientations=8)  # relative: 2 joints, 45 degree steps
    client.put(f"/objects/{oid}/goal", json={"joint_angles_deg": [90, 0]})
    first = perceive(client, oid, [0, 0, 0])
    action = client.post(f"/objects/{oid}/actions/next").json()
    assert first["decision"] == "replan"
    assert (action["step"], action["last_step"], action["macro_steps"]) == (1, 2, 2)
    assert abs(action["delta_deg"]) == 90  # two 45 degree steps as one 90 degree motion
    links = move([0, 0, 0], action)
    r = client.post(f"/objects/{oid}/actions/{action['id']}/feedback", json={"outcome": "succeeded"})
    assert r.json()["execution"]["next_step"] == 3
    answer = perceive(client, oid, noisy(links))
    assert answer["decision"] == "goal_reached"


# -- one write per perception ------------------------------------------------------------------------------------
def test_a_perception_is_stored_all_or_nothing(client, monkeypatch):
    """The re-planning perception's perceived state, problem, plan, expected states, execution and event are one
    write: when its last part fails, none of it is stored, and the same perception then succeeds."""
    oid = new_object(client)
    client.put(f"/objects/{oid}/goal", json={"link_orientations_deg": [0, 90, 90, 180]})
    kb = client.app.state.kb
    before = (kb_size(client, oid), kb.get_execution(oid), len(kb.list_events(oid)))
    real_add_event = kb.add_event

    def fail_on_decision(object_id, kind, reason, data):
        real_add_event(object_id, kind, reason, data)
        raise RuntimeError("disk full")

    monkeypatch.setattr(kb, "add_event", fail_on_decision)
    with pytest.raises(RuntimeError, match="disk full"):
        perceive(client, oid, [0, 0, 0, 0])
    assert (kb_size(client, oid), kb.get_execution(oid), len(kb.list_events(oid))) == before
    assert kb.latest_plan(oid) is None
    monkeypatch.undo()
    answer = perceive(client, oid, [0, 0, 0, 0])
    assert answer["decision"] == "replan" and kb.get_plan(answer["plan_id"]).actions
    assert client.get(f"/states/{answer['perceived_state_id']}").status_code == 200


# -- HTTP semantics -----------------------------------------------------------------------------------------------
def test_the_old_get_of_the_next_action_is_gone_and_changes_nothing(client):
    oid = new_object(client)
    client.put(f"/objects/{oid}/goal", json={"link_orientations_deg": [0, 90, 90, 180]})
    perceive(client, oid, [0, 0, 0, 0])
    before = client.get(f"/objects/{oid}").json()["execution"]
    r = client.get(f"/objects/{oid}/next-action")
    assert r.status_code == 410 and f"POST /objects/{oid}/actions/next" in r.json()["detail"]
    assert client.get(f"/objects/{oid}").json()["execution"] == before == {**before, "status": "ready"}
    assert client.post(f"/objects/{oid}/actions/next").json()["step"] == 1
    assert client.get(f"/objects/{oid}").json()["execution"]["status"] == "dispatched"


def test_openapi_examples_use_ids_the_store_really_produces(client):
    """Every id in the schemas' examples names a record that the first object's first episode stores."""
    oid = new_object(client)
    assert oid == "obj1"
    client.put(f"/objects/{oid}/goal", json={"link_orientations_deg": [0, 90, 90, 180]})
    assert perceive(client, oid, [0, 0, 0, 0])["plan_id"] == "obj1_plan_1"
    text = json.dumps(client.get("/openapi.json").json())
    ids = set(re.findall(r'"(obj\d+_(?:state|problem|plan)_\d+(?:_a\d+)?)"', text))
    assert {"obj1_state_1", "obj1_problem_1", "obj1_plan_1", "obj1_plan_1_a2"} <= ids
    routes = {"state": "/states/{}", "problem": "/problems/{}", "plan": "/plans/{}"}
    for ident in sorted(ids):
        kind = re.match(r"obj\d+_(state|problem|plan)", ident).group(1)
        if re.search(r"_a\d+$", ident):
            plan_id, step = ident.rsplit("_a", 1)
            assert ident in [s["id"] for s in client.get(f"/plans/{plan_id}").json()["steps"]]
            continue
        assert client.get(routes[kind].format(ident)).status_code == 200, ident


def test_a_plan_val_refuses_is_never_stored_or_dispatched(client, monkeypatch):
    """VAL runs while the store writes the new plan; when it refuses, the write is rolled back and the perception
    is stored alone, answered no_plan. (VAL is made to refuse: the unit under test is the perception's use case.)"""
    from planhrc.pipeline import val_runs
    from planhrc.planner.validate import ValidationResult

    class Refusing:  # a VAL run (pipeline.ValCheck) that refuses
        def verdict(self, timeout_s=None):
            return ValidationResult(False, "stub refusal", 0.0)

        def cancel(self):
            pass

    monkeypatch.setattr(val_runs, "start_val", lambda *a, **k: Refusing())
    oid = new_object(client)
    client.put(f"/objects/{oid}/goal", json={"link_orientations_deg": [0, 90, 90, 180]})
    answer = perceive(client, oid, [0, 0, 0, 0])
    assert answer["decision"] == "no_plan" and "VAL rejected the plan: stub refusal" in answer["reason"]
    assert client.get(f"/objects/{oid}/plan").status_code == 404
    assert client.post(f"/objects/{oid}/actions/next").json() is None
    assert client.get(f"/states/{answer['perceived_state_id']}").json()["kind"] == "perceived"
    events = client.get(f"/objects/{oid}/events").json()
    assert events[-1]["kind"] == "no_plan" and events[-1]["data"]["planning_status"] == "invalid"
    monkeypatch.undo()
    again = perceive(client, oid, [0, 0, 0, 0])
    assert again["decision"] == "replan" and client.get(f"/plans/{again['plan_id']}").status_code == 200

"""The service as history grows: reads cost what they return, /health stays cheap, bounds refuse hostile input."""
from __future__ import annotations

import warnings

import pytest

with warnings.catch_warnings():
    warnings.simplefilter("ignore")  # starlette's notice about httpx2
    from fastapi.testclient import TestClient

from planhrc.kb_service.app import create_app
from planhrc.kb_service.store import SqliteStore
from planhrc.kb_service.store.knowledge_base import MAX_EVENTS_PAGE, MAX_SEQ
from planhrc.settings import make_settings
from tests.servers import settled_health, timed_beside


@pytest.fixture
def db(tmp_path):
    return str(tmp_path / "kb.sqlite3")


@pytest.fixture
def client(db):
    with TestClient(create_app(make_settings(db_path=db, token=None))) as c:
        yield c


def new_object(client, links=3, orientations=4) -> str:
    r = client.post("/objects", json={"name": "rod", "links": links, "orientations": orientations,
                                      "formulation": "relative"})
    assert r.status_code == 201, r.text
    return r.json()["id"]


def test_health_counts_are_kept_by_commits_and_match_a_fresh_scan(client, db):
    before = client.get("/health").json()
    oid = new_object(client)
    client.put(f"/objects/{oid}/goal", json={"link_orientations_deg": [0, 90, 90]})
    for links in ([0, 0, 0], [0, 0, 90], [5, 3, 2]):
        assert client.post(f"/objects/{oid}/perceptions", json={"link_orientations_deg": links}).status_code == 200
    refused = client.post(f"/objects/{oid}/perceptions", json={"link_orientations_deg": [0, 0]})
    assert refused.status_code == 422
    after = settled_health(client)
    assert after["objects"] == before["objects"] + 1 and after["triples"] > before["triples"]
    client.app.state.kb.close()
    with SqliteStore(db, make_settings().tbox_path) as kb:  # counted by a scan of the tables
        assert (kb.object_count(), kb.triple_count()) == (after["objects"], after["triples"])


def test_events_come_in_pages(client):
    oid = new_object(client)
    client.put(f"/objects/{oid}/goal", json={"link_orientations_deg": [0, 90, 90]})
    for _ in range(4):
        client.post(f"/objects/{oid}/perceptions", json={"link_orientations_deg": [0, 0, 0]})
    every = client.get(f"/objects/{oid}/events").json()
    assert len(every) == 6 and [e["seq"] for e in every] == list(range(1, 7))
    page = client.get(f"/objects/{oid}/events", params={"after_seq": 2, "limit": 3}).json()
    assert [e["seq"] for e in page] == [3, 4, 5]
    assert client.get(f"/objects/{oid}/events", params={"after_seq": MAX_SEQ}).json() == []
    for params, field in (({"after_seq": 10**30}, "after_seq"), ({"after_seq": MAX_SEQ + 1}, "after_seq"),
                          ({"limit": MAX_EVENTS_PAGE + 1}, "limit"), ({"limit": 0}, "limit")):
        r = client.get(f"/objects/{oid}/events", params=params)
        assert r.status_code == 422 and r.json()["detail"].startswith(field), (params, r.text)
    r = client.get(f"/objects/{oid}/events/stream", params={"after_seq": 10**30})
    assert r.status_code == 422 and r.json()["detail"].startswith("after_seq")


def test_pddl_problem_is_the_latest_problem(client):
    oid = new_object(client)
    client.put(f"/objects/{oid}/goal", json={"link_orientations_deg": [0, 90, 90]})
    client.post(f"/objects/{oid}/perceptions", json={"link_orientations_deg": [0, 0, 0]})
    first = client.get(f"/objects/{oid}/pddl/problem").text
    client.put(f"/objects/{oid}/goal", json={"link_orientations_deg": [0, 0, 90]})  # a second problem
    second = client.get(f"/objects/{oid}/pddl/problem").text
    assert first[:first.index("(:goal")] == second[:second.index("(:goal")]  # same perceived state
    assert first[first.index("(:goal"):] != second[second.index("(:goal"):]  # the new goal
    plan = client.get(f"/objects/{oid}/plan").json()
    assert plan["id"] == f"{oid}_plan_1"


@pytest.mark.parametrize("body, field", [
    ({"name": "rod\n", "links": 3}, "name"),
    ({"name": "rod\x1b[31m", "links": 3}, "name"),
    ({"name": "rod\u202e", "links": 3}, "name"),
    ({"name": "rod", "links": [{"name": "l\x00", "length_m": 0.1}] * 3}, "links"),
    ({"name": "rod", "links": [{"name": "l", "length_m": 0.1}] * 201}, "links"),
    ({"name": "rod", "links": 201}, "links"),
])
def test_names_are_printable_and_objects_bounded_in_every_form(client, body, field):
    before = client.get("/health").json()
    r = client.post("/objects", json={**body, "orientations": 4, "formulation": "relative"})
    assert r.status_code == 422 and field in r.json()["detail"], r.text
    assert client.get("/health").json() == before


# -- the ontology export ------------------------------------------------------------------------------------
NT = {"Accept": "application/n-triples"}


def _graph(data: bytes):
    import rdflib

    return rdflib.Graph().parse(data=data, format="nt")


def _individuals(graph, oid: str) -> set[str]:
    """ABox individuals of `oid` (subjects), by fragment."""
    return {str(s).rsplit("#", 1)[1] for s in graph.subjects() if str(s).startswith("http://planhrc.org/abox#")
            and str(s).rsplit("#", 1)[1].startswith(oid)}


def test_ontology_exports_the_current_abox_by_default_and_the_history_on_request(client):
    oid, other = new_object(client), new_object(client)
    client.put(f"/objects/{oid}/goal", json={"link_orientations_deg": [0, 90, 90]})
    answers = [client.post(f"/objects/{oid}/perceptions", json={"link_orientations_deg": links}).json()
               for links in ([0, 0, 0], [0, 90, 0], [0, 0, 0], [0, 0, 90])]
    everything = _graph(client.app.state.kb.ntriples())  # owlready2's own serialisation of the world

    history = client.get("/ontology", params={"history": "all"}, headers=NT)
    assert history.status_code == 200 and history.headers["content-type"].startswith("application/n-triples")
    assert len(_graph(history.content)) == len(everything)

    current = _graph(client.get("/ontology", headers=NT).content)
    names = _individuals(current, oid)
    latest, older = answers[-1], answers[:-1]
    plan_id = client.get(f"/objects/{oid}").json()["execution"]["plan_id"] or latest["plan_id"]
    assert latest["perceived_state_id"] in names and plan_id in names and f"{oid}_l3" in names
    problem = client.get(f"/problems/{client.get(f'/plans/{plan_id}').json()['problem_id']}").json()
    kept = {problem["init_state_id"]}  # the state the current plan starts from
    past = {a["perceived_state_id"] for a in older} - kept
    assert past and not past & names, "past perceptions are history"
    assert past <= _individuals(_graph(history.content), oid)
    assert len(current) < len(everything) and _individuals(current, other)  # every object, by default

    one = _graph(client.get("/ontology", params={"object": oid}, headers=NT).content)
    assert _individuals(one, oid) == names and not _individuals(one, other)
    xml = client.get("/ontology", params={"object": oid})
    assert xml.headers["content-type"].startswith("application/rdf+xml") and b"<rdf:RDF" in xml.content

    for params, status, field in (({"object": "obj999"}, 404, "object_id"), ({"history": "some"}, 422, "history"),
                                  ({"history": "all", "object": oid}, 422, "object")):
        r = client.get("/ontology", params=params, headers=NT)
        assert r.status_code == status and r.json()["detail"].startswith(field), (params, r.text)


# -- no object stalls another ---------------------------------------------------------------------------------
def test_a_slow_plan_on_one_object_stalls_neither_another_object_nor_reads(client, monkeypatch):
    """Object A's planning takes 3 s (the planner is slowed for A only); meanwhile B is perceived, re-planned
    and read, and /health answers, each well before A's plan is done."""
    import threading
    import time

    from planhrc.pipeline import stages

    slow, fast = new_object(client), new_object(client)
    real_plan = stages.find_plan
    started = threading.Event()

    def plan(obj, *args, **kwargs):
        if obj.ident == slow:
            started.set()
            time.sleep(3.0)
        return real_plan(obj, *args, **kwargs)

    for oid in (slow, fast):
        client.put(f"/objects/{oid}/goal", json={"link_orientations_deg": [0, 90, 90]})
    client.post(f"/objects/{fast}/perceptions", json={"link_orientations_deg": [0, 90, 0]})  # the planner's imports
    monkeypatch.setattr(stages, "find_plan", plan)
    slow_answer, timings, done_before = timed_beside(
        lambda: client.post(f"/objects/{slow}/perceptions", json={"link_orientations_deg": [0, 0, 0]}),
        started, (
            ("perception", lambda: client.post(f"/objects/{fast}/perceptions", json={"link_orientations_deg": [0, 0, 0]})),
            ("replan", lambda: client.post(f"/objects/{fast}/perceptions", json={"link_orientations_deg": [90, 0, 0]})),
            ("health", lambda: client.get("/health")),
            ("object", lambda: client.get(f"/objects/{fast}")),
            ("events", lambda: client.get(f"/objects/{fast}/events")),
            ("ontology", lambda: client.get("/ontology", params={"object": fast}, headers=NT)),
            ("health_again", lambda: client.get("/health")),
        ))
    assert slow_answer.status_code == 200 and slow_answer.json()["decision"] == "replan"
    assert done_before < 3.0, (done_before, timings)  # everything on B answered while A was still planning
    assert max(timings["health"], timings["health_again"]) < 0.25, timings

"""The knowledge routes in process (FastAPI TestClient, on each store backend): /sparql as the SPARQL 1.1 Protocol
says (GET, POST form, POST query; formats by Accept; updates, SERVICE and unknown graphs refused; time and size
limits), a graph that follows the store as perceptions arrive, the subsumption route, the token policy."""
from __future__ import annotations

import csv
import io
import random

import pytest
from fastapi.testclient import TestClient

from planhrc.kb_service.app import create_app
from planhrc.kb_service.knowledge.graph import GRAPHS, KnowledgeGraph
from planhrc.model import is_subsumed
from planhrc.settings import make_settings
from tests.servers import store_location

TOKEN, READ = "write-token", "read-token"
W = {"Authorization": f"Bearer {TOKEN}"}
# The latest perceived state of every object (the current ABox also holds the perceived state its problem started
# from) and the orientation of each joint in it.
CURRENT = """SELECT ?object ?joint ?deg WHERE {
  { SELECT ?object (MAX(?t) AS ?latest) WHERE {
      ?s a planhrc:PerceivedState ; planhrc:stateOf ?object ; planhrc:createdAt ?t } GROUP BY ?object }
  ?state a planhrc:PerceivedState ; planhrc:stateOf ?object ; planhrc:createdAt ?latest ; planhrc:madeof ?p .
  ?p a planhrc:HasOrientation ; planhrc:arg1 ?joint ; planhrc:arg2 ?o . ?o planhrc:degrees ?deg .
} ORDER BY ?joint"""


@pytest.fixture(scope="module", params=["sqlite", "postgresql"])
def service(request, tmp_path_factory):
    """A service on each backend (`tests/store_backends.py`), the knowledge routes reading it through its interface."""
    db = store_location(request.param, tmp_path_factory.mktemp("knowledge"), request)
    settings = make_settings(db_path=db, token=TOKEN, read_token=READ, validate_plans=False, sparql_max_results=500)
    with TestClient(create_app(settings)) as client:
        oid = client.post("/objects", json={"name": "rod", "links": 4, "orientations": 4,
                                            "formulation": "relative"}, headers=W).json()["id"]
        goal = client.put(f"/objects/{oid}/goal", json={"link_orientations_deg": [0, 90, 90, 180]}, headers=W).json()
        first = client.post(f"/objects/{oid}/perceptions", json={"link_orientations_deg": [0, 0, 0, 0]}, headers=W)
        yield client, oid, goal["goal_state_id"], first.json()["perceived_state_id"]


def rows(response) -> list[dict[str, str]]:
    assert response.status_code == 200, response.text
    return [{k: v["value"] for k, v in b.items()} for b in response.json()["results"]["bindings"]]


def test_get_and_both_posts_answer_the_same(service):
    client = service[0]
    by_get = rows(client.get("/sparql", params={"query": CURRENT}))
    by_form = rows(client.post("/sparql", data={"query": CURRENT}))
    by_body = rows(client.post("/sparql", content=CURRENT, headers={"Content-Type": "application/sparql-query"}))
    assert by_get == by_form == by_body
    assert [r["deg"] for r in by_get] == ["0", "0", "0"]  # relative: three joints, every link at 0


def test_formats_by_accept(service):
    client = service[0]
    query = {"query": CURRENT}
    xml = client.get("/sparql", params=query, headers={"Accept": "application/sparql-results+xml"})
    assert xml.headers["content-type"].startswith("application/sparql-results+xml") and b"<sparql" in xml.content
    text = client.get("/sparql", params=query, headers={"Accept": "text/csv"})
    table = list(csv.DictReader(io.StringIO(text.text)))
    assert text.headers["content-type"].startswith("text/csv") and len(table) == 3 and table[0]["deg"] == "0"
    graph = client.get("/sparql", params={"query": "CONSTRUCT { ?s a planhrc:State } WHERE { ?s a planhrc:State }"},
                       headers={"Accept": "application/n-triples"})
    assert graph.headers["content-type"].startswith("application/n-triples")
    assert graph.text.count("#State>") == len(graph.text.strip().splitlines()) >= 2


def test_entailed_facts_are_in_the_default_graph_and_can_be_left_out(service):
    client, oid = service[0], service[1]
    ask = "ASK { abox:%s_state_2 a planhrc:State }" % oid
    assert client.get("/sparql", params={"query": ask}).json()["boolean"] is True
    asserted_only = {"query": ask, "default-graph-uri": ["http://planhrc.org/graph/tbox",
                                                         "http://planhrc.org/graph/abox"]}
    assert client.get("/sparql", params=asserted_only).json()["boolean"] is False
    chain = rows(client.get("/sparql", params={"query": "SELECT ?j ?l WHERE { GRAPH graph:entailed "
                                               "{ ?j planhrc:turns ?l } } ORDER BY ?j"}))
    assert [(r["j"][-2:], r["l"][-2:]) for r in chain] == [("j1", "l2"), ("j2", "l3"), ("j3", "l4")]


@pytest.mark.parametrize("body,headers,words", [
    ({"update": "INSERT DATA { <a:b> <a:c> <a:d> }"}, {}, "read-only"),
    ("CLEAR ALL", {"Content-Type": "application/sparql-update"}, "read-only"),
    ("DELETE WHERE { ?s ?p ?o }", {"Content-Type": "application/sparql-query"}, "read-only"),
    ({"query": "SELECT * WHERE { SERVICE <http://127.0.0.1:1/sparql> { ?s ?p ?o } }"}, {}, "SERVICE"),
    ({"query": "SELECT * FROM <http://example.org/g> WHERE { ?s ?p ?o }"}, {}, "no graph"),
    ({"query": "SELEKT ?s WHERE { ?s ?p ?o }"}, {}, "not SPARQL 1.1"),
    ({"query": "SELECT ?s WHERE { ?s ?p ?o }"}, {}, "more than 500"),
    ({"query": ""}, {}, "empty"),
])
def test_what_is_refused_is_refused_in_one_line(service, body, headers, words):
    client = service[0]
    before = client.get("/health").json()["triples"]
    if isinstance(body, dict):
        response = client.post("/sparql", data=body, headers=headers)
    else:
        response = client.post("/sparql", content=body, headers=headers)
    assert response.status_code == 400, response.text
    assert words in response.json()["detail"] and "\n" not in response.json()["detail"]
    assert client.get("/health").json()["triples"] == before


def test_a_query_past_its_time_limit_is_stopped():
    settings = make_settings(db_path=None, token=None, validate_plans=False, sparql_timeout_s=0.2)
    with TestClient(create_app(settings)) as client:
        # a count over three copies of every triple: billions of rows, far past the limit on any machine
        everything_thrice = "SELECT (COUNT(*) AS ?n) WHERE { ?a ?b ?c . ?d ?e ?f . ?g ?h ?i }"
        response = client.get("/sparql", params={"query": everything_thrice})
        assert response.status_code == 503 and "0.2 s" in response.json()["detail"]
        assert client.get("/sparql", params={"query": "ASK { ?s a owl:Class }"}).json()["boolean"] is True


def test_the_graph_follows_the_store_and_equals_a_fresh_one(service):
    client, oid = service[0], service[1]
    rng = random.Random(3)
    app = client.app
    for _ in range(4):
        links = [rng.choice([0, 90, 180, 270]) for _ in range(4)]
        assert client.post(f"/objects/{oid}/perceptions", json={"link_orientations_deg": links},
                           headers=W).status_code == 200
        degrees = [int(r["deg"]) for r in rows(client.get("/sparql", params={"query": CURRENT}))]
        assert degrees == [(b - a) % 360 for a, b in zip(links, links[1:])]
    knowledge = app.state.knowledge
    fresh = KnowledgeGraph(app.state.kb, app.state.settings.tbox_path)
    with knowledge.graph.lock:
        knowledge.graph.refresh()
        fresh.refresh()
        mine, theirs = knowledge.graph.contents(), fresh.contents()
        for name in ("abox", "entailed", "inferred"):  # (the TBox's blank nodes differ from one parse to the next)
            assert mine[name] == theirs[name], name
        sizes = fresh.sizes()
        assert knowledge.graph.sizes() == sizes
    # the engine's copy, brought up to date change by change, holds the same number of triples in each graph
    for name, iri in GRAPHS.items():
        count = rows(client.get("/sparql", params={"query": f"SELECT (COUNT(*) AS ?n) WHERE {{ GRAPH <{iri}> "
                                                            "{ ?s ?p ?o } }"}))
        assert int(count[0]["n"]) == sizes[name], name
    union = rows(client.get("/sparql", params={"query": "SELECT (COUNT(*) AS ?n) WHERE { ?s ?p ?o }"}))
    assert int(union[0]["n"]) == len(theirs["default"])


def test_subsumption_route_is_the_in_process_check(service):
    client, oid = service[0], service[1]
    ids = [f"{oid}_state_{n}" for n in range(1, 12)]
    states = {}
    for sid in ids:
        r = client.get(f"/states/{sid}")
        if r.status_code == 200:
            states[sid] = r.json()
    assert len(states) >= 4
    app = client.app
    rng = random.Random(5)
    for _ in range(30):
        a, b = rng.choice(list(states)), rng.choice(list(states))
        answer = client.get(f"/states/{a}/subsumed-by/{b}").json()
        atoms_a, atoms_b = app.state.kb.get_state(a).atoms, app.state.kb.get_state(b).atoms
        assert answer["subsumed"] is is_subsumed(atoms_a, atoms_b)
        assert len(answer["missing"]) == len(atoms_b - atoms_a)
        assert answer["subsumed"] == (answer["missing"] == [])


def test_why_not_names_the_joints_and_their_orientations(service):
    client, _, goal, perceived = service
    answer = client.get(f"/states/{perceived}/subsumed-by/{goal}").json()
    assert answer["subsumed"] is False
    assert answer["differs"] == [{"joint": "obj1_j1", "has": "deg_0", "wants": "deg_90"},
                                 {"joint": "obj1_j3", "has": "deg_0", "wants": "deg_90"}]
    assert client.get(f"/states/{perceived}/subsumed-by/nostate").status_code == 404


def test_reads_follow_the_read_token_policy():
    settings = make_settings(db_path=None, token=TOKEN, read_token=READ, protect_reads=True, validate_plans=False)
    with TestClient(create_app(settings)) as client:
        query = {"query": "ASK { ?s ?p ?o }"}
        assert client.get("/sparql", params=query).status_code == 401
        assert client.post("/sparql", data=query).status_code == 401
        read = {"Authorization": f"Bearer {READ}"}
        assert client.get("/sparql", params=query, headers=read).status_code == 200
        assert client.post("/sparql", data=query, headers=read).status_code == 200
        assert client.post("/reasoning", json={"reasoner": "pellet"}, headers=read).status_code == 403  # a reader
        bad = client.post("/reasoning", json={"reasoner": "fact++"}, headers=W)
        assert bad.status_code == 422 and "reasoner" in bad.json()["detail"]
        assert client.get("/reasoning/job99", headers=read).status_code == 404
        assert "security" in client.get("/openapi.json").json()["paths"]["/sparql"]["get"]

"""The knowledge service of a real `planhrc serve`, asked by a client we did not write (SPARQLWrapper): SELECT in
JSON, XML and CSV, ASK, CONSTRUCT, an update refused; the subsumption route against the in-process check; and
reasoning jobs with both reasoners, on a consistent ABox and on one made inconsistent on disk. The service under
the first three runs on each store backend."""
from __future__ import annotations

import csv
import io
import random
import time

import httpx
import pytest
import rdflib

from planhrc.bench.knowledge import CURRENT_STATE_QUERY
from planhrc.kb_service.store import SqliteStore
from planhrc.kb_service.store.owl import RDF_TYPE
from planhrc.model import is_subsumed
from planhrc.paths import default_tbox_path
from tests.servers import TOKEN, serving, store_location, token_client

SPARQLWrapper = pytest.importorskip("SPARQLWrapper", reason="SPARQLWrapper is in the test extra")

pytestmark = pytest.mark.integration

CURRENT = CURRENT_STATE_QUERY  # the console's first example too


@pytest.fixture(scope="module", params=["sqlite", "postgresql"])
def served(request, tmp_path_factory):
    """A service on each backend (`tests/store_backends.py`): the knowledge service reads any store through its
    interface, so every test here runs on both."""
    folder = tmp_path_factory.mktemp("knowledge")
    db = store_location(request.param, folder, request)
    with serving(db, args=["--token", TOKEN], env={"PLANHRC_VALIDATE_PLANS": "false"}, folder=folder) as base:
        with token_client(base) as client:
            made = {}
            for links, formulation in ((4, "relative"), (3, "absolute")):
                oid = client.post("/objects", json={"name": "rod", "links": links, "orientations": 4,
                                                    "formulation": formulation}).json()["id"]
                client.put(f"/objects/{oid}/goal", json={"link_orientations_deg": [90] * links})
                rng = random.Random(links)
                for _ in range(3):
                    angles = [rng.choice([0, 90, 180, 270]) for _ in range(links)]
                    assert client.post(f"/objects/{oid}/perceptions",
                                       json={"link_orientations_deg": angles}).status_code == 200
                made[oid] = (formulation, angles)
            yield base, client, made


def wrapper(base: str, query: str, fmt: str) -> SPARQLWrapper.SPARQLWrapper:
    sparql = SPARQLWrapper.SPARQLWrapper(f"{base}/sparql")
    sparql.setQuery(query)
    sparql.setReturnFormat(fmt)
    return sparql


def test_sparqlwrapper_reads_the_current_state_of_every_object(served):
    base, _, made = served
    answer = wrapper(base, CURRENT, SPARQLWrapper.JSON).queryAndConvert()
    got: dict[str, list[int]] = {}
    for b in answer["results"]["bindings"]:
        got.setdefault(b["object"]["value"].rsplit("#", 1)[1], []).append(int(b["degrees"]["value"]))
    for oid, (formulation, angles) in made.items():
        want = angles if formulation == "absolute" else [(b - a) % 360 for a, b in zip(angles, angles[1:])]
        assert got[oid] == want


def test_sparqlwrapper_in_xml_csv_by_post_ask_and_construct(served):
    base = served[0]
    xml = wrapper(base, CURRENT, SPARQLWrapper.XML)
    xml.setMethod(SPARQLWrapper.POST)
    doc = xml.queryAndConvert()
    assert len(doc.getElementsByTagName("result")) == 3 + 3
    table = wrapper(base, CURRENT, SPARQLWrapper.CSV).queryAndConvert()
    assert len(list(csv.DictReader(io.StringIO(table.decode())))) == 6
    ask = wrapper(base, "ASK { ?j <http://planhrc.org/ontology/planhrc.owl#affectsJoint> ?k }", SPARQLWrapper.JSON)
    assert ask.queryAndConvert()["boolean"] is True
    construct = wrapper(base, "CONSTRUCT { ?s a ?c } WHERE { ?s a <http://planhrc.org/ontology/planhrc.owl#State> "
                        ". BIND(<http://planhrc.org/ontology/planhrc.owl#State> AS ?c) }", SPARQLWrapper.TURTLE)
    graph = rdflib.Graph().parse(data=construct.queryAndConvert(), format="turtle")
    state = rdflib.URIRef("http://planhrc.org/ontology/planhrc.owl#State")
    assert len(graph) >= 2 and set(graph.objects(None, rdflib.RDF.type)) == {state}


def test_sparqlwrapper_gets_a_bad_query_error_for_an_update(served):
    from SPARQLWrapper.SPARQLExceptions import QueryBadFormed

    update = wrapper(served[0], "INSERT DATA { <http://a/b> <http://a/c> <http://a/d> }", SPARQLWrapper.JSON)
    update.setMethod(SPARQLWrapper.POST)
    update.setRequestMethod(SPARQLWrapper.URLENCODED)
    update.queryType = SPARQLWrapper.INSERT  # sent as `update=`, which the endpoint refuses
    with pytest.raises(QueryBadFormed, match="read-only"):
        update.query()


def test_subsumption_over_http_is_the_in_process_check(served):
    _, client, made = served
    states = {}
    for oid in made:
        for n in range(1, 40):
            r = client.get(f"/states/{oid}_state_{n}")
            if r.status_code == 200:
                states[r.json()["id"]] = frozenset(tuple(a.strip("()").split()) for a in r.json()["atoms"])
    assert len(states) > 10
    rng = random.Random(11)
    pairs = [(rng.choice(list(states)), rng.choice(list(states))) for _ in range(60)]
    pairs += [(a, a) for a in list(states)[:3]]
    answers = [client.get(f"/states/{a}/subsumed-by/{b}").json() for a, b in pairs]
    for (a, b), answer in zip(pairs, answers):
        assert answer["subsumed"] is is_subsumed(states[a], states[b]), (a, b)
        assert len(answer["missing"]) == len(states[b] - states[a])
    assert any(a["subsumed"] for a in answers) and not all(a["subsumed"] for a in answers)


@pytest.mark.reasoner
def test_reasoning_jobs_with_both_reasoners(served):
    base, _, made = served
    with token_client(base, timeout=300) as client:
        for name in ("pellet", "hermit"):
            oid = next(iter(made))
            r = client.post("/reasoning", json={"reasoner": name, "object_id": oid})
            assert r.status_code in (200, 202), r.text
            job = r.json()
            while job["status"] in ("queued", "running"):
                time.sleep(0.5)
                job = client.get(f"/reasoning/{job['id']}").json()
            assert job["status"] == "done" and job["consistent"] is True and job["inferred"] > 0
            assert job["reasoner"] == name and job["seconds"] > 0
        inferred = client.get("/sparql", params={"query": "SELECT (COUNT(*) AS ?n) WHERE { GRAPH "
                                                 "<http://planhrc.org/graph/inferred> { ?s ?p ?o } }"}).json()
        assert int(inferred["results"]["bindings"][0]["n"]["value"]) > 0


@pytest.mark.reasoner
def test_an_inconsistent_abox_is_named(tmp_path):
    db = tmp_path / "kb.sqlite3"
    with serving(db, args=["--token", TOKEN]) as base:
        with token_client(base) as client:
            oid = client.post("/objects", json={"name": "rod", "links": 3, "orientations": 4,
                                                "formulation": "relative"}).json()["id"]
    with SqliteStore(str(db), default_tbox_path()) as kb:  # a fact no write of the service accepts
        abox = kb._abox
        with kb.lock:
            abox.q.insert_objs(abox.c, [(abox.sid(f"{oid}_l2"), RDF_TYPE, abox.t["Joint"])])
            abox.q.commit()
    with serving(db, args=["--token", TOKEN]) as base:
        with token_client(base, timeout=300) as client:
            for name in ("pellet", "hermit"):
                job = client.post("/reasoning", json={"reasoner": name}).json()
                while job["status"] in ("queued", "running"):
                    time.sleep(0.5)
                    job = client.get(f"/reasoning/{job['id']}").json()
                assert job["consistent"] is False, job
                assert job["individuals"] == [f"{oid}_l2"]
                assert any("Joint" in axiom and "Link" in axiom for axiom in job["axioms"])


def test_reasoning_refuses_more_jobs_than_its_queue(tmp_path):
    db = tmp_path / "kb.sqlite3"
    env = {"PLANHRC_REASONING_QUEUE": "1", "PLANHRC_REASONING_ANSWER_WAIT_S": "0"}
    with serving(db, args=["--token", TOKEN], env=env) as base:
        with token_client(base) as client:
            first = client.post("/reasoning", json={"reasoner": "hermit"})
            second = client.post("/reasoning", json={"reasoner": "hermit"})
            assert first.status_code == 202 and first.headers["location"] == f"/reasoning/{first.json()['id']}"
            assert second.status_code == 429 and "reasoning_queue" in second.json()["detail"]
            assert second.headers["retry-after"]
            httpx.get(f"{base}/health").raise_for_status()

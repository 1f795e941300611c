"""The SPARQL engines: Oxigraph (the default, in a process of its own) answers as rdflib (the endpoint's first
engine) on a set of queries over the same store; what a query's text says about what it reads (`query_text`),
keywords hidden in comments, strings and IRIs included; a query past its time limit stops the query process
without holding up the service, and the next query starts another."""
from __future__ import annotations

import csv
import io
import json
import os
import threading
import time

import pytest
from fastapi.testclient import TestClient
from rdflib import XSD, BNode, Graph, Literal, URIRef
from rdflib.compare import isomorphic

from planhrc.kb_service.app import create_app
from planhrc.kb_service.knowledge.graph import KnowledgeGraph
from planhrc.kb_service.knowledge.query_text import read_query_text
from planhrc.kb_service.knowledge.query_engine import QueryError
from planhrc.kb_service.knowledge.sparql import ENGINES, PREFIXES, SparqlEndpoint, SparqlRequest
from planhrc.settings import make_settings
from planhrc.vocabulary import SparqlEngineName
from tests.test_knowledge_api import CURRENT

pytest.importorskip("pyoxigraph", reason="pyoxigraph is a dependency of the service")

T = "http://planhrc.org/graph/"
QUERIES = [
    CURRENT,
    "SELECT ?j ?l WHERE { GRAPH graph:entailed { ?j planhrc:turns ?l } } ORDER BY ?j ?l",
    "ASK { ?s a planhrc:PerceivedState }",
    "ASK { ?s a planhrc:NoSuchClass }",
    # the default graph is a union: a triple in two of its graphs counts once
    "SELECT (COUNT(*) AS ?n) WHERE { ?s ?p ?o }",
    f"SELECT (COUNT(*) AS ?n) FROM <{T}tbox> FROM <{T}abox> WHERE {{ ?s ?p ?o }}",
    "SELECT (COUNT(*) AS ?n) FROM graph:abox FROM graph:entailed FROM graph:inferred WHERE { ?s ?p ?o }",
    "SELECT ?g (COUNT(*) AS ?n) WHERE { GRAPH ?g { ?s ?p ?o } } GROUP BY ?g ORDER BY ?g",
    "SELECT ?s (COUNT(?p) AS ?n) WHERE { ?s planhrc:madeof ?p } GROUP BY ?s ORDER BY ?s",
    "SELECT DISTINCT ?c WHERE { ?x a ?c FILTER(isIRI(?c)) } ORDER BY ?c",
    "SELECT ?o ?d WHERE { ?o a planhrc:Orientation ; planhrc:degrees ?d FILTER(?d >= 90 && ?d != 180) } ORDER BY ?o",
    "SELECT ?s ?t WHERE { ?s planhrc:createdAt ?t } ORDER BY DESC(?t) ?s LIMIT 5 OFFSET 1",
    "SELECT ?x ?label WHERE { ?x rdfs:label ?label } ORDER BY ?x ?label",
    "SELECT ?p ?v WHERE { abox:obj1 ?p ?v FILTER(isLiteral(?v)) } ORDER BY ?p ?v",
    "CONSTRUCT { ?s a planhrc:State } WHERE { ?s a planhrc:State }",
    "CONSTRUCT { ?j planhrc:affectsJoint ?k } WHERE { ?j planhrc:affectsJoint ?k }",
]


# What the rdflib engine cannot evaluate (as the endpoint calls it, an OPTIONAL with its filter fails inside rdflib)
# and Oxigraph answers: the reference here is a query without OPTIONAL, and the rows it leaves out.
OPTIONAL = ("SELECT ?o ?d WHERE { ?o a planhrc:Orientation OPTIONAL { ?o planhrc:degrees ?d } } ORDER BY ?o",
            "SELECT ?o ?d WHERE { ?o a planhrc:Orientation ; planhrc:degrees ?d } ORDER BY ?o")


@pytest.fixture(scope="module")
def store():
    settings = make_settings(db_path=None, token=None, validate_plans=False)
    with TestClient(create_app(settings)) as client:
        for links, formulation in ((4, "relative"), (3, "absolute")):
            oid = client.post("/objects", json={"name": "rod", "links": links, "orientations": 4,
                                                "formulation": formulation}).json()["id"]
            client.put(f"/objects/{oid}/goal", json={"link_orientations_deg": [90] * links})
            for angles in ([0] * links, [90, 180, 270, 0][:links]):
                client.post(f"/objects/{oid}/perceptions", json={"link_orientations_deg": angles})
        yield client.app.state.kb, settings


@pytest.fixture(scope="module")
def endpoints(store):
    kb, settings = store
    made = {name: SparqlEndpoint(KnowledgeGraph(kb, settings.tbox_path), make(5.0), 5.0, 10_000)
            for name, make in ENGINES.items()}
    yield made
    for endpoint in made.values():
        endpoint.close()


def _term(b: dict[str, str]):
    if b["type"] == "uri":
        return URIRef(b["value"])
    if b["type"] == "bnode":
        return BNode()
    # RDF 1.1: a literal without a datatype is an xsd:string (rdflib writes the datatype, Oxigraph does not)
    datatype = None if b.get("datatype") == str(XSD.string) else b.get("datatype")
    return Literal(b["value"], lang=b.get("xml:lang"), datatype=datatype)


def answer(endpoint: SparqlEndpoint, query: str, accept: str | None = None):
    got = endpoint.run(SparqlRequest(query, accept))
    if got.media_type == "text/turtle":
        return isomorphic, Graph().parse(data=got.body, format="turtle")
    doc = json.loads(got.body)
    if "boolean" in doc:
        return None, doc["boolean"]
    rows = [tuple(sorted((k, _term(v)) for k, v in b.items())) for b in doc["results"]["bindings"]]
    ordered = "ORDER BY" in query
    return None, (doc["head"]["vars"], rows if ordered else sorted(rows))


@pytest.mark.parametrize("query", QUERIES)
def test_oxigraph_answers_as_rdflib(endpoints, query):
    compare, ours = answer(endpoints[SparqlEngineName.OXIGRAPH], query)
    _, theirs = answer(endpoints[SparqlEngineName.RDFLIB], query)
    if compare is not None:
        assert len(ours) > 0 and compare(ours, theirs)
    else:
        assert ours == theirs
    if isinstance(ours, tuple) and query != QUERIES[3]:
        assert ours[1], "a query of this set that answers nothing compares nothing"


def test_an_optional_pattern_that_rdflib_could_not_evaluate(endpoints):
    with pytest.raises(QueryError, match="cannot be evaluated"):
        endpoints[SparqlEngineName.RDFLIB].run(SparqlRequest(OPTIONAL[0]))
    _, (names, rows) = answer(endpoints[SparqlEngineName.OXIGRAPH], OPTIONAL[0])
    _, (_, bound) = answer(endpoints[SparqlEngineName.RDFLIB], OPTIONAL[1])
    assert names == ["o", "d"] and bound and set(bound) <= set(rows)
    assert all(len(row) == 1 for row in set(rows) - set(bound))  # an orientation without degrees, unbound


def test_csv_and_xml_agree_too(endpoints):
    csvs = [endpoints[name].run(SparqlRequest(CURRENT, "text/csv")).body.decode() for name in ENGINES]
    tables = [list(csv.DictReader(io.StringIO(text))) for text in csvs]
    assert tables[0] == tables[1] and len(tables[0]) == 3 + 3
    xml = endpoints[SparqlEngineName.OXIGRAPH].run(SparqlRequest(CURRENT, "application/sparql-results+xml"))
    assert xml.media_type == "application/sparql-results+xml" and xml.body.count(b"<result>") == 3 + 3


@pytest.mark.parametrize("name", list(ENGINES))
@pytest.mark.parametrize("query,words", [
    ("SELECT * WHERE { SERVICE <http://127.0.0.1:9/sparql> { ?s ?p ?o } }", "SERVICE"),
    ("PREFIX : <http://127.0.0.1:9/> SELECT * WHERE { SERVICE:x { ?s ?p ?o } }", "SERVICE"),
    ("select * where { service silent <http://127.0.0.1:9/> { ?s ?p ?o } }", "SERVICE"),
    ("# a comment\nINSERT DATA { <a:b> <a:c> <a:d> }", "read-only"),
    ("PREFIX ex: <http://example.org/> LOAD <http://127.0.0.1:9/x.ttl>", "read-only"),
    ("SELECT * FROM ex:g WHERE { ?s ?p ?o }", "no graph"),
    ("SELECT * FROM NAMED <http://example.org/g> WHERE { ?s ?p ?o }", "no graph"),
    ("SELEKT ?s WHERE { ?s ?p ?o }", "not SPARQL 1.1"),
    ("SELECT ?s WHERE { ?s ?p ?o }", "more than 10"),
])
def test_both_engines_refuse_alike(store, name, query, words):
    kb, settings = store
    endpoint = SparqlEndpoint(KnowledgeGraph(kb, settings.tbox_path), ENGINES[name](5.0), 5.0, 10)
    try:
        with pytest.raises(QueryError) as err:
            endpoint.run(SparqlRequest(query))
        assert words in str(err.value) and "\n" not in str(err.value)
    finally:
        endpoint.close()


@pytest.mark.parametrize("text,form,froms,service", [
    ("SELECT * WHERE { ?s ?p 'SERVICE' }", "SELECT", (), False),
    ("SELECT * WHERE { ?s ?p \"\"\"a\nSERVICE <x:y> {}\"\"\" }", "SELECT", (), False),
    ("SELECT * WHERE { ?s <http://e/SERVICE> ?service . ?s ex:service ?o } # SERVICE <x:y>", "SELECT", (), False),
    ("PREFIX g: <http://planhrc.org/graph/>\nSELECT * FROM g:abox FROM <http://planhrc.org/graph/tbox> "
     "WHERE { ?s ?p ?o }", "SELECT", ("http://planhrc.org/graph/abox", "http://planhrc.org/graph/tbox"), False),
    ("BASE <http://e/> PREFIX : <http://e/> ASK { ?s ?p ?o }", "ASK", (), False),
    ("construct where { ?s ?p ?o } ", "CONSTRUCT", (), False),
    ("PREFIX a.b: <http://e/> # SELECT\nPREFIX : <http://f/>\nCONSTRUCT { ?s a a.b:C } WHERE { ?s ?p ?o }", "CONSTRUCT",
     (), False),
    ("PREFIX x: <http://e/> x:y", None, (), False),
    ("SELECT * WHERE { FILTER(?a<1) SERVICE ?x { ?s ?p ?o } }", "SELECT", (), True),
    ("delete where { ?s ?p ?o }", "DELETE", (), False),
])
def test_what_a_query_text_says(text, form, froms, service):
    read = read_query_text(text, PREFIXES)
    assert (read.form, read.from_graphs, read.service) == (form, froms, service)


def test_a_query_past_its_limit_stops_the_query_process_and_nothing_else():
    settings = make_settings(db_path=None, token=None, validate_plans=False, sparql_timeout_s=1.0)
    with TestClient(create_app(settings)) as client:
        assert client.get("/sparql", params={"query": "ASK { ?s a owl:Class }"}).json()["boolean"] is True
        engine = client.app.state.knowledge.endpoint.engine
        first = engine.pid()
        slow: dict[str, object] = {}

        def ask() -> None:
            began = time.monotonic()
            slow["response"] = client.get("/sparql", params={
                "query": "SELECT (COUNT(*) AS ?n) WHERE { ?a ?b ?c . ?d ?e ?f . ?g ?h ?i }"})
            slow["seconds"] = time.monotonic() - began

        thread = threading.Thread(target=ask)
        thread.start()
        time.sleep(0.3)
        began = time.monotonic()
        assert client.get("/health").status_code == 200  # the query's process computes; the service answers
        assert time.monotonic() - began < 1.0
        thread.join(30)
        response = slow["response"]
        assert response.status_code == 503 and "1 s" in response.json()["detail"]
        assert slow["seconds"] < 5
        with pytest.raises(ProcessLookupError):
            for _ in range(50):  # the stopped process is reaped at once; give the kernel a moment all the same
                os.kill(first, 0)
                time.sleep(0.1)
        # a query that is not SPARQL is refused before the stopped process is started again (which takes seconds
        # on a loaded machine: the graphs are loaded anew)
        refused = client.get("/sparql", params={"query": "SELECT ?s WHERE { ?s ?p }"})
        assert refused.status_code == 400 and "not SPARQL 1.1" in refused.json()["detail"], refused.text
        assert engine.pid() is None
        assert client.get("/sparql", params={"query": "ASK { ?s a owl:Class }"}).json()["boolean"] is True
        assert engine.pid() not in (None, first)
        last = engine.pid()
    with pytest.raises(ProcessLookupError):  # closing the service stops its query process
        os.kill(last, 0)

"""The API contract is the API behaviour: schemathesis tests every operation of a real `planhrc serve` process
(token set) from its own `/openapi.json`, with every check, and finds no failure: no 5xx, no answer outside the
documented schemas and statuses, no schema-violating request accepted, and no schema-valid request refused except
for the rules no JSON Schema can state (tests/contract_rules.py: they depend on the stored object, the service's
settings, or two query parameters together).

Three runs. The first drives schemathesis's generator from Python with the path parameter `object_id` pinned to a
stored object with a goal, so generated goals and perceptions reach the cooperation model (and the planner)
instead of stopping at a 404. The second is the `schemathesis run` command with the generated phases (the
schema's examples, coverage of boundaries and invalid values, fuzzing); the third its stateful phase, sequences
that follow the OpenAPI links the service declares (a new object to its goal, perceptions and next action; a goal
to its problem; a perception to its plan and state; an action to its feedback). Both commands use the
repository's schemathesis.toml, so the same run by hand from the repository's root finds what they find (see
that file). A few examples per operation keep each run short; `PLANHRC_FUZZ_EXAMPLES` asks for more.
"""
from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path
from typing import Iterator

import httpx
import pytest

schemathesis = pytest.importorskip("schemathesis")
import jsonschema_rs  # noqa: E402  (schemathesis's own schema validator)
from hypothesis import HealthCheck, Phase, given, settings  # noqa: E402
from hypothesis.errors import Unsatisfiable  # noqa: E402
from schemathesis import GenerationMode, checks  # noqa: E402

REPO = Path(__file__).resolve().parent.parent
if str(REPO / "tests") not in sys.path:
    sys.path.insert(0, str(REPO / "tests"))

from test_service_integration import running_server  # noqa: E402
from tests.contract_rules import RULES_BEYOND_THE_SCHEMA, refused_beyond_the_schema  # noqa: E402

pytestmark = pytest.mark.integration

TOKEN = "contract-token"
EXAMPLES = int(os.environ.get("PLANHRC_FUZZ_EXAMPLES", "6"))
CONFIG = REPO / "schemathesis.toml"


def positive_data_acceptance_but_the_rules(ctx, response, case) -> bool | None:
    """schemathesis's `positive_data_acceptance`, which lets through only the refusals no schema can state (what
    schemathesis.toml and tests/contract_rules.py do together for the `schemathesis run` command)."""
    if refused_beyond_the_schema(case.operation.label, response.status_code, response.content):
        return None
    return checks.positive_data_acceptance(ctx, response, case)


CHECKS = [
    checks.not_a_server_error,
    checks.response_schema_conformance,
    checks.status_code_conformance,
    checks.content_type_conformance,
    checks.negative_data_rejection,
    checks.ignored_auth,
    positive_data_acceptance_but_the_rules,
]


@pytest.fixture(scope="module")
def service(tmp_path_factory) -> Iterator[tuple[httpx.Client, str]]:
    db = tmp_path_factory.mktemp("contract") / "kb.sqlite3"
    with running_server(db, token=TOKEN) as client:
        r = client.post("/objects", json={"name": "rod", "links": 3, "orientations": 4, "formulation": "relative"})
        assert r.status_code == 201, r.text
        oid = r.json()["id"]
        assert client.put(f"/objects/{oid}/goal", json={"joint_angles_deg": [90, 0]}).status_code == 200
        yield client, oid


def test_every_operation_keeps_its_contract(service):
    client, oid = service
    schema = schemathesis.openapi.from_url(f"{client.base_url}/openapi.json")
    failures: list[str] = []
    operations = [result.ok() for result in schema.get_all_operations()]
    assert len(operations) >= 15
    for operation in operations:
        for mode in (GenerationMode.POSITIVE, GenerationMode.NEGATIVE):
            pinned = {"object_id": oid} if "{object_id}" in operation.path and mode is GenerationMode.POSITIVE else None
            strategy = operation.as_strategy(generation_mode=mode, path_parameters=pinned)

            @given(case=strategy)
            @settings(max_examples=EXAMPLES, deadline=None, derandomize=True, database=None,
                      phases=[Phase.generate], suppress_health_check=list(HealthCheck))
            def run(case) -> None:
                if case.path.endswith("/events/stream"):  # a live stream must end: ask for a short one
                    case.query = {**(case.query or {}), "timeout_s": 0.2}
                try:
                    case.call_and_validate(base_url=str(client.base_url), checks=CHECKS, timeout=60,
                                           headers={"Authorization": f"Bearer {TOKEN}"})
                except (AssertionError, ExceptionGroup) as failure:  # every failed check, collected
                    failures.append(f"{operation.label} [{mode.value}]: {str(failure)[:600]}")

            try:
                run()
            except Unsatisfiable:  # nothing of this operation can be made invalid (no parameters, no body)
                assert mode is GenerationMode.NEGATIVE, operation.label
    assert not failures, "\n\n".join(failures)


def test_store_bounds_answer_422_not_500(service):
    """The fuzzer's first finding: a seq past SQLite's INTEGER reached the store as an OverflowError."""
    client, oid = service
    too_big = 2**63
    for path in (f"/objects/{oid}/events", f"/objects/{oid}/events/stream"):
        r = client.get(path, params={"after_seq": too_big, "timeout_s": 0.2})
        assert r.status_code == 422 and "after_seq" in r.json()["detail"], (path, r.text)
    r = client.get(f"/objects/{oid}/events", params={"after_seq": too_big - 1})
    assert r.status_code == 200 and r.json() == []
    with client.stream("GET", f"/objects/{oid}/events/stream", params={"timeout_s": 0.2},
                       headers={"Last-Event-ID": str(too_big)}) as r:
        assert r.status_code == 200
        r.read()


def test_error_bodies_are_the_documented_schema(service):
    client, oid = service
    doc = client.get("/openapi.json").json()
    error = doc["components"]["schemas"]["ErrorPublic"]
    assert set(error["properties"]) == {"detail"} and error.get("additionalProperties") is False
    for path in ("/objects/{object_id}/pddl/domain", "/objects/{object_id}/pddl/problem"):
        assert set(doc["paths"][path]["get"]["responses"]["404"]["content"]) == {"application/json"}
    for path, method in (("/objects", "post"), ("/objects/{object_id}/perceptions", "post"),
                         ("/objects/{object_id}/goal", "put"), ("/objects/{object_id}/actions/{action_id}/feedback", "post")):
        assert {"400", "401", "413", "422"} <= set(doc["paths"][path][method]["responses"]), (path, method)
    links = doc["components"]["schemas"]["ObjectCreate"]["properties"]["links"]["anyOf"]
    as_int = next(s for s in links if s.get("type") == "integer")
    as_list = next(s for s in links if s.get("type") == "array")
    assert (as_list["minItems"], as_list["maxItems"]) == (as_int["minimum"], as_int["maximum"])

    answers = {
        422: client.post(f"/objects/{oid}/perceptions", json={"link_orientations_deg": [0]}),
        400: client.post(f"/objects/{oid}/perceptions", content=b'{"link_orientations_deg": [\xff]}',
                         headers={"Content-Type": "application/json"}),
        404: client.get("/objects/nope/pddl/domain"),
        401: httpx.post(f"{client.base_url}/objects", json={"links": 2, "orientations": 4, "formulation": "relative"}),
        413: client.post("/objects", content=b"x" * (2 * 1_048_576), headers={"Content-Type": "application/json"}),
    }
    for status, r in answers.items():
        assert r.status_code == status, (status, r.text)
        assert r.headers["content-type"].startswith("application/json")
        assert set(r.json()) == {"detail"} and r.json()["detail"], (status, r.text)


def run_schemathesis(tmp_path: Path, phases: list[str], examples: int) -> tuple[dict, str]:
    """`schemathesis run --checks all` with the repository's schemathesis.toml over a fresh service with a token:
    its JSON report and its output."""
    report = tmp_path / "report.json"
    env = {**os.environ, "PYTHONPATH": str(REPO)}  # the config's hooks module, tests.contract_rules
    with running_server(tmp_path / "kb.sqlite3", token=TOKEN) as client:
        run = subprocess.run(
            [str(Path(sys.executable).with_name("schemathesis")), "--config-file", str(CONFIG),
             "run", f"{client.base_url}/openapi.json", "--header", f"Authorization: Bearer {TOKEN}",
             "--phases", ",".join(phases), "--checks", "all", "--max-examples", str(examples),
             "--seed", "7", "--workers", "1", "--request-timeout", "60",
             "--continue-on-failure", "--report", "json", "--report-json-path", str(report)],
            cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600)
    output = run.stdout[-8000:] + run.stderr[-2000:]
    assert report.exists(), output
    summary = json.loads(report.read_text())
    assert run.returncode == 0 and not summary["failures"] and not summary["errors"], output
    assert {name: phase["status"] for name, phase in summary["phases"].items()
            if name in phases} == dict.fromkeys(phases, "success"), output
    return summary, run.stdout


@pytest.mark.slow
def test_the_generated_phases_find_nothing(tmp_path):
    """`schemathesis run` over a fresh service: the schema's examples, coverage of boundaries and invalid values,
    and fuzzing pass every check."""
    summary, _ = run_schemathesis(tmp_path, ["examples", "coverage", "fuzzing"], max(1, EXAMPLES // 2))
    assert summary["operations"]["tested"] == summary["operations"]["total"] >= 15, summary["operations"]


@pytest.mark.slow
def test_the_stateful_phase_finds_nothing(tmp_path):
    """The stateful phase follows the declared OpenAPI links from answer to request (a new object to its goal,
    perceptions and next action; a perception to its plan and state; an action to its feedback) and every
    check passes on every step."""
    summary, stdout = run_schemathesis(tmp_path, ["stateful"], 10 * EXAMPLES)  # sequences, cheap: more of them
    covered = re.search(r"API Links:\s+(\d+) covered", stdout)  # the stateful phase followed links
    assert covered and int(covered.group(1)) >= 8, stdout[-8000:]


def test_the_rules_beyond_the_schema_are_exactly_those_the_service_answers(service):
    """The refusals the contract test lets through are the service's own answers, word for word, and nothing
    else: a schema-level refusal on the same operations is not one of them."""
    client, oid = service  # 3 links, 4 orientations, relative
    beyond = {
        "POST /objects": client.post("/objects", json={"links": 200, "orientations": 360, "formulation": "relative"}),
        "PUT /objects/{object_id}/goal": client.put(f"/objects/{oid}/goal", json={"joint_angles_deg": [45, 0]}),
        "POST /objects/{object_id}/perceptions": client.post(f"/objects/{oid}/perceptions",
                                                             json={"link_orientations_deg": [0, 0]}),
        "GET /ontology": client.get("/ontology", params={"history": "all", "object": oid}),
        "GET /sparql": client.get("/sparql", params={"query": "SELECT ?s WHERE {"}),
        "POST /sparql": client.post("/sparql", content="", headers={"Content-Type": "application/sparql-query"}),
    }
    assert set(beyond) == set(RULES_BEYOND_THE_SCHEMA)
    for label, r in beyond.items():
        assert refused_beyond_the_schema(label, r.status_code, r.content), (label, r.status_code, r.text)
    for label, body in (("PUT /objects/{object_id}/goal", {"joint_angles_deg": [None, None]}),
                        ("POST /objects/{object_id}/perceptions", {"link_orientations_deg": [None, None, None]})):
        method, path = label.split(" ")
        r = client.request(method, path.format(object_id=oid), json=body)
        assert r.status_code == 422 and not refused_beyond_the_schema(label, r.status_code, r.content), r.text


OBJECT = {"links": 3, "orientations": 4, "formulation": "relative"}
GOAL, PERCEPTION, FEEDBACK = "/objects/{oid}/goal", "/objects/{oid}/perceptions", "/objects/{oid}/actions/a9/feedback"
# (schema, method, path, body, accepted): what the schema says of a body is what the service does with it
AGREEMENT = [
    ("ObjectCreate", "POST", "/objects", {**OBJECT, "links": 3.0, "orientations": 4.0}, True),
    ("ObjectCreate", "POST", "/objects", {**OBJECT, "links": "3"}, False),
    ("ObjectCreate", "POST", "/objects", {**OBJECT, "orientations": True}, False),
    ("ObjectCreate", "POST", "/objects", {**OBJECT, "orientations": 7}, False),
    ("ObjectCreate", "POST", "/objects", {**OBJECT, "name": "rod\u00a02 \U0007c0e9"}, True),
    ("ObjectCreate", "POST", "/objects", {**OBJECT, "name": "rod\u200b"}, False),
    ("ObjectCreate", "POST", "/objects", {**OBJECT, "name": "rod\n"}, False),
    ("GoalUpdate", "PUT", GOAL, {"link_orientations_deg": [0, 90, 90], "joint_angles_deg": None}, True),
    ("GoalUpdate", "PUT", GOAL, {"joint_angles_deg": [90, None]}, True),
    ("GoalUpdate", "PUT", GOAL, {"link_orientations_deg": [0, None, 90]}, False),
    ("GoalUpdate", "PUT", GOAL, {"link_orientations_deg": [0, 90, 90], "joint_angles_deg": [90, 0]}, False),
    ("GoalUpdate", "PUT", GOAL, {"link_orientations_deg": None}, False),
    ("GoalUpdate", "PUT", GOAL, {"joint_angles_deg": [None, None]}, False),
    ("GoalUpdate", "PUT", GOAL, {"joint_angles_deg": [90, 0], "allow_infeasible": 0}, False),
    ("PerceptionCreate", "POST", PERCEPTION, {"link_orientations_deg": [1.5, None, 3]}, True),
    ("PerceptionCreate", "POST", PERCEPTION, {"link_orientations_deg": [None, None, None]}, False),
    ("FeedbackCreate", "POST", FEEDBACK, {"outcome": "failed", "reason": "stall"}, True),
    ("FeedbackCreate", "POST", FEEDBACK, {"outcome": "succeeded", "reason": None}, True),
    ("FeedbackCreate", "POST", FEEDBACK, {"outcome": "succeeded", "reason": "stall"}, False),
    ("GiveUpCreate", "POST", "/objects/{oid}/give-up", {"reason": "stuck", "message": "tab\there"}, False),
]


@pytest.mark.parametrize("name, method, path, body, accepted", AGREEMENT,
                         ids=[f"{row[0]}-{i}" for i, row in enumerate(AGREEMENT)])
def test_the_schema_says_what_the_service_accepts(service, name, method, path, body, accepted):
    """A body the published schema accepts is not refused as invalid (a 404 or 409 for the object's state is
    fine), and one it refuses gets a 422 whose one-line message starts with the field; schemathesis's schema
    validator decides, as in the runs above."""
    client, oid = service
    doc = client.get("/openapi.json").json()
    validator = jsonschema_rs.validator_for({"$ref": f"#/components/schemas/{name}", "components": doc["components"]})
    assert validator.is_valid(body) is accepted, (name, body)
    r = client.request(method, path.format(oid=oid), json=body)
    if accepted:
        assert r.status_code in (200, 201, 404, 409), (body, r.text)
    else:
        detail = r.json()["detail"]
        fields = [field for field in body if detail.startswith(field)]
        assert r.status_code == 422 and fields and "\n" not in detail and "Value error" not in detail, (body, r.text)


def _targets(links: dict[str, dict]) -> set[str]:
    return {link["operationRef"].removeprefix("#/paths/").rsplit("/", 1)[0].replace("~1", "/").replace("~0", "~")
            for link in links.values()}


def test_the_openapi_links_lead_from_a_new_object_to_its_routes(service):
    client, _ = service
    doc = client.get("/openapi.json").json()
    created = doc["paths"]["/objects"]["post"]["responses"]["201"]["links"]
    taken = doc["paths"]["/objects/{object_id}/actions/next"]["post"]["responses"]["200"]["links"]
    perceived = doc["paths"]["/objects/{object_id}/perceptions"]["post"]["responses"]["200"]["links"]
    assert {"set_goal", "perceive", "take_next_action"} <= set(created)
    assert taken["feedback"]["parameters"] == {"object_id": "$request.path.object_id", "action_id": "$response.body#/id"}
    assert perceived["read_plan"]["parameters"] == {"plan_id": "$response.body#/plan_id"}
    every = [link for path in doc["paths"].values() for op in path.values()
             for answer in op["responses"].values() for link in answer.get("links", {}).values()]
    assert len(every) >= 12
    for link in every:
        path, method = link["operationRef"].removeprefix("#/paths/").rsplit("/", 1)
        assert method in doc["paths"][path.replace("~1", "/").replace("~0", "~")], link
    # links only where they hold: a new object has no plan and no problem, nor has every perceived one
    not_yet = {"/objects/{object_id}/plan", "/objects/{object_id}/pddl/problem"}
    assert not not_yet & (_targets(created) | _targets(perceived))


def test_the_retired_route_is_no_operation_and_its_replacement_says_so(service):
    client, oid = service
    doc = client.get("/openapi.json").json()
    assert "/objects/{object_id}/next-action" not in doc["paths"]
    assert "410" in doc["paths"]["/objects/{object_id}/actions/next"]["post"]["description"]
    r = client.get(f"/objects/{oid}/next-action")
    assert r.status_code == 410 and r.json() == {"detail": r.json()["detail"]} and "POST" in r.json()["detail"]


def test_a_405_names_every_method_of_the_path(service):
    """A schemathesis finding: the router named only the first matching route's methods in `Allow`."""
    client, oid = service
    for method, path, allowed in (("OPTIONS", "/objects", "GET, POST"), ("DELETE", f"/objects/{oid}", "GET"),
                                  ("GET", f"/objects/{oid}/actions/a1/feedback", "POST")):
        r = client.request(method, path)
        assert (r.status_code, r.headers.get("allow"), r.json()) == (405, allowed, {"detail": "Method Not Allowed"})


def test_numbers_are_json_numbers(service):
    """A schemathesis finding: pydantic's lax mode took `false` for 0.0 (and "90" for 90.0) where the schema says
    number, so a schema-violating body created an object."""
    client, oid = service
    before = client.get("/objects").json()
    for path, body, field in (
            ("/objects", {"links": 3, "orientations": 4, "formulation": "relative", "base_point_xy": [False, 0.0]},
             "base_point_xy"),
            ("/objects", {"links": [{"name": "l", "length_m": "0.1"}] * 3, "orientations": 4,
                          "formulation": "relative"}, "links"),
            (f"/objects/{oid}/perceptions", {"link_orientations_deg": ["90", 0, 0]}, "link_orientations_deg")):
        r = client.post(path, json=body)
        assert r.status_code == 422 and r.json()["detail"].startswith(field), (body, r.text)
    assert client.get("/objects").json() == before


ROLE_CHECKS = [checks.not_a_server_error, checks.response_schema_conformance, checks.status_code_conformance,
               checks.content_type_conformance]


@pytest.fixture(scope="module")
def role_keys(service, tmp_path_factory) -> dict[str, str]:
    """One client per role on the contract's service, made by `planhrc keys` beside it (in effect within a
    second, without a restart)."""
    client, _ = service
    db = next(Path(p) for p in tmp_path_factory.getbasetemp().glob("contract*/kb.sqlite3"))
    keys = {}
    for role in ("robot", "operator", "reader"):
        made = subprocess.run([sys.executable, "-m", "planhrc.cli", "keys", "add", f"contract-{role}", "--role", role,
                               "--db", str(db)], capture_output=True, text=True, timeout=120,
                              env={**os.environ, "PYTHONPATH": str(REPO)})
        assert made.returncode == 0, made.stderr
        keys[role] = made.stdout.strip()
    probe = httpx.get(f"{client.base_url}/objects", headers={"Authorization": f"Bearer {keys['reader']}"})
    assert probe.status_code == 200
    return keys


@pytest.mark.parametrize("role", ["robot", "operator", "reader"])
def test_each_role_keeps_the_contract(service, role_keys, role):
    """schemathesis with each role's key over every operation: no server error, and every answer (a 403 where
    the role may not go) is a documented status with its documented schema; the refusals name the role needed."""
    client, oid = service
    key = role_keys[role]
    schema = schemathesis.openapi.from_url(f"{client.base_url}/openapi.json")
    failures: list[str] = []
    refused: set[str] = set()
    for operation in [result.ok() for result in schema.get_all_operations()]:
        pinned = {"object_id": oid} if "{object_id}" in operation.path else None
        strategy = operation.as_strategy(generation_mode=GenerationMode.POSITIVE, path_parameters=pinned)

        @given(case=strategy)
        @settings(max_examples=2, deadline=None, derandomize=True, database=None, phases=[Phase.generate],
                  suppress_health_check=list(HealthCheck))
        def run(case) -> None:
            if case.path.endswith("/events/stream"):
                case.query = {**(case.query or {}), "timeout_s": 0.2}
            try:
                response = case.call_and_validate(base_url=str(client.base_url), checks=ROLE_CHECKS, timeout=60,
                                                  headers={"Authorization": f"Bearer {key}"})
            except (AssertionError, ExceptionGroup) as failure:
                failures.append(f"{operation.label} [{role}]: {str(failure)[:600]}")
                return
            if response.status_code == 403:
                assert "needs the role" in response.json()["detail"]
                refused.add(operation.label)

        run()
    assert not failures, "\n\n".join(failures)
    writes = {"robot": {"POST /objects", "PUT /objects/{object_id}/goal", "POST /reasoning"},
              "operator": {"POST /objects/{object_id}/perceptions", "POST /objects/{object_id}/actions/next",
                           "POST /objects/{object_id}/actions/{action_id}/feedback",
                           "POST /objects/{object_id}/give-up"}}
    writes["reader"] = writes["robot"] | writes["operator"]
    assert refused == writes[role], (role, refused)

"""The API contract is the API behaviour: schemathesis fuzzes every operation of a real `planhrc serve` process
(token set) from its own `/openapi.json` and finds no 5xx and no answer outside the documented schemas.

Two runs. The first drives schemathesis's generator from Python with the path parameter `object_id` pinned to a
stored object with a goal, so generated goals and perceptions reach the cooperation model (and the planner)
instead of stopping at a 404. The second is the `schemathesis run` command with all four phases (the schema's
examples, coverage of boundaries and invalid values, fuzzing, and stateful sequences that follow the OpenAPI
links from `POST /objects` to the routes taking its id). A few examples per operation keep each run short;
`PLANHRC_FUZZ_EXAMPLES` asks for more.
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
from hypothesis import HealthCheck, Phase, given, settings  # noqa: E402
from hypothesis.errors import Unsatisfiable  # noqa: E402
from schemathesis import GenerationMode, checks  # noqa: E402

REPO = Path(__file__).resolve().parent.parent
if str(REPO / "tests") not in sys.path:
    sys.path.insert(0, str(REPO / "tests"))

from test_service_integration import running_server  # noqa: E402

pytestmark = pytest.mark.integration

TOKEN = "contract-token"
EXAMPLES = int(os.environ.get("PLANHRC_FUZZ_EXAMPLES", "6"))
CHECKS = [
    checks.not_a_server_error,
    checks.response_schema_conformance,
    checks.status_code_conformance,
    checks.content_type_conformance,
    checks.negative_data_rejection,
    checks.ignored_auth,
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


# Every check of `schemathesis run` except `positive_data_acceptance`, which expects every schema-valid request to
# be accepted: the service refuses some with a 422 naming the field for rules that hold between values and a JSON
# schema cannot state (a perception has one value per link of *that* object, 360 must be divisible by K, a goal
# gives exactly one of its two forms, `history=all` is for every object).
CLI_EXCLUDED_CHECKS = ["positive_data_acceptance"]
CLI_PHASES = ["examples", "coverage", "fuzzing", "stateful"]
CLI_CONFIG = f"""
generation.max-examples = {max(1, EXAMPLES // 2)}

# Sequences are cheap (most requests are refused early): more of them, so that some reach a plan.
[phases.stateful]
max-steps = 10
generation.max-examples = {5 * EXAMPLES}

# The stateful phase follows the links the OpenAPI declares, not links schemathesis guesses from parameter names
# (a guessed `POST /objects` -> `GET /objects/{{object_id}}/plan` expects a plan from a bare object).
[phases.stateful.inference]
algorithms = []

[[operations]]
include-path = "/objects/{{object_id}}/events/stream"
parameters = {{ "query.timeout_s" = 0.2 }}  # a live stream must end: ask for a short one
"""


def test_every_schemathesis_phase_finds_nothing(tmp_path):
    """`schemathesis run` over a fresh service: examples, coverage, fuzzing and stateful phases all pass, with
    every check but one (see CLI_EXCLUDED_CHECKS); the stateful phase follows the declared links."""
    (tmp_path / "schemathesis.toml").write_text(CLI_CONFIG)
    report = tmp_path / "report.json"
    with running_server(tmp_path / "kb.sqlite3", token=TOKEN) as client:
        run = subprocess.run(
            [str(Path(sys.executable).with_name("schemathesis")), "--config-file", str(tmp_path / "schemathesis.toml"),
             "run", f"{client.base_url}/openapi.json", "--header", f"Authorization: Bearer {TOKEN}",
             "--phases", ",".join(CLI_PHASES), "--checks", "all", "--exclude-checks", ",".join(CLI_EXCLUDED_CHECKS),
             "--seed", "7", "--workers", "1", "--request-timeout", "60",
             "--continue-on-failure", "--report", "json", "--report-json-path", str(report)],
            cwd=tmp_path, capture_output=True, text=True, timeout=600)
    summary = json.loads(report.read_text())
    output = run.stdout[-6000:] + run.stderr[-2000:]
    assert run.returncode == 0 and not summary["failures"] and not summary["errors"], output
    assert {name: phase["status"] for name, phase in summary["phases"].items()} == dict.fromkeys(CLI_PHASES, "success"), output
    assert summary["operations"]["tested"] == summary["operations"]["total"] >= 15, summary["operations"]
    covered = re.search(r"API Links:\s+(\d+) covered", run.stdout)  # the stateful phase followed links
    assert covered and int(covered.group(1)) >= 3, output


def test_the_openapi_links_lead_from_a_new_object_to_its_routes(service):
    client, _ = service
    doc = client.get("/openapi.json").json()
    created = doc["paths"]["/objects"]["post"]["responses"]["201"]["links"]
    taken = doc["paths"]["/objects/{object_id}/actions/next"]["post"]["responses"]["200"]["links"]
    assert {"set_goal", "perceive", "take_next_action"} <= set(created)
    assert taken["feedback"]["parameters"] == {"object_id": "$request.path.object_id", "action_id": "$response.body#/id"}
    for link in (*created.values(), *taken.values()):
        path, method = link["operationRef"].removeprefix("#/paths/").rsplit("/", 1)
        assert method in doc["paths"][path.replace("~1", "/").replace("~0", "~")], link


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

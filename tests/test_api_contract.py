"""The API contract is the API behaviour: schemathesis fuzzes every operation of a real `planhrc serve` process
(token set) from its own `/openapi.json` and finds no 5xx and no answer outside the documented schemas.

The path parameter `object_id` is pinned to a stored object with a goal, so generated goals and perceptions reach
the cooperation model (and the planner) instead of stopping at a 404. A few examples per operation keep the run
short; `PLANHRC_FUZZ_EXAMPLES` asks for more.
"""
from __future__ import annotations

import os
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

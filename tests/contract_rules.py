"""The service's refusals that no JSON Schema can state, as a schemathesis check (loaded as the hooks module named
in `schemathesis.toml`).

The OpenAPI schema states every rule about a request itself (see `kb_service/schemas.py`), so a body it accepts is
accepted: schemathesis's `positive_data_acceptance` holds the service to that. A few rules depend on something a
schema served to every client does not know: the stored object (a perception or a goal has one value per link or
joint of *that* object, each goal value one of *its* orientations, a goal for a placed object lies on the table
where *it* lies), the service's settings (links x orientations up to `max_task_size`), or two query parameters
together (OpenAPI cannot relate them). The service refuses such a request with a 422 whose one-line message names
the field. For the four operations concerned `schemathesis.toml` lets `positive_data_acceptance` take a 422, and
`refusals_beyond_the_schema` checks that every such 422 is one of the rules listed here, by the start of its
message: any other refusal of schema-valid data is still a failure.
"""
from __future__ import annotations

import json
import re
from typing import Any

import schemathesis
from schemathesis.specs.openapi.checks import is_unexpected_http_status_case

_GOAL_FIELD = r"(link_orientations_deg|joint_angles_deg)"
_SPARQL_REFUSAL = (r"query: (empty|not SPARQL 1\.1|cannot be evaluated|this endpoint is read-only|SERVICE is refused"
                   r"|send one query)|(default|named)-graph-uri: no graph ")
RULES_BEYOND_THE_SCHEMA: dict[str, re.Pattern[str]] = {
    # the service's setting max_task_size
    "POST /objects": re.compile(r"links, orientations: \d+ links x \d+ orientations = \d+ is over the largest "
                                r"planning task this service takes"),
    # the stored object: its number of links or joints, its orientations, where it lies on the table
    "PUT /objects/{object_id}/goal": re.compile(
        rf"{_GOAL_FIELD}: expected \d+ values \(one per (link|joint)\)"
        rf"|{_GOAL_FIELD}\[\d+\]: \S+ is not one of the allowed orientations"
        r"|goal: .*\(send allow_infeasible: true to set it anyway\)$"),
    "POST /objects/{object_id}/perceptions": re.compile(r"link_orientations_deg: expected \d+ values \(one per link\)"),
    # two query parameters together
    "GET /ontology": re.compile(r"object: the whole history is exported for every object \(history=all\)$"),
    # the SPARQL 1.1 grammar (any string is schema-valid, not every string is a query: the Protocol's 400), and the
    # graphs this endpoint holds
    "GET /sparql": re.compile(_SPARQL_REFUSAL),
    "POST /sparql": re.compile(_SPARQL_REFUSAL),
}
# the status of each rule's refusal: 422 (a field the schema cannot check), but 400 for a malformed SPARQL query
RULE_STATUS: dict[str, int] = {"GET /sparql": 400, "POST /sparql": 400}


def refused_beyond_the_schema(label: str, status_code: int, body: bytes) -> bool:
    """Whether an answer is the service refusing, for one of the rules above, a request its schema accepts."""
    rule = RULES_BEYOND_THE_SCHEMA.get(label)
    if rule is None or status_code != RULE_STATUS.get(label, 422):
        return False
    try:
        detail = json.loads(body)["detail"]
    except (ValueError, KeyError, TypeError):
        return False
    return isinstance(detail, str) and rule.match(detail) is not None


@schemathesis.check
def refusals_beyond_the_schema(ctx: Any, response: Any, case: Any) -> bool | None:
    """A schema-valid request that an operation of RULES_BEYOND_THE_SCHEMA refuses with 422 was refused for one of
    the listed rules (there, and only there, schemathesis.toml lets `positive_data_acceptance` take a 422)."""
    positive = case.meta is not None and case.meta.generation.mode.is_positive
    label = case.operation.label
    if (not positive or response.status_code != RULE_STATUS.get(label, 422) or label not in RULES_BEYOND_THE_SCHEMA
            or is_unexpected_http_status_case(case)):
        return None
    if not refused_beyond_the_schema(label, response.status_code, response.content):
        raise AssertionError(f"{label}: a schema-valid request was refused for a rule the schema could state: "
                             f"{response.content[:300]!r}")
    return None

"""The service's refusals that no JSON Schema can state, for schemathesis's check that schema-valid data is accepted.

The OpenAPI schema states every rule about a request itself (see `kb_service/schemas.py`), so a body it accepts is
accepted. A few rules depend on something a schema served to every client does not know: the stored object (a
perception or a goal has one value per link or joint of *that* object, each goal value one of *its* orientations,
a goal for a placed object lies on the table where *it* lies), the service's settings (links x orientations up to
`max_task_size`), or two query parameters together (OpenAPI has no way to relate them). The service refuses such
a request with a 422 whose one-line message names the field; this module lists those refusals, per operation, by
the message's start, and `positive_data_acceptance_beyond_the_schema` lets exactly them through before it applies
schemathesis's `positive_data_acceptance`. Any other refusal of schema-valid data is still a failure.

`schemathesis run` loads this file as its hooks module (the config's `hooks`), which registers the check; the
contract test then runs every check with this one in place of the built-in one.
"""
from __future__ import annotations

import json
import re
from typing import Any

import schemathesis
from schemathesis.specs.openapi.checks import positive_data_acceptance

_GOAL_FIELD = r"(link_orientations_deg|joint_angles_deg)"
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
}


def refused_beyond_the_schema(label: str, status_code: int, body: bytes) -> bool:
    """Whether an answer is the service refusing, for one of the rules above, a request its schema accepts."""
    rule = RULES_BEYOND_THE_SCHEMA.get(label)
    if rule is None or status_code != 422:
        return False
    try:
        detail = json.loads(body)["detail"]
    except (ValueError, KeyError, TypeError):
        return False
    return isinstance(detail, str) and rule.match(detail) is not None


@schemathesis.check
def positive_data_acceptance_beyond_the_schema(ctx: Any, response: Any, case: Any) -> bool | None:
    """schemathesis's `positive_data_acceptance`, except for the refusals listed in RULES_BEYOND_THE_SCHEMA."""
    if refused_beyond_the_schema(case.operation.label, response.status_code, response.content):
        return None
    return positive_data_acceptance(ctx, response, case)

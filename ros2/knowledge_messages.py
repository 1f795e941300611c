"""The knowledge service's ROS 2 requests and answers as JSON in `std_msgs/String` (no rclpy here: the tests run it
in `.venv`). A request names its `request_id`; the answer carries it back with `ok`, and either what the HTTP route
answers or, when the request is refused, `status` (the service's HTTP status, or null for a message the bridge
could not read) and `detail` (one line that names the field).
"""
from __future__ import annotations

import json
from dataclasses import dataclass
from typing import Any, Mapping, Sequence

from planhrc.client import ProtocolError, SparqlAnswer

from .convert import _json_object
from .errors import Ros2Error

MAX_REQUEST_ID = 200


@dataclass(frozen=True)
class KnowledgeRequest:
    topic: str  # sparql, subsumption, reasoning
    request_id: str
    fields: Mapping[str, Any]


# the fields of each request: name -> (type, required)
FIELDS: dict[str, dict[str, tuple[type, bool]]] = {
    "sparql": {"query": (str, True), "accept": (str, False), "default_graph_uri": (list, False),
               "named_graph_uri": (list, False)},
    "subsumption": {"state_id": (str, True), "by_state_id": (str, True)},
    "reasoning": {"reasoner": (str, True), "object_id": (str, False), "scope": (str, False)},
}


def read_request(topic: str, data: str) -> KnowledgeRequest:
    """A request's JSON; Ros2Error naming the field when it is not one."""
    body = _json_object(topic, data)
    request_id = body.get("request_id", "")
    if not isinstance(request_id, str) or len(request_id) > MAX_REQUEST_ID:
        raise Ros2Error(f"{topic}.request_id: a string of at most {MAX_REQUEST_ID} characters")
    spec = FIELDS[topic]
    unknown = sorted(set(body) - set(spec) - {"request_id"})
    if unknown:
        raise Ros2Error(f"{topic}.{unknown[0]}: unknown field (the fields are {', '.join(sorted(spec))})")
    fields: dict[str, Any] = {}
    for name, (kind, required) in spec.items():
        value = body.get(name)
        if value is None:
            if required:
                raise Ros2Error(f"{topic}.{name}: required")
            continue
        if kind is list:
            if not isinstance(value, list):
                raise Ros2Error(f"{topic}.{name}: expected a list of non-empty strings")
            if not all(isinstance(v, str) for v in value):
                raise Ros2Error(f"{topic}.{name}: expected a list of strings")
            fields[name] = tuple(value)
        elif not isinstance(value, str) or not value:
            raise Ros2Error(f"{topic}.{name}: expected a non-empty string")
        else:
            fields[name] = value
    return KnowledgeRequest(topic, request_id, fields)


def answer_text(request_id: str, body: Mapping[str, Any]) -> str:
    return json.dumps({"request_id": request_id, "ok": True, **body}, separators=(",", ":"))


def sparql_answer_text(request_id: str, answer: SparqlAnswer) -> str:
    return answer_text(request_id, {"media_type": answer.media_type, "result_count": answer.rows,
                                    "body": answer.text})


def refusal_text(request_id: str, exc: Exception) -> str:
    status = exc.status if isinstance(exc, ProtocolError) else None
    return json.dumps({"request_id": request_id, "ok": False, "status": status, "detail": str(exc)},
                      separators=(",", ":"))


def request_id_of(data: str) -> str:
    """The request id of a message that may not be a request at all ('' then)."""
    try:
        body = json.loads(data)
    except ValueError:
        return ""
    value = body.get("request_id") if isinstance(body, dict) else None
    return value if isinstance(value, str) else ""


def graphs(value: Sequence[str] | None) -> tuple[str, ...]:
    return tuple(value or ())

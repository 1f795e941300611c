"""The knowledge service's ROS 2 messages (`ros2.knowledge_messages`, no rclpy): requests read field by field with
one-line refusals naming the field, and the answers' JSON."""
from __future__ import annotations

import json

import pytest

from planhrc.client import ProtocolError, SparqlAnswer
from planhrc.ros2.errors import Ros2Error
from planhrc.ros2.knowledge_messages import (answer_text, read_request, refusal_text, request_id_of,
                                             sparql_answer_text)


def test_a_request_is_read_with_its_fields():
    request = read_request("sparql", json.dumps({"request_id": "a", "query": "ASK {}", "default_graph_uri": ["g"]}))
    assert (request.request_id, request.fields) == ("a", {"query": "ASK {}", "default_graph_uri": ("g",)})
    assert read_request("reasoning", '{"reasoner": "pellet"}').request_id == ""


@pytest.mark.parametrize("topic,data,words", [
    ("sparql", "not json", "sparql.data: not JSON"),
    ("sparql", "[1]", "sparql.data: expected a JSON object, got list"),
    ("sparql", '{"request_id": 5, "query": "ASK {}"}', "sparql.request_id: a string"),
    ("sparql", '{"query": ""}', "sparql.query: expected a non-empty string"),
    ("sparql", '{"query": "ASK {}", "default_graph_uri": "g"}', "sparql.default_graph_uri: expected a list"),
    ("sparql", '{"query": "ASK {}", "named_graph_uri": [1]}', "sparql.named_graph_uri: expected a list of strings"),
    ("subsumption", '{"state_id": "a"}', "subsumption.by_state_id: required"),
    ("reasoning", '{"reasoner": "pellet", "objet_id": "obj1"}', "reasoning.objet_id: unknown field"),
])
def test_bad_requests_are_refused_naming_the_field(topic, data, words):
    with pytest.raises(Ros2Error) as err:
        read_request(topic, data)
    assert str(err.value).startswith(words) and "\n" not in str(err.value)


def test_answers():
    assert json.loads(answer_text("a", {"subsumed": True})) == {"request_id": "a", "ok": True, "subsumed": True}
    sparql = json.loads(sparql_answer_text("b", SparqlAnswer("text/csv", "x\r\n1\r\n", 1)))
    assert sparql == {"request_id": "b", "ok": True, "media_type": "text/csv", "result_count": 1, "body": "x\r\n1\r\n"}
    refused = json.loads(refusal_text("c", ProtocolError("POST /sparql: 400 query: empty", 400)))
    assert refused == {"request_id": "c", "ok": False, "status": 400, "detail": "POST /sparql: 400 query: empty"}
    assert json.loads(refusal_text("", Ros2Error("x")))["status"] is None
    assert request_id_of('{"request_id": "d"}') == "d" and request_id_of("nope") == "" and request_id_of("[]") == ""


def test_the_documentation_names_every_knowledge_topic_and_the_service():
    from pathlib import Path

    from planhrc.ros2 import topics

    page = (Path(__file__).resolve().parents[1] / "docs" / "ros2.md").read_text()
    for spec in topics.KNOWLEDGE_TOPICS:
        row = next((line for line in page.splitlines() if line.startswith(f"| `{spec.suffix}` |")), None)
        assert row is not None, spec.suffix
        assert f"`{spec.type_name}`" in row and spec.qos_text in row and f"| {spec.direction} |" in row
    assert topics.REASON_NOW[0].endswith("/reason_now") and f"`{topics.REASON_NOW[1]}` (service)" in page

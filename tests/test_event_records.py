"""One record per event kind (`planhrc.event_log`): the only module that reads an event's data by its keys; the
object's memory is built from the records; a store written before the records existed reads as it did (the same
memory, the same events, the same remembered answers); the API documents each kind's schema, and its stream sends
what its list shows."""
from __future__ import annotations

import ast
import dataclasses
import gzip
import importlib.util
import json
import warnings
from pathlib import Path
from typing import Any

import pytest

with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    from fastapi.testclient import TestClient

from planhrc.event_log import (DATA, DecisionData, EventData, EventKind, FeedbackData, IncompleteData, RefusalData,
                               SkillRequest, ValVerdictData, data_of)
from planhrc.json_record import RecordError
from planhrc.kb_service.app import create_app
from planhrc.kb_service.record_schemas import EVENT_MODELS
from planhrc.kb_service.usecases import FeedbackResult, Turn
from planhrc.kb_service.usecases.values import NextAction
from planhrc.ordering import HelpItem
from planhrc.settings import make_settings
from planhrc.vocabulary import Accepted, ActionOutcome, DecisionKind, ExecutionStatus, FailureReason, Infeasible
from planhrc.vocabulary import PlanningStatus, Remedy, Skill
from tests.test_layers import ALL

OLD = Path(__file__).resolve().parent / "data" / "old-store"
EVENT_MODULE = "planhrc.event_log"
SERVICE_AND_BENCHES = ("planhrc.kb_service", "planhrc.bench")


def _generator() -> Any:
    spec = importlib.util.spec_from_file_location("old_store_make", OLD / "make.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


plain = _generator().plain  # a memo as JSON, as the old service's was written


# -- the records ----------------------------------------------------------------------------------------------
EXAMPLES: list[EventData] = [
    data_of("object_created", {"formulation": "relative", "links": 5, "orientations": 8, "base_point_xy": [0.6, 0.4]}),
    DecisionData(perceived_state_id="obj1_state_2", plan_id="obj1_plan_1", next_step=3, next_action_id="a3",
                 matched_expected_step=3, base_point_xy=(0.5, 0.25), goal_state_id="obj1_state_1",
                 remedy=Remedy.SPLIT, val_pieces=((1, 2), (3, 9)), val_accepted=(1,),
                 planning_status=PlanningStatus.SOLVED, problem_id="obj1_problem_1", timings={"plan": 0.01},
                 ordering="in the planner's order", help=(HelpItem(2, 90, "turn link 2 to 90°"),),
                 skill=SkillRequest(Skill.SLIDE, (0.5, 0.2), (1, 2), "slide the object"), gave_up="max_steps"),
    IncompleteData(unseen_links=(2,), link_orientations_deg=(0.0, None, 90.0), base_point_xy=None),
    FeedbackData(action_id="a1", step=1, outcome=ActionOutcome.FAILED, accepted=Accepted.LATE,
                 reason=FailureReason.LEFT_TABLE, measured_deg=None, message="no", joint_index=4, turned_link_index=5,
                 refusal=RefusalData(from_deg=(90.4, 89.7), base_point_xy=(0.6, 0.39), turned=5, held=4,
                                     direction=-1, code=Infeasible.OFF_TABLE, link=5, against="the edge"),
                 control=(("free", "left"), ("holding", "right", "obj1_l2"))),
    ValVerdictData(plan_id="p", piece=2, first_step=3, last_step=9, verdict="refused", reason="step 4", seconds=0.2),
]


@pytest.mark.parametrize("record", EXAMPLES, ids=lambda r: type(r).__name__)
def test_a_record_reads_back_from_its_data_stored_or_listed(record):
    kind = next(k for k, cls in DATA.items() if cls is type(record))
    assert data_of(kind, record.to_data()) == record
    assert data_of(kind, json.loads(json.dumps(record.to_data(defaults=True)))) == record


def test_a_stored_record_leaves_out_its_defaults_and_reads_them_back():
    bare = DecisionData(plan_id="p")
    assert bare.to_data() == {"plan_id": "p"}
    assert set(bare.to_data(defaults=True)) == {f.name for f in dataclasses.fields(DecisionData)}


def test_the_answers_an_idempotency_key_remembers_are_kept_as_themselves():
    action = NextAction("a1", "rotateclockwise", ("l2", "l1"), 1, 2, "p", 1, 2, 1, 90, 2)
    turn = Turn(DecisionKind.ROBOT_SKILL, "p", "s", action, 1, "why", help=(HelpItem(3, 45, "turn"),),
                unseen_links=None, skill=SkillRequest(Skill.SLIDE, (0.1, 0.2), (1, 2), "slide"))
    assert Turn.of_data(json.loads(json.dumps(turn.to_data()))) == turn
    from planhrc.kb_service.store import Execution

    result = FeedbackResult("a1", Accepted.CURRENT, Execution("p", 3, ExecutionStatus.READY, None))
    assert FeedbackResult.of_data(result.to_data()) == result


@pytest.mark.parametrize("kind, data, field", [
    ("goal_set", {}, "goal_state_id"),
    ("feedback", {"action_id": "a", "step": "one", "outcome": "succeeded", "accepted": "current"}, "step"),
    ("val_verdict", {"plan_id": "p", "piece": 1, "first_step": 1, "last_step": 2, "verdict": "maybe"}, "verdict"),
    ("perception", {}, "kind"),
])
def test_data_that_holds_no_record_is_refused_naming_the_field(kind, data, field):
    with pytest.raises(RecordError, match=field):
        data_of(kind, data)


# -- nobody else reads the keys ----------------------------------------------------------------------------------
def _event_keys() -> set[str]:
    records = set(DATA.values()) | {RefusalData}
    return {f.name for record in records for f in dataclasses.fields(record)}


def _is_event_data(node: ast.expr, names: set[str]) -> bool:
    """`x.data`, `x["data"]`, `x.get("data")`, or a name in `names`."""
    if isinstance(node, ast.Name):
        return node.id in names
    if isinstance(node, ast.Attribute):
        return node.attr == "data"
    if isinstance(node, ast.Subscript):
        return isinstance(node.slice, ast.Constant) and node.slice.value == "data"
    if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr == "get":
        return bool(node.args) and isinstance(node.args[0], ast.Constant) and node.args[0].value == "data"
    if isinstance(node, ast.BoolOp):  # `event.get("data") or {}`
        return any(_is_event_data(value, names) for value in node.values)
    return False


def key_reads(source: str, keys: set[str], data_is_named_data: bool = False) -> list[str]:
    """Each read of an event payload key by hand: `event.data["plan_id"]`, `e["data"].get("remedy")`, and the same
    through a name assigned such data in the same function (with `data_is_named_data`, any name `data` too: the
    service's and the benches' word for an event's data)."""
    found = []
    tree = ast.parse(source)
    for scope in [tree, *(n for n in ast.walk(tree) if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef)))]:
        names = {t.id for n in ast.walk(scope) if isinstance(n, ast.Assign) and _is_event_data(n.value, set())
                 for t in n.targets if isinstance(t, ast.Name)} | ({"data"} if data_is_named_data else set())
        for node in ast.walk(scope):
            if (isinstance(node, ast.Subscript) and isinstance(node.ctx, ast.Load)
                    and _is_event_data(node.value, names)):
                key = node.slice.value if isinstance(node.slice, ast.Constant) else None
            elif (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr == "get"
                  and _is_event_data(node.func.value, names) and node.args and isinstance(node.args[0], ast.Constant)):
                key = node.args[0].value
            else:
                continue
            if key in keys:
                found.append(f"line {node.lineno}: {key}")
    return sorted(set(found))


def test_no_module_but_the_event_log_reads_an_events_data_by_its_keys():
    keys = _event_keys()
    found = {module: reads for module, path in ALL.items() if module != EVENT_MODULE
             and (reads := key_reads(path.read_text(), keys, module.startswith(SERVICE_AND_BENCHES)))}
    assert found == {}


def test_the_search_finds_a_key_read_by_hand():
    keys = _event_keys()
    assert key_reads("def f(e):\n    data = e.data\n    return data.get('remedy')\n", keys) == ["line 3: remedy"]
    assert key_reads("def f(e):\n    return e['data']['plan_id']\n", keys) == ["line 2: plan_id"]
    assert key_reads("def f(e):\n    x = e.get('data') or {}\n    return x['val_pieces']\n", keys) == [
        "line 3: val_pieces"]
    assert key_reads("def f(data):\n    return data.get('outcome')\n", keys, data_is_named_data=True) == [
        "line 2: outcome"]
    assert key_reads("def f(body):\n    return body['plan_id']\n", keys) == []  # an answer's body, not an event's


# -- a store written before the records --------------------------------------------------------------------------
@pytest.fixture(scope="module")
def old_store(tmp_path_factory):
    db = tmp_path_factory.mktemp("old-store") / "store.sqlite3"
    db.write_bytes(gzip.decompress((OLD / "store.sqlite3.gz").read_bytes()))
    expected = json.loads((OLD / "expected.json").read_text())
    app = create_app(make_settings(db_path=str(db), token=None, compact_every_s=0))
    with TestClient(app) as client:
        yield app, client, expected


def test_the_old_store_holds_every_kind(old_store):
    _, _, expected = old_store
    assert set(expected["kinds"]) == {str(kind) for kind in DATA}


def test_an_old_store_gives_the_memory_it_gave(old_store):
    app, _, expected = old_store
    context = app.state.context
    for oid, entry in expected["objects"].items():
        memo = plain(context.memory.of(context.store, oid))
        assert {k: memo[k] for k in entry["memo"]} == entry["memo"], (oid, entry["scenario"])


def test_an_old_store_lists_the_events_it_listed(old_store):
    _, client, expected = old_store
    for oid, entry in expected["objects"].items():
        listed = client.get(f"/objects/{oid}/events").json()
        assert len(listed) == len(entry["events"])
        for now, then in zip(listed, entry["events"]):
            assert {k: v for k, v in now.items() if k != "data"} == {k: v for k, v in then.items() if k != "data"}
            assert extends(now["data"], then["data"]), (oid, then["kind"], now["data"], then["data"])
            defaults = {f.name: plain(f.default) for f in dataclasses.fields(DATA[now["kind"]])}
            assert {k: now["data"][k] for k in set(now["data"]) - set(then["data"])} == \
                {k: defaults[k] for k in set(now["data"]) - set(then["data"])}  # what the old row left out


def extends(now: Any, then: Any) -> bool:
    """`now` says what `then` says, and where it says more (a field the old row left out) a default value."""
    if isinstance(then, dict):
        return (isinstance(now, dict) and all(k in now and extends(now[k], v) for k, v in then.items())
                and all(now[k] in (None, [], "", 0, False) for k in set(now) - set(then)))
    if isinstance(then, list):
        return isinstance(now, list) and len(now) == len(then) and all(map(extends, now, then))
    return bool(now == then)


def test_an_old_store_answers_a_repeated_request_as_it_did(old_store):
    _, client, expected = old_store
    assert len(expected["keyed"]) >= 10
    for request in expected["keyed"]:
        again = client.post(request["path"], json=request["body"], headers={"Idempotency-Key": request["key"]})
        assert again.status_code == 200 and again.json() == request["answer"], request["path"]


# -- the API ---------------------------------------------------------------------------------------------------
def test_the_event_routes_document_each_kinds_record(old_store):
    _, client, _ = old_store
    doc = client.get("/openapi.json").json()
    schemas = doc["components"]["schemas"]
    listed = doc["paths"]["/objects/{object_id}/events"]["get"]["responses"]["200"]["content"]["application/json"]
    streamed = doc["paths"]["/objects/{object_id}/events/stream"]["get"]["responses"]["200"]["content"][
        "text/event-stream"]
    for schema in (listed["schema"]["items"], streamed["schema"]["properties"]["data"]["contentSchema"]):
        mapping = schema["discriminator"]["mapping"]
        assert set(mapping) == {str(kind) for kind in DATA}
        for kind, ref in mapping.items():
            variant = schemas[ref.rsplit("/", 1)[1]]
            kinds = variant["properties"]["kind"]
            assert kinds.get("enum", [kinds.get("const")]) == [k for k in map(str, DATA) if mapping[k] == ref]
            data_ref = variant["properties"]["data"]["$ref"].rsplit("/", 1)[1]
            assert data_ref == DATA[kind].__name__ and schemas[data_ref]["description"]
            assert all(p.get("description") for p in schemas[data_ref]["properties"].values()), data_ref
    assert {m.__name__ for m in EVENT_MODELS.values()} <= set(schemas)


def test_the_stream_sends_each_event_as_the_list_shows_it(old_store):
    _, client, expected = old_store
    oid = next(o for o, e in expected["objects"].items() if e["scenario"] == "refusals")
    listed = client.get(f"/objects/{oid}/events").json()
    with client.stream("GET", f"/objects/{oid}/events/stream", params={"max_events": len(listed)}) as response:
        frames = [json.loads(line[5:]) for line in response.iter_lines() if line.startswith("data:")]
    assert frames == listed

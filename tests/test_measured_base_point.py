"""The base point as measured: a perception may carry where the worker saw the object's base point p1, and the
service checks a placed object's plans, goals, reach and help there, not where the object was created.

In process (in-memory store, VAL on), and across a restart (SQLite): the measured point is kept with the
perception's event.
"""
from __future__ import annotations

import warnings

import pytest

with warnings.catch_warnings():
    warnings.simplefilter("ignore")  # starlette's notice about httpx2
    from fastapi.testclient import TestClient

from planhrc.geometry import ObjectGeometry, sweep_feasible
from planhrc.kb_service.app import create_app
from planhrc.settings import make_settings

CREATED = [0.6, 0.39]
SLID = [0.8, 0.39]  # 20 cm towards the far edge (x = 0.9): the chain's end turned forward by 45° leaves the table
STRAIGHT = [90, 90, 90, 90, 90]
GOAL = [90, 90, 90, 90, 45]  # link 5 turned towards the far edge: on the table at CREATED, past its edge at SLID


def _app(db_path: str | None = None) -> TestClient:
    return TestClient(create_app(make_settings(db_path=db_path, token=None, validate_plans=True)))


@pytest.fixture
def client():
    with _app() as c:
        yield c


def _placed(client) -> str:
    oid = client.post("/objects", json={"name": "rod", "links": 5, "orientations": 8, "formulation": "relative",
                                        "base_point_xy": CREATED}).json()["id"]
    assert client.put(f"/objects/{oid}/goal", json={"link_orientations_deg": GOAL}).json()["warnings"] == []
    return oid


def _perceive(client, oid: str, base: list[float] | None = None) -> dict:
    body: dict = {"link_orientations_deg": STRAIGHT}
    if base is not None:
        body["base_point_xy"] = base
    answer = client.post(f"/objects/{oid}/perceptions", json=body)
    assert answer.status_code == 200, answer.text
    return answer.json()


def test_a_plan_feasible_where_the_object_was_created_is_not_dispatched_as_is_where_it_was_measured(client):
    oid = _placed(client)
    first = _perceive(client, oid)
    assert first["decision"] == "replan"
    plan_id, action = first["plan_id"], first["next_action"]
    assert _perceive(client, oid, CREATED)["decision"] == "continue"  # measured where created: nothing changes
    assert _perceive(client, oid, [0.6, 0.392])["decision"] == "continue"  # a few millimetres neither

    slid = _perceive(client, oid, SLID)
    assert slid["decision"] != "continue", slid
    assert "base point measured at (0.800, 0.390)" in slid["reason"]
    assert "leaves the table" in slid["reason"] or "unreachable" in slid["reason"]
    follow = slid["next_action"]
    if slid["decision"] == "robot_skill":  # or the robot slides it back to where the plan fits
        assert slid["skill"]["name"] == "slide" and slid["skill"]["base_point_xy"][0] < SLID[0]
    elif follow is not None:  # a new plan: it stays on the table where the object lies now
        assert follow["id"] != action["id"]
        assert sweep_feasible(ObjectGeometry((0.155,) * 5, tuple(SLID)), STRAIGHT, follow["turned_link_index"],
                              follow["held_link_index"], follow["delta_deg"]).ok
    else:  # or the human is asked, naming the link and where to turn it
        assert slid["decision"] == "human_help_requested" and slid["help"][0]["link"] == 5
    assert client.get(f"/objects/{oid}/plan").json()["id"] != plan_id or follow is None
    event = client.get(f"/objects/{oid}/events").json()[-1]
    assert event["data"]["base_point_xy"] == SLID  # kept with the perception's event


def test_a_restarted_service_checks_goals_at_the_last_measured_base_point(tmp_path):
    db = str(tmp_path / "kb.sqlite3")
    with _app(db) as first:
        oid = _placed(first)
        _perceive(first, oid, SLID)
    with _app(db) as again:
        refused = again.put(f"/objects/{oid}/goal", json={"link_orientations_deg": GOAL})
        assert refused.status_code == 422 and "link 5" in refused.json()["detail"], refused.text
        assert again.get(f"/objects/{oid}").json()["base_point_xy"] == CREATED  # as created, still
        _perceive(again, oid, CREATED)  # measured back where it was created: the goal fits again
        assert again.put(f"/objects/{oid}/goal", json={"link_orientations_deg": GOAL}).status_code == 200


@pytest.mark.parametrize("base, field", [
    ([0.6], "base_point_xy"),
    ([0.6, 0.39, 0.0], "base_point_xy"),
    ([0.6, "x"], "base_point_xy[1]"),
    ([True, 0.39], "base_point_xy[0]"),
    ([60.0, 0.39], "base_point_xy[0]"),
    ("0.6, 0.39", "base_point_xy"),
])
def test_a_bad_measured_base_point_is_refused_in_one_line_and_changes_nothing(client, base, field):
    oid = _placed(client)
    _perceive(client, oid)
    events = client.get(f"/objects/{oid}/events").json()
    answer = client.post(f"/objects/{oid}/perceptions", json={"link_orientations_deg": STRAIGHT, "base_point_xy": base})
    assert answer.status_code == 422, answer.text
    detail = answer.json()["detail"]
    assert detail.startswith(field) and "\n" not in detail, detail
    assert client.get(f"/objects/{oid}/events").json() == events


def test_the_library_entry_refuses_a_bad_base_point_naming_it():
    from planhrc.kb_service.store import ValidationError
    from planhrc.kb_service.usecases.inputs import measured_base

    assert measured_base([0.6, 0.39]) == (0.6, 0.39) and measured_base(None) is None
    for bad in ([0.6], [float("nan"), 0.0], ["x", 0.0], 0.6):
        with pytest.raises(ValidationError, match="^base_point_xy: "):
            measured_base(bad)  # type: ignore[arg-type]


def test_the_openapi_documents_the_measured_base_point(client):
    spec = client.get("/openapi.json").json()["components"]["schemas"]["PerceptionCreate"]["properties"]
    assert "measured" in spec["base_point_xy"]["description"]

"""Task-size limit at object creation, a per-request planning deadline, and VAL off the store's lock."""
from __future__ import annotations

import threading
import time
import warnings

import pytest

with warnings.catch_warnings():
    warnings.simplefilter("ignore")  # starlette's notice about httpx2
    from fastapi.testclient import TestClient

from planhrc import pipeline
from planhrc.kb_service.app import create_app
from planhrc.settings import make_settings
from tests.servers import timed_beside


@pytest.fixture
def db(tmp_path):
    return str(tmp_path / "kb.sqlite3")


def _object(client, links, orientations=4, formulation="relative") -> str:
    r = client.post("/objects", json={"name": "rod", "links": links, "orientations": orientations,
                                      "formulation": formulation})
    assert r.status_code == 201, r.text
    return r.json()["id"]


@pytest.mark.parametrize("links", [100, [{"name": "l", "length_m": 0.1}] * 100])
def test_a_task_over_the_size_limit_is_refused_at_creation_in_every_form(db, links):
    with TestClient(create_app(make_settings(db_path=db, token=None, max_task_size=1000))) as client:
        before = client.get("/health").json()
        r = client.post("/objects", json={"name": "rod", "links": links, "orientations": 12,
                                          "formulation": "absolute"})
        assert r.status_code == 422, r.text
        assert "links, orientations" in r.json()["detail"] and "1200" in r.json()["detail"]
        assert client.get("/health").json() == before
        assert client.post("/objects", json={"name": "rod", "links": 50, "orientations": 12,
                                             "formulation": "absolute"}).status_code == 201  # 600: allowed


def test_settings_refuse_a_bad_deadline_or_limit():
    from pydantic import ValidationError

    for field, value in (("planning_deadline_s", 0), ("planning_deadline_s", -1), ("max_task_size", 0),
                         ("val_pieces", 0)):
        with pytest.raises(ValidationError, match=field):
            make_settings(**{field: value})


def test_a_huge_task_answers_503_within_the_deadline_and_other_objects_go_on(db):
    """A 200-link x 12 absolute object cannot be planned within a 1 s deadline: its perception answers 503
    with the reason after about that long (not minutes) and stores nothing, while another object's perceptions
    answer as usual."""
    settings = make_settings(db_path=db, token=None, planning_deadline_s=1.0)
    with TestClient(create_app(settings)) as client:
        big, small = _object(client, 200, 12, "absolute"), _object(client, 3)
        client.put(f"/objects/{big}/goal", json={"link_orientations_deg": [(30 * i) % 360 for i in range(200)]})
        client.put(f"/objects/{small}/goal", json={"link_orientations_deg": [0, 90, 90]})
        client.post(f"/objects/{small}/perceptions", json={"link_orientations_deg": [0, 0, 0]})
        before = client.get("/health").json()
        result: dict = {}

        def perceive_big() -> None:
            t = time.perf_counter()
            result["r"] = client.post(f"/objects/{big}/perceptions", json={"link_orientations_deg": [0] * 200})
            result["s"] = time.perf_counter() - t

        worker = threading.Thread(target=perceive_big)
        worker.start()
        small_times = []
        while worker.is_alive() and len(small_times) < 50:
            t = time.perf_counter()
            angles = [0, 90, 0] if len(small_times) % 2 else [90, 0, 0]
            r = client.post(f"/objects/{small}/perceptions", json={"link_orientations_deg": angles})
            assert r.status_code == 200, r.text
            small_times.append(time.perf_counter() - t)
        worker.join(60)
        r = result["r"]
        assert r.status_code == 503, r.text
        assert "deadline of 1 s exceeded" in r.json()["detail"]
        assert result["s"] < 15, result["s"]  # about the deadline (plus translation), not minutes
        assert small_times and max(small_times) < 2.0, small_times
        events = client.get(f"/objects/{big}/events").json()
        assert [e["kind"] for e in events] == ["object_created", "goal_set"]  # the perception left nothing
        assert client.get("/health").json()["triples"] > before["triples"]  # only the small object's writes


def test_a_slow_val_on_one_object_does_not_hold_the_store(db, monkeypatch):
    """VAL takes 3 s on object A's plan; meanwhile B's perceptions (writes) and /health answer at once: VAL no
    longer runs inside the store's transaction."""
    with TestClient(create_app(make_settings(db_path=db, token=None))) as client:
        slow, fast = _object(client, 3), _object(client, 3)
        for oid in (slow, fast):
            client.put(f"/objects/{oid}/goal", json={"link_orientations_deg": [0, 90, 90]})
        client.post(f"/objects/{fast}/perceptions", json={"link_orientations_deg": [0, 90, 0]})
        real = pipeline._run_val
        started = threading.Event()

        def run_val(outcome, obj, n_pieces, timeout_s):
            if obj is not None and obj.ident == slow:
                started.set()
                time.sleep(3.0)
            return real(outcome, obj, n_pieces, timeout_s)

        monkeypatch.setattr(pipeline, "_run_val", run_val)
        slow_answer, timings, done_before = timed_beside(
            lambda: client.post(f"/objects/{slow}/perceptions", json={"link_orientations_deg": [0, 0, 0]}),
            started, (
                ("replan", lambda: client.post(f"/objects/{fast}/perceptions", json={"link_orientations_deg": [90, 0, 0]})),
                ("health", lambda: client.get("/health")),
                ("replan_again", lambda: client.post(f"/objects/{fast}/perceptions",
                                                     json={"link_orientations_deg": [0, 0, 0]})),
            ))
        assert slow_answer.status_code == 200 and slow_answer.json()["decision"] == "replan"
        assert done_before < 3.0, (done_before, timings)
        assert timings["health"] < 0.25, timings

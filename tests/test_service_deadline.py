"""Task-size limit at object creation, a per-request planning deadline, and VAL off the store's lock."""
from __future__ import annotations

import threading
import time
import warnings

import pytest

with warnings.catch_warnings():
    warnings.simplefilter("ignore")  # starlette's notice about httpx2
    from fastapi.testclient import TestClient

from planhrc.kb_service.usecases import unit_of_work
from planhrc.pipeline import val_runs
from planhrc.kb_service.app import create_app
from planhrc.kb_service.store import SqliteStore
from planhrc.planner.validate import ValidationResult
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
    longer runs inside the store's transaction (a relative plan's write, begun while VAL checks, waits for it in
    the transaction for OVERLAP_WAIT_S only, then rolls back and waits outside)."""
    with TestClient(create_app(make_settings(db_path=db, token=None))) as client:
        slow, fast = _object(client, 3), _object(client, 3)
        for oid in (slow, fast):
            client.put(f"/objects/{oid}/goal", json={"link_orientations_deg": [0, 90, 90]})
        client.post(f"/objects/{fast}/perceptions", json={"link_orientations_deg": [0, 90, 0]})
        real = val_runs.start_val
        started = threading.Event()

        def start_val(task, steps, armed=None):
            check = real(task, steps, armed)
            if f"(problem {slow}-task)" in task.problem:
                started.set()
                return _Slower(check, 3.0)
            return check

        monkeypatch.setattr(val_runs, "start_val", start_val)
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


class _Slower:
    """A VAL run (`pipeline.ValCheck`) whose verdict comes `seconds` after it began at the earliest (and, with
    `verdict`, is that); the time it is first given is appended to `ended`."""

    def __init__(self, check, seconds: float, verdict: ValidationResult | None = None,
                 ended: list[float] | None = None) -> None:
        self.check, self.ready_at, self.forced, self.ended = check, time.monotonic() + seconds, verdict, ended

    def verdict(self, timeout_s=None):
        wait = self.ready_at - time.monotonic()
        if wait > 0:
            if timeout_s is not None and timeout_s < wait:
                time.sleep(max(timeout_s, 0.0))
                return None
            time.sleep(wait)
        real = self.check.verdict(timeout_s)
        if real is None:
            return None
        if self.ended is not None and not self.ended:
            self.ended.append(time.monotonic())
        return real if self.forced is None else self.forced

    def cancel(self):
        self.check.cancel()


def _timed_val(monkeypatch, seconds: float, verdict: ValidationResult | None = None) -> list[float]:
    """VAL made `seconds` slower (and, with `verdict`, answering that); the times its runs end."""
    real, ended = val_runs.start_val, []

    def start_val(task, steps, armed=None):
        return _Slower(real(task, steps, armed), seconds, verdict, ended)

    monkeypatch.setattr(val_runs, "start_val", start_val)
    return ended


def _write_starts(monkeypatch) -> list[float]:
    starts, real = [], SqliteStore.add_perception

    def add_perception(self, perception):
        starts.append(time.monotonic())
        return real(self, perception)

    monkeypatch.setattr(SqliteStore, "add_perception", add_perception)
    return starts


def test_a_relative_replan_writes_while_val_checks_and_stores_only_what_val_accepted(db, monkeypatch):
    """The perception's write begins while VAL still checks the new plan (its run overlaps the write on the
    second core), and commits the plan only once VAL accepted it; a plan VAL refuses meanwhile is not stored."""
    with TestClient(create_app(make_settings(db_path=db, token=None))) as client:
        oid = _object(client, 3)
        client.put(f"/objects/{oid}/goal", json={"link_orientations_deg": [0, 90, 90]})
        monkeypatch.setattr(unit_of_work, "OVERLAP_WAIT_S", 10.0)  # this test is about the overlap, not its bound
        ended, starts = _timed_val(monkeypatch, 0.05), _write_starts(monkeypatch)
        answer = client.post(f"/objects/{oid}/perceptions", json={"link_orientations_deg": [0, 0, 0]}).json()
        assert answer["decision"] == "replan" and answer["next_action"] is not None
        assert len(starts) == len(ended) == 1 and starts[0] < ended[0]  # the write began before VAL answered
        assert client.get(f"/objects/{oid}/plan").json()["id"] == answer["plan_id"]

        monkeypatch.undo()
        monkeypatch.setattr(unit_of_work, "OVERLAP_WAIT_S", 10.0)
        ended = _timed_val(monkeypatch, 0.05, ValidationResult(False, "step 1: precondition not satisfied", 0.0))
        starts = _write_starts(monkeypatch)
        refused = client.post(f"/objects/{oid}/perceptions", json={"link_orientations_deg": [0, 270, 180]}).json()
        assert starts[0] < ended[0]
        assert refused["decision"] == "no_plan" and refused["plan_id"] is None
        assert "VAL rejected the plan: step 1: precondition not satisfied" in refused["reason"]
        event = client.get(f"/objects/{oid}/events").json()[-1]
        assert event["data"]["plan_id"] is None and event["data"]["planning_status"] == "invalid"

"""Write `store.sqlite3.gz` and `expected.json` beside this file: a store written by the service of commit baf17fe, the
last before each event kind had its own record (`kb_service.usecases.log`), and what that service's memory, event
log and remembered answers said of it. `tests/test_event_records.py` reads the store with today's code and compares.

Run from a checkout of that commit, with its environment: `.venv/bin/python tests/data/old-store/make.py`. Every
event kind is written by the service's own code, through its HTTP routes (a dispatch withheld: its VAL gate made to
refuse once); each decision, feedback and give-up kind the memory reads is there, with idempotency keys on some
requests.
"""
from __future__ import annotations

import dataclasses
import enum
import gzip
import json
import sqlite3
import sys
import time
import warnings
from pathlib import Path
from typing import Any

with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    from fastapi.testclient import TestClient

from planhrc.kb_service.app import create_app
from planhrc.kb_service.usecases import dispatch
from planhrc.settings import make_settings

HERE = Path(__file__).resolve().parent
STRAIGHT = [90, 90, 90, 90, 90]
PLACED = {"name": "rod", "links": 5, "orientations": 8, "base_point_xy": [0.6, 0.39]}


def plain(value: Any) -> Any:
    """A memo as JSON: records as objects, sets sorted, enums as their values."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {f.name: plain(getattr(value, f.name)) for f in dataclasses.fields(value)}
    if isinstance(value, enum.Enum):
        return value.value
    if isinstance(value, (frozenset, set)):
        return sorted(plain(v) for v in value)
    if isinstance(value, (list, tuple)):
        return [plain(v) for v in value]
    if isinstance(value, dict):
        return {str(k): plain(v) for k, v in value.items()}
    return value


class Recorder:
    """Requests sent with an idempotency key, and their answers."""

    def __init__(self, client: TestClient) -> None:
        self.client = client
        self.keyed: list[dict[str, Any]] = []
        self.count = 0

    def post(self, path: str, body: dict[str, Any], keyed: bool = False) -> Any:
        headers = {}
        if keyed:
            self.count += 1
            headers["Idempotency-Key"] = f"key-{self.count}"
        answer = self.client.post(path, json=body, headers=headers)
        assert answer.status_code == 200, answer.text
        if keyed:
            self.keyed.append({"path": path, "key": headers["Idempotency-Key"], "body": body, "answer": answer.json()})
        return answer.json()

    def act(self, oid: str, outcome: str = "succeeded", keyed: bool = False, **feedback: Any) -> dict[str, Any]:
        action = self.client.post(f"/objects/{oid}/actions/next").json()
        assert action is not None
        self.post(f"/objects/{oid}/actions/{action['id']}/feedback", {"outcome": outcome, **feedback}, keyed)
        return dict(action)


def stalls(r: Recorder) -> str:
    """A repeated stall: split, the other way round, re-planned, then the human asked; then the goal."""
    c = r.client
    oid = c.post("/objects", json={**PLACED, "formulation": "relative"}).json()["id"]
    c.put(f"/objects/{oid}/goal", json={"link_orientations_deg": [90, 90, 90, 90, 0]})
    for _ in range(6):
        decision = r.post(f"/objects/{oid}/perceptions", {"link_orientations_deg": STRAIGHT}, keyed=True)
        if decision["decision"] == "human_help_requested":
            break
        if c.post(f"/objects/{oid}/actions/next").json() is None:
            continue
        action = c.get(f"/objects/{oid}").json()["execution"]["dispatched_action_id"]
        r.post(f"/objects/{oid}/actions/{action}/feedback",
               {"outcome": "failed", "reason": "stall", "message": "link 5 stalled at 90°", "measured_deg": 90.4},
               keyed=True)
    r.post(f"/objects/{oid}/perceptions", {"link_orientations_deg": [90, 90, 90, 90, 0]})
    return str(oid)


def refusals(r: Recorder) -> str:
    """A turn refused with the worker's fact, then one refused without it (the memo's pose and base point)."""
    c = r.client
    measured = [90.4, 89.7, 90.2, 90.1, 89.8]
    oid = c.post("/objects", json={**PLACED, "formulation": "absolute"}).json()["id"]
    c.put(f"/objects/{oid}/goal", json={"link_orientations_deg": [90, 90, 90, 90, 45]})
    r.post(f"/objects/{oid}/perceptions", {"link_orientations_deg": measured})
    fact = {"code": "off_table", "link": 5, "against": "the table's far edge", "distance_m": 0.02}
    r.act(oid, "failed", keyed=True, reason="left_table", refusal=fact,
          message="not started: link 5 leaves the table: 0.02 m past its edge")
    r.post(f"/objects/{oid}/perceptions", {"link_orientations_deg": measured, "base_point_xy": [0.6, 0.39]},
           keyed=True)
    bare = c.post("/objects", json={**PLACED, "formulation": "relative"}).json()["id"]
    c.put(f"/objects/{bare}/goal", json={"link_orientations_deg": [90, 90, 90, 90, 45]})
    r.post(f"/objects/{bare}/perceptions", {"link_orientations_deg": STRAIGHT})
    r.act(bare, "failed", reason="collision", message="not started")
    r.post(f"/objects/{bare}/perceptions", {"link_orientations_deg": STRAIGHT}, keyed=True)
    return str(oid)


def slide(r: Recorder) -> str:
    """No plan fits where the object lies: the robot slides it first (`robot_skill`); measured there, the plan goes
    on; a perception with links unseen (and a base point) changes nothing."""
    c = r.client
    start, base = [315.4, 45.01, 179.85, 45.47, 179.85], [0.649, 0.124]
    oid = c.post("/objects", json={**PLACED, "formulation": "relative", "base_point_xy": base}).json()["id"]
    c.put(f"/objects/{oid}/goal", json={"link_orientations_deg": [315, 225, 0, 270, 180]})
    skill = r.post(f"/objects/{oid}/perceptions", {"link_orientations_deg": start, "base_point_xy": base},
                   keyed=True)
    assert skill["decision"] == "robot_skill", skill
    r.post(f"/objects/{oid}/perceptions",
           {"link_orientations_deg": [315.4, None, 179.85, 45.47, None], "base_point_xy": [0.5, 0.2]}, keyed=True)
    r.post(f"/objects/{oid}/perceptions",
           {"link_orientations_deg": start, "base_point_xy": skill["skill"]["base_point_xy"]})
    return str(oid)


def far(r: Recorder) -> str:
    """A goal set with warnings; out of the arms' reach: the human is asked, naming the link."""
    c = r.client
    oid = c.post("/objects", json={**PLACED, "formulation": "absolute", "base_point_xy": [0.88, 0.5]}).json()["id"]
    assert c.put(f"/objects/{oid}/goal", json={"link_orientations_deg": [90, 135, 135, 135, 135]}).json()["warnings"]
    asked = r.post(f"/objects/{oid}/perceptions", {"link_orientations_deg": STRAIGHT}, keyed=True)
    assert asked["decision"] == "human_help_requested", asked
    return str(oid)


def gives_up(r: Recorder) -> str:
    """A worker gives up with an action dispatched: the help request beside it; a feedback reported late."""
    c = r.client
    oid = c.post("/objects", json={**PLACED, "formulation": "relative"}).json()["id"]
    c.put(f"/objects/{oid}/goal", json={"link_orientations_deg": [90, 90, 90, 90, 0]})
    first = r.post(f"/objects/{oid}/perceptions", {"link_orientations_deg": STRAIGHT})
    action = c.post(f"/objects/{oid}/actions/next").json()
    assert action["id"] == first["next_action"]["id"] and action["macro_steps"] == 2, action
    turned = [90, 90, 90, 90, 45]  # half the macro step: the execution moves on to its second step
    r.post(f"/objects/{oid}/perceptions", {"link_orientations_deg": turned})  # moves the execution on
    r.post(f"/objects/{oid}/actions/{action['id']}/feedback", {"outcome": "succeeded"}, keyed=True)  # late
    c.post(f"/objects/{oid}/actions/next")
    r.post(f"/objects/{oid}/give-up", {"reason": "repeated_failure", "message": "a_2 failed three times"})
    return str(oid)


def early(r: Recorder) -> str:
    """A re-plan answered once VAL accepted the first piece, the later pieces' verdicts behind the answer, and a
    dispatch the VAL gate withheld."""
    c = r.client
    start = [0, 45, 90, 135, 180, 225, 270, 315, 0, 45]
    oid = c.post("/objects", json={"name": "bar", "links": 10, "orientations": 8,
                                   "formulation": "absolute"}).json()["id"]
    c.put(f"/objects/{oid}/goal", json={"link_orientations_deg": [180, 0, 180, 0, 180, 0, 180, 0, 180, 0]})
    answer = r.post(f"/objects/{oid}/perceptions", {"link_orientations_deg": start}, keyed=True)
    assert answer["decision"] == "replan", answer
    deadline = time.monotonic() + 120
    while not any(e["kind"] == "val_verdict" for e in c.get(f"/objects/{oid}/events").json()):
        assert time.monotonic() < deadline, "no VAL verdict behind the answer"
        time.sleep(0.2)
    real = dispatch.val_gate
    dispatch.val_gate = lambda *args, **kwargs: "VAL refused piece 1 (made up by make.py)"
    try:
        assert c.post(f"/objects/{oid}/actions/next").json() is None
    finally:
        dispatch.val_gate = real
    r.post(f"/objects/{oid}/perceptions", {"link_orientations_deg": start})
    return str(oid)


def refused(r: Recorder) -> str:
    """VAL refuses the plan (its run made to refuse): no plan, the planning status `invalid`."""
    from planhrc.pipeline import val_runs
    from planhrc.planner.validate import ValidationResult

    class Refusing:
        def verdict(self, timeout_s: float | None = None) -> ValidationResult:
            return ValidationResult(False, "refused (made up by make.py)", 0.0)

        def cancel(self) -> None:
            pass

    c = r.client
    oid = c.post("/objects", json={"name": "abstract", "links": 4, "orientations": 4,
                                   "formulation": "relative"}).json()["id"]
    c.put(f"/objects/{oid}/goal", json={"link_orientations_deg": [0, 90, 90, 180]})
    real = val_runs.start_val
    val_runs.start_val = lambda *args, **kwargs: Refusing()
    try:
        answer = r.post(f"/objects/{oid}/perceptions", {"link_orientations_deg": [0, 0, 0, 0]}, keyed=True)
    finally:
        val_runs.start_val = real
    assert answer["decision"] == "no_plan", answer
    return str(oid)


def bimanual(r: Recorder) -> str:
    """A bimanual object: the feedback events keep the robot's control facts."""
    c = r.client
    oid = c.post("/objects", json={"name": "bi", "links": 4, "orientations": 4,
                                   "formulation": "bimanual"}).json()["id"]
    c.put(f"/objects/{oid}/goal", json={"link_orientations_deg": [0, 90, 90, 180]})
    links = [0.0, 0.0, 0.0, 0.0]
    r.post(f"/objects/{oid}/perceptions", {"link_orientations_deg": links})
    r.act(oid, keyed=True)
    r.post(f"/objects/{oid}/perceptions", {"link_orientations_deg": links})
    r.act(oid, "failed", reason="grasp_lost")
    r.post(f"/objects/{oid}/perceptions", {"link_orientations_deg": links}, keyed=True)
    return str(oid)


def main() -> int:
    db = HERE / "store.sqlite3"
    for path in (db, HERE / "store.sqlite3-wal", HERE / "store.sqlite3-shm"):
        path.unlink(missing_ok=True)
    settings = make_settings(db_path=str(db), token=None, validate_plans=True, planning_deadline_s=60.0,
                             compact_every_s=0)
    expected: dict[str, Any] = {"commit": "baf17fe", "objects": {}}
    app = create_app(settings)
    with TestClient(app) as client:
        r = Recorder(client)
        for make in (stalls, refusals, slide, far, gives_up, early, refused, bimanual):
            before = {o["id"] for o in client.get("/objects").json()}
            make(r)
            for oid in sorted({o["id"] for o in client.get("/objects").json()} - before):
                expected["objects"][oid] = {"scenario": make.__name__}
        context = app.state.context
        for oid, entry in expected["objects"].items():
            entry["memo"] = plain(context.memory.of(context.store, oid))
            entry["events"] = client.get(f"/objects/{oid}/events").json()
        expected["keyed"] = r.keyed
    conn = sqlite3.connect(db)
    conn.execute("PRAGMA wal_checkpoint(TRUNCATE)")
    conn.execute("PRAGMA journal_mode=DELETE")  # one file, every page in it
    conn.execute("VACUUM")
    conn.close()
    assert not (HERE / "store.sqlite3-wal").exists()
    (HERE / "store.sqlite3.gz").write_bytes(gzip.compress(db.read_bytes(), compresslevel=9, mtime=0))
    db.unlink()
    kinds = sorted({e["kind"] for entry in expected["objects"].values() for e in entry["events"]})
    expected["kinds"] = kinds
    (HERE / "expected.json").write_text(json.dumps(expected, indent=1, sort_keys=True) + "\n")
    size = (HERE / "store.sqlite3.gz").stat().st_size
    print(f"{HERE / 'store.sqlite3.gz'}: {size / 1e3:.0f} kB; kinds: {', '.join(kinds)}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())

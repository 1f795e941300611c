"""Retention: compaction keeps each object's current records and its last perceived states, drops the rest."""
from __future__ import annotations

import os
import subprocess
import sys
import warnings

import pytest

with warnings.catch_warnings():
    warnings.simplefilter("ignore")  # starlette's notice about httpx2
    from fastapi.testclient import TestClient

from planhrc.kb_service.app import create_app
from planhrc.kb_service.store import SqliteStore, ValidationError
from planhrc.settings import make_settings

NT = {"Accept": "application/n-triples"}
CONFIGS = ([0, 0, 0], [0, 90, 0], [0, 0, 90], [90, 0, 0], [0, 0, 0], [0, 90, 0], [0, 0, 180])


def _history(client) -> tuple[str, list[dict]]:
    oid = client.post("/objects", json={"name": "rod", "links": 3, "orientations": 4,
                                        "formulation": "relative"}).json()["id"]
    client.put(f"/objects/{oid}/goal", json={"link_orientations_deg": [0, 90, 90]})
    answers = [client.post(f"/objects/{oid}/perceptions", json={"link_orientations_deg": links}).json()
               for links in CONFIGS]
    return oid, answers


def test_compaction_keeps_the_current_abox_and_the_last_perceptions(tmp_path):
    db = str(tmp_path / "kb.sqlite3")
    with TestClient(create_app(make_settings(db_path=db, token=None, compact_every_s=0))) as client:
        oid, answers = _history(client)
        other, _ = _history(client)
        kb = client.app.state.kb
        current = set(client.get("/ontology", headers=NT).text.splitlines())
        before = client.get("/health").json()["triples"]
        plans = {a["plan_id"] for a in answers if a["plan_id"]}
        done = kb.compact(keep_perceived=2)
        assert done.objects == 2 and done.individuals > 0 and done.triples > 0
        after = client.get("/health").json()["triples"]
        assert after == before - done.triples
        assert set(client.get("/ontology", headers=NT).text.splitlines()) == current  # the current ABox is whole
        perceived = [a["perceived_state_id"] for a in answers]
        for state in perceived[-2:]:
            assert client.get(f"/states/{state}").status_code == 200
        plan = client.get(f"/objects/{oid}/plan").json()
        problem = client.get(f"/problems/{plan['problem_id']}").json()
        for state in perceived[:-2]:
            expected = 200 if state == problem["init_state_id"] else 404
            assert client.get(f"/states/{state}").status_code == expected, state
        assert all(client.get(f"/states/{s}").status_code == 200 for s in plan["expected_state_ids"])
        assert client.get(f"/objects/{oid}/pddl/problem").status_code == 200
        assert any(client.get(f"/plans/{p}").status_code == 404 for p in plans - {plan["id"]})
        assert len(client.get(f"/objects/{oid}/events").json()) == len(answers) + 2  # the log is kept whole
        again = client.post(f"/objects/{oid}/perceptions", json={"link_orientations_deg": [0, 0, 0]})
        assert again.status_code == 200 and again.json()["decision"] in ("continue", "replan", "resume")
        assert kb.compact(keep_perceived=2).individuals <= 1 + 3  # only what the new perception pushed out
        with pytest.raises(ValidationError, match="keep_perceived"):
            kb.compact(keep_perceived=0)
        final = client.get("/health").json()["triples"]
    with SqliteStore(db, make_settings().tbox_path) as kb:  # a scan of the tables agrees with the counters
        assert kb.triple_count() == final


def test_planhrc_compact_on_a_store_file(tmp_path):
    db = str(tmp_path / "kb.sqlite3")
    with TestClient(create_app(make_settings(db_path=db, token=None, compact_every_s=0))) as client:
        _history(client)
    run = subprocess.run([sys.executable, "-m", "planhrc.cli", "compact", "--db", db, "--keep", "1"],
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == 0 and "compacted" in run.stdout and "individuals" in run.stdout, run.stderr
    for argv, needle in ((["--db", str(tmp_path / "none.sqlite3")], "--db: no store file"),
                         (["--db", db, "--keep", "0"], "--keep")):
        bad = subprocess.run([sys.executable, "-m", "planhrc.cli", "compact", *argv], capture_output=True,
                             text=True, timeout=120)
        assert bad.returncode == 2 and needle in bad.stderr and "Traceback" not in bad.stderr, bad.stderr


def test_planhrc_compact_vacuum_gives_an_old_store_small_pages_and_its_space_back(tmp_path):
    """A store file made with owlready2's 32 KiB pages (as every store was before they were 4 KiB): `planhrc
    compact --vacuum` drops the history, rewrites the file with 4 KiB pages, gives the freed space back, and the
    store still holds what it held."""
    import sqlite3

    db = str(tmp_path / "kb.sqlite3")
    with TestClient(create_app(make_settings(db_path=db, token=None, compact_every_s=0))) as client:
        _history(client)
        objects = client.get("/objects").json()
    old = sqlite3.connect(db)
    old.execute("PRAGMA journal_mode=DELETE").fetchall()
    old.execute("PRAGMA page_size = 32768")
    old.execute("VACUUM")
    old.execute("PRAGMA journal_mode=WAL").fetchall()
    old.close()
    size = os.path.getsize(db)
    argv = [sys.executable, "-m", "planhrc.cli", "compact", "--db", db, "--keep", "1", "--vacuum"]
    with SqliteStore(db, make_settings().tbox_path):  # a process that has the file open: refused, in one line
        busy = subprocess.run(argv, capture_output=True, text=True, timeout=120)
    assert busy.returncode == 1 and "Traceback" not in busy.stderr, busy.stderr
    assert busy.stderr.strip().splitlines() == ["planhrc compact: store: another process has the file open (a "
                                                "running service?); stop it before rewriting the file"]
    run = subprocess.run(argv, capture_output=True, text=True, timeout=120)
    assert run.returncode == 0 and "rewrote" in run.stdout, run.stderr
    check = sqlite3.connect(db)
    assert check.execute("PRAGMA page_size").fetchone()[0] == 4096
    assert check.execute("PRAGMA journal_mode").fetchone()[0] == "wal"
    check.close()
    assert os.path.getsize(db) < size
    with TestClient(create_app(make_settings(db_path=db, token=None, compact_every_s=0))) as client:
        assert client.get("/objects").json() == objects
        assert client.get("/health").status_code == 200

"""Clients and their roles: named keys in the store, each route open to the role it declares.

The OpenAPI document is walked, so a new route cannot be left open: every operation declares its access
(`x-planhrc-access`), each role's key is answered (not 401/403) where its role is allowed and 403 naming the role
needed elsewhere, without a key 401, and a refusal stores nothing. Keys are made, rotated and revoked by `planhrc
keys` in another process while a real service runs, and take effect without a restart; only their hash is in the
database; every event names the client that caused it; a SQLite store made before clients opens and works.
"""
from __future__ import annotations

import hashlib
import sqlite3
import subprocess
import sys
import time
from pathlib import Path
from typing import Any, Iterator

import httpx
import pytest
from fastapi.testclient import TestClient

from planhrc.kb_service.app import create_app
from planhrc.kb_service.clients import ROLES
from planhrc.kb_service.guard import ACCESS, OPEN, READ
from planhrc.settings import make_settings
from tests.servers import serve_env, serving, store_location

GOAL = [0, 90, 90, 180]
# A body for each write the walk sends; a write not named here gets `{}` (a 422 once admitted: still no 401/403).
BODIES: dict[tuple[str, str], Any] = {
    ("post", "/objects"): {"name": "rod", "links": 4, "orientations": 4, "formulation": "relative"},
    ("put", "/objects/{object_id}/goal"): {"link_orientations_deg": GOAL},
    ("post", "/objects/{object_id}/perceptions"): {"link_orientations_deg": [0, 0, 0, 0]},
    ("post", "/objects/{object_id}/actions/{action_id}/feedback"): {"outcome": "succeeded"},
    ("post", "/objects/{object_id}/give-up"): {"reason": "unreachable", "message": "walked"},
    ("post", "/reasoning"): {"reasoner": "hermit", "object_id": "nothing-such"},
    ("post", "/sparql"): "ASK { ?s ?p ?o }",
}


def keys_cli(*args: str, db: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "planhrc.cli", "keys", *args, "--db", str(db)], env=serve_env(),
                          capture_output=True, text=True, timeout=120)


@pytest.fixture
def site(tmp_path: Path) -> Iterator[tuple[TestClient, dict[str, str], str]]:
    """A service on a SQLite file with one key per role, reads protected, an object with a goal and a plan."""
    app = create_app(make_settings(db_path=str(tmp_path / "kb.sqlite3"), protect_reads=True, val_armed=False))
    with TestClient(app) as client:
        keys = {role: app.state.clients.add(f"the-{role}", role) for role in sorted(ROLES)}
        app.state.clients.refresh()
        operator = {"Authorization": f"Bearer {keys['operator']}"}
        oid = client.post("/objects", json=BODIES[("post", "/objects")], headers=operator).json()["id"]
        assert client.put(f"/objects/{oid}/goal", json={"link_orientations_deg": GOAL}, headers=operator).is_success
        robot = {"Authorization": f"Bearer {keys['robot']}"}
        assert client.post(f"/objects/{oid}/perceptions", json={"link_orientations_deg": [0, 0, 0, 0]},
                           headers=robot).json()["decision"] == "replan"
        yield client, keys, oid


def operations(client: TestClient) -> list[tuple[str, str, str]]:
    """(method, path template, access) of every operation of the OpenAPI document."""
    document = client.get("/openapi.json").json()
    return [(method, path, op.get(ACCESS)) for path, ops in document["paths"].items() for method, op in ops.items()]


def concrete(path: str, oid: str, client: TestClient, headers: dict[str, str]) -> str:
    """The template with ids of the site's records (an unknown id where none fits: a 404 is still an answer)."""
    plan = client.get(f"/objects/{oid}/plan", headers=headers).json()
    values = {"object_id": oid, "plan_id": plan["id"], "state_id": plan["expected_state_ids"][0],
              "by_state_id": plan["expected_state_ids"][-1], "problem_id": plan["problem_id"],
              "action_id": plan["actions"][0]["id"] if plan.get("actions") else "none", "job_id": "none"}
    return path.format(**values)


def snapshot(client: TestClient, oid: str, headers: dict[str, str]) -> tuple[Any, ...]:
    objects = client.get("/objects", headers=headers).json()
    events = client.get(f"/objects/{oid}/events", headers=headers).json()
    return len(objects), [(e["seq"], e["kind"]) for e in events]


def send(client: TestClient, method: str, path: str, template: str, headers: dict[str, str]) -> httpx.Response:
    body = BODIES.get((method, template), {})
    if isinstance(body, str):
        headers = {**headers, "Content-Type": "application/sparql-query"}
        return client.request(method.upper(), path, content=body, headers=headers)
    return client.request(method.upper(), path, json=body if method != "get" else None, headers=headers,
                          params={"timeout_s": 0.1, "max_events": 1} if path.endswith("/stream") else None)


def test_every_route_declares_its_access_and_answers_each_role_accordingly(site):
    client, keys, oid = site
    reader = {"Authorization": f"Bearer {keys['reader']}"}
    ops = operations(client)
    assert ops and all(access in (OPEN, READ, *ROLES) for _, _, access in ops), \
        [o for o in ops if o[2] not in (OPEN, READ, *ROLES)]
    # each writing role is some route's (a reader only reads), and the probes are open
    assert {access for _, _, access in ops} == {OPEN, READ, "robot", "operator"}
    assert {p for _, p, a in ops if a == OPEN} == {"/health", "/health/live", "/health/ready"}
    before = snapshot(client, oid, reader)
    refused = 0
    for method, template, access in ops:
        path = concrete(template, oid, client, reader)
        if access == OPEN:
            assert send(client, method, path, template, {}).status_code == 200, template
            continue
        nobody = send(client, method, path, template, {})
        assert nobody.status_code == 401 and nobody.headers["www-authenticate"] == "Bearer", (template, nobody.text)
        for role, key in keys.items():
            if access != READ and role != access:
                answer = send(client, method, path, template, {"Authorization": f"Bearer {key}"})
                assert answer.status_code == 403, (template, role, answer.text)
                assert f"needs the role {access}" in answer.json()["detail"]
                refused += 1
        assert snapshot(client, oid, reader) == before, f"a refusal of {method} {template} stored something"
    assert refused == 2 * len([o for o in ops if o[2] in ROLES])
    # and the allowed: a write after every refusal, so that each one's effect does not hide another's refusal
    for method, template, access in ops:
        if access in (OPEN,):
            continue
        roles = sorted(ROLES) if access == READ else [access]
        for role in roles:
            path = concrete(template, oid, client, reader)
            answer = send(client, method, path, template, {"Authorization": f"Bearer {keys[role]}"})
            assert answer.status_code not in (401, 403) and answer.status_code < 500, (template, role, answer.text)


def test_each_event_names_the_client_that_caused_it(site):
    client, keys, oid = site
    events = client.get(f"/objects/{oid}/events", headers={"Authorization": f"Bearer {keys['reader']}"}).json()
    by_kind = {e["kind"]: e["client"] for e in events}
    assert by_kind["object_created"] == "the-operator" and by_kind["goal_set"] == "the-operator"
    assert by_kind["replan"] == "the-robot"
    assert all("client" not in e["data"] for e in events)  # a field of the event, not of its data


def test_an_open_service_stays_open_until_it_has_a_key(tmp_path):
    app = create_app(make_settings(db_path=str(tmp_path / "kb.sqlite3"), val_armed=False))
    with TestClient(app) as client:
        body = BODIES[("post", "/objects")]
        oid = client.post("/objects", json=body).json()["id"]
        assert client.get(f"/objects/{oid}/events").json()[0]["client"] is None  # nobody in particular
        key = app.state.clients.add("ops", "operator")
        app.state.clients.refresh()
        assert client.post("/objects", json=body).status_code == 401  # a key exists: writes need one now
        assert client.get("/objects").status_code == 200  # reads stay open without --protect-reads
        assert client.post("/objects", json=body, headers={"Authorization": f"Bearer {key}"}).status_code == 201


@pytest.mark.integration
def test_keys_made_rotated_and_revoked_by_the_command_line_take_effect_without_a_restart(tmp_path):
    db = tmp_path / "kb.sqlite3"
    body = BODIES[("post", "/objects")]
    with serving(db) as base, httpx.Client(base_url=base, timeout=60) as http:
        assert http.post("/objects", json=body).status_code == 201  # no key yet: open, as before clients
        made = keys_cli("add", "ops", "--role", "operator", db=db)
        assert made.returncode == 0, made.stderr
        key = made.stdout.strip()
        assert key.startswith("phk_") and "\n" not in key  # the key alone on stdout, for scripts
        auth = {"Authorization": f"Bearer {key}"}
        assert eventually(lambda: http.post("/objects", json=body).status_code == 401)
        assert http.post("/objects", json=body, headers=auth).status_code == 201
        rotated = keys_cli("rotate", "ops", db=db)
        assert rotated.returncode == 0, rotated.stderr
        new = {"Authorization": f"Bearer {rotated.stdout.strip()}"}
        assert eventually(lambda: http.post("/objects", json=body, headers=auth).status_code == 401)
        assert http.post("/objects", json=body, headers=new).status_code == 201
        assert keys_cli("revoke", "ops", db=db).returncode == 0
        assert eventually(lambda: http.post("/objects", json=body, headers=new).status_code == 401)
        listed = keys_cli("list", db=db)
        assert listed.returncode == 0 and "ops" in listed.stdout and "operator" in listed.stdout
        assert key not in listed.stdout and rotated.stdout.strip() not in listed.stdout
    with sqlite3.connect(db) as conn:  # at rest: the hash of the current key, never a key
        rows = conn.execute("SELECT * FROM planhrc_client").fetchall()
    text = repr(rows)
    assert "phk_" not in text and hashlib.sha256(rotated.stdout.strip().encode()).hexdigest() in text
    bad = keys_cli("add", "ops", "--role", "reader", db=db)
    assert bad.returncode == 1 and bad.stderr.count("\n") == 1 and "exists already" in bad.stderr


def eventually(check: Any, within_s: float = 10.0) -> bool:
    """A change made by another process shows within the registry's refresh (a second), with slack for a loaded
    machine; counted in attempts, not asserted on time."""
    deadline = time.monotonic() + within_s
    while time.monotonic() < deadline:
        if check():
            return True
        time.sleep(0.1)
    return False


@pytest.mark.parametrize("backend", ["sqlite", "postgresql"])
def test_a_store_made_before_clients_opens_and_works(tmp_path, backend, request):
    """An existing store written before events named their client (no `client` column, no client table)."""
    db = store_location(backend, tmp_path, request)
    settings = make_settings(db_path=db, val_armed=False)
    with TestClient(create_app(settings)) as client:
        oid = client.post("/objects", json=BODIES[("post", "/objects")]).json()["id"]
    if backend == "sqlite":
        with sqlite3.connect(db) as conn:  # as main's code left it
            conn.execute("ALTER TABLE planhrc_event DROP COLUMN client")
            conn.execute("DROP TABLE planhrc_client")
    else:
        import psycopg

        with psycopg.connect(db, autocommit=True) as conn:
            conn.execute("ALTER TABLE planhrc_event DROP COLUMN client")
            conn.execute("DROP TABLE planhrc_client")
    with TestClient(create_app(settings)) as client:
        old = client.get(f"/objects/{oid}/events").json()
        assert [e["kind"] for e in old] == ["object_created"] and old[0]["client"] is None
        assert client.put(f"/objects/{oid}/goal", json={"link_orientations_deg": GOAL}).status_code == 200
        assert client.post(f"/objects/{oid}/perceptions", json={"link_orientations_deg": [0, 0, 0, 0]}).is_success
        assert [e["kind"] for e in client.get(f"/objects/{oid}/events").json()] == \
            ["object_created", "goal_set", "replan"]


def test_a_registry_whose_database_is_away_keeps_the_keys_it_read_and_does_not_retry_at_every_request():
    from planhrc.kb_service.clients import ClientRegistry, open_table
    from planhrc.kb_service.store.errors import UnavailableError

    class Away:
        """The registry's table, until `down`: then every statement fails as a lost connection does."""

        def __init__(self) -> None:
            self.table, self.down, self.tries = open_table(None), False, 0

        def rows(self, sql: str, params: Any = ()) -> list[tuple[Any, ...]]:
            if self.down:
                self.tries += 1
                raise UnavailableError("db: cannot connect")
            return self.table.rows(sql, params)

        def close(self) -> None:
            self.table.close()

    table = Away()
    registry = ClientRegistry(table, refresh_s=60.0)  # type: ignore[arg-type]
    with pytest.raises(UnavailableError):  # never read: nothing to go on with
        table.down = True
        registry.refresh()
    assert not registry.read_once and not registry.stale() and table.tries == 1  # not again before refresh_s
    table.down = False
    key = registry.add("baxter-1", "robot")
    registry.refresh()
    table.down = True
    with pytest.raises(UnavailableError):
        registry.refresh()
    assert registry.read_once and registry.client_of(key) is not None  # the copy read before still answers

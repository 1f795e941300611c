"""A service on a PostgreSQL store whose database goes away (a restart cuts its connection, or the server takes no
connections for a while): every route that needs the store answers 503 with a one-line error, the cooperation
routes and the knowledge routes alike, nothing of the request is written, and the service answers again once the
database is back, without a restart (`UnavailableError`, `kb_service/api.py`'s error mapping)."""
from __future__ import annotations

from collections.abc import Iterator

import pytest
from fastapi.testclient import TestClient

from planhrc.kb_service.app import create_app
from planhrc.settings import make_settings


@pytest.fixture
def service(pg_cluster) -> Iterator[tuple[TestClient, str]]:
    url = pg_cluster.database()
    settings = make_settings(db_path=url, token=None, validate_plans=False, compact_every_s=0)
    try:
        with TestClient(create_app(settings)) as client:
            yield client, url.rsplit("/", 1)[1]
    finally:
        pg_cluster.drop(url)


def cut(admin_url: str, database: str, allow: bool) -> None:
    """End the service's connections to `database`; `allow` False: and take no new ones until allowed again."""
    import psycopg
    from psycopg import sql

    with psycopg.connect(admin_url, autocommit=True) as admin:
        admin.execute(sql.SQL("ALTER DATABASE {} ALLOW_CONNECTIONS {}").format(
            sql.Identifier(database), sql.Literal(allow)))
        admin.execute("SELECT pg_terminate_backend(pid) FROM pg_stat_activity WHERE datname = %s "
                      "AND pid <> pg_backend_pid()", (database,))


def refused(response, words: str) -> None:
    assert response.status_code == 503, response.text
    detail = response.json()["detail"]
    assert detail.startswith("db: ") and words in detail and "\n" not in detail, detail


def test_a_lost_connection_fails_one_request_with_503_and_the_next_connects_again(service, pg_cluster):
    client, database = service
    oid = client.post("/objects", json={"name": "rod", "links": 3, "orientations": 4,
                                        "formulation": "relative"}).json()["id"]
    cut(pg_cluster.url, database, allow=True)
    refused(client.put(f"/objects/{oid}/goal", json={"link_orientations_deg": [0, 90, 90]}),
            "connection to the database was lost")
    assert client.get(f"/objects/{oid}/events").json()[-1]["kind"] == "object_created"  # the goal was not written
    assert client.put(f"/objects/{oid}/goal", json={"link_orientations_deg": [0, 90, 90]}).status_code == 200


def test_while_the_database_takes_no_connections_every_store_route_answers_503(service, pg_cluster):
    client, database = service
    oid = client.post("/objects", json={"name": "rod", "links": 3, "orientations": 4,
                                        "formulation": "relative"}).json()["id"]
    state = client.post(f"/objects/{oid}/perceptions", json={"link_orientations_deg": [0, 0, 0]}).json()
    perceived = state["perceived_state_id"]
    ask = {"query": f"ASK {{ abox:{perceived} a planhrc:State }}"}
    assert client.get("/sparql", params=ask).json()["boolean"] is True
    cut(pg_cluster.url, database, allow=False)
    try:
        refused(client.get(f"/objects/{oid}"), "connection to the database was lost")  # the first finds it cut
        refused(client.get(f"/objects/{oid}"), "cannot connect")  # the next ones cannot connect again
        refused(client.post("/objects", json={"name": "rod", "links": 3, "orientations": 4,
                                              "formulation": "relative"}), "cannot connect")
        refused(client.post(f"/objects/{oid}/perceptions", json={"link_orientations_deg": [0, 90, 0]}),
                "cannot connect")
        refused(client.get("/sparql", params=ask), "cannot connect")
        refused(client.post("/sparql", data=ask), "cannot connect")
        refused(client.get(f"/states/{perceived}/subsumed-by/{perceived}"), "cannot connect")
        refused(client.post("/reasoning", json={"reasoner": "hermit", "object_id": oid}), "cannot connect")
        assert client.get("/health").status_code == 200  # counts kept in memory: the process itself is fine
    finally:
        cut(pg_cluster.url, database, allow=True)
    assert [o["id"] for o in client.get("/objects").json()] == [oid]  # nothing of the refused requests
    assert client.get(f"/states/{perceived}/subsumed-by/{perceived}").json()["subsumed"] is True
    assert client.get("/sparql", params=ask).json()["boolean"] is True

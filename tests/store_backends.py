"""The store's backends as test fixtures: every test that takes `kb` or `place` runs once per backend of
`BACKENDS` (`sqlite`, `postgresql`). A backend added to the store gets its throwaway location here, in `location`,
and the store tests run on it. A PostgreSQL store is a fresh database of the session's throwaway cluster
(`tests/conftest.py`), which starts only when such a test runs.

Import the fixtures into a test module: `from tests.store_backends import kb, place  # noqa: F401 (fixtures)`.
"""
from __future__ import annotations

import sqlite3
from collections.abc import Iterator
from pathlib import Path

import pytest

from planhrc.kb_service.store import BACKENDS, KnowledgeStore, open_store
from planhrc.paths import default_tbox_path
from tests.pg_cluster import Cluster


def location(backend: str, folder: Path, cluster: Cluster | None = None) -> str:
    """Where a throwaway store of `backend` lives (it may be opened, closed and opened again)."""
    if backend == "sqlite":
        return str(folder / "kb.sqlite3")
    if backend == "postgresql" and cluster is not None:
        return cluster.database()
    raise AssertionError(f"tests/store_backends.py: no throwaway location for the backend {backend!r}")


def journal_rows(backend: str, db: str) -> int:
    """Plans stored as journal rows whose facts are not written out yet, read from the database itself (not from
    the process that wrote them)."""
    if backend == "sqlite":
        with sqlite3.connect(db) as conn:
            return int(conn.execute("SELECT COUNT(*) FROM planhrc_plan_journal").fetchone()[0])
    if backend == "postgresql":
        import psycopg

        with psycopg.connect(db) as conn:
            row = conn.execute("SELECT count(*) FROM planhrc_plan_journal").fetchone()
            return int(row[0]) if row else 0
    raise AssertionError(f"tests/store_backends.py: no journal reader for the backend {backend!r}")


class Place:
    """One store's location: open it (again) as the service would."""

    def __init__(self, backend: str, db: str, cluster: Cluster | None = None, made: list[str] | None = None) -> None:
        self.backend = backend
        self.db = db
        self.cluster = cluster
        self.made = [db] if made is None else made  # the databases of this test (dropped after it)

    def open(self) -> KnowledgeStore:
        return open_store(self.db, default_tbox_path())

    def journal_rows(self) -> int:
        return journal_rows(self.backend, self.db)

    def another(self, folder: Path) -> Place:
        """A second throwaway store of the same backend."""
        folder.mkdir(parents=True, exist_ok=True)
        db = location(self.backend, folder, self.cluster)
        self.made.append(db)
        return Place(self.backend, db, self.cluster, self.made)


@pytest.fixture(params=sorted(BACKENDS))
def place(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[Place]:
    cluster = request.getfixturevalue("pg_cluster") if request.param == "postgresql" else None
    made = Place(request.param, location(request.param, tmp_path, cluster), cluster)
    yield made
    if cluster is not None:
        for db in made.made:
            cluster.drop(db)


@pytest.fixture
def kb(place: Place) -> Iterator[KnowledgeStore]:
    with place.open() as store:
        yield store

"""Fixtures every test module shares by name: one throwaway PostgreSQL cluster per test session (`pg_cluster`),
started only when a test asks for it (the store's tests on the `postgresql` backend, `tests/store_backends.py`)."""
from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager
from typing import NoReturn

import pytest

from tests.pg_cluster import Cluster, ClusterUnavailable


@pytest.fixture(scope="session")
def pg_cluster() -> Iterator[Cluster]:
    with throwaway_cluster() as cluster:
        yield cluster


@contextmanager
def throwaway_cluster() -> Iterator[Cluster]:
    """A new cluster, removed afterwards (a test that restarts one has its own); skipped where none can start."""
    try:
        import psycopg  # noqa: F401
    except ImportError as exc:
        _unavailable(f"psycopg 3 is not installed (pip install 'planhrc[postgresql]'): {exc}")
    try:
        cluster = Cluster()
    except ClusterUnavailable as exc:
        _unavailable(str(exc))
    try:
        yield cluster
    finally:
        cluster.close()


def _unavailable(reason: str) -> NoReturn:
    """Skip a PostgreSQL test that cannot run here; in CI, where it must run, fail it."""
    if os.environ.get("CI"):
        pytest.fail(f"PostgreSQL is needed in CI: {reason}")
    pytest.skip(f"PostgreSQL: {reason}")

"""The store's backends by name, and the one that a database location names (`open_store`).

A path (or None, '' or ':memory:': in memory) names the embedded SQLite store, the default. A URL names its backend
by its scheme: `postgresql://user@host:port/db` (or `postgres://`) the PostgreSQL store, whose password comes from
`password` (read from a file by the caller), the environment (`PGPASSWORD`, `PGPASSFILE`) or `~/.pgpass`, never
only from a command line. A backend is one entry of `BACKENDS`, made from the location, the TBox file and the
password, and implements `interface.KnowledgeStore`.
"""
from __future__ import annotations

from pathlib import Path
from typing import Callable

from .errors import KBError
from .interface import KnowledgeStore
from .knowledge_base import SqliteStore

IN_MEMORY = ("", ":memory:")
SCHEMES = {"postgres": "postgresql"}  # other spellings of a backend's scheme


def _sqlite(db: str | None, tbox_path: Path | str, password: str | None) -> KnowledgeStore:
    if password is not None:
        raise KBError("db_password: the embedded SQLite store takes no password (it is a file)")
    return SqliteStore(None if db in IN_MEMORY else db, tbox_path)


def _postgresql(db: str | None, tbox_path: Path | str, password: str | None) -> KnowledgeStore:
    try:
        from .postgres import PostgresStore
    except ImportError as exc:  # psycopg is an optional dependency
        raise KBError(f"db: a PostgreSQL store needs psycopg 3: pip install 'planhrc[postgresql]' ({exc})") from None
    return PostgresStore(db, tbox_path, password)


BACKENDS: dict[str, Callable[[str | None, Path | str, str | None], KnowledgeStore]] = {
    "sqlite": _sqlite,
    "postgresql": _postgresql,
}


def backend_of(db: str | None) -> str:
    """The backend a database location names: the scheme of a URL, else `sqlite` (a file path, or None)."""
    if db and "://" in db:
        scheme = db.split("://", 1)[0].lower()
        return SCHEMES.get(scheme, scheme)
    return "sqlite"


def open_store(db: str | None, tbox_path: Path | str, password: str | None = None) -> KnowledgeStore:
    """Open the store at `db` (a SQLite file path, None for a store in memory, or a backend's URL)."""
    name = backend_of(db)
    make = BACKENDS.get(name)
    if make is None:
        raise KBError(f"db: no store backend for {name}:// (this version has: {', '.join(sorted(BACKENDS))})")
    return make(db, tbox_path, password)

"""The store's backends by name, and the one that a database location names (`open_store`).

A path (or None: in memory) names the embedded SQLite store, the default. A URL names its backend by its scheme
(`postgresql://user@host:port/db`), which a later version adds here: a backend is one entry of `BACKENDS`, made
from the location and the TBox file, and implements `interface.KnowledgeStore`.
"""
from __future__ import annotations

from pathlib import Path
from typing import Callable

from .errors import KBError
from .interface import KnowledgeStore
from .knowledge_base import SqliteStore

# Assigning the class here also has mypy check that it implements `KnowledgeStore`.
BACKENDS: dict[str, Callable[[str | None, Path | str], KnowledgeStore]] = {"sqlite": SqliteStore}


def backend_of(db: str | None) -> str:
    """The backend a database location names: the scheme of a URL, else `sqlite` (a file path, or None)."""
    if db and "://" in db:
        return db.split("://", 1)[0].lower()
    return "sqlite"


def open_store(db: str | None, tbox_path: Path | str) -> KnowledgeStore:
    """Open the store at `db` (a SQLite file path, None for a store in memory, or a backend's URL)."""
    name = backend_of(db)
    make = BACKENDS.get(name)
    if make is None:
        raise KBError(f"db: no store backend for {name}:// (this version has: {', '.join(sorted(BACKENDS))})")
    return make(db, tbox_path)

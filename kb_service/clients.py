"""Clients and their roles: named API keys kept in the store's database, only their hash at rest.

A client is a name, a role and a key. The key is shown once, when it is made (`planhrc keys add`, `rotate`); the
database keeps its SHA-256 (a key is 32 random bytes, so a plain hash is as strong as a slow one and costs a
microsecond per request). A key is a bearer token: `Authorization: Bearer <key>`.

| role       | may                                                                                         |
|------------|---------------------------------------------------------------------------------------------|
| `robot`    | post perceptions, take the next action, report its outcome, give up; read                   |
| `operator` | create objects, set goals, run the reasoner; read                                           |
| `reader`   | read: objects, records, PDDL, the ontology, SPARQL, events, /metrics                        |

Every route names the one role that may write through it (`Role` in `ROUTE_ROLES`, checked by `route_role`); a
read is any role's. `planhrc serve --token T` stays as the one-key shortcut: T is a client named `token` that may
do everything, and `--read-token` a reader named `read-token`.

The registry (`ClientRegistry`) reads the table again at most every `REFRESH_S` seconds when a request needs it,
so a key added, revoked or rotated by `planhrc keys` (another process, on another host for a PostgreSQL store)
takes effect within that time without a restart; replicas on one PostgreSQL database share the table.
"""
from __future__ import annotations

import hashlib
import hmac
import re
import secrets
import sqlite3
import threading
import time
from dataclasses import dataclass
from enum import StrEnum
from typing import Any, Protocol, Sequence

from .store.backends import backend_of
from .store.errors import KBError, ValidationError

REFRESH_S = 1.0  # how stale the registry's copy of the table may be: a revoked key works at most this long
KEY_PREFIX = "phk_"
NAME_PATTERN = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,63}$")
TOKEN_CLIENT = "token"  # the client `--token` stands for
READ_TOKEN_CLIENT = "read-token"

SQLITE_TABLE = ("CREATE TABLE IF NOT EXISTS planhrc_client (name TEXT PRIMARY KEY, role TEXT NOT NULL, "
                "key_sha256 TEXT NOT NULL UNIQUE, created_at REAL NOT NULL, rotated_at REAL, revoked_at REAL)")
POSTGRES_TABLE = ("CREATE TABLE IF NOT EXISTS planhrc_client (name text PRIMARY KEY, role text NOT NULL, "
                  "key_sha256 text NOT NULL UNIQUE, created_at double precision NOT NULL, "
                  "rotated_at double precision, revoked_at double precision)")


class Role(StrEnum):
    ROBOT = "robot"
    OPERATOR = "operator"
    READER = "reader"


ROLES = frozenset(r.value for r in Role)


class ClientError(KBError):
    """A `planhrc keys` request the registry refuses (unknown client, a name taken, a bad role)."""


@dataclass(frozen=True)
class Client:
    """Who made a request: a named key's client, or the `--token` shortcut (`roles`: every role)."""

    name: str
    roles: frozenset[Role]

    def may(self, role: Role | None) -> bool:
        """A read (`role` None) is every client's; a write its role's."""
        return role is None or role in self.roles


@dataclass(frozen=True)
class ClientRecord:
    """One row of the registry, as `planhrc keys list` shows it (never the key)."""

    name: str
    role: Role
    created_at: float
    rotated_at: float | None
    revoked_at: float | None


def key_hash(key: str) -> str:
    return hashlib.sha256(key.encode("utf-8")).hexdigest()


def new_key() -> str:
    return KEY_PREFIX + secrets.token_urlsafe(32)


def check_name(name: str) -> str:
    if not NAME_PATTERN.match(name):
        raise ValidationError("name: 1-64 letters, digits, '_', '.' or '-', starting with a letter or digit")
    if name in (TOKEN_CLIENT, READ_TOKEN_CLIENT):
        raise ValidationError(f"name: {name!r} is the name of the --token shortcut's client; choose another")
    return name


def check_role(role: str) -> Role:
    try:
        return Role(role)
    except ValueError:
        raise ValidationError(f"role: {role!r} is not a role; choose from {', '.join(r.value for r in Role)}") \
            from None


# -- where the table lives -----------------------------------------------------------------------------------
class _Table(Protocol):
    """One engine's statements on the table (`?` placeholders; the PostgreSQL engine turns them into `%s`)."""

    def rows(self, sql: str, params: Sequence[Any] = ()) -> list[tuple[Any, ...]]: ...

    def close(self) -> None: ...


class _SqliteTable:
    def __init__(self, path: str) -> None:
        self._conn = sqlite3.connect(path, isolation_level=None, check_same_thread=False, timeout=10)
        self._lock = threading.Lock()
        with self._lock:
            self._conn.execute(SQLITE_TABLE)

    def rows(self, sql: str, params: Sequence[Any] = ()) -> list[tuple[Any, ...]]:
        with self._lock:
            try:
                return self._conn.execute(sql, tuple(params)).fetchall()
            except sqlite3.IntegrityError as exc:
                raise ClientError(f"name: already taken ({exc})") from None

    def close(self) -> None:
        self._conn.close()


class _PostgresTable:
    def __init__(self, db: str, password: str | None) -> None:
        from .store.postgres.schema import SCHEMA_LOCK
        from .store.postgres.session import Connection, connect

        def connected() -> Connection:
            return connect(db, password, "planhrc-clients")

        self._connect = connected
        self._lock = threading.Lock()
        self._conn = connected()
        with self._conn.transaction():
            self._conn.execute("SELECT pg_advisory_xact_lock(%s)", (SCHEMA_LOCK,))
            self._conn.execute(POSTGRES_TABLE)

    def rows(self, sql: str, params: Sequence[Any] = ()) -> list[tuple[Any, ...]]:
        import psycopg

        from .store.errors import UnavailableError

        with self._lock:
            try:
                if self._conn.broken:
                    self._conn.close()
                    self._conn = self._connect()
                cursor = self._conn.execute(sql.replace("?", "%s"), tuple(params))
                return cursor.fetchall() if cursor.description is not None else []
            except psycopg.errors.UniqueViolation as exc:
                raise ClientError(f"name: already taken ({str(exc).splitlines()[0]})") from None
            except psycopg.OperationalError as exc:
                raise UnavailableError(f"db: the client registry lost its connection ({' '.join(str(exc).split())[:200]})") \
                    from None

    def close(self) -> None:
        with self._lock:
            self._conn.close()


class _MemoryTable(_SqliteTable):
    def __init__(self) -> None:
        super().__init__(":memory:")


def open_table(db: str | None, password: str | None = None) -> _Table:
    """The registry's table in the store's database (made when missing); an in-memory store's is in memory."""
    if db in (None, "", ":memory:"):
        return _MemoryTable()
    if backend_of(db) == "postgresql":
        return _PostgresTable(db, password)
    return _SqliteTable(db)


# -- the registry ----------------------------------------------------------------------------------------------
class ClientRegistry:
    """The clients' keys (`add`, `revoke`, `rotate`, `records`: what `planhrc keys` does) and who a key is
    (`client_of`, what the service asks per request: its copy of the table, refreshed every `REFRESH_S`)."""

    def __init__(self, table: _Table, token: str | None = None, read_token: str | None = None,
                 refresh_s: float = REFRESH_S) -> None:
        self._table = table
        self._refresh_s = refresh_s
        self._shortcuts: dict[str, Client] = {}
        if token:
            self._shortcuts[key_hash(token)] = Client(TOKEN_CLIENT, frozenset(Role))
        if read_token:
            self._shortcuts[key_hash(read_token)] = Client(READ_TOKEN_CLIENT, frozenset({Role.READER}))
        self._guard = threading.Lock()
        self._keys: dict[str, Client] = {}
        self._ever = False
        self._read_once = False
        self._read_at = float("-inf")

    def close(self) -> None:
        self._table.close()

    # -- the service's side ----------------------------------------------------------------------------------
    def stale(self) -> bool:
        return time.monotonic() - self._read_at >= self._refresh_s

    @property
    def read_once(self) -> bool:
        """Whether the table was ever read (its copy, stale or not, can answer)."""
        return self._read_once

    def refresh(self) -> None:
        """Read the table again (a blocking read: the service runs it off its event loop). A read that fails (the
        database away) is tried again only after `refresh_s`, so an outage does not cost every request a connect
        timeout; the caller may go on with the copy it has (`read_once`)."""
        try:
            rows = self._table.rows("SELECT key_sha256, name, role, revoked_at FROM planhrc_client")
        except KBError:
            with self._guard:
                self._read_at = time.monotonic()
            raise
        keys = {digest: Client(name, frozenset({Role(role)})) for digest, name, role, revoked in rows
                if role in ROLES and revoked is None}
        with self._guard:
            self._keys, self._ever, self._read_at = keys, bool(rows), time.monotonic()
            self._read_once = True

    def guarded(self) -> bool:
        """Whether the service needs keys: it has a token, or a client was ever added (revoking every key closes
        the service, it does not open it). Without either it is open, as before clients."""
        return bool(self._shortcuts or self._ever)

    def client_of(self, key: str) -> Client | None:
        """The client whose key `key` is (None: no such key, or revoked). The lookup is by hash; the hash found is
        compared again in constant time."""
        digest = key_hash(key)
        client = self._shortcuts.get(digest) or self._keys.get(digest)
        if client is None:
            return None
        return client if hmac.compare_digest(digest, key_hash(key)) else None

    # -- `planhrc keys` --------------------------------------------------------------------------------------
    def add(self, name: str, role: str) -> str:
        """A new client; its key (shown once)."""
        check_name(name)
        checked = check_role(role)
        key = new_key()
        try:
            self._table.rows("INSERT INTO planhrc_client (name, role, key_sha256, created_at) VALUES (?, ?, ?, ?)",
                             (name, checked.value, key_hash(key), time.time()))
        except ClientError:
            raise ClientError(f"name: a client named {name!r} exists already (a revoked client keeps its name: its "
                              "events name it)") from None
        return key

    def rotate(self, name: str) -> str:
        """A new key for the client; the old one stops working (within `REFRESH_S` on a running service)."""
        key = new_key()
        done = self._table.rows("UPDATE planhrc_client SET key_sha256 = ?, rotated_at = ? "
                                "WHERE name = ? AND revoked_at IS NULL RETURNING name",
                                (key_hash(key), time.time(), name))
        if not done:
            raise ClientError(f"name: no client {name!r} in force (`planhrc keys list`)")
        return key

    def revoke(self, name: str) -> None:
        """The client's key stops working; its name stays (the events it caused still name it)."""
        done = self._table.rows("UPDATE planhrc_client SET revoked_at = ? WHERE name = ? AND revoked_at IS NULL "
                                "RETURNING name", (time.time(), name))
        if not done:
            raise ClientError(f"name: no client {name!r} in force (`planhrc keys list`)")

    def records(self) -> tuple[ClientRecord, ...]:
        rows = self._table.rows("SELECT name, role, created_at, rotated_at, revoked_at FROM planhrc_client "
                                "ORDER BY name")
        return tuple(ClientRecord(name, Role(role), float(created), None if rotated is None else float(rotated),
                                  None if revoked is None else float(revoked))
                     for name, role, created, rotated, revoked in rows)

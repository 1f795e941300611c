"""Where an object's current ABox starts (`Export.current_roots`): the object, the goal and the perceived state its
event log names last, the plan its execution follows, its latest plan and its latest problem.

Every backend keeps the tables this reads (the event log, the execution cursor, the counters) with the same columns,
so the policy is written once here, for the export, retention and the knowledge service alike; a backend gives only
its SQL dialect (`SQLITE`, `POSTGRESQL`) and a connection.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Protocol, Sequence

from .names import counter_name, record_name


class Connection(Protocol):
    """What is read through: `sqlite3.Connection` and `psycopg.Connection` alike."""

    def execute(self, sql: str, params: Sequence[Any], /) -> Any: ...


@dataclass(frozen=True)
class Dialect:
    """How a backend's SQL writes a parameter, and a field of an event's JSON `data` as text."""

    param: str
    json_field: str  # with `{name}` where the field's name goes

    def field(self, name: str) -> str:
        return self.json_field.format(name=name)


SQLITE = Dialect("?", "json_extract(data, '$.{name}')")
POSTGRESQL = Dialect("%s", "data->>'{name}'")


def current_roots(conn: Connection, dialect: Dialect, object_id: str) -> list[str]:
    """Names of the individuals the object's current ABox starts from, each once, the object first (it need not
    exist: the caller checks that)."""
    p, goal, perceived = dialect.param, dialect.field("goal_state_id"), dialect.field("perceived_state_id")
    roots = [object_id]
    for sql in (f"SELECT {goal} FROM planhrc_event WHERE object_id = {p} AND kind = 'goal_set' "
                "ORDER BY seq DESC LIMIT 1",
                f"SELECT {perceived} FROM planhrc_event WHERE object_id = {p} AND {perceived} IS NOT NULL "
                "ORDER BY seq DESC LIMIT 1",
                f"SELECT plan_id FROM planhrc_execution WHERE object_id = {p}"):
        row = conn.execute(sql, (object_id,)).fetchone()
        if row and row[0]:
            roots.append(str(row[0]))
    for kind in ("plan", "problem"):
        row = conn.execute(f"SELECT value FROM planhrc_counter WHERE name = {p}",
                           (counter_name(object_id, kind),)).fetchone()
        if row and row[0]:
            roots.append(record_name(object_id, kind, int(row[0])))
    return list(dict.fromkeys(roots))

"""The PostgreSQL backend of the knowledge base (`PostgresStore`), split by responsibility. psycopg 3 is an
optional dependency (`planhrc[postgresql]`): nothing here is imported unless a `postgresql://` location is opened.

| module | owns |
|---|---|
| `schema` | the tables (the ABox as triples, the side tables), the schema version, how a location is shown |
| `rows` | a batch of rows, literals' forms, individuals read back, rows as N-Triples |
| `session` | the engine's unit of work (`..work.UnitOfWork`): one connection, its transactions, counters, which individuals exist |
| `records` | records read back from the rows (the engine of `..identity.IdentityMap`) |
| `tables` | the side tables' SQL: the event log, the execution cursor, idempotent responses |
| `history` | the current ABox of an object: the export, and compaction |
| `inferred` | what a DL reasoner inferred, kept beside the ABox, replaced per scope |
| `replicas` | what several processes on one store need: the per-object lock, the event feed |
| `store` | `PostgresStore`, the parts above given to the store's core (`..facade.StoreCore`) |
"""
from .replicas import EVENT_CHANNEL, ObjectLocking, PgEventFeed
from .store import PostgresStore

__all__ = ["EVENT_CHANNEL", "ObjectLocking", "PgEventFeed", "PostgresStore"]

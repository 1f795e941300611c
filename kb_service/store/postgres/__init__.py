"""The PostgreSQL backend of the knowledge base (`PostgresStore`), split by responsibility. psycopg 3 is an
optional dependency (`planhrc[postgresql]`): nothing here is imported unless a `postgresql://` location is opened.

| module | owns |
|---|---|
| `schema` | the tables (the ABox as triples, the side tables), the schema version, how a location is shown |
| `rows` | a batch of rows, literals' forms, individuals read back, rows as N-Triples |
| `session` | the unit of work: one connection, transactions, counters, which individuals exist |
| `records` | records read back from the rows, cached |
| `history` | the current ABox of an object: the export, and compaction |
| `inferred` | what a DL reasoner inferred, kept beside the ABox, replaced per scope |
| `replicas` | what several processes on one store need: the per-object lock, the event feed |
| `store` | `PostgresStore`, the parts above behind `interface.KnowledgeStore` |
"""
from .replicas import EVENT_CHANNEL, ObjectLocking, PgEventFeed
from .store import PostgresStore

__all__ = ["EVENT_CHANNEL", "ObjectLocking", "PgEventFeed", "PostgresStore"]

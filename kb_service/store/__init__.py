"""The knowledge base of the service: an interface (`interface.KnowledgeStore`) and its backends, SQLite (the
default) and PostgreSQL (`postgres/`, an optional dependency), split by responsibility.

| module | owns |
|---|---|
| `interface` | the protocols the service uses and every backend implements (writes, reads, plan checks, the plan journal, export, retention) |
| `records`, `errors` | the immutable records the store hands out and its typed errors (root `KBError`) |
| `names` | the IRIs of the TBox and the ABox, and how each record and ground predicate is named |
| `checks` | the input checks of every write (pure: they read only the object), `check_plan` -> `CheckedPlan` |
| `cache`, `identity` | the one cached get of records (cache -> load -> `NotFoundError`); the identity map every engine's records are (the journal first, the cache limit) |
| `backends`, `location` | the backends by name; `open_store(db, tbox)` opens the one a location names; a location as it may be shown (no password) |
| `work`, `unit`, `facade` | the core every engine shares: the unit of work and the guard (`UnitOfWork`); what the shared writes ask of an engine; the store's core (`StoreCore`: life cycle, reads, side tables' checks, compaction's steps) |
| `knowledge_base` | `SqliteStore`: the SQLite backend, the parts below in one database |
| `abox` | the SQLite engine's unit of work: the owlready2 world, names of individuals, counters, its connection's commit and rollback |
| `reads`, `writes`, `triples` | the SQLite engine's reads of records (`SqliteRecords`), the writes, and what each record is as triples |
| `journal`, `backlog` | a new plan's journal row (the plan, read from it), written out as triples when a reader of the triples needs them |
| `events`, `execution`, `responses`, `inferred` | the SQLite engine's side tables: the event log, the execution cursor, idempotent responses, what a reasoner inferred (checked by `checks`) |
| `retention`, `export`, `roots` | compaction of each object's history; RDF export (N-Triples, RDF/XML, Turtle); where an object's current ABox starts (every backend's) |
| `owl` | every use of owlready2's internals (its SQLite tables, storids, literal encoding, reasoner settings) |
| `postgres` | `PostgresStore`: the ABox as rows of triples in PostgreSQL, the side tables beside it, what replicas need |
"""
from .backends import BACKENDS, open_store
from .errors import (ConflictError, DamagedStoreError, DeadlineError, KBError, NotFoundError, ReasonerError,
                     UnavailableError, ValidationError)
from .interface import (MAX_EVENTS_PAGE, MAX_SEQ, EventFeed, EventFeeding, Export, Inferences, KnowledgeStore,
                        ObjectLocking, PlanChecks, PlanJournal, Reads, Retention, Writes)
from .knowledge_base import SqliteStore
from .names import ABOX_IRI, PREDICATES, TBOX_IRI, atom_fragment
from .records import (STATE_KINDS, ActionSpec, CheckedPlan, Compaction, CondEffect, Execution, StoredAction,
                      StoredEvent, StoredPlan, StoredProblem, StoredState)

__all__ = [
    "ABOX_IRI", "BACKENDS", "MAX_EVENTS_PAGE", "MAX_SEQ", "PREDICATES", "STATE_KINDS", "TBOX_IRI", "ActionSpec",
    "CheckedPlan", "Compaction", "CondEffect", "ConflictError", "DamagedStoreError", "DeadlineError", "EventFeed",
    "EventFeeding", "Execution", "Export", "Inferences", "KBError", "KnowledgeStore",
    "NotFoundError", "ObjectLocking", "PlanChecks", "PlanJournal", "Reads", "ReasonerError", "Retention",
    "SqliteStore", "StoredAction", "StoredEvent", "StoredPlan", "StoredProblem", "StoredState", "UnavailableError",
    "ValidationError", "Writes", "atom_fragment", "open_store",
]

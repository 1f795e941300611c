"""The knowledge base of the service, split by responsibility:

| module | owns |
|---|---|
| `owl` | every use of owlready2's internals (its SQLite tables, storids, literal encoding, reasoner settings) |
| `abox` | the ABox: objects, states, problems, plans and their actions, over the TBox |
| `events` | the event log of each object |
| `execution` | the execution cursor of each object |
| `responses` | idempotent responses |
| `export` | RDF export (RDF/XML, Turtle) |
| `knowledge_base` | `KnowledgeBase`: the parts above in one database, with `transaction()` |
| `records`, `errors` | the immutable records the store hands out and its typed errors (root `KBError`) |
"""
from .abox import ABOX_IRI, PREDICATES, TBOX_IRI, atom_fragment
from .errors import ConflictError, DeadlineError, KBError, NotFoundError, ReasonerError, ValidationError
from .knowledge_base import KnowledgeBase
from .records import (STATE_KINDS, ActionSpec, CondEffect, Execution, StoredAction, StoredEvent, StoredPlan,
                      StoredProblem, StoredState)

__all__ = [
    "ABOX_IRI", "PREDICATES", "STATE_KINDS", "TBOX_IRI", "ActionSpec", "CondEffect", "ConflictError", "DeadlineError", "Execution",
    "KBError", "KnowledgeBase", "NotFoundError", "ReasonerError", "StoredAction", "StoredEvent", "StoredPlan",
    "StoredProblem", "StoredState", "ValidationError", "atom_fragment",
]

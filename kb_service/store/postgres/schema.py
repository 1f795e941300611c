"""The PostgreSQL store's tables.

The ABox is one table of triples, `planhrc_triple (s, p, o, lit, dt)`, with the same IRIs the SQLite store gives
its individuals (`names`): an object property's row has the object's IRI in `o`; a data property's row has the
literal's lexical form in `lit` and its datatype IRI in `dt` (the forms owlready2 writes, so both stores export the
same N-Triples). The service's side tables (events, execution cursor, idempotent responses, counters) are tables
beside it, in the same transactions, and so are the plan journal, what a reasoner inferred (`planhrc_inferred`),
the count of commits (`planhrc_revision`) and the planning job queue (`planhrc_planning_job`, `jobs`).
"""
from __future__ import annotations

from ..names import ABOX_IRI
from .jobs import JOB_TABLES

SCHEMA_VERSION = "1"  # planhrc_meta.schema; a database of another version is refused when it is opened

RDF_TYPE = "http://www.w3.org/1999/02/22-rdf-syntax-ns#type"
OWL = "http://www.w3.org/2002/07/owl#"
NAMED_INDIVIDUAL = OWL + "NamedIndividual"
ABOX_ONTOLOGY = ABOX_IRI.rstrip("#")  # the ABox is an owl:Ontology, as in the SQLite store

TABLES = (
    "CREATE TABLE IF NOT EXISTS planhrc_meta (key text PRIMARY KEY, value text NOT NULL)",
    # Counters: object ids, each object's records of each kind and its events (an upsert takes the next value,
    # and its row lock orders the writers of one object, across processes too).
    "CREATE TABLE IF NOT EXISTS planhrc_counter (name text PRIMARY KEY, value bigint NOT NULL)",
    "CREATE TABLE IF NOT EXISTS planhrc_triple (s text NOT NULL, p text NOT NULL, o text, lit text, dt text,"
    " CHECK ((o IS NULL) <> (lit IS NULL)))",
    # A record is read by subject; compaction and the list of objects look individuals up by object.
    "CREATE INDEX IF NOT EXISTS planhrc_triple_sp ON planhrc_triple (s, p)",
    "CREATE INDEX IF NOT EXISTS planhrc_triple_op ON planhrc_triple (o, p) WHERE o IS NOT NULL",
    "CREATE TABLE IF NOT EXISTS planhrc_event (object_id text NOT NULL, seq bigint NOT NULL, kind text NOT NULL,"
    " reason text NOT NULL, data json NOT NULL, created_at double precision NOT NULL, PRIMARY KEY (object_id, seq))",
    # The client whose request caused the event (`clients`; null: the service on its own, or a store made before
    # clients were recorded).
    # (a look first: an ALTER TABLE, even one that finds the column, locks the table against every replica's reads)
    "DO $$ BEGIN IF NOT EXISTS (SELECT 1 FROM information_schema.columns WHERE table_schema = current_schema() "
    "AND table_name = 'planhrc_event' AND column_name = 'client') THEN ALTER TABLE planhrc_event ADD COLUMN client text; "
    "END IF; END $$",
    "CREATE TABLE IF NOT EXISTS planhrc_execution (object_id text PRIMARY KEY, plan_id text, next_step integer,"
    " status text NOT NULL, dispatched_action_id text)",
    "CREATE TABLE IF NOT EXISTS planhrc_response (object_id text NOT NULL, key text NOT NULL, response json NOT NULL,"
    " PRIMARY KEY (object_id, key))",
    # Plans whose triples are not written yet (`journal`), oldest first; a row names the expected states it holds.
    "CREATE TABLE IF NOT EXISTS planhrc_plan_journal (seq bigserial PRIMARY KEY, plan_id text UNIQUE NOT NULL,"
    " object_id text NOT NULL, first_state bigint NOT NULL, last_state bigint NOT NULL, payload bytea NOT NULL)",
    # What a DL reasoner inferred, as N-Triples lines under a scope (`inferred`): never among the ABox's triples.
    "CREATE TABLE IF NOT EXISTS planhrc_inferred (seq bigserial PRIMARY KEY, scope text NOT NULL, line text NOT NULL)",
    "CREATE INDEX IF NOT EXISTS planhrc_inferred_scope ON planhrc_inferred (scope)",
    # Commits that wrote, counted per connection's shard (`session.COUNT_COMMIT`); their sum is `Reads.revision`.
    "CREATE TABLE IF NOT EXISTS planhrc_revision (shard integer PRIMARY KEY, value bigint NOT NULL)",
    # Planning jobs for `planhrc planning-worker` processes (`jobs`; a worker creates it too, should it come first).
    *JOB_TABLES,
)
# Two processes opening a new database at once must not both create it: creation holds this lock.
SCHEMA_LOCK = 0x706C616E68726301  # "planhrc\x01"

"""Settings of the service and the pipeline, read from `PLANHRC_*` environment variables: one variable a setting
(`env_name`), `PLANHRC_` and the field's name but for the store's, `PLANHRC_DB`.

Nothing is read or created at import time: `get_settings()` builds the process-wide settings on first use
(cached), and tests build their own with `make_settings(**overrides)`.
"""
from __future__ import annotations

from functools import lru_cache
from typing import Any, Literal

from pydantic import Field, SecretStr
from pydantic_settings import BaseSettings, SettingsConfigDict

from planhrc.paths import default_tbox_path
from planhrc.vocabulary import SparqlEngineName


class Settings(BaseSettings):
    """Where the knowledge base lives, how the service listens, and how plans are made."""

    model_config = SettingsConfigDict(env_prefix="PLANHRC_", extra="ignore", frozen=True, populate_by_name=True)

    db_path: str | None = Field(
        default="planhrc.sqlite3",
        validation_alias="PLANHRC_DB",
        description="Where the store lives: a SQLite file of the ABox, relative to the current directory (':memory:' "
        "or None for a throwaway store, tests), or a PostgreSQL URL `postgresql://user@host:port/database` "
        "(environment PLANHRC_DB).",
    )
    db_password_file: str | None = Field(
        default=None,
        description="File holding the PostgreSQL password (its first line). Without it libpq's own PGPASSWORD, "
        "PGPASSFILE or ~/.pgpass apply; a password in the URL works but shows in the process list.",
    )
    db_password: SecretStr | None = Field(
        default=None,
        description="The PostgreSQL password itself (read from `db_password_file` by the command line).",
    )
    tbox_path: str = Field(default_factory=lambda: str(default_tbox_path()), description="OWL file of the TBox.")
    host: str = Field(default="127.0.0.1", description="Interface the HTTP service binds to.")
    port: int = Field(default=8000, ge=0, le=65535, description="TCP port of the HTTP service.")
    token: str | None = Field(
        default=None,
        description="When set, every request that changes something needs `Authorization: Bearer <token>`.",
    )
    token_file: str | None = Field(
        default=None,
        description="File holding the bearer token (its first line): a secret the process list does not show.",
    )
    insecure: bool = Field(
        default=False,
        description="Serve on an address other than loopback without a token (anyone who reaches the port may "
        "set goals and post perceptions the robot acts on); without it such a service refuses to start. The "
        "service warns at every start.",
    )
    ssl_certfile: str | None = Field(
        default=None, description="TLS certificate (PEM) of the HTTP service: it then serves HTTPS (uvicorn).")
    ssl_keyfile: str | None = Field(
        default=None, description="Private key (PEM) of `ssl_certfile`, unless the certificate file holds it.")
    planner: str = Field(default="inproc", description="Planner backend name (see planner/).")
    fallback_planner: str | None = Field(
        default="fd-lama",
        description="Planner used when the in-process planner cannot take a task (a domain outside the rotation "
        "family, e.g. after the TBox gained an action); empty for none.",
    )
    planner_timeout_s: float = Field(default=5.0, gt=0, description="Time limit of one planner call.")
    validate_plans: bool = Field(default=True, description="Check every plan with VAL before storing it.")
    planning_deadline_s: float = Field(
        default=10.0, gt=0, le=3600,
        description="Time one request may spend planning and validating (VAL) a plan; a task that needs more "
        "answers 503 with the reason instead of holding its object for minutes.",
    )
    val_pieces: int = Field(
        default=2, ge=1, le=16,
        description="VAL checks a long plan in this many pieces at once (one process each; each piece ends in "
        "an exact expected state, so together they say what one run says); 1: one run on the whole plan.",
    )
    val_early_answer: bool = Field(
        default=True,
        description="A re-plan on a domain with conditional effects (absolute) is answered once VAL has accepted "
        "the plan's first piece (the first motion, from the perceived state to the exact expected state after it); "
        "the later pieces are checked behind the answer, and a step is dispatched only once VAL has accepted its "
        "piece. False: the whole plan is checked before the answer. Plans without conditional effects are always "
        "checked whole before the answer.",
    )
    val_armed: bool = Field(
        default=True,
        description="Start VAL ahead of need so that a short check skips VAL's start-up, most of its cost: one "
        "`Validate` process past its start-up forks a run per check (`planner.valfork`; needs a C compiler once, to "
        "build its small preloaded library), or where it cannot, one VAL process per domain in use waits with its "
        "domain already read (`planner.armed`). The same binary, inputs and output as a cold run; Linux only.",
    )
    planning_workers: int = Field(
        default=2, ge=0, le=16,
        description="Worker processes of the service's planning pool (started on the first large task, stopped "
        "with the service): a large task's translation, planning and replay run there, not in the service's "
        "interpreter; 0: every task is planned in the service's process.",
    )
    planning_queue: bool = Field(
        default=False,
        description="Large tasks (`planning_pool_min_atoms`) are planned by `planhrc planning-worker` processes, on "
        "any host that reaches the database, through its planning job queue (a PostgreSQL store only), instead of "
        "the service's own planning workers; a task no worker finished by the planning deadline answers 503.",
    )
    planning_lease_s: float = Field(
        default=3.0, gt=0, le=600,
        description="A planning worker's lease on the job it plans, renewed every third of it while it plans: a job "
        "whose worker stopped renewing (killed, cut off) is taken by another worker this long after the last "
        "renewal, if its deadline leaves time.",
    )
    planning_pool_min_atoms: int = Field(
        default=150, ge=1,
        description="A task goes to the planning pool when a state of its object holds at least this many atoms "
        "(static facts and orientations: relative 20 x 12: 69, absolute 20 x 12: 282); smaller tasks cost less "
        "than the trip and are planned in the service's process.",
    )
    max_task_size: int = Field(
        default=14_400, ge=4, le=1_000_000,
        description="Largest planning task an object may pose, as links x orientations (200 x 72 by default); "
        "a larger object is refused when it is created.",
    )
    merge_macro_steps: bool = Field(
        default=True,
        description="Dispatch consecutive steps of one joint in one direction as one motion (the paper's "
        "two 45 degree steps as one 90 degree step); the expected state after the merged step is checked.",
    )
    log_level: str = Field(default="info", description="Logging level of the service (uvicorn names).")
    log_format: Literal["text", "json"] = Field(
        default="text",
        description="`json`: one JSON object a log line, with the request id, the object id and the trace id.",
    )
    metrics: bool = Field(
        default=True,
        description="Serve `/metrics` (Prometheus' text format) and count what the service does; false: neither.",
    )
    otlp_endpoint: str | None = Field(
        default=None,
        description="Send traces (OpenTelemetry, OTLP over HTTP) to this collector, e.g. http://127.0.0.1:4318; "
        "without it tracing is off unless OpenTelemetry's own OTEL_EXPORTER_OTLP_ENDPOINT (or "
        "OTEL_TRACES_EXPORTER=otlp) is set.",
    )
    trace_ratio: float | None = Field(
        default=None, ge=0, le=1,
        description="The share of requests traced (a request whose client sent a sampled `traceparent` always is); "
        "default: OpenTelemetry's OTEL_TRACES_SAMPLER, else every request.",
    )
    read_token: str | None = Field(
        default=None,
        description="A second, read-only bearer token: accepted for reads of the knowledge base when "
        "`protect_reads` is on, never for writes.",
    )
    read_token_file: str | None = Field(
        default=None, description="File holding the read-only bearer token (its first line).")
    protect_reads: bool = Field(
        default=False,
        description="Every read (objects, states, problems, plans, events, ontology, SPARQL, /metrics) needs a "
        "client's key (any role) or a token too; the health probes, the API docs and the console page stay open.",
    )
    max_body_bytes: int = Field(
        default=1_048_576, ge=1024, le=1_073_741_824,
        description="Largest request body accepted; larger ones get 413 before they are read.",
    )
    keep_perceived: int = Field(
        default=100, ge=1,
        description="Retention: the perceived states kept per object when the store is compacted (besides every "
        "record the current plan, goal and latest problem refer to).",
    )
    compact_every_s: float = Field(
        default=3600.0, ge=0,
        description="The service compacts its store this often (seconds; 0: never). `planhrc compact` runs it "
        "on a store by hand.",
    )
    sparql_timeout_s: float = Field(
        default=5.0, gt=0, le=600,
        description="Time one SPARQL query may take (waiting for the query before it included); a longer one is "
        "stopped and answered 503.",
    )
    sparql_engine: SparqlEngineName = Field(
        default=SparqlEngineName.OXIGRAPH,
        description="What evaluates SPARQL queries: `oxigraph` (in a process of its own, stopped when a query "
        "overruns its time limit) or `rdflib` (in the service's process; slower, kept to compare).",
    )
    sparql_max_results: int = Field(
        default=10_000, ge=1, le=10_000_000,
        description="Most solutions (SELECT) or triples (CONSTRUCT, DESCRIBE) one SPARQL answer may hold; a query "
        "with more is answered 400 and asked to use LIMIT.",
    )
    reasoning_timeout_s: float = Field(
        default=120.0, gt=0, le=3600,
        description="Time one reasoning job (POST /reasoning: the DL reasoner on the live ABox) may take.",
    )
    reasoning_queue: int = Field(
        default=2, ge=1, le=64,
        description="Reasoning jobs waiting or running at once (they run one at a time); more are refused with "
        "429 until one finishes.",
    )
    reasoning_answer_wait_s: float = Field(
        default=2.0, ge=0, le=60,
        description="POST /reasoning waits this long for its job: a job done by then is answered with its result "
        "(200), a longer one with 202 and the job's location.",
    )


# Variables no longer read, each with the one read in its place (a command refuses to start while one is set).
RENAMED = {"PLANHRC_DB_PATH": "PLANHRC_DB"}


def env_name(field: str) -> str:
    """The environment variable of a setting (a field's name, or the variable itself as pydantic may name it)."""
    if field.startswith("PLANHRC_"):
        return field
    info = Settings.model_fields.get(field)
    alias = info.validation_alias if info is not None else None
    return alias if isinstance(alias, str) else f"PLANHRC_{field.upper()}"


@lru_cache
def get_settings() -> Settings:
    """The process-wide settings (environment variables), built once on first use."""
    return Settings()


def make_settings(**overrides: Any) -> Settings:
    """Settings for tests and the CLI: the environment, with the given fields replaced."""
    return Settings(**overrides)

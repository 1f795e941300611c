"""`planhrc serve`: run the knowledge-base service with uvicorn.

Registered by `planhrc.cli` through `add_serve_parser`; `python -m planhrc.kb_service.cli serve ...` works too.
"""
from __future__ import annotations

import argparse
import logging
import os
import signal
import socket
import sys
import threading
import time
from pathlib import Path
from typing import TYPE_CHECKING, Callable, TypeVar

from planhrc.cli_args import OneLineParser, port, tbox_file, tbox_problem, writable_dir

from .command_settings import CommandSettings, add_store_options, read_settings, settings_or_say, store_given
from .network import Name, SettingsProblem, check_exposure
from .store.backends import backend_of
from .store.errors import KBError

if TYPE_CHECKING:
    from planhrc.settings import Settings

_Parser = TypeVar("_Parser", bound=argparse.ArgumentParser)

__all__ = ["SERVE_OPTIONS", "SettingsProblem", "add_compact_parser", "add_planning_worker_parser", "add_serve_parser",
           "check_serve_settings", "main", "run_compact", "run_planning_worker", "run_serve"]

REQUEST_THREADS_WAIT_S = 2.0  # what request threads still running when the server has stopped are given

# Settings field -> the option that sets it, to name the right one in an error.
SERVE_OPTIONS = {"host": "--host", "port": "--port", "db_path": "--db", "db_password_file": "--db-password-file",
                 "token": "--token", "token_file": "--token-file", "read_token": "--read-token",
                 "read_token_file": "--read-token-file", "protect_reads": "--protect-reads", "insecure": "--insecure",
                 "ssl_certfile": "--ssl-certfile", "ssl_keyfile": "--ssl-keyfile", "tbox_path": "--tbox",
                 "planner": "--planner", "log_level": "--log-level", "planning_queue": "--planning-queue",
                 "log_format": "--log-format", "otlp_endpoint": "--otlp-endpoint", "metrics": "--no-metrics",
                 "trace_ratio": "--trace-ratio"}


def add_serve_parser(subparsers: argparse._SubParsersAction[_Parser]) -> _Parser:
    from uvicorn.config import LOG_LEVELS

    from planhrc.planner.registry import PLANNERS

    p = subparsers.add_parser("serve", help="run the knowledge-base HTTP service",
                              description="Run the planHRC knowledge-base service (FastAPI + uvicorn).")
    p.add_argument("--host", default=None, help="interface to bind (default 127.0.0.1, env PLANHRC_HOST)")
    p.add_argument("--port", type=port, default=None, help="TCP port (default 8000, env PLANHRC_PORT)")
    add_store_options(p, "a SQLite file (default planhrc.sqlite3; ':memory:' for none) or a PostgreSQL URL "
                      "postgresql://user@host:port/database")
    p.add_argument("--token", default=None,
                   help="bearer token required for writes (env PLANHRC_TOKEN; default: no authentication); the "
                   "process list shows it: prefer --token-file")
    p.add_argument("--token-file", default=None, metavar="FILE",
                   help="file holding the bearer token (env PLANHRC_TOKEN_FILE)")
    p.add_argument("--read-token", default=None,
                   help="read-only bearer token, accepted for reads when reads are protected (env PLANHRC_READ_TOKEN)")
    p.add_argument("--read-token-file", default=None, metavar="FILE",
                   help="file holding the read-only bearer token (env PLANHRC_READ_TOKEN_FILE)")
    p.add_argument("--insecure", action="store_true", default=None,
                   help="serve an address other than loopback without a token (env PLANHRC_INSECURE): refused "
                   "otherwise, warned at every start")
    p.add_argument("--ssl-certfile", default=None, metavar="FILE",
                   help="serve HTTPS with this certificate (PEM; env PLANHRC_SSL_CERTFILE)")
    p.add_argument("--ssl-keyfile", default=None, metavar="FILE",
                   help="the certificate's private key (PEM; env PLANHRC_SSL_KEYFILE)")
    p.add_argument("--protect-reads", action="store_true", default=None,
                   help="reads of the knowledge base need a token too (env PLANHRC_PROTECT_READS)")
    p.add_argument("--tbox", type=tbox_file, default=None,
                   help="TBox OWL file (default: the repository's ontology/planhrc.owl)")
    p.add_argument("--planner", default=None, choices=list(PLANNERS), help="planner backend (default inproc)")
    p.add_argument("--planning-queue", action="store_true", default=None,
                   help="plan large tasks through the database's planning job queue, served by `planhrc "
                   "planning-worker` processes on any host (a PostgreSQL store; env PLANHRC_PLANNING_QUEUE)")
    p.add_argument("--log-level", default=None, choices=list(LOG_LEVELS), help="uvicorn log level (default info)")
    add_observing_options(p)
    p.add_argument("--no-metrics", dest="metrics", action="store_false", default=None,
                   help="serve no /metrics and count nothing (env PLANHRC_METRICS=false)")
    p.add_argument("--trace-ratio", type=float, default=None, metavar="0..1",
                   help="the share of requests traced (env PLANHRC_TRACE_RATIO; default: OTEL_TRACES_SAMPLER, else "
                   "every request); a request whose client sent a sampled traceparent is always traced")
    p.set_defaults(func=run_serve)
    return p


def add_observing_options(p: argparse.ArgumentParser) -> None:
    """The options `serve` and `planning-worker` share: the log lines' format and where traces go."""
    from .logs import LOG_FORMATS

    p.add_argument("--log-format", default=None, choices=LOG_FORMATS,
                   help="log lines as text (default) or one JSON object a line, with request, object and trace ids "
                   "(env PLANHRC_LOG_FORMAT)")
    p.add_argument("--otlp-endpoint", default=None, metavar="URL",
                   help="send traces over OTLP/HTTP to this collector, e.g. http://127.0.0.1:4318 (env "
                   "PLANHRC_OTLP_ENDPOINT, or OpenTelemetry's OTEL_EXPORTER_OTLP_ENDPOINT); default: no traces")


def check_otlp_endpoint(settings: Settings, name: Callable[[str], str]) -> None:
    """An endpoint is an http(s) URL, and tracing needs the `tracing` extra."""
    from urllib.parse import urlsplit

    from .tracing import tracing_wanted

    endpoint = settings.otlp_endpoint
    if endpoint:
        parts = urlsplit(endpoint)
        if parts.scheme not in ("http", "https") or not parts.hostname:
            raise SettingsProblem(f"{name('otlp_endpoint')}: {endpoint!r} is not an http:// or https:// URL of an "
                                  "OTLP collector (e.g. http://127.0.0.1:4318)")
    if tracing_wanted(endpoint):
        try:
            import opentelemetry.exporter.otlp.proto.http  # noqa: F401
            import opentelemetry.sdk  # noqa: F401
        except ImportError:
            raise SettingsProblem(f"{name('otlp_endpoint') if endpoint else 'OTEL_EXPORTER_OTLP_ENDPOINT'}: tracing "
                                  "needs OpenTelemetry: pip install 'planhrc[tracing]'") from None


def serve_settings(args: argparse.Namespace) -> CommandSettings:
    """`planhrc serve`'s settings: the environment with its options on top (`command_settings`)."""
    given = {"host": args.host, "port": args.port, "db_path": args.db, "db_password_file": args.db_password_file,
             "token": args.token, "token_file": args.token_file, "read_token": args.read_token,
             "read_token_file": args.read_token_file, "protect_reads": args.protect_reads, "insecure": args.insecure,
             "ssl_certfile": args.ssl_certfile, "ssl_keyfile": args.ssl_keyfile, "tbox_path": args.tbox,
             "planner": args.planner, "log_level": args.log_level, "planning_queue": args.planning_queue,
             "log_format": args.log_format, "otlp_endpoint": args.otlp_endpoint, "metrics": args.metrics,
             "trace_ratio": args.trace_ratio}
    return read_settings({field: (SERVE_OPTIONS[field], value) for field, value in given.items()})


def check_serve_settings(settings: Settings, name: Name, warnings: list[str] | None = None) -> None:
    """Refuse, before anything starts, settings the service would only trip over later (a planner name, the
    TBox, the store's folder or server, a busy port, a service open to the network without a token, TLS files that
    do not load). Raises SettingsProblem naming the option or `PLANHRC_*` variable (`name`); adds to `warnings`
    what it can start with but should not."""
    from uvicorn.config import LOG_LEVELS

    from planhrc.planner.registry import PLANNERS, available_planners

    if settings.planner not in PLANNERS:
        raise SettingsProblem(f"{name('planner')}: unknown planner {settings.planner!r}; "
                              f"choose from {', '.join(PLANNERS)}")
    if settings.planner not in available_planners():
        raise SettingsProblem(f"{name('planner')}: {settings.planner!r} cannot run here "
                              f"(usable: {', '.join(available_planners())})")
    if settings.fallback_planner and settings.fallback_planner not in PLANNERS:
        raise SettingsProblem(f"{name('fallback_planner')}: unknown planner {settings.fallback_planner!r}; "
                              f"choose from {', '.join(PLANNERS)} or empty for none")
    if settings.log_level.lower() not in LOG_LEVELS:
        raise SettingsProblem(f"{name('log_level')}: unknown level {settings.log_level!r}; "
                              f"choose from {', '.join(LOG_LEVELS)}")
    if problem := tbox_problem(settings.tbox_path):
        raise SettingsProblem(f"{name('tbox_path')}: {problem}")
    check_otlp_endpoint(settings, name)
    warnings = [] if warnings is None else warnings
    check_exposure(settings, name, warnings, has_clients=store_has_clients(settings))
    if settings.planning_queue and backend_of(settings.db_path) != "postgresql":
        raise SettingsProblem(f"{name('planning_queue')}: the planning job queue is a PostgreSQL store's; give "
                              f"{name('db_path')} a postgresql:// URL, or plan in the service's own workers")
    if backend_of(settings.db_path) != "sqlite":
        check_store_server(settings, name("db_path"))
    elif settings.db_path not in (None, "", ":memory:"):
        db = Path(settings.db_path)
        if db.is_dir():
            raise SettingsProblem(f"{name('db_path')}: {db} is a folder")
        try:
            writable_dir(str(db.absolute().parent))
        except argparse.ArgumentTypeError as exc:
            raise SettingsProblem(f"{name('db_path')}: {exc}") from None
    with socket.socket(socket.AF_INET6 if ":" in settings.host else socket.AF_INET, socket.SOCK_STREAM) as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind((settings.host, settings.port))
        except OSError as exc:
            raise SettingsProblem(f"{name('port')}/{name('host')}: cannot listen on {settings.host}:{settings.port} "
                                  f"({exc.strerror or exc})") from None


def store_has_clients(settings: Settings) -> bool:
    """Whether the store names a client (`planhrc keys`): then its writes need keys. False when the store does not
    exist yet or cannot be read now (the checks below say why)."""
    from .clients import ClientRegistry, open_table

    db = settings.db_path
    if db in (None, "", ":memory:") or (backend_of(db) == "sqlite" and not Path(str(db)).is_file()):
        return False
    password = settings.db_password.get_secret_value() if settings.db_password else None
    try:
        registry = ClientRegistry(open_table(str(db), password))
    except Exception:  # not a store, or a database away: the store's own checks say so in their words
        return False
    try:
        return bool(registry.records())
    except Exception:
        return False
    finally:
        registry.close()


def check_store_server(settings: Settings, option: str) -> None:
    """A store on a database server: its backend exists and the server answers (one connection, closed)."""
    from .store import BACKENDS

    backend = backend_of(settings.db_path)
    if settings.db_path is None or backend not in BACKENDS:
        raise SettingsProblem(f"{option}: no store backend for {backend}:// (this version has: "
                              f"{', '.join(sorted(BACKENDS))})")
    try:
        from .store.postgres.session import connect
    except ImportError as exc:
        raise SettingsProblem(f"{option}: a PostgreSQL store needs psycopg 3: pip install 'planhrc[postgresql]' "
                              f"({exc})") from None
    password = settings.db_password.get_secret_value() if settings.db_password else None
    try:
        connect(settings.db_path, password, "planhrc-check").close()
    except KBError as exc:
        raise SettingsProblem(f"{option}: {str(exc).split(': ', 1)[-1]}") from None


def run_serve(args: argparse.Namespace) -> int:
    from .app import create_app
    from .server import serve

    try:
        read = serve_settings(args)
        warnings = list(read.warnings)
        check_serve_settings(read.settings, read.name, warnings)
    except SettingsProblem as exc:
        print(f"planhrc serve: {exc}", file=sys.stderr)
        return 2
    settings = read.settings
    for warning in warnings:  # at every start, whatever the log level
        print(f"planhrc serve: warning: {warning}", file=sys.stderr, flush=True)
    from .logs import configure_logging

    level = settings.log_level.lower()
    configure_logging(level, settings.log_format)
    # JSON lines: uvicorn's loggers write through the root's handler (no configuration of its own)
    uvicorn_logging = {"log_config": None} if settings.log_format == "json" else {}
    try:
        serve(create_app(settings), host=settings.host, port=settings.port, log_level=level, **uvicorn_logging,
              ssl_certfile=settings.ssl_certfile, ssl_keyfile=settings.ssl_keyfile,
              # an open event stream (a console page) must not keep a stopping service alive
              timeout_graceful_shutdown=2)
    except KeyboardInterrupt:
        _leave_request_threads(128 + signal.SIGINT, "interrupted")
        raise
    except BaseException as exc:  # SIGTERM arrives as the command line's Terminated
        _leave_request_threads(128 + signal.SIGTERM if type(exc).__name__ == "Terminated" else 1, "terminated")
        raise
    _leave_request_threads(0, "stopped")
    return 0


def _leave_request_threads(code: int, how: str) -> None:
    """End the process when request threads outlive the server. uvicorn, stopping, cancels what awaits a request
    run on a thread but not the thread itself, and the interpreter joins such threads at exit: a long export kept
    a stopped service alive (and growing) for minutes. They get `REQUEST_THREADS_WAIT_S`; the app's shutdown has
    closed the store by then, and what a thread still writes is one transaction that commits or does not."""
    deadline = time.monotonic() + REQUEST_THREADS_WAIT_S
    for thread in threading.enumerate():
        if thread is not threading.current_thread() and not thread.daemon:
            thread.join(max(0.0, deadline - time.monotonic()))
    left = [t for t in threading.enumerate() if t is not threading.current_thread() and not t.daemon and t.is_alive()]
    if left:
        print(f"planhrc serve: {how}; {len(left)} request(s) still running were abandoned", file=sys.stderr,
              flush=True)
        logging.shutdown()
        os._exit(code)


def add_compact_parser(subparsers: argparse._SubParsersAction[_Parser]) -> _Parser:
    p = subparsers.add_parser(
        "compact", help="drop the history the retention policy does not keep",
        description="Compact a store: keep each object's current records (goal, latest problem, current plan and "
        "what they refer to) and its last N perceived states, delete the rest of its history. Run it on a store "
        "no service is writing; a running service compacts its own store every PLANHRC_COMPACT_EVERY_S seconds.")
    add_store_options(p)
    p.add_argument("--keep", type=int, default=None,
                   help="perceived states kept per object (default 100, env PLANHRC_KEEP_PERCEIVED)")
    p.add_argument("--tbox", type=tbox_file, default=None, help="TBox OWL file (default: the repository's)")
    p.add_argument("--vacuum", action="store_true",
                   help="then rewrite the SQLite file: the space the dropped history held goes back to the file "
                   "system, and a store made before stores had 4 KiB pages gets them (PostgreSQL: its own VACUUM)")
    p.set_defaults(func=run_compact)
    return p


def run_compact(args: argparse.Namespace) -> int:
    from .store import KBError, SqliteStore, open_store
    from .store.location import shown_location

    read = settings_or_say("planhrc compact", {**store_given(args), "keep_perceived": ("--keep", args.keep),
                                                "tbox_path": ("--tbox", args.tbox)})
    if read is None:
        return 2
    settings, db_option = read.settings, read.name("db_path")
    sqlite = backend_of(settings.db_path) == "sqlite"
    if sqlite and (settings.db_path in (None, "", ":memory:") or not Path(settings.db_path).is_file()):
        print(f"planhrc compact: {db_option}: no store file {settings.db_path!r}", file=sys.stderr)
        return 2
    if args.vacuum and not sqlite:
        print(f"planhrc compact: --vacuum rewrites a SQLite file; the space of a store on a database server is the "
              f"server's to reclaim (PostgreSQL: VACUUM)", file=sys.stderr)
        return 2
    where = shown_location(str(settings.db_path))
    password = settings.db_password.get_secret_value() if settings.db_password else None
    try:
        with open_store(settings.db_path, settings.tbox_path, password) as kb:
            done = kb.compact(settings.keep_perceived)
            print(f"compacted {where}: {done.individuals} individuals and {done.triples} triples dropped "
                  f"from {done.objects} objects (the last {settings.keep_perceived} perceived states of each kept)",
                  flush=True)
            if args.vacuum and isinstance(kb, SqliteStore):
                before, after = kb.rewrite()
                print(f"rewrote {where}: {before / 1e6:.1f} MB -> {after / 1e6:.1f} MB")
    except KBError as exc:
        print(f"planhrc compact: {exc}", file=sys.stderr)
        return 1
    return 0


def add_planning_worker_parser(subparsers: argparse._SubParsersAction[_Parser]) -> _Parser:
    p = subparsers.add_parser(
        "planning-worker", help="plan queued tasks for the services of a PostgreSQL store, on any host",
        description="Serve the planning job queue of a PostgreSQL store: take the large tasks the services on that "
        "database queue (`planhrc serve --planning-queue`), one at a time, plan them (and check them with VAL when "
        "the service asks) by each task's deadline, and store the outcome for the service. Run as many as the "
        "hosts have cores; a killed worker's task is taken again by another once its lease expires.")
    add_store_options(p, "a PostgreSQL URL postgresql://user@host:port/database")
    p.add_argument("--tbox", type=tbox_file, default=None,
                   help="TBox OWL file (default: the repository's ontology/planhrc.owl); the services' own")
    p.add_argument("--lease-s", type=float, default=None, metavar="SECONDS",
                   help="the lease on a task, renewed while it plans: another worker takes the task this long after "
                   "this one stopped renewing it (default 3, env PLANHRC_PLANNING_LEASE_S)")
    p.add_argument("--nice", type=int, default=10, choices=range(0, 20), metavar="0..19",
                   help="scheduling priority below the other processes of the host (default 10: on a service's "
                   "host, the service's requests come first)")
    p.add_argument("--metrics-port", type=port, default=None, metavar="PORT",
                   help="serve this worker's /metrics (Prometheus' text format) on this port; default: none")
    p.add_argument("--metrics-host", default="127.0.0.1", metavar="HOST",
                   help="the interface of --metrics-port (default 127.0.0.1)")
    add_observing_options(p)
    p.set_defaults(func=run_planning_worker)
    return p


def run_planning_worker(args: argparse.Namespace) -> int:
    import threading

    try:
        read = read_settings({**store_given(args), "tbox_path": ("--tbox", args.tbox),
                              "planning_lease_s": ("--lease-s", args.lease_s),
                              "log_format": ("--log-format", args.log_format),
                              "otlp_endpoint": ("--otlp-endpoint", args.otlp_endpoint)})
        settings, name, warnings = read.settings, read.name, read.warnings
        if backend_of(settings.db_path) != "postgresql" or not settings.db_path:
            raise SettingsProblem(f"{name('db_path')}: a planning worker serves the job queue of a PostgreSQL store: "
                                  "give its URL, postgresql://user@host:port/database")
        check_store_server(settings, name("db_path"))
        check_otlp_endpoint(settings, name)
    except SettingsProblem as exc:
        print(f"planhrc planning-worker: {exc}", file=sys.stderr)
        return 2
    for warning in warnings:
        print(f"planhrc planning-worker: warning: {warning}", file=sys.stderr, flush=True)
    from .logs import configure_logging
    from .metrics import WorkerMetrics
    from .planning_queue import serve_jobs
    from .tracing import Tracing

    configure_logging("warning", settings.log_format)
    logging.getLogger("planhrc").setLevel(logging.INFO)
    metrics = WorkerMetrics()
    server = None
    if args.metrics_port is not None:
        try:
            server = metrics.serve(args.metrics_host, args.metrics_port)
        except OSError as exc:
            print(f"planhrc planning-worker: --metrics-port/--metrics-host: cannot listen on "
                  f"{args.metrics_host}:{args.metrics_port} ({exc.strerror or exc})", file=sys.stderr)
            return 2
    os.nice(args.nice)
    password = settings.db_password.get_secret_value() if settings.db_password else None
    tracing = Tracing.start("planhrc-planning-worker", settings.otlp_endpoint)
    try:
        serve_jobs(settings.db_path, password, settings.tbox_path, settings.planning_lease_s, threading.Event(),
                   metrics=metrics, tracing=tracing)
    finally:
        tracing.close()
        if server is not None:
            server.shutdown()
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = OneLineParser(prog="python -m planhrc.kb_service.cli")
    add_serve_parser(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(sys.argv[1:] if argv is None else argv)
    return int(args.func(args) or 0)


if __name__ == "__main__":
    sys.exit(main())

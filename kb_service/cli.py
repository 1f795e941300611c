"""`planhrc serve`: run the knowledge-base service with uvicorn.

Registered by `planhrc.cli` through `add_serve_parser`; `python -m planhrc.kb_service.cli serve ...` works too.
"""
from __future__ import annotations

import argparse
import logging
import socket
import sys
from pathlib import Path
from typing import TYPE_CHECKING, TypeVar

from planhrc.errors import PlanhrcError

if TYPE_CHECKING:
    from planhrc.settings import Settings

_Parser = TypeVar("_Parser", bound=argparse.ArgumentParser)


# Settings field -> the option that sets it, to name the right one in an error.
SERVE_OPTIONS = {"host": "--host", "port": "--port", "db_path": "--db", "token": "--token",
                 "read_token": "--read-token", "protect_reads": "--protect-reads", "tbox_path": "--tbox",
                 "planner": "--planner", "log_level": "--log-level"}


def add_serve_parser(subparsers: argparse._SubParsersAction[_Parser]) -> _Parser:
    from uvicorn.config import LOG_LEVELS

    from planhrc.cli_args import port, tbox_file
    from planhrc.planner.registry import PLANNERS

    p = subparsers.add_parser("serve", help="run the knowledge-base HTTP service",
                              description="Run the planHRC knowledge-base service (FastAPI + uvicorn).")
    p.add_argument("--host", default=None, help="interface to bind (default 127.0.0.1, env PLANHRC_HOST)")
    p.add_argument("--port", type=port, default=None, help="TCP port (default 8000, env PLANHRC_PORT)")
    p.add_argument("--db", default=None,
                   help="SQLite file of the ABox (default planhrc.sqlite3, env PLANHRC_DB_PATH; ':memory:' for none)")
    p.add_argument("--token", default=None,
                   help="bearer token required for writes (env PLANHRC_TOKEN; default: no authentication)")
    p.add_argument("--read-token", default=None,
                   help="read-only bearer token, accepted for reads when reads are protected (env PLANHRC_READ_TOKEN)")
    p.add_argument("--protect-reads", action="store_true", default=None,
                   help="reads of the knowledge base need a token too (env PLANHRC_PROTECT_READS)")
    p.add_argument("--tbox", type=tbox_file, default=None,
                   help="TBox OWL file (default: the repository's ontology/planhrc.owl)")
    p.add_argument("--planner", default=None, choices=list(PLANNERS), help="planner backend (default inproc)")
    p.add_argument("--log-level", default=None, choices=list(LOG_LEVELS), help="uvicorn log level (default info)")
    p.set_defaults(func=run_serve)
    return p


class SettingsProblem(PlanhrcError):
    """A setting the service cannot start with; the message names the option or variable. (Under the project's
    root rather than the store's `KBError`, whose import loads the whole store: `planhrc serve --help` stays
    quick.)"""


def check_serve_settings(settings: Settings, given: set[str]) -> None:
    """Refuse, before anything starts, settings the service would only trip over later (a planner name, the
    TBox, the store's folder, a busy port). Raises SettingsProblem naming the option or `PLANHRC_*` variable."""
    from uvicorn.config import LOG_LEVELS

    from planhrc.cli_args import tbox_problem, writable_dir
    from planhrc.planner.registry import PLANNERS, available_planners

    def name(field: str) -> str:
        return SERVE_OPTIONS[field] if field in given else f"PLANHRC_{field.upper()}"

    if settings.planner not in PLANNERS:
        raise SettingsProblem(f"{name('planner')}: unknown planner {settings.planner!r}; "
                              f"choose from {', '.join(PLANNERS)}")
    if settings.planner not in available_planners():
        raise SettingsProblem(f"{name('planner')}: {settings.planner!r} cannot run here "
                              f"(usable: {', '.join(available_planners())})")
    if settings.fallback_planner and settings.fallback_planner not in PLANNERS:
        raise SettingsProblem(f"PLANHRC_FALLBACK_PLANNER: unknown planner {settings.fallback_planner!r}; "
                              f"choose from {', '.join(PLANNERS)} or empty for none")
    if settings.log_level.lower() not in LOG_LEVELS:
        raise SettingsProblem(f"{name('log_level')}: unknown level {settings.log_level!r}; "
                              f"choose from {', '.join(LOG_LEVELS)}")
    if problem := tbox_problem(settings.tbox_path):
        raise SettingsProblem(f"{name('tbox_path')}: {problem}")
    if settings.db_path not in (None, "", ":memory:"):
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


def run_serve(args: argparse.Namespace) -> int:
    import uvicorn
    from pydantic import ValidationError

    from planhrc.cli_args import settings_error_line
    from planhrc.settings import make_settings

    from .app import create_app

    overrides = {key: value for key, value in {
        "host": args.host, "port": args.port, "db_path": args.db, "token": args.token,
        "read_token": args.read_token, "protect_reads": args.protect_reads,
        "tbox_path": args.tbox, "planner": args.planner, "log_level": args.log_level,
    }.items() if value is not None}
    try:
        settings = make_settings(**overrides)
        check_serve_settings(settings, set(overrides))
    except ValidationError as exc:
        print(f"planhrc serve: {settings_error_line(exc, {f: SERVE_OPTIONS[f] for f in overrides})}", file=sys.stderr)
        return 2
    except SettingsProblem as exc:
        print(f"planhrc serve: {exc}", file=sys.stderr)
        return 2
    level = settings.log_level.lower()
    logging.basicConfig(level=logging.DEBUG if level == "trace" else level.upper(),
                        format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    uvicorn.run(create_app(settings), host=settings.host, port=settings.port, log_level=level,
                # an open event stream (a console page) must not keep a stopping service alive
                timeout_graceful_shutdown=2)
    return 0


def add_compact_parser(subparsers: argparse._SubParsersAction[_Parser]) -> _Parser:
    from planhrc.cli_args import tbox_file

    p = subparsers.add_parser(
        "compact", help="drop the history the retention policy does not keep",
        description="Compact a store: keep each object's current records (goal, latest problem, current plan and "
        "what they refer to) and its last N perceived states, delete the rest of its history. Run it on a store "
        "no service is writing; a running service compacts its own store every PLANHRC_COMPACT_EVERY_S seconds.")
    p.add_argument("--db", default=None, help="SQLite file of the store (default planhrc.sqlite3, env PLANHRC_DB_PATH)")
    p.add_argument("--keep", type=int, default=None,
                   help="perceived states kept per object (default 100, env PLANHRC_KEEP_PERCEIVED)")
    p.add_argument("--tbox", type=tbox_file, default=None, help="TBox OWL file (default: the repository's)")
    p.add_argument("--vacuum", action="store_true",
                   help="then rewrite the file: the space the dropped history held goes back to the file system, "
                   "and a store made before stores had 4 KiB pages gets them")
    p.set_defaults(func=run_compact)
    return p


def run_compact(args: argparse.Namespace) -> int:
    from pydantic import ValidationError

    from planhrc.cli_args import settings_error_line
    from planhrc.settings import make_settings

    from .store import KBError, KnowledgeBase

    options = {"db_path": "--db", "keep_perceived": "--keep", "tbox_path": "--tbox"}
    overrides = {key: value for key, value in {"db_path": args.db, "keep_perceived": args.keep,
                                               "tbox_path": args.tbox}.items() if value is not None}
    try:
        settings = make_settings(**overrides)
    except ValidationError as exc:
        print(f"planhrc compact: {settings_error_line(exc, {f: options[f] for f in overrides})}", file=sys.stderr)
        return 2
    db_option = "--db" if "db_path" in overrides else "PLANHRC_DB_PATH"
    if settings.db_path in (None, "", ":memory:") or not Path(settings.db_path).is_file():
        print(f"planhrc compact: {db_option}: no store file {settings.db_path!r}", file=sys.stderr)
        return 2
    try:
        with KnowledgeBase(settings.db_path, settings.tbox_path) as kb:
            done = kb.compact(settings.keep_perceived)
            print(f"compacted {settings.db_path}: {done.individuals} individuals and {done.triples} triples dropped "
                  f"from {done.objects} objects (the last {settings.keep_perceived} perceived states of each kept)",
                  flush=True)
            if args.vacuum:
                before, after = kb.rewrite()
                print(f"rewrote {settings.db_path}: {before / 1e6:.1f} MB -> {after / 1e6:.1f} MB")
    except KBError as exc:
        print(f"planhrc compact: {exc}", file=sys.stderr)
        return 1
    return 0


def main(argv: list[str] | None = None) -> int:
    from planhrc.cli_args import OneLineParser

    parser = OneLineParser(prog="python -m planhrc.kb_service.cli")
    add_serve_parser(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(sys.argv[1:] if argv is None else argv)
    return int(args.func(args) or 0)


if __name__ == "__main__":
    sys.exit(main())

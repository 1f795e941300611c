"""`planhrc serve`: run the knowledge-base service with uvicorn.

Registered by `planhrc.cli` through `add_serve_parser`; `python -m planhrc.kb_service.cli serve ...` works too.
"""
from __future__ import annotations

import argparse
import logging
import sys


def add_serve_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = subparsers.add_parser("serve", help="run the knowledge-base HTTP service",
                              description="Run the planHRC knowledge-base service (FastAPI + uvicorn).")
    p.add_argument("--host", default=None, help="interface to bind (default 127.0.0.1, env PLANHRC_HOST)")
    p.add_argument("--port", type=int, default=None, help="TCP port (default 8000, env PLANHRC_PORT)")
    p.add_argument("--db", default=None,
                   help="SQLite file of the ABox (default planhrc.sqlite3, env PLANHRC_DB_PATH; ':memory:' for none)")
    p.add_argument("--token", default=None,
                   help="bearer token required for writes (env PLANHRC_TOKEN; default: no authentication)")
    p.add_argument("--read-token", default=None,
                   help="read-only bearer token, accepted for reads when reads are protected (env PLANHRC_READ_TOKEN)")
    p.add_argument("--protect-reads", action="store_true", default=None,
                   help="reads of the knowledge base need a token too (env PLANHRC_PROTECT_READS)")
    p.add_argument("--tbox", default=None, help="TBox OWL file (default: the repository's ontology/planhrc.owl)")
    p.add_argument("--planner", default=None, help="planner backend (default inproc)")
    p.add_argument("--log-level", default=None, help="uvicorn log level (default info)")
    p.set_defaults(func=run_serve)
    return p


def run_serve(args: argparse.Namespace) -> int:
    import uvicorn

    from planhrc.settings import make_settings

    from .app import create_app

    overrides = {key: value for key, value in {
        "host": args.host, "port": args.port, "db_path": args.db, "token": args.token,
        "read_token": args.read_token, "protect_reads": args.protect_reads,
        "tbox_path": args.tbox, "planner": args.planner, "log_level": args.log_level,
    }.items() if value is not None}
    settings = make_settings(**overrides)
    logging.basicConfig(level=settings.log_level.upper(),
                        format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    uvicorn.run(create_app(settings), host=settings.host, port=settings.port, log_level=settings.log_level.lower(),
                # an open event stream (a console page) must not keep a stopping service alive
                timeout_graceful_shutdown=2)
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m planhrc.kb_service.cli")
    add_serve_parser(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(sys.argv[1:] if argv is None else argv)
    return int(args.func(args) or 0)


if __name__ == "__main__":
    sys.exit(main())

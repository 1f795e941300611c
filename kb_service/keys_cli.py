"""`planhrc keys add|list|revoke|rotate --db DB`: the clients of a store and their keys (`clients`).

The registry lives in the store's database, so every service on it (replicas on one PostgreSQL database) sees a
change within a second, without a restart. `add` and `rotate` print the new key alone on standard output (for a
script: `KEY=$(planhrc keys add baxter-1 --role robot --db ...)`); it is shown only then, the database keeps its
hash.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import TypeVar

from .command_settings import add_store_options, settings_or_say, store_given
from .store.backends import backend_of
from .store.errors import KBError

_Parser = TypeVar("_Parser", bound=argparse.ArgumentParser)

DESCRIPTION = ("Manage the clients of a store: each has a name, a role (robot: perceptions, next action, feedback, "
               "give-up; operator: objects, goals, reasoning; reader: reads) and a key, kept as a hash. Changes take "
               "effect on running services within a second.")


def add_keys_parser(subparsers: argparse._SubParsersAction[_Parser]) -> _Parser:
    from .clients import Role

    p = subparsers.add_parser("keys", help="the clients of a store: their names, roles and API keys",
                              description=DESCRIPTION)
    sub = p.add_subparsers(dest="keys_command", required=True, metavar="ACTION")
    add = sub.add_parser("add", help="a new client; prints its key alone on standard output")
    add.add_argument("name", help="the client's name (recorded on every event it causes)")
    add.add_argument("--role", required=True, choices=[r.value for r in Role], help="what the client may do")
    sub.add_parser("list", help="every client: name, role, when made, rotated and revoked (never a key)")
    revoke = sub.add_parser("revoke", help="the client's key stops working (its name stays on its events)")
    revoke.add_argument("name")
    rotate = sub.add_parser("rotate", help="a new key for the client, printed alone; the old one stops working")
    rotate.add_argument("name")
    for action in (add, revoke, rotate, sub.choices["list"]):
        add_store_options(action)
    p.set_defaults(func=run_keys)
    return p


def run_keys(args: argparse.Namespace) -> int:
    from .clients import ClientRegistry, open_table
    from .store.location import shown_location

    command = f"planhrc keys {args.keys_command}"
    read = settings_or_say(command, store_given(args))
    if read is None:
        return 2
    settings, db_option = read.settings, read.name("db_path")
    db = settings.db_path
    if db in (None, "", ":memory:"):
        print(f"{command}: {db_option}: an in-memory store has no clients to manage; name its file or URL",
              file=sys.stderr)
        return 2
    if backend_of(db) == "sqlite" and not Path(db).is_file():
        print(f"{command}: {db_option}: no store file {db!r} (a service makes it when it first starts)",
              file=sys.stderr)
        return 2
    password = settings.db_password.get_secret_value() if settings.db_password else None
    try:
        registry = ClientRegistry(open_table(db, password))
    except KBError as exc:
        print(f"{command}: {exc}", file=sys.stderr)
        return 1
    try:
        if args.keys_command == "add":
            print(registry.add(args.name, args.role), flush=True)
            print(f"client {args.name!r} ({args.role}) added to {shown_location(db)}; the key above is shown only "
                  "now", file=sys.stderr)
        elif args.keys_command == "rotate":
            print(registry.rotate(args.name), flush=True)
            print(f"client {args.name!r}: new key above; the old one no longer works", file=sys.stderr)
        elif args.keys_command == "revoke":
            registry.revoke(args.name)
            print(f"client {args.name!r}: key revoked", file=sys.stderr)
        else:
            print(f"{'name':<24} {'role':<9} {'created':<20} {'rotated':<20} revoked")
            for record in registry.records():
                print(f"{record.name:<24} {record.role.value:<9} {_when(record.created_at):<20} "
                      f"{_when(record.rotated_at):<20} {_when(record.revoked_at)}")
    except KBError as exc:
        print(f"{command}: {exc}", file=sys.stderr)
        return 1
    finally:
        registry.close()
    return 0


def _when(moment: float | None) -> str:
    return "-" if moment is None else time.strftime("%Y-%m-%d %H:%M:%S", time.localtime(moment))

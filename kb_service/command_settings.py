"""The settings of every command that builds them (`serve`, `compact`, `planning-worker`, `keys`), by one path:
the environment, one `PLANHRC_*` variable a setting (`planhrc.settings.env_name`), with the options given on the
command line on top; secrets read from their files (`network.resolve_secrets`). A setting the command cannot take
is a `SettingsProblem` in one line naming where it came from: the option when given, else the variable when set,
else (a default) the command's option for it, or the variable where the command has none.
"""
from __future__ import annotations

import argparse
import os
import sys
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Mapping

from .network import Name, SettingsProblem, resolve_secrets

if TYPE_CHECKING:
    from planhrc.settings import Settings


@dataclass(frozen=True)
class CommandSettings:
    """A command's settings, and how to name each of its fields in a message."""

    settings: Settings
    name: Name
    given: frozenset[str]  # the fields set on the command line
    warnings: tuple[str, ...]  # what the command may start with but should not (a secret on the command line...)


def add_store_options(parser: argparse.ArgumentParser,
                      store: str = "a SQLite file (default planhrc.sqlite3) or a PostgreSQL URL") -> None:
    """The options naming a command's store, `--db` and `--db-password-file` (`store`: what `--db` may be)."""
    parser.add_argument("--db", default=None, help=f"the store: {store} (env PLANHRC_DB)")
    parser.add_argument("--db-password-file", default=None, metavar="FILE",
                        help="file holding the PostgreSQL password (env PLANHRC_DB_PASSWORD_FILE; libpq's PGPASSFILE "
                        "and PGPASSWORD work too)")


def store_given(args: argparse.Namespace) -> dict[str, tuple[str, Any]]:
    """What `add_store_options`' options gave, for `read_settings`."""
    return {"db_path": ("--db", args.db), "db_password_file": ("--db-password-file", args.db_password_file)}


def settings_or_say(command: str, options: Mapping[str, tuple[str, Any]]) -> CommandSettings | None:
    """`read_settings` for a command that has nothing more to check: a problem printed as one line on standard error
    (None: the command exits 2), the warnings printed there too."""
    try:
        read = read_settings(options)
    except SettingsProblem as exc:
        print(f"{command}: {exc}", file=sys.stderr)
        return None
    for warning in read.warnings:
        print(f"{command}: warning: {warning}", file=sys.stderr)
    return read


def read_settings(options: Mapping[str, tuple[str, Any]]) -> CommandSettings:
    """The settings a command runs with: `options` maps each field its command line may set to (the option, the
    value given: None when not given). Raises SettingsProblem (see the module's note)."""
    from pydantic import ValidationError

    from planhrc.cli_args import settings_error_line
    from planhrc.settings import RENAMED, env_name, make_settings

    for old, new in RENAMED.items():
        if old in os.environ:
            raise SettingsProblem(f"{old}: no longer read; set {new} instead")
    flags = {field: flag for field, (flag, _) in options.items()}
    overrides = {field: value for field, (_, value) in options.items() if value is not None}

    def name(field: str) -> str:
        if field in overrides:
            return flags[field]
        variable = env_name(field)
        return variable if variable in os.environ or field not in flags else flags[field]

    try:
        settings = make_settings(**overrides)
    except ValidationError as exc:
        raise SettingsProblem(settings_error_line(exc, {f: flags[f] for f in overrides})) from None
    warnings: list[str] = []
    settings = resolve_secrets(settings, set(overrides), name, warnings)
    return CommandSettings(settings, name, frozenset(overrides), tuple(warnings))

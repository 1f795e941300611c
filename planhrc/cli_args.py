"""Validated argument types shared by every `planhrc` command, and the parser class that reports a mistake in
one line.

Each type is a callable for argparse's `type=`: it returns the parsed value or raises
`argparse.ArgumentTypeError` with a message that says what was expected; argparse adds the argument's name.
The same checks serve the environment settings (`PLANHRC_*`), so a port or a TBox file is judged alike
wherever it comes from. Nothing here imports a heavy dependency at import time.
"""
from __future__ import annotations

import argparse
import math
import os
import sys
import tempfile
from pathlib import Path
from typing import Callable, NoReturn, Sequence, TypeAlias
from urllib.parse import urlsplit

PORT_RANGE = (0, 65535)
# What `add_subparsers()` returns, as each command's `add_*_parser(subparsers)` receives it (a string: argparse's
# class is generic only in the type stubs).
SubParsers: TypeAlias = "argparse._SubParsersAction[OneLineParser]"


class OneLineParser(argparse.ArgumentParser):
    """An ArgumentParser whose errors are one line on stderr (`prog: message (see prog --help)`), exit 2.

    Sub-parsers made with `add_subparsers().add_parser` inherit the class, so every command behaves alike.
    """

    def error(self, message: str) -> NoReturn:
        sys.stderr.write(f"{self.prog}: {message} (see `{self.prog} --help`)\n")
        sys.exit(2)


def _int(text: str) -> int:
    try:
        return int(text, 10)
    except (TypeError, ValueError):
        raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None


def int_in(low: int | None = None, high: int | None = None) -> Callable[[str], int]:
    """An integer within [low, high] (either bound may be open)."""

    def parse(text: str) -> int:
        value = _int(text)
        if (low is not None and value < low) or (high is not None and value > high):
            raise argparse.ArgumentTypeError(f"must be {_bounds(low, high)}, got {value}")
        return value

    parse.__name__ = "integer"  # argparse names the type in "invalid <name> value" messages
    return parse


def _bounds(low: float | None, high: float | None, strict_low: bool = False) -> str:
    if low is not None and high is not None:
        return f"between {low} and {high}"
    if low is not None:
        return f"> {low}" if strict_low else f">= {low}"
    return f"<= {high}"


positive_int = int_in(1)
non_negative_int = int_in(0)
port = int_in(*PORT_RANGE)


def float_in(low: float | None = None, high: float | None = None, strict_low: bool = False) -> Callable[[str], float]:
    """A finite number within [low, high], or (low, high] when `strict_low`."""

    def parse(text: str) -> float:
        try:
            value = float(text)
        except (TypeError, ValueError):
            raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
        too_low = low is not None and (value <= low if strict_low else value < low)
        if not math.isfinite(value) or too_low or (high is not None and value > high):
            raise argparse.ArgumentTypeError(f"must be a finite number {_bounds(low, high, strict_low)}, got {text}")
        return value

    parse.__name__ = "number"
    return parse


positive_float = float_in(0.0, strict_low=True)
non_negative_float = float_in(0.0)


def int_list(low: int | None = None, high: int | None = None) -> Callable[[str], list[int]]:
    """`A-B` (inclusive range) or `a,b,c`: integers within [low, high], at least one."""
    one = int_in(low, high)

    def parse(text: str) -> list[int]:
        text = text.strip()
        if "-" in text.lstrip("-") and "," not in text:
            first, _, last = text.partition("-")
            a, b = one(first), one(last)
            if a > b:
                raise argparse.ArgumentTypeError(f"range {text!r} is empty (start > end)")
            return list(range(a, b + 1))
        values = [one(part) for part in text.split(",") if part.strip()]
        if not values:
            raise argparse.ArgumentTypeError(f"expected A-B or a comma separated list of integers, got {text!r}")
        return values

    parse.__name__ = "list"
    return parse


def name_list(choices: Sequence[str]) -> Callable[[str], list[str]]:
    """A comma separated list of names, each one of `choices`, at least one."""

    def parse(text: str) -> list[str]:
        names = [part.strip() for part in text.split(",") if part.strip()]
        unknown = [n for n in names if n not in choices]
        if unknown or not names:
            raise argparse.ArgumentTypeError(
                f"unknown {', '.join(map(repr, unknown)) or 'empty list'}; choose from {', '.join(choices)}")
        return names

    parse.__name__ = "list"
    return parse


def existing_file(text: str) -> str:
    path = Path(text)
    if not path.is_file():
        raise argparse.ArgumentTypeError(f"no such file: {text}")
    if not os.access(path, os.R_OK):
        raise argparse.ArgumentTypeError(f"cannot read {text}")
    return text


def tbox_problem(text: str) -> str | None:
    """Why `text` is not a readable OWL file (parsed in a throwaway world), or None when it is one."""
    path = Path(text)
    if not path.is_file():
        return f"no such file: {text}"
    from owlready2 import World

    world = World()
    try:
        with path.open("rb") as f:
            world.get_ontology("http://planhrc.org/tbox-check").load(fileobj=f)
    except Exception as exc:  # owlready2 raises several kinds for a file it cannot parse
        return f"{text} is not an OWL ontology ({type(exc).__name__})"
    finally:
        world.close()
    return None


def tbox_file(text: str) -> str:
    """An OWL file that owlready2 can parse (RDF/XML, OWL/XML or N-Triples)."""
    problem = tbox_problem(text)
    if problem:
        raise argparse.ArgumentTypeError(problem)
    return text


def writable_dir(text: str) -> str:
    """A folder that exists or can be created: its nearest existing ancestor is a folder where a sub-folder can
    be made (probed with a temporary folder, removed at once, so nothing is left behind)."""
    if not text.strip():
        raise argparse.ArgumentTypeError("empty path")
    path = Path(text).absolute()
    if path.exists() and not path.is_dir():
        raise argparse.ArgumentTypeError(f"{text} exists and is not a folder")
    ancestor = path
    while not ancestor.exists():
        ancestor = ancestor.parent
    if not ancestor.is_dir():
        raise argparse.ArgumentTypeError(f"cannot create {text}: {ancestor} is not a folder")
    try:
        tempfile.TemporaryDirectory(dir=ancestor, prefix=".planhrc-probe-").cleanup()
    except OSError as exc:
        raise argparse.ArgumentTypeError(f"cannot write in {ancestor}: {exc.strerror or exc}") from None
    return text


def writable_file(text: str) -> str:
    """A file path whose folder exists or can be created (the file itself is written later)."""
    path = Path(text)
    if path.is_dir():
        raise argparse.ArgumentTypeError(f"{text} is a folder")
    writable_dir(str(path.absolute().parent))
    return text


def http_url(text: str) -> str:
    """An http(s) URL with a host, e.g. http://127.0.0.1:8000."""
    parts = urlsplit(text)
    if parts.scheme not in ("http", "https") or not parts.hostname:
        raise argparse.ArgumentTypeError(f"expected an http(s) URL such as http://127.0.0.1:8000, got {text!r}")
    try:
        parts.port  # raises for a port that is not a number or out of range
    except ValueError:
        raise argparse.ArgumentTypeError(f"bad port in {text!r}") from None
    return text


def float_tuple(text: str) -> tuple[float, ...]:
    """Comma separated finite numbers (degrees or metres)."""
    try:
        values = tuple(float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma separated numbers, got {text!r}") from None
    if not all(math.isfinite(v) for v in values):
        raise argparse.ArgumentTypeError(f"expected finite numbers, got {text!r}")
    return values


def settings_error_line(exc: Exception, cli_names: dict[str, str] | None = None) -> str:
    """A pydantic ValidationError of the settings as one line naming the option or `PLANHRC_*` variable."""
    from planhrc.settings import env_name  # pydantic's import only where settings are read

    cli_names = cli_names or {}
    parts = []
    for error in exc.errors():  # type: ignore[attr-defined]
        field = str(error["loc"][0]) if error.get("loc") else "?"
        name = cli_names.get(field, env_name(field))
        parts.append(f"{name}: {error['msg']}, got {error.get('input')!r}")
    return "; ".join(parts)

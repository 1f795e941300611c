"""The explicit registry of planner backends.

    get_planner("fd-lama")                                  # Fast Downward, lama-first
    get_planner("probe", binary="/opt/probe/probe")        # or set PLANHRC_PROBE
    get_planner("madagascar")                              # needs PLANHRC_MADAGASCAR (path to M / MpC)
    get_planner("symk"), get_planner("bfws")               # SymK, LAPKT's BFWS: the `bench` extra

External binaries are looked up at call time (an option, else the environment variable); nothing is
configured at import time.
"""
from __future__ import annotations

import os
from typing import Any, Callable, Mapping

from .base import Planner
from .errors import PlannerError
from .external import make_bfws, make_madagascar, make_probe
from .fast_downward import SYMK_BIDIRECTIONAL, FastDownwardPlanner, symk_script
from .inproc import InprocPlanner

BINARY_ENV = {"probe": "PLANHRC_PROBE", "madagascar": "PLANHRC_MADAGASCAR"}


def _inproc(**options: Any) -> Planner:
    _no_options("inproc", options)
    return InprocPlanner()


def _fd(name: str, search: str) -> Callable[..., Planner]:
    def build(**options: Any) -> Planner:
        unknown = set(options) - {"script", "python", "search"}
        if unknown:
            raise PlannerError(f"{name}: unknown option(s) {', '.join(sorted(unknown))}")
        return FastDownwardPlanner(name, options.get("search", search), options.get("script"), options.get("python"))
    return build


def _symk(**options: Any) -> Planner:
    _no_options("symk", options)
    return FastDownwardPlanner("symk", SYMK_BIDIRECTIONAL, symk_script(), proves_optimal=True)


def _bfws(**options: Any) -> Planner:
    _no_options("bfws", options)
    return make_bfws()


def _external(name: str, make: Callable[..., Planner]) -> Callable[..., Planner]:
    def build(**options: Any) -> Planner:
        unknown = set(options) - {"binary"}
        if unknown:
            raise PlannerError(f"{name}: unknown option(s) {', '.join(sorted(unknown))}")
        binary = configured_binary(name, options)
        if not binary:
            raise PlannerError(f"{name}: no binary configured; pass binary=PATH or set {BINARY_ENV[name]}")
        return make(binary, name=name)
    return build


def _no_options(name: str, options: Mapping[str, Any]) -> None:
    if options:
        raise PlannerError(f"{name}: takes no options, got {', '.join(sorted(options))}")


PLANNERS: dict[str, Callable[..., Planner]] = {
    "inproc": _inproc,
    "fd-lama": _fd("fd-lama", "lama"),
    "fd-opt": _fd("fd-opt", "opt"),
    "symk": _symk,
    "bfws": _bfws,
    "probe": _external("probe", make_probe),
    "madagascar": _external("madagascar", make_madagascar),
}


def configured_binary(name: str, options: Mapping[str, Any] | None = None) -> str | None:
    """The binary path for an external planner: option `binary`, else its environment variable."""
    if options and options.get("binary"):
        return str(options["binary"])
    return os.environ.get(BINARY_ENV[name]) or None


def get_planner(name: str, **options: Any) -> Planner:
    try:
        factory = PLANNERS[name]
    except KeyError:
        raise PlannerError(f"unknown planner {name!r}; known planners: {', '.join(PLANNERS)}") from None
    return factory(**options)


def available_planners(binaries: Mapping[str, str] | None = None) -> list[str]:
    """Names usable on this machine: built-ins whose dependencies import, external ones whose binary is set."""
    names = []
    for name in PLANNERS:
        try:
            get_planner(name, **({"binary": binaries[name]} if binaries and name in binaries else {}))
        except PlannerError:
            continue
        names.append(name)
    return names

"""`planhrc` command line: one sub-command per job, each registered by the module that owns it.

Modules are imported only when their command runs, so a quick command does not pay for the simulator.
"""
from __future__ import annotations

import argparse
import importlib
import logging
import sys
from typing import Callable

# command -> (module, name of its `add_*_parser(subparsers)` function)
COMMANDS: dict[str, tuple[str, str]] = {
    "ontology": ("planhrc.kb.check", "add_ontology_parser"),
    "plan": ("planhrc.planner.cli", "add_plan_parser"),
    "solve": ("planhrc.solve", "add_solve_parser"),
    "bench": ("planhrc.bench", "add_bench_parser"),
    "serve": ("planhrc.kb_service.cli", "add_serve_parser"),
    "worker": ("planhrc.robot_sim.worker", "add_worker_parser"),
    "demo": ("planhrc.robot_sim.demo", "add_demo_parser"),
    "sim-bench": ("planhrc.robot_sim.measure", "add_sim_bench_parser"),
    "service-bench": ("planhrc.service_bench", "add_service_bench_parser"),
}


def build_parser(argv: list[str]) -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="planhrc", description=__doc__.splitlines()[0])
    parser.add_argument("-v", "--verbose", action="store_true", help="log at DEBUG level")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    wanted = next((a for a in argv if a in COMMANDS), None)
    for name, (module, func) in COMMANDS.items():
        if wanted is not None and name != wanted:
            sub.add_parser(name, help=f"see `planhrc {name} --help`")
            continue
        try:
            add: Callable = getattr(importlib.import_module(module), func)
        except (ImportError, AttributeError) as exc:  # a part that cannot load must not hide the others
            p = sub.add_parser(name, help=f"unavailable: {exc}")
            p.set_defaults(func=lambda args, exc=exc: _unavailable(exc))
            continue
        add(sub)
    return parser


def _unavailable(exc: Exception) -> int:
    print(f"planhrc: this command cannot run here: {exc}", file=sys.stderr)
    return 2


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = build_parser(argv)
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.DEBUG if args.verbose else logging.WARNING,
                        format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    func = getattr(args, "func", None)
    if func is None:
        parser.error(f"{args.command}: no handler")
    return int(func(args) or 0)


if __name__ == "__main__":
    sys.exit(main())

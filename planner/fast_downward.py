"""Fast Downward backend: `up_fast_downward/downward/fast-downward.py` run with `sys.executable`.

Each call runs in a fresh `tempfile.TemporaryDirectory` (domain, problem, output.sas and sas_plan all live
there and are removed afterwards) and in its own process group, killed at the time limit.

Configurations:
* ``fd-lama``: ``--alias lama-first`` (satisficing, handles conditional effects).
* ``symk``: SymK, a Fast Downward fork with symbolic search, from the `up-symk` wheel (the ``bench`` extra):
  ``--search "sym_bd()"``, bidirectional symbolic search, optimal and with conditional effects.
* ``fd-opt``: ``--alias seq-opt-lmcut`` (A* with LM-cut) for STRIPS domains. LM-cut in this build rejects
  conditional effects (exit code 34, "This configuration does not support conditional effects"), and so do
  ``seq-opt-bjolp`` and ``cegar``; for a domain with conditional effects (the absolute formulation)
  ``fd-opt`` therefore runs ``--search "astar(hmax())"``, which supports them and is admissible.
"""
from __future__ import annotations

import logging
import re
import sys
import tempfile
import time
from pathlib import Path

from .errors import PlannerError
from .normalise import for_external
from .plan_file import read_best_plan
from .process import installed_file, run_limited
from .result import PlanResult, PlanStatus

log = logging.getLogger(__name__)

LAMA_FIRST = ("--alias", "lama-first")
SEQ_OPT_LMCUT = ("--alias", "seq-opt-lmcut")
OPT_CONDITIONAL = ("--search", "astar(hmax())")

# Exit codes, https://www.fast-downward.org/latest/documentation/exit-codes/ (driver/returncodes.py).
SOLVED_CODES = {0: "", 1: "plan found, then out of memory", 2: "plan found, then out of time",
                3: "plan found, then out of memory and time"}
UNSOLVABLE_CODES = {10: "translator proved the task unsolvable", 11: "search proved the task unsolvable",
                    12: "search ended without a plan (incomplete search)",
                    13: "no plan within the cost bound"}
TIMEOUT_CODES = {21: "translator out of time", 23: "search out of time", 24: "search out of memory and time"}
ERROR_CODES = {20: "translator out of memory", 22: "search out of memory", 30: "translator critical error",
               31: "translator input error", 32: "search critical error", 33: "search input error",
               34: "search does not support a feature of this task", 35: "driver critical error",
               36: "driver input error", 37: "driver does not support this"}

_WHEN = re.compile(r"\(\s*when[\s(]", re.IGNORECASE)


SYMK_BIDIRECTIONAL = ("--search", "sym_bd()")


def fast_downward_script() -> Path:
    return installed_file("up_fast_downward", "downward/fast-downward.py", "fast downward")


def symk_script() -> Path:
    return installed_file("up_symk", "symk/fast-downward.py", "symk (pip install planhrc[bench])")


def has_conditional_effects(domain: str) -> bool:
    text = "\n".join(line.split(";", 1)[0] for line in domain.splitlines())
    return bool(_WHEN.search(text))


class FastDownwardPlanner:
    """`search` is the driver arguments, or "opt" (LM-cut, hmax for conditional effects) / "lama";
    `proves_optimal` says that driver arguments given as `search` run an optimal search (SymK's)."""

    def __init__(self, name: str, search: str | tuple[str, ...] = "lama", script: str | Path | None = None,
                 python: str | None = None, proves_optimal: bool = False) -> None:
        if isinstance(search, str) and search not in ("lama", "opt"):
            raise PlannerError(f"fast downward: search must be 'lama', 'opt' or driver arguments, got {search!r}")
        self.name = name
        self.search = search
        self.script = Path(script) if script else fast_downward_script()
        self.python = python or sys.executable
        self.proves_optimal = proves_optimal

    def search_args(self, domain: str) -> tuple[str, ...]:
        if self.search == "lama":
            return LAMA_FIRST
        if self.search == "opt":
            return OPT_CONDITIONAL if has_conditional_effects(domain) else SEQ_OPT_LMCUT
        return tuple(self.search)

    @property
    def optimal_config(self) -> bool:
        return self.search == "opt" or self.proves_optimal

    def solve(self, domain: str, problem: str, timeout_s: float) -> PlanResult:
        start = time.perf_counter()
        domain, problem = for_external(domain, problem)  # its translator rejects `?j -joint`, reads duplicates
        args = self.search_args(domain)
        alias = args[:2] if args and args[0] == "--alias" else ()
        rest = args[2:] if alias else args
        with tempfile.TemporaryDirectory(prefix="planhrc-fd-") as tmp:
            Path(tmp, "domain.pddl").write_text(domain)
            Path(tmp, "problem.pddl").write_text(problem)
            cmd = [self.python, str(self.script), *alias, "--plan-file", "sas_plan", "domain.pddl", "problem.pddl",
                   *rest]
            log.debug("running %s", " ".join(cmd))
            outcome = run_limited(cmd, tmp, timeout_s)
            plan = read_best_plan(Path(tmp), "sas_plan")
        elapsed = time.perf_counter() - start
        if outcome.timed_out:
            return PlanResult(PlanStatus.TIMEOUT, (), elapsed, self.name, f"killed after {timeout_s} s")
        code = outcome.returncode
        if code in SOLVED_CODES and plan is not None:
            return PlanResult(PlanStatus.SOLVED, plan, elapsed, self.name, SOLVED_CODES[code],
                              True if self.optimal_config and code == 0 else None)
        if code in UNSOLVABLE_CODES:
            return PlanResult(PlanStatus.UNSOLVABLE, (), elapsed, self.name, UNSOLVABLE_CODES[code])
        if code in TIMEOUT_CODES:
            return PlanResult(PlanStatus.TIMEOUT, (), elapsed, self.name, TIMEOUT_CODES[code])
        detail = ERROR_CODES.get(code, f"unexpected exit code {code}") if code is not None else "no exit code"
        tail = _tail(outcome.stderr or outcome.stdout)
        return PlanResult(PlanStatus.ERROR, (), elapsed, self.name, f"exit code {code}: {detail}. {tail}".strip())


def _tail(text: str, lines: int = 5) -> str:
    return " | ".join(line.strip() for line in text.strip().splitlines()[-lines:])

"""Generic external PDDL planner backend (Probe, Madagascar, ...): a binary given by path and a command template.

The template names the placeholders {domain}, {problem} and {plan}; each call runs in a fresh temporary
directory (removed afterwards) and its own process group, killed at the time limit. The plan file (or the
last of an anytime planner's numbered files ``plan.1``, ``plan.2``, ...) is read with
`planner.plan_file.parse_plan_text`. Exit codes of these planners do not say "unsolvable" reliably, so a
run that ends without a plan file is reported as status error with the output's tail, except when the
output contains one of `unsolvable_markers`.
"""
from __future__ import annotations

import importlib.util
import logging
import os
import sys
import tempfile
import time
from pathlib import Path
from typing import Sequence

from .errors import PlannerError
from .normalise import for_external
from .plan_file import read_best_plan
from .process import run_limited
from .result import PlanResult, PlanStatus

log = logging.getLogger(__name__)

PROBE_TEMPLATE = ("{binary}", "-d", "{domain}", "-i", "{problem}", "-o", "{plan}")
# LAPKT's BFWS (the `lapkt` wheel, the ``bench`` extra; its Tarski grounder needs `clingo`): what its lapkt_cmd.py
# script does, run by this interpreter so that no script path is needed.
BFWS_CODE = ("from lapkt.parseargs import process_arguments; from lapkt.load_planner import Planner; "
             "Planner(process_arguments()).solve()")
# Its last, complete search (BFWS with novelty, landmarks and h_ff) ends so when the task has no plan.
BFWS_UNSOLVABLE = ("plan found with cost: notfound",)
BFWS_TEMPLATE = ("{binary}", "-c", BFWS_CODE, "BFWS", "-d", "{domain}", "-p", "{problem}", "--plan_file", "{plan}")
MADAGASCAR_TEMPLATE = ("{binary}", "{domain}", "{problem}", "-o", "{plan}")
DEFAULT_UNSOLVABLE_MARKERS = ("unsolvable", "no plan exists", "problem has no solution", "goal not reachable")


class ExternalPlanner:
    def __init__(self, name: str, binary: str | Path, template: Sequence[str],
                 unsolvable_markers: Sequence[str] = DEFAULT_UNSOLVABLE_MARKERS) -> None:
        path = Path(binary).expanduser()
        if not path.is_file() or not os.access(path, os.X_OK):
            raise PlannerError(f"{name}: binary {str(path)!r} is not an executable file")
        for key in ("{domain}", "{problem}", "{plan}"):
            if not any(key in part for part in template):
                raise PlannerError(f"{name}: command template must contain {key}")
        self.name = name
        self.binary = path.resolve()
        self.template = tuple(template)
        self.unsolvable_markers = tuple(m.lower() for m in unsolvable_markers)

    def command(self, directory: Path) -> list[str]:
        values = {"binary": str(self.binary), "domain": str(directory / "domain.pddl"),
                  "problem": str(directory / "problem.pddl"), "plan": str(directory / "plan")}
        return [part.format(**values) for part in self.template]

    def solve(self, domain: str, problem: str, timeout_s: float) -> PlanResult:
        start = time.perf_counter()
        domain, problem = for_external(domain, problem)  # the text as VAL reads it (planner.normalise)
        with tempfile.TemporaryDirectory(prefix=f"planhrc-{self.name}-") as tmp:
            directory = Path(tmp)
            (directory / "domain.pddl").write_text(domain)
            (directory / "problem.pddl").write_text(problem)
            outcome = run_limited(self.command(directory), tmp, timeout_s)
            plan = read_best_plan(directory, "plan")
        elapsed = time.perf_counter() - start
        if outcome.timed_out:
            return PlanResult(PlanStatus.TIMEOUT, (), elapsed, self.name, f"killed after {timeout_s} s")
        text = (outcome.stdout + "\n" + outcome.stderr).lower()
        says_unsolvable = any(m in text for m in self.unsolvable_markers)
        if plan is not None and (plan or not says_unsolvable):  # BFWS writes an empty plan file when it finds none
            return PlanResult(PlanStatus.SOLVED, plan, elapsed, self.name, f"exit code {outcome.returncode}")
        if says_unsolvable:
            return PlanResult(PlanStatus.UNSOLVABLE, (), elapsed, self.name, "planner reports no plan")
        tail = " | ".join((outcome.stderr or outcome.stdout).strip().splitlines()[-5:])
        return PlanResult(PlanStatus.ERROR, (), elapsed, self.name,
                          f"exit code {outcome.returncode}, no plan file. {tail}".strip())


def make_probe(binary: str | Path, name: str = "probe") -> ExternalPlanner:
    return ExternalPlanner(name, binary, PROBE_TEMPLATE)


def make_madagascar(binary: str | Path, name: str = "madagascar") -> ExternalPlanner:
    """`binary` may be M, Mp or MpC; all take the same arguments."""
    return ExternalPlanner(name, binary, MADAGASCAR_TEMPLATE)


def make_bfws(name: str = "bfws") -> ExternalPlanner:
    """LAPKT's BFWS (by Probe's author) in this interpreter; PlannerError when `lapkt` or `clingo` is missing."""
    for package in ("lapkt", "clingo"):
        if importlib.util.find_spec(package) is None:
            raise PlannerError(f"{name}: the {package} package is not installed (pip install planhrc[bench])")
    return ExternalPlanner(name, sys.executable, BFWS_TEMPLATE, BFWS_UNSOLVABLE)

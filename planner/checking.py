"""The independent check of one plan, and which check gave its verdict (`check_plan` -> `Checked`).

A plan is checked by VAL against the domain and problem as given. When it uses macros that the domain's macro check
proved faithful (`planner.macros`: once per domain text) and the problem meets that proof's premises, VAL checks its
*expansion* into the actions the macros stand for instead, against the same domain and problem: the plan is valid
exactly when its expansion is, and VAL checks the expansion of a 45-degree turn of the bimanual files in a fraction
of the time it takes to expand the macro's own conditional effect (seconds per step at K = 24). `Checked.by` says
which check gave the verdict and `Checked.note` why (the macros expanded, or why the plan went to VAL as it is).

VAL on the plan as given still tells whether both agree, where it can finish: off an answer's path
(`check_as_given`: the benches, and the service behind its answer).
"""
from __future__ import annotations

import logging
import re
import time
from dataclasses import dataclass
from enum import StrEnum
from typing import Sequence

from .errors import PlannerError
from .macros import ExpandedPlan, macro_report
from .pddl import parse_problem
from .validate import ValidationResult, validate_plan

log = logging.getLogger(__name__)


class CheckedBy(StrEnum):
    """Which check gave a plan's verdict."""

    VAL = "val"  # VAL on the plan as given
    VAL_EXPANSION = "val-expansion"  # VAL on the plan's expansion into the actions its faithful macros stand for


@dataclass(frozen=True)
class Route:
    """What `check_plan` gives VAL: the plan as given, or its expansion (`expanded`), and why."""

    by: CheckedBy
    steps: tuple[str, ...]
    note: str
    expanded: ExpandedPlan | None = None


@dataclass(frozen=True)
class Checked:
    """A validator's verdict on a plan: valid or not (with the validator's reason), its seconds, which check gave
    it and why that one."""

    valid: bool
    reason: str
    seconds: float
    by: CheckedBy
    note: str


def route(domain: str, problem: str, plan: Sequence[str]) -> Route:
    """Which check a plan gets (see the module's note). Cheap: the macro check is made once per domain text."""
    steps = tuple(plan)
    report = macro_report(domain)
    expanded = report.expand(steps) if report.faithful else None
    if expanded is None:
        return Route(CheckedBy.VAL, steps, "VAL on the plan as given" + (
            "" if not report.faithful else ": it uses none of the domain's macros"))
    try:
        unmet = report.premises(parse_problem(problem))
    except PlannerError as exc:
        unmet = f"the problem does not parse ({exc})"
    if unmet is not None:
        return Route(CheckedBy.VAL, steps, f"VAL on the plan as given: the macros' proof does not hold here ({unmet})")
    used = sorted({step.strip().strip("()").split()[0].lower() for step in steps} & set(report.faithful))
    note = (f"VAL on the plan's expansion into {len(expanded.steps)} steps: {expanded.macro_steps} macro step"
            f"{'s' if expanded.macro_steps != 1 else ''} ({', '.join(used)}) proved faithful compositions of the "
            "domain's other actions")
    return Route(CheckedBy.VAL_EXPANSION, expanded.steps, note, expanded)


def check_plan(domain: str, problem: str, plan: Sequence[str], timeout_s: float) -> Checked:
    """The plan's verdict by the check `route` picks, within `timeout_s` seconds. PlannerError when VAL does not
    answer in time (no verdict: the caller says the plan is unvalidated)."""
    way = route(domain, problem, plan)
    result = validate_plan(domain, problem, way.steps, timeout_s)
    reason = result.reason
    if not result.valid and way.expanded is not None:
        reason = _in_plan_steps(reason, way.expanded, plan)
    return Checked(result.valid, reason, result.seconds, way.by, way.note)


def check_as_given(domain: str, problem: str, plan: Sequence[str], timeout_s: float) -> ValidationResult | None:
    """VAL on the plan as given, macros and all (None when it does not answer within `timeout_s`): the verdict to
    set beside an expansion's, off an answer's path."""
    start = time.perf_counter()
    try:
        return validate_plan(domain, problem, tuple(plan), timeout_s)
    except PlannerError as exc:
        log.info("VAL on the plan as given did not answer in %.1f s: %s", time.perf_counter() - start, exc)
        return None


_AT_TIME = re.compile(r"at time (\d+)")


def _in_plan_steps(reason: str, expanded: ExpandedPlan, plan: Sequence[str]) -> str:
    """VAL's reason on an expansion, with the plan step its failing step belongs to."""
    found = _AT_TIME.search(reason)
    if found is None:
        return reason
    step = int(found.group(1))
    if not 1 <= step <= len(expanded.steps):
        return reason
    origin = expanded.origin[step - 1]
    if expanded.origin.count(origin) == 1:
        return f"{reason}\n(expanded step {step} is plan step {origin + 1})"
    part = expanded.origin[:step].count(origin)
    return (f"{reason}\n(expanded step {step} is part {part} of the expansion of plan step {origin + 1}, "
            f"{plan[origin].strip()})")

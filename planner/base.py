"""The interface every planner backend implements."""
from __future__ import annotations

from typing import Protocol, runtime_checkable

from .result import PlanResult


@runtime_checkable
class Planner(Protocol):
    """A planner takes PDDL *text* (not paths) and a time limit, and never raises for unsolvable or
    timed-out tasks: those are statuses of the returned `PlanResult`."""

    name: str

    def solve(self, domain: str, problem: str, timeout_s: float) -> PlanResult:
        ...

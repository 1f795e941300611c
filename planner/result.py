"""The value every planner backend returns."""
from __future__ import annotations

from dataclasses import dataclass
from enum import Enum


class PlanStatus(str, Enum):
    SOLVED = "solved"
    UNSOLVABLE = "unsolvable"
    TIMEOUT = "timeout"
    ERROR = "error"


@dataclass(frozen=True)
class PlanResult:
    """Outcome of one planner call.

    `plan` holds one lower-case ``"(action arg ...)"`` string per step (empty unless solved);
    `seconds` is wall-clock time of the call; `optimal` is True only when the backend proves the plan
    shortest, False when it is known not to, None when unknown.
    """

    status: PlanStatus
    plan: tuple[str, ...]
    seconds: float
    planner: str
    message: str = ""
    optimal: bool | None = None

    @property
    def solved(self) -> bool:
        return self.status is PlanStatus.SOLVED

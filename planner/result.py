"""The value every planner backend returns."""
from __future__ import annotations

from dataclasses import dataclass

from planhrc.vocabulary import PlanStatus as PlanStatus


@dataclass(frozen=True)
class PlannerAttempt:
    """One planner's try inside a fallback chain: its name, the status it answered, why, and how long it took."""

    planner: str
    status: PlanStatus
    message: str
    seconds: float


@dataclass(frozen=True)
class PlanResult:
    """Outcome of one planner call.

    `plan` holds one lower-case ``"(action arg ...)"`` string per step (empty unless solved);
    `seconds` is wall-clock time of the call; `optimal` is True only when the backend proves the plan
    shortest, False when it is known not to, None when unknown. `attempts` lists, in order, every planner a
    fallback chain tried (the last one produced this result); it is empty for a single planner's call.
    `validated` is True once VAL accepted `plan` against the domain and problem as given (the fallback chain's
    check, `planner.chain`); a single planner's answer, or the chain's with `validate=False`, is unvalidated.
    `checked_by` says which check gave the verdict (`planner.checking.CheckedBy`: VAL on the plan, or on its
    expansion into the actions its macros stand for; "" when none did) and `check_note` why that one.
    `warnings` are the domain's reading notes (`planner.pddl.Domain.warnings`).
    """

    status: PlanStatus
    plan: tuple[str, ...]
    seconds: float
    planner: str
    message: str = ""
    optimal: bool | None = None
    attempts: tuple[PlannerAttempt, ...] = ()
    validated: bool = False
    warnings: tuple[str, ...] = ()
    checked_by: str = ""
    check_note: str = ""

    @property
    def solved(self) -> bool:
        return self.status is PlanStatus.SOLVED

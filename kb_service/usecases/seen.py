"""The values a perception's steps hand on (`perception.perceive`): what it found before its write (`Seen`), which
every refinement step of its decision (`refine`) and its write (`turns`) take whole, and a re-plan as its write
stores it (`NewPlan`)."""
from __future__ import annotations

from dataclasses import dataclass

from planhrc.cooperation import PlanView
from planhrc.model import ArticulatedObject, Perception
from planhrc.pipeline import EarlyAnswer, PlanOutcome

from ..store import CheckedPlan, Execution, StoredPlan, StoredState
from .memory import ObjectMemo

Base = tuple[float, float] | None  # where a placed object's base point lies (None: an abstract object)


@dataclass(frozen=True, kw_only=True)
class Seen:
    """What a perception found under the object's lock, before its write: the object as perceived, where its
    cooperation stands (execution, goal, plan and the cooperation model's view of it, the event log's memo), where
    the checks place its base point, the planning deadline, and what the write keeps of the request."""

    obj: ArticulatedObject
    perception: Perception
    execution: Execution
    goal: StoredState | None
    plan: StoredPlan | None
    view: PlanView | None
    memo: ObjectMemo
    base: Base  # where the checks place a placed object's base point: as measured, else as last measured
    measured: tuple[float, float] | None  # the base point the perception measured
    deadline_at: float  # the planning deadline (`time.monotonic()`)
    key: str | None  # the request's idempotency key, and its fingerprint
    fingerprint: str
    mark: int  # where the object's log stood before anything was read (`unit_of_work.read_mark`)


@dataclass(frozen=True, kw_only=True)
class NewPlan:
    """A re-plan as its write stores it: the outcome as VAL checked it, the store's checks of its steps (None:
    nothing to check), and the pieces VAL checks behind the answer (None: VAL checked all it had to)."""

    outcome: PlanOutcome
    checks: CheckedPlan | None
    early: EarlyAnswer | None

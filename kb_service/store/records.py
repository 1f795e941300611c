"""Immutable records the knowledge base hands out. Atoms and states are those of `planhrc.model`."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Sequence

from planhrc.model import ActionSpec, Atom, CondEffect
from planhrc.vocabulary import ExecutionStatus

__all__ = ["STATE_KINDS", "ActionSpec", "CheckedPlan", "Compaction", "CondEffect", "Execution", "StoredAction",
           "StoredEvent", "StoredPlan", "StoredProblem", "StoredState"]

STATE_KINDS = ("perceived", "expected", "goal", "initial")


@dataclass(frozen=True)
class StoredState:
    id: str
    object_id: str
    kind: str
    atoms: frozenset[Atom]
    created_at: float
    link_orientations_deg: tuple[float, ...] | None = None  # perceived states: the raw observation


@dataclass(frozen=True)
class StoredProblem:
    id: str
    object_id: str
    init_state_id: str
    goal_state_id: str
    created_at: float


@dataclass(frozen=True)
class StoredAction:
    id: str
    step: int  # 1-based position in the plan
    spec: ActionSpec


@dataclass(frozen=True)
class StoredPlan:
    id: str
    object_id: str
    problem_id: str
    planner: str
    actions: tuple[StoredAction, ...]
    expected_state_ids: tuple[str, ...]  # s^e_1 .. s^e_{N+1}
    created_at: float


@dataclass(frozen=True)
class StoredEvent:
    seq: int
    object_id: str
    kind: str
    reason: str
    data: dict[str, Any] = field(default_factory=dict)
    created_at: float = 0.0
    client: str | None = None  # who caused it (`clients`); None: the service on its own (VAL's later verdicts)


@dataclass(frozen=True)
class Execution:
    """Where the cooperation model stands for one object."""

    plan_id: str | None
    next_step: int | None  # 1-based step of the next action to dispatch, None when no plan / done
    status: ExecutionStatus
    dispatched_action_id: str | None = None


@dataclass(frozen=True)
class CheckedPlan:
    """A plan's actions and expected states, checked against their object (`check_plan`) before its write: the
    write (`add_plan(..., checked=...)`) given these very tuples does not check them again, and takes its journal
    row's body from `journal_body` when there is one (made with the check, outside the store's lock). A check of the
    first steps only (`checked_steps`: their actions and the states up to s^e_(checked_steps+1)) leaves the later
    steps to the caller (`check_steps`, before each is used)."""

    object_id: str
    actions: tuple[ActionSpec, ...]
    expected_states: Sequence[frozenset[Atom]]  # a tuple, or the replay's `ExpectedStates` (made whole when read)
    journal_body: bytes | None = None
    checked_steps: int | None = None  # None: every step


@dataclass(frozen=True)
class Compaction:
    """What one compaction dropped."""

    objects: int
    individuals: int
    triples: int

"""Immutable records the knowledge base hands out. Atoms and states are those of `planhrc.model`."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from planhrc.model import Atom

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
class CondEffect:
    """A ground conditional effect: when `when` holds, delete `eff_neg` and add `eff_pos`."""

    when: frozenset[Atom]
    eff_neg: frozenset[Atom]
    eff_pos: frozenset[Atom]


@dataclass(frozen=True)
class ActionSpec:
    """A ground action to store: PDDL name, arguments, pre, eff-, eff+ and conditional effects."""

    name: str
    params: tuple[str, ...]
    pre: frozenset[Atom]
    eff_neg: frozenset[Atom]
    eff_pos: frozenset[Atom]
    cond_eff: tuple[CondEffect, ...] = ()


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


@dataclass(frozen=True)
class Execution:
    """Where the cooperation model stands for one object."""

    plan_id: str | None
    next_step: int | None  # 1-based step of the next action to dispatch, None when no plan / done
    status: str  # "idle" | "ready" | "dispatched" | "goal_reached" | "no_plan"
    dispatched_action_id: str | None = None

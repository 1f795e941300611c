"""The use cases' results, as frozen values (the HTTP layer maps them to its response models, `schemas`). The
results an idempotency key remembers (`Turn`, `FeedbackResult`) are kept as themselves (`json_record`)."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping

from planhrc.event_log import SkillRequest
from planhrc.json_record import JsonRecord
from planhrc.ordering import HelpItem
from planhrc.vocabulary import Accepted, DecisionKind

from ..store import Execution


@dataclass(frozen=True)
class NextAction:
    """The action to execute next and the motion it means (a macro step: `step` .. `last_step`)."""

    id: str
    name: str
    params: tuple[str, ...]
    step: int
    last_step: int
    plan_id: str
    joint_index: int
    turned_link_index: int
    held_link_index: int
    delta_deg: int
    macro_steps: int
    ends_plan: bool = False  # the plan's last motion: it comes to rest in the goal (judged as drawn)


@dataclass(frozen=True)
class Turn(JsonRecord):
    """What one perception decided: the decision, the plan followed after it, the next action (not yet
    dispatched), the expected state that matched, why in words, and what to ask the human or which links were
    not seen."""

    decision: DecisionKind
    plan_id: str | None
    perceived_state_id: str | None
    next_action: NextAction | None
    matched_expected_step: int | None
    reason: str
    help: tuple[HelpItem, ...] | None = None
    unseen_links: tuple[int, ...] | None = None
    skill: SkillRequest | None = None


@dataclass(frozen=True)
class GoalSet:
    goal_state_id: str
    problem_id: str | None
    warnings: tuple[str, ...]


@dataclass(frozen=True)
class FeedbackResult(JsonRecord):
    action_id: str
    accepted: Accepted
    execution: Execution


@dataclass(frozen=True)
class GaveUp:
    """A recorded give-up, and the help request it became (`decision` human_help_requested; None without a goal
    left to ask for)."""

    event_seq: int
    decision: DecisionKind | None = None
    reason: str = ""
    help: tuple[HelpItem, ...] = ()


# -- reads -------------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class LinkRead:
    name: str
    length_m: float


@dataclass(frozen=True, kw_only=True)
class ObjectRead:
    id: str
    name: str
    formulation: str
    orientations: int
    step_deg: int
    goal_state_id: str | None
    base_point_xy: tuple[float, float] | None
    links: tuple[LinkRead, ...]
    joints: tuple[str, ...]
    execution: Execution


@dataclass(frozen=True, kw_only=True)
class StateRead:
    id: str
    object_id: str
    atoms: tuple[str, ...]
    kind: str
    joint_values_deg: Mapping[str, int]
    link_orientations_deg: tuple[float, ...] | None
    created_at: float


@dataclass(frozen=True, kw_only=True)
class PlanStepRead:
    id: str
    step: int
    name: str
    params: tuple[str, ...]
    pre: tuple[str, ...]
    eff_neg: tuple[str, ...]
    eff_pos: tuple[str, ...]
    cond_eff: tuple[Mapping[str, tuple[str, ...]], ...]  # each: when, eff_neg, eff_pos
    joint_index: int
    turned_link_index: int
    held_link_index: int
    delta_deg: int


@dataclass(frozen=True, kw_only=True)
class PlanRead:
    id: str
    object_id: str
    problem_id: str
    planner: str
    steps: tuple[PlanStepRead, ...]
    created_at: float
    expected_state_ids: tuple[str, ...]
    expected_states: tuple[StateRead, ...]


@dataclass(frozen=True)
class Health:
    """Counts kept by the store's commits."""

    objects: int
    triples: int
    plans_to_write: int

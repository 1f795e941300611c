"""The use cases' results, as frozen values (the HTTP layer maps them to its response models, `schemas`), and the
JSON records of the results an idempotency key remembers (the same JSON as the response bodies)."""
from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum
from typing import Any, Mapping

from planhrc.ordering import HelpItem
from planhrc.vocabulary import DecisionKind, ExecutionStatus, Skill

from ..store import Execution



class Accepted(StrEnum):
    """How a feedback was taken."""

    CURRENT = "current"  # it moved the execution on
    LATE = "late"  # a perception had already moved the execution: it is only recorded


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
class Turn:
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
class SkillRequest:
    """A robot skill asked for (`DecisionKind.ROBOT_SKILL`): slide the object, its base point to `base_point_xy`,
    holding links `links`; why in words."""

    name: Skill
    base_point_xy: tuple[float, float]
    links: tuple[int, ...]
    sentence: str


@dataclass(frozen=True)
class GoalSet:
    goal_state_id: str
    problem_id: str | None
    warnings: tuple[str, ...]


@dataclass(frozen=True)
class FeedbackResult:
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


@dataclass(frozen=True)
class ObjectRead:
    id: str
    name: str
    formulation: str
    orientations: int
    step_deg: int
    links: tuple[LinkRead, ...]
    joints: tuple[str, ...]
    goal_state_id: str | None
    base_point_xy: tuple[float, float] | None
    execution: Execution


@dataclass(frozen=True)
class StateRead:
    id: str
    object_id: str
    kind: str
    atoms: tuple[str, ...]
    joint_values_deg: Mapping[str, int]
    link_orientations_deg: tuple[float, ...] | None
    created_at: float


@dataclass(frozen=True)
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


@dataclass(frozen=True)
class PlanRead:
    id: str
    object_id: str
    problem_id: str
    planner: str
    steps: tuple[PlanStepRead, ...]
    expected_state_ids: tuple[str, ...]
    expected_states: tuple[StateRead, ...]
    created_at: float


@dataclass(frozen=True)
class EventRead:
    seq: int
    object_id: str
    kind: str
    reason: str
    data: Mapping[str, Any]
    created_at: float
    client: str | None = None


@dataclass(frozen=True)
class Health:
    """Counts kept by the store's commits."""

    objects: int
    triples: int
    plans_to_write: int


# -- the records an idempotency key remembers ----------------------------------------------------------------------
def turn_record(turn: Turn) -> dict[str, Any]:
    action = turn.next_action
    return {"decision": turn.decision, "plan_id": turn.plan_id, "perceived_state_id": turn.perceived_state_id,
            "next_action": {**vars(action), "params": list(action.params)} if action is not None else None,
            "matched_expected_step": turn.matched_expected_step, "reason": turn.reason,
            "help": [dict(vars(h)) for h in turn.help] if turn.help is not None else None,
            "unseen_links": list(turn.unseen_links) if turn.unseen_links is not None else None,
            "skill": skill_record(turn.skill) if turn.skill is not None else None}


def skill_record(skill: SkillRequest) -> dict[str, Any]:
    return {"name": skill.name, "base_point_xy": list(skill.base_point_xy), "links": list(skill.links),
            "sentence": skill.sentence}


def turn_of(record: Mapping[str, Any]) -> Turn:
    action, help_items, unseen = record["next_action"], record.get("help"), record.get("unseen_links")
    skill = record.get("skill")
    return Turn(DecisionKind(record["decision"]), record["plan_id"], record["perceived_state_id"],
                NextAction(**{**action, "params": tuple(action["params"])}) if action is not None else None,
                record["matched_expected_step"], record["reason"],
                tuple(HelpItem(**h) for h in help_items) if help_items is not None else None,
                tuple(unseen) if unseen is not None else None,
                SkillRequest(Skill(skill["name"]), (float(skill["base_point_xy"][0]), float(skill["base_point_xy"][1])),
                             tuple(int(k) for k in skill["links"]), str(skill["sentence"]))
                if skill is not None else None)


def execution_record(execution: Execution) -> dict[str, Any]:
    return {"plan_id": execution.plan_id, "next_step": execution.next_step, "status": execution.status,
            "dispatched_action_id": execution.dispatched_action_id}


def feedback_record(result: FeedbackResult) -> dict[str, Any]:
    return {"action_id": result.action_id, "accepted": result.accepted,
            "execution": execution_record(result.execution)}


def feedback_of(record: Mapping[str, Any]) -> FeedbackResult:
    e = record["execution"]
    return FeedbackResult(record["action_id"], Accepted(record["accepted"]),
                          Execution(e["plan_id"], e["next_step"], ExecutionStatus(e["status"]),
                                    e["dispatched_action_id"]))

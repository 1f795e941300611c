"""Records of the knowledge base as the JSON bodies of the service's responses (the schemas in `schemas`)."""
from __future__ import annotations

from typing import Any, Iterable

from planhrc.model import HAS_ORIENTATION, ArticulatedObject, Atom, format_atom
from planhrc.pipeline import action_motion

from .store import Execution, StoredEvent, StoredPlan, StoredProblem, StoredState


def execution_public(execution: Execution) -> dict[str, Any]:
    return {"plan_id": execution.plan_id, "next_step": execution.next_step, "status": execution.status,
            "dispatched_action_id": execution.dispatched_action_id}


def object_public(obj: ArticulatedObject, execution: Execution, goal_state_id: str | None,
                  base_point_xy: tuple[float, float] | None = None) -> dict[str, Any]:
    return {
        "id": obj.ident, "name": obj.name, "formulation": obj.formulation.value, "orientations": obj.orientations,
        "step_deg": obj.step,
        "links": [{"name": name, "length_m": length} for name, length in zip(obj.links, obj.link_lengths_m)],
        "joints": list(obj.joints), "goal_state_id": goal_state_id,
        "base_point_xy": list(base_point_xy) if base_point_xy is not None else None,
        "execution": execution_public(execution),
    }


def atoms_public(atoms: Iterable[Atom]) -> list[str]:
    return [format_atom(a) for a in sorted(atoms)]


def state_public(state: StoredState) -> dict[str, Any]:
    joints = {a[2]: int(a[1].split("_", 1)[1]) for a in state.atoms if a[0] == HAS_ORIENTATION and len(a) == 3}
    return {"id": state.id, "object_id": state.object_id, "kind": state.kind, "atoms": atoms_public(state.atoms),
            "joint_values_deg": dict(sorted(joints.items())),
            "link_orientations_deg": list(state.link_orientations_deg) if state.link_orientations_deg else None,
            "created_at": state.created_at}


def problem_public(problem: StoredProblem) -> dict[str, Any]:
    return {"id": problem.id, "object_id": problem.object_id, "init_state_id": problem.init_state_id,
            "goal_state_id": problem.goal_state_id, "created_at": problem.created_at}


def plan_public(obj: ArticulatedObject, plan: StoredPlan, expected: Iterable[StoredState]) -> dict[str, Any]:
    steps = []
    for a in sorted(plan.actions, key=lambda a: a.step):
        motion = action_motion(obj, a)
        steps.append({
            "id": a.id, "step": a.step, "name": a.spec.name, "params": list(a.spec.params),
            "pre": atoms_public(a.spec.pre), "eff_neg": atoms_public(a.spec.eff_neg),
            "eff_pos": atoms_public(a.spec.eff_pos),
            "cond_eff": [{"when": atoms_public(c.when), "eff_neg": atoms_public(c.eff_neg),
                          "eff_pos": atoms_public(c.eff_pos)} for c in a.spec.cond_eff],
            **{key: motion[key] for key in ("joint_index", "turned_link_index", "held_link_index", "delta_deg")},
        })
    return {"id": plan.id, "object_id": plan.object_id, "problem_id": plan.problem_id, "planner": plan.planner,
            "steps": steps, "expected_state_ids": list(plan.expected_state_ids),
            "expected_states": [state_public(s) for s in expected], "created_at": plan.created_at}


def event_public(event: StoredEvent) -> dict[str, Any]:
    return {"seq": event.seq, "object_id": event.object_id, "kind": event.kind, "reason": event.reason,
            "data": dict(event.data), "created_at": event.created_at}

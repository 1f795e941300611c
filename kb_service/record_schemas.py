"""Response bodies of the stored records (states, problems, plans, events), the service's health and its errors.
Every schema and every field has a description and examples, as in `schemas` (the request bodies and decisions).
"""
from __future__ import annotations

from typing import Any, Literal

from pydantic import BaseModel, Field

from .schemas import schema_config


class StatePublic(BaseModel):
    model_config = schema_config(
        "A stored State: its ground atoms (PDDL syntax) and, for perceived states, the raw observation.",
        {"id": "obj1_state_2", "object_id": "obj1", "kind": "perceived", "atoms": ["(hasorientation deg_90 obj1_j1)"],
         "joint_values_deg": {"obj1_j1": 90}, "link_orientations_deg": [1.7, 88.9], "created_at": 1.7e9},
    )

    id: str = Field(description="Identifier of the state.", examples=["obj1_state_2"])
    object_id: str = Field(description="Object the state describes.", examples=["obj1"])
    kind: str = Field(description="perceived, expected, goal or initial.", examples=["perceived"])
    atoms: list[str] = Field(description="Ground atoms, sorted.", examples=[["(hasorientation deg_90 obj1_j1)"]])
    joint_values_deg: dict[str, int] = Field(description="Orientation carried by each joint the state mentions.",
                                             examples=[{"obj1_j1": 90}])
    link_orientations_deg: list[float] | None = Field(description="Raw observed link orientations (perceived).",
                                                      examples=[[1.7, 88.9]])
    created_at: float = Field(description="Unix time of storage.", examples=[1.7e9])


class ProblemPublic(BaseModel):
    model_config = schema_config(
        "A stored Problem: from an initial state to a goal state.",
        {"id": "obj1_problem_1", "object_id": "obj1", "init_state_id": "obj1_state_2", "goal_state_id": "obj1_state_1", "created_at": 1.7e9},
    )

    id: str = Field(description="Identifier of the problem.", examples=["obj1_problem_1"])
    object_id: str = Field(description="Object of the problem.", examples=["obj1"])
    init_state_id: str = Field(description="Initial State.", examples=["obj1_state_2"])
    goal_state_id: str = Field(description="Goal State.", examples=["obj1_state_1"])
    created_at: float = Field(description="Unix time of storage.", examples=[1.7e9])


class PlanStepPublic(BaseModel):
    model_config = schema_config(
        "One action of a plan with its ground preconditions and effects.",
        {"id": "obj1_plan_1_a1", "step": 1, "name": "rotateclockwise",
         "params": ["obj1_l2", "obj1_l1", "obj1_j1", "deg_0", "deg_90"],
         "pre": ["(hasorientation deg_0 obj1_j1)"], "eff_neg": ["(hasorientation deg_0 obj1_j1)"],
         "eff_pos": ["(hasorientation deg_90 obj1_j1)"], "cond_eff": [], "joint_index": 1, "turned_link_index": 2,
         "held_link_index": 1, "delta_deg": 90},
    )

    id: str = Field(description="Identifier of the action.", examples=["obj1_plan_1_a1"])
    step: int = Field(description="1-based position in the plan.", examples=[1])
    name: str = Field(description="PDDL action name.", examples=["rotateclockwise"])
    params: list[str] = Field(description="PDDL arguments.", examples=[["obj1_l2", "obj1_l1", "obj1_j1", "deg_0", "deg_90"]])
    pre: list[str] = Field(description="Ground preconditions.", examples=[["(hasorientation deg_0 obj1_j1)"]])
    eff_neg: list[str] = Field(description="Ground negative effects.", examples=[["(hasorientation deg_0 obj1_j1)"]])
    eff_pos: list[str] = Field(description="Ground positive effects.", examples=[["(hasorientation deg_90 obj1_j1)"]])
    cond_eff: list[dict[str, list[str]]] = Field(
        description="Ground conditional effects (absolute and bimanual formulations): when, eff_neg, eff_pos.",
        examples=[[{"when": ["(hasorientation deg_0 obj1_j2)"], "eff_neg": ["(hasorientation deg_0 obj1_j2)"],
                    "eff_pos": ["(hasorientation deg_90 obj1_j2)"]}]])
    joint_index: int = Field(description="K of the joint jK rotated about.", examples=[1])
    turned_link_index: int = Field(description="Index of the link that turns (with every link beyond it).", examples=[2])
    held_link_index: int = Field(description="Index of the link held still (0 = the table).", examples=[1])
    delta_deg: int = Field(description="Signed rotation of the turned link, + clockwise seen from above.", examples=[90])


class PlanPublic(BaseModel):
    model_config = schema_config(
        "A stored plan: its actions a_1..a_N and expected states s^e_1..s^e_{N+1}.",
        {"id": "obj1_plan_1", "object_id": "obj1", "problem_id": "obj1_problem_1", "planner": "inproc", "steps": [],
         "expected_state_ids": ["obj1_state_3"], "expected_states": [], "created_at": 1.7e9},
    )

    id: str = Field(description="Identifier of the plan.", examples=["obj1_plan_1"])
    object_id: str = Field(description="Object of the plan.", examples=["obj1"])
    problem_id: str = Field(description="Problem the plan solves.", examples=["obj1_problem_1"])
    planner: str = Field(description="Planner that found it.", examples=["inproc"])
    steps: list[PlanStepPublic] = Field(description="Actions in order.", examples=[[]])
    expected_state_ids: list[str] = Field(description="Ids of s^e_1..s^e_{N+1}.", examples=[["obj1_state_3", "obj1_state_4"]])
    expected_states: list[StatePublic] = Field(description="The expected states themselves.", examples=[[]])
    created_at: float = Field(description="Unix time of storage.", examples=[1.7e9])


class EventPublic(BaseModel):
    model_config = schema_config(
        "One entry of an object's log: a decision with its reason, a goal, a dispatch or a feedback.",
        {"seq": 4, "object_id": "obj1", "kind": "continue", "reason": "the perceived state is subsumed by s^e_2",
         "data": {"perceived_state_id": "obj1_state_2", "next_step": 2}, "created_at": 1.7e9, "client": "baxter-1"},
    )

    seq: int = Field(description="Position in the log (increasing).", examples=[4])
    object_id: str = Field(description="Object the event is about.", examples=["obj1"])
    kind: str = Field(description="A decision kind (goal_reached, continue, resume, replan, no_plan, "
                      "human_help_requested, incomplete_perception), or goal_set, dispatched, feedback, "
                      "worker_gave_up, object_created, val_verdict (VAL's verdict on a piece of a plan checked "
                      "after the answer), dispatch_withheld (a step not dispatched: VAL refused or has not decided "
                      "on its piece).",
                      examples=["continue"])
    reason: str = Field(description="Why, in words.", examples=["the perceived state is subsumed by s^e_2"])
    data: dict[str, Any] = Field(description="Ids and numbers of the event.", examples=[{"next_step": 2}])
    created_at: float = Field(description="Unix time of storage.", examples=[1.7e9])
    client: str | None = Field(default=None, description="The client (API key's name) whose request caused the "
                               "event; `token` for the --token shortcut; null when no key was needed or the service "
                               "wrote it on its own (VAL's verdicts checked after the answer).",
                               examples=["baxter-1"])


class HealthPublic(BaseModel):
    model_config = schema_config(
        "Liveness of the service and size of its knowledge base.",
        {"status": "ok", "version": "0.1.0", "objects": 2, "triples": 1520, "plans_to_write": 0, "auth": False},
    )

    status: Literal["ok"] = Field(description="Always ok when the service answers.", examples=["ok"])
    version: str = Field(description="planhrc version.", examples=["0.1.0"])
    objects: int = Field(description="Number of stored objects.", examples=[2])
    triples: int = Field(description="Number of triples in the ABox (written ones: see plans_to_write).",
                         examples=[1520])
    plans_to_write: int = Field(
        description="Plans stored as their journal rows whose triples are not written yet: they are written when "
        "something reads the triples (the RDF export, SPARQL, a reasoner, compaction), and compaction drops those "
        "of plans it does not keep unwritten. The service answers for them from their rows; their triples are not "
        "in `triples` until then.", examples=[0])
    auth: bool = Field(description="Whether writes need a bearer token.", examples=[False])


class ErrorPublic(BaseModel):
    model_config = schema_config(
        "Every error the service sends (400, 401, 404, 409, 410, 413, 422), as JSON whatever the route's own media "
        "type: one message that names the offending field.",
        {"detail": "link_orientations_deg: expected 4 values (one per link), got 3"},
    )

    detail: str = Field(description="What was wrong, naming the field.",
                        examples=["link_orientations_deg: expected 4 values (one per link), got 3"])


class LivePublic(BaseModel):
    model_config = schema_config("The process answers.", {"status": "alive", "version": "0.1.0"})

    status: Literal["alive"] = Field(description="Always `alive`: an answer at all is the news.")
    version: str = Field(description="The planhrc version serving.")


class ReadyPublic(BaseModel):
    model_config = schema_config(
        "Whether the service may take traffic, and each check's result.",
        {"status": "ready", "version": "0.1.0", "checks": {"store": "ok", "tbox": "ok", "planning": "ok"}})

    status: Literal["ready", "not ready"] = Field(description="`ready` when every check is `ok`.")
    version: str = Field(description="The planhrc version serving.")
    checks: dict[str, str] = Field(description="`store` (its database answers), `tbox` (loaded), `planning` (the "
                                   "planning pool is open or the planning queue's database answers): `ok`, or why "
                                   "not.")

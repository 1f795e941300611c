"""Response bodies of the stored records (states, problems, plans, events), the service's health and its errors.
Every schema and every field has a description and examples, as in `schemas` (the request bodies and decisions).
"""
from __future__ import annotations

from typing import Annotated, Any, Literal, Union

from pydantic import BaseModel, Field

from planhrc.event_log import (DATA, DecisionData, DispatchData, EventData, FeedbackData, GaveUpData, GoalSetData,
                               IncompleteData, ObjectCreatedData, ValVerdictData)
from planhrc.model import Formulation
from planhrc.vocabulary import Accepted, ActionOutcome, PlanningStatus

from .schemas import schema_config
from .usecases.log import EventRead


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


class EventFields(BaseModel):
    """What every event of an object's log holds; each kind's `kind` and `data` are its variant's (`EventPublic`)."""

    seq: int = Field(description="Position in the log (increasing).", examples=[4])
    object_id: str = Field(description="Object the event is about.", examples=["obj1"])
    kind: str = Field(description="The event's kind.", examples=["continue"])
    reason: str = Field(description="Why, in words.", examples=["the perceived state is subsumed by s^e_2"])
    data: Any = Field(description="The kind's record.")
    created_at: float = Field(description="Unix time of storage.", examples=[1.7e9])
    client: str | None = Field(default=None, description="The client (API key's name) whose request caused the "
                               "event; `token` for the --token shortcut; null when no key was needed or the service "
                               "wrote it on its own (VAL's verdicts checked after the answer).",
                               examples=["baxter-1"])


# One example of each record, and the kind and reason it comes with.
_EXAMPLES: dict[type[EventData], tuple[str, str, EventData]] = {
    ObjectCreatedData: ("object_created", "object obj1 created",
                        ObjectCreatedData(formulation=Formulation.RELATIVE, links=5, orientations=8, base_point_xy=(0.6, 0.39))),
    GoalSetData: ("goal_set", "goal set; the next perception plans towards it",
                  GoalSetData(goal_state_id="obj1_state_1", problem_id=None)),
    DecisionData: ("replan", "the perceived state matches no expected state; new plan obj1_plan_1 of 2 actions",
                   DecisionData(perceived_state_id="obj1_state_2", plan_id="obj1_plan_1", next_step=1,
                                next_action_id="obj1_plan_1_a1", goal_state_id="obj1_state_1",
                                planning_status=PlanningStatus.SOLVED, problem_id="obj1_problem_1",
                                timings={"plan": 0.012, "validate": 0.004})),
    IncompleteData: ("incomplete_perception", "links 3 and 5 were not seen: look again",
                     IncompleteData(unseen_links=(3, 5), link_orientations_deg=(90.0, 90.0, None, 90.0, None))),
    DispatchData: ("dispatched", "a_1 (rotateclockwise) dispatched",
                   DispatchData(plan_id="obj1_plan_1", action_id="obj1_plan_1_a1", step=1)),
    FeedbackData: ("feedback", "a_1 succeeded: the next perception checks s^e_2",
                   FeedbackData(action_id="obj1_plan_1_a1", step=1, outcome=ActionOutcome.SUCCEEDED,
                                accepted=Accepted.CURRENT, joint_index=4, turned_link_index=5)),
    GaveUpData: ("worker_gave_up", "the worker gave up (repeated_failure): a_1 failed three times",
                 GaveUpData(reason="repeated_failure", message="a_1 failed three times", plan_id="obj1_plan_1")),
    ValVerdictData: ("val_verdict", "VAL accepted piece 3 of plan obj1_plan_1: a_5..a_18",
                     ValVerdictData(plan_id="obj1_plan_1", piece=3, first_step=5, last_step=18, verdict="accepted",
                                    reason="Plan valid", seconds=0.21)),
}


def _event_model(record: type[EventData], kinds: tuple[str, ...]) -> type[EventFields]:
    """The variant of `EventPublic` whose data is `record`, for `kinds`."""
    kind, reason, data = _EXAMPLES[record]
    name = record.__name__.removesuffix("Data") + "EventPublic"
    description = f"An event of kind {', '.join(kinds)}: {(record.__doc__ or '').strip()}"
    example = {"seq": 4, "object_id": "obj1", "kind": kind, "reason": reason, "data": data.to_data(defaults=True),
               "created_at": 1.7e9, "client": "baxter-1"}
    namespace = {
        "__module__": __name__, "__doc__": description,
        "__annotations__": {"kind": Literal[kinds], "data": record},
        "model_config": schema_config(description, example),
        "kind": Field(description=f"{' or '.join(kinds)}.", examples=[kind]),
        "data": Field(description=f"The event's record: {(record.__doc__ or '').strip()}", examples=[example["data"]]),
    }
    return type(name, (EventFields,), namespace)


def _event_models() -> dict[type[EventData], type[EventFields]]:
    kinds: dict[type[EventData], list[str]] = {}
    for kind, record in DATA.items():
        kinds.setdefault(record, []).append(str(kind))
    return {record: _event_model(record, tuple(names)) for record, names in kinds.items()}


EVENT_MODELS = _event_models()  # record -> its variant of EventPublic
# An event of the log, one schema per record (its `kind` tells which): what GET /objects/{id}/events lists and the
# Server-Sent Events stream sends.
EventPublic: Any = Annotated[Union[tuple(EVENT_MODELS.values())], Field(discriminator="kind")]


def event_public(event: EventRead) -> EventFields:
    """An event as the API shows it: the variant of its data's record."""
    return EVENT_MODELS[type(event.data)].model_validate(event, from_attributes=True)


def event_stream_schema() -> dict[str, Any]:
    """The schema of one Server-Sent Event of the stream: `id` the event's seq, `event` its kind, `data` the event as
    JSON, one of the variants of `EventPublic` (by reference)."""
    refs = {record: f"#/components/schemas/{model.__name__}" for record, model in EVENT_MODELS.items()}
    event = {"oneOf": [{"$ref": ref} for ref in refs.values()],
             "discriminator": {"propertyName": "kind",
                               "mapping": {str(kind): refs[record] for kind, record in DATA.items()}}}
    return {"type": "object", "required": ["id", "event", "data"], "properties": {
        "id": {"type": "string", "description": "The event's `seq` (send it back as `Last-Event-ID`).",
               "examples": ["4"]},
        "event": {"type": "string", "description": "The event's `kind`.", "examples": ["continue"]},
        "data": {"type": "string", "contentMediaType": "application/json", "contentSchema": event,
                 "description": "The event as `GET /objects/{object_id}/events` lists it."}}}


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

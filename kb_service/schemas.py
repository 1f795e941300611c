"""Request bodies of the service and the decisions it answers with (the stored records' bodies: `record_schemas`).

A request schema states every rule about the request itself, so that a body the schema accepts is accepted and
one it refuses is refused (the contract test checks both): counts of orientations that divide 360, the two forms
of a goal, a reason only for a failure, printable names. What depends on the stored object (one value per link,
its allowed orientations, where it lies) or on the service's settings (the largest planning task) is checked by
the service and refused with a 422 naming the field.

Floats in requests refuse NaN and ±Infinity (the JSON parser accepts the `NaN`/`Infinity` tokens; pydantic
then rejects them with the field's name), so a malformed perception never reaches the knowledge base. Integers
are JSON integers: `4` or `4.0` (JSON Schema's integer), never `"4"` or `true`.
"""
from __future__ import annotations

import math
import re
from typing import Annotated, Any, Literal

from pydantic import AfterValidator, BaseModel, BeforeValidator, ConfigDict, Field, field_validator, model_validator

from planhrc.model import Formulation
from planhrc.vocabulary import ActionOutcome, DecisionKind, ExecutionStatus, FailureReason, Infeasible, Skill

# strict: a JSON number, as documented (pydantic's lax mode took `false` for 0.0 and "1.5" for 1.5)
FiniteFloat = Annotated[float, Field(strict=True, allow_inf_nan=False)]
TableCoordinate = Annotated[float, Field(strict=True, allow_inf_nan=False, ge=-10.0, le=10.0)]  # metres from the robot
# strict: a JSON integer, as documented (lax mode took "4" and true); integral floats are made ints before it
JsonInt = Annotated[int, Field(strict=True)]
MIN_LINKS, MAX_LINKS = 2, 200  # one bound for both forms of ObjectCreate.links, and for every list of link values
SQLITE_MAX_INT = 2**63 - 1  # the largest integer the store (SQLite INTEGER) can hold: the bound of every count and seq
ORIENTATION_COUNTS = tuple(k for k in range(2, 361) if 360 % k == 0)  # the K that planhrc.model accepts

# What a name may not hold, as one character class that reads the same in Python, in ECMA-262 (the schema's
# `pattern`) and in Rust: control characters (C0, DEL, C1), the line and paragraph separators, invisible
# formatting (soft hyphen, zero-width and direction marks and overrides, word joiners, the byte order mark,
# interlinear annotation) and the non-characters U+FFFE and U+FFFF. So every output (log line, console, RDF/XML
# export) shows a name as it was sent.
NOT_PRINTABLE = r"\x00-\x1f\x7f-\x9f\u00ad\u200b-\u200f\u2028-\u202e\u2060-\u206f\ufeff\ufff9-\ufffb\ufffe\uffff"
PRINTABLE_PATTERN = f"^[^{NOT_PRINTABLE}]*$"
_NOT_PRINTABLE = re.compile(f"[{NOT_PRINTABLE}]")


def _printable(value: str) -> str:
    bad = _NOT_PRINTABLE.search(value)
    if bad:
        raise ValueError(f"must be printable characters only, got {bad.group()!r}")
    return value


PrintableName = Annotated[str, AfterValidator(_printable), Field(json_schema_extra={"pattern": PRINTABLE_PATTERN})]


def _integral(value: Any) -> Any:
    """4.0 is the JSON integer 4 (JSON Schema's `integer` counts it), so it is taken as 4; 4.5 stays a float
    for the strict check to refuse."""
    return int(value) if isinstance(value, float) and value.is_integer() else value


def _query_integral(value: Any) -> Any:
    """A query parameter's integer as a JSON Schema `integer` may be written: `12`, `12.0` or `1.2e1` (a client
    that serialises numbers as floats writes large ones with an exponent); anything else is left for the integer
    check to refuse."""
    if isinstance(value, str):
        try:
            return int(value)
        except ValueError:
            try:
                number = float(value)
            except ValueError:
                return value
            return int(number) if math.isfinite(number) and number.is_integer() else value
    return value


QUERY_INTEGRAL = BeforeValidator(_query_integral)  # after a query parameter's Query(...) in its Annotated[int, ...]


def _orientation_count(k: int) -> int:
    if k not in ORIENTATION_COUNTS:
        raise ValueError(f"360 must be divisible by K and K >= 2, got {k}")
    return k


def schema_config(description: str, example: dict[str, Any], rules: dict[str, Any] | None = None) -> ConfigDict:
    """A model's description, example and `rules`: JSON Schema keywords over several fields (`oneOf`, `if`...)
    that the model's own validator enforces."""
    return ConfigDict(json_schema_extra={"description": description, "examples": [example], **(rules or {})},
                      extra="forbid")


# -- objects ------------------------------------------------------------------------------------------------
class LinkSpec(BaseModel):
    model_config = schema_config("One link of an articulated object.", {"name": "l1", "length_m": 0.155})

    name: PrintableName = Field(min_length=1, max_length=64, description="Name of the link (informative).",
                                examples=["l1"])
    length_m: FiniteFloat = Field(gt=0, description="Length of the link in metres.", examples=[0.155])


class ObjectCreate(BaseModel):
    model_config = schema_config(
        "An articulated object to create: a chain of links, its orientation set and its formulation.",
        {"name": "rod", "links": 4, "orientations": 4, "formulation": "relative"},
    )

    name: PrintableName = Field(default="", max_length=200, description="Human-readable name (printable characters).",
                                examples=["rod"])
    links: Annotated[JsonInt, Field(ge=MIN_LINKS, le=MAX_LINKS)] | Annotated[
        list[LinkSpec], Field(min_length=MIN_LINKS, max_length=MAX_LINKS)
    ] = Field(
        description="Number of links (each 0.155 m long), or the list of links in chain order. Links x "
        "orientations may not exceed the service's largest planning task (setting max_task_size, "
        "PLANHRC_MAX_TASK_SIZE: 14400 by default); a larger object is refused with 422.",
        examples=[4, [{"name": "l1", "length_m": 0.155}, {"name": "l2", "length_m": 0.2}]],
    )
    orientations: Annotated[JsonInt, AfterValidator(_orientation_count)] = Field(
        description="K, the number of allowed orientations: 360 must be divisible by K.", examples=[4, 8],
        json_schema_extra={"enum": list(ORIENTATION_COUNTS)},
    )
    formulation: Formulation = Field(
        description="Planning formulation: joints carry relative angles (relative), absolute link orientations "
        "(absolute), or each link's orientation from link 1 with two grippers turning one joint at a time at the "
        "centre, grasping and releasing the links it joins (bimanual).",
        examples=["relative"],
    )
    base_point_xy: list[TableCoordinate] | None = Field(
        default=None, min_length=2, max_length=2,
        description="Where the object's base point p1 lies on the table, [x, y] in metres in the robot's frame "
        "(+x forward, +y left; the simulated cell's default is [0.6, 0.39]). An object given a base point is "
        "placed in the cell: its goals and every planned configuration are checked against the table, the robot's "
        "body and reach. Without it the object is abstract (no geometric checks).",
        examples=[[0.6, 0.39]],
    )

    @field_validator("links", "orientations", mode="before")
    @classmethod
    def _json_integer(cls, value: Any) -> Any:
        return _integral(value)


class LinkPublic(BaseModel):
    model_config = schema_config("A link as stored: its PDDL name and length.", {"name": "obj1_l1", "length_m": 0.155})

    name: str = Field(description="Name of the link in the ontology and in PDDL.", examples=["obj1_l1"])
    length_m: float = Field(description="Length of the link in metres.", examples=[0.155])


class ExecutionPublic(BaseModel):
    model_config = schema_config(
        "Where the cooperation model stands for one object.",
        {"plan_id": "obj1_plan_1", "next_step": 2, "status": "dispatched", "dispatched_action_id": "obj1_plan_1_a2"},
    )

    plan_id: str | None = Field(description="Plan being followed, if any.", examples=["obj1_plan_1"])
    next_step: int | None = Field(description="1-based step of the next action to execute.", examples=[2])
    status: ExecutionStatus = Field(
        description="idle, ready, dispatched, goal_reached or no_plan.", examples=["ready", "dispatched"]
    )
    dispatched_action_id: str | None = Field(
        description="Action handed to a worker whose feedback is still accepted.", examples=["obj1_plan_1_a2"]
    )


class ObjectPublic(BaseModel):
    model_config = schema_config(
        "An articulated object as stored in the knowledge base.",
        {
            "id": "obj1", "name": "rod", "formulation": "relative", "orientations": 4, "step_deg": 90,
            "links": [{"name": "obj1_l1", "length_m": 0.155}, {"name": "obj1_l2", "length_m": 0.155}],
            "joints": ["obj1_j1"], "goal_state_id": None, "base_point_xy": [0.6, 0.39],
            "execution": {"plan_id": None, "next_step": None, "status": "idle", "dispatched_action_id": None},
        },
    )

    id: str = Field(description="Identifier of the object (also the prefix of its individuals).", examples=["obj1"])
    name: str = Field(description="Human-readable name.", examples=["rod"])
    formulation: Formulation = Field(description="relative, absolute or bimanual.", examples=["relative"])
    orientations: int = Field(description="K, the number of allowed orientations.", examples=[4])
    step_deg: int = Field(description="360 / K: the angle of one planned rotation.", examples=[90])
    links: list[LinkPublic] = Field(description="Links l1..lN in chain order.", examples=[[{"name": "obj1_l1", "length_m": 0.155}]])
    joints: list[str] = Field(description="Joints that carry orientations, in order.", examples=[["obj1_j1"]])
    goal_state_id: str | None = Field(description="Current goal state, if one was set.", examples=["obj1_state_1"])
    base_point_xy: list[float] | None = Field(
        description="The object's base point p1 on the table, [x, y] in metres; null for an abstract object (no "
        "geometric checks).", examples=[[0.6, 0.39], None])
    execution: ExecutionPublic = Field(
        description="Execution state of the cooperation model.",
        examples=[{"plan_id": None, "next_step": None, "status": "idle", "dispatched_action_id": None}],
    )


# -- goals and perceptions --------------------------------------------------------------------------------
def _only(given: str, absent: str) -> dict[str, Any]:
    """The JSON Schema of a body that gives `given` (a list) and leaves `absent` out or null."""
    return {"required": [given], "properties": {given: {"type": "array"}, absent: {"type": "null"}}}


class GoalUpdate(BaseModel):
    model_config = schema_config(
        "A goal configuration: either every link's orientation, or one angle per joint (null = any). Exactly "
        "one of the two is given (the other is left out or null).",
        {"link_orientations_deg": [0, 90, 90, 180]},
        {"oneOf": [_only("link_orientations_deg", "joint_angles_deg"),
                   _only("joint_angles_deg", "link_orientations_deg")]},
    )

    link_orientations_deg: list[FiniteFloat] | None = Field(
        default=None, min_length=MIN_LINKS, max_length=MAX_LINKS,
        description="Absolute orientation of every link l1..lN, in degrees clockwise; each must be an allowed "
        "orientation. Relative objects use only the differences. Every link has one (unlike a perception, no "
        "null).",
        examples=[[0, 90, 90, 180]],
    )
    joint_angles_deg: list[FiniteFloat | None] | None = Field(
        default=None, min_length=MIN_LINKS - 1, max_length=MAX_LINKS,
        description="One value per joint: the N-1 relative angles (relative formulation), the N link "
        "orientations (absolute formulation) or the orientations of links 2..N from link 1 (bimanual); null leaves "
        "that joint free (a partial goal), but at least one joint has a value.",
        examples=[[90, 0, 90], [90, None, 90]],
        json_schema_extra={"contains": {"type": "number"}},  # at least one joint has a value
    )
    allow_infeasible: bool = Field(
        default=False, strict=True,  # true or false, as documented (lax mode took 0 and "yes")
        description="Accept a goal configuration that does not lie on the table (off the table, inside the "
        "robot, folded onto itself); without it such a goal is refused with 422 naming the links.",
        examples=[False],
    )

    @model_validator(mode="after")
    def _exactly_one(self) -> "GoalUpdate":
        if (self.link_orientations_deg is None) == (self.joint_angles_deg is None):
            raise ValueError("link_orientations_deg, joint_angles_deg: give exactly one of them")
        return self


class GoalPublic(BaseModel):
    model_config = schema_config(
        "The stored goal and, when a perceived state already exists, the problem from it to the goal.",
        {"goal_state_id": "obj1_state_1", "problem_id": "obj1_problem_1"},
    )

    goal_state_id: str = Field(description="The stored goal State.", examples=["obj1_state_1"])
    problem_id: str | None = Field(
        description="Problem (latest perceived state -> goal); null until the first perception arrives.",
        examples=["obj1_problem_1", None],
    )
    warnings: list[str] = Field(
        default_factory=list,
        description="What the service noticed about a goal it accepted: links whose grasp point is beyond the "
        "robot's reach in the goal configuration (the robot will ask the human for them), or an infeasible goal "
        "accepted with allow_infeasible.",
        examples=[["goal: link 5 unreachable: 0.08 m beyond reach"]],
    )


class PerceptionCreate(BaseModel):
    model_config = schema_config(
        "A perceived configuration: the measured orientation of every link, noisy real values; null for a link "
        "the camera did not see.",
        {"link_orientations_deg": [1.7, 88.9, 91.2, 179.4]},
    )

    link_orientations_deg: list[FiniteFloat | None] = Field(
        min_length=MIN_LINKS, max_length=MAX_LINKS,
        description="Measured absolute orientation of every link l1..lN, in degrees clockwise seen from above; "
        "snapped to the nearest allowed orientation. null = the link was not seen: such a perception changes "
        "nothing and is answered with the decision incomplete_perception; at least one link must be seen.",
        examples=[[1.7, 88.9, 91.2, 179.4], [1.7, None, 91.2, 179.4]],
        json_schema_extra={"contains": {"type": "number"}},  # at least one link seen
    )

    base_point_xy: list[TableCoordinate] | None = Field(
        default=None, min_length=2, max_length=2,
        description="Where the worker measured the object's base point p1 on the table, [x, y] in metres in the "
        "robot's frame (from the camera: the first link's marker). Optional. The object is a physical body that "
        "turns and hands may slide: for an object placed in the cell, goals, plans, reach and help requests are "
        "checked at the latest measured base point instead of the one it was created with, and a plan whose rest "
        "would leave the table there is re-planned. Kept with the perception's event.",
        examples=[[0.6, 0.39]],
    )

    @field_validator("link_orientations_deg")
    @classmethod
    def _one_seen(cls, values: list[float | None]) -> list[float | None]:
        if values and all(v is None for v in values):
            raise ValueError("at least one link must be seen (every value is null)")
        return values


class NextActionPublic(BaseModel):
    model_config = schema_config(
        "The action to execute next and the motion it means.",
        {
            "id": "obj1_plan_1_a2", "name": "rotateclockwise", "params": ["obj1_l2", "obj1_l1", "obj1_j1", "deg_90", "deg_180"],
            "step": 2, "last_step": 2, "plan_id": "obj1_plan_1", "joint_index": 1, "turned_link_index": 2, "held_link_index": 1,
            "delta_deg": 90, "macro_steps": 1,
        },
    )

    id: str = Field(description="Identifier of the action (for feedback).", examples=["obj1_plan_1_a2"])
    name: str = Field(description="PDDL action name.", examples=["rotateclockwise"])
    params: list[str] = Field(description="PDDL arguments: turned link, held link, joint, from, to (bimanual: "
                              "turned link, kept link, joint, then the action's own, the grippers last).",
                              examples=[["obj1_l2", "obj1_l1", "obj1_j1", "deg_90", "deg_180"]])
    step: int = Field(description="1-based position of the action in its plan.", examples=[2])
    last_step: int = Field(description="Last plan step this motion covers: consecutive steps of one joint in one "
                           "direction are merged into one macro step; feedback 'succeeded' moves the execution to "
                           "last_step + 1.", examples=[2])
    plan_id: str = Field(description="Plan the action belongs to.", examples=["obj1_plan_1"])
    joint_index: int = Field(description="K of the joint jK rotated about.", examples=[1])
    turned_link_index: int = Field(description="Index of the link that turns (with every link beyond it).", examples=[2])
    held_link_index: int = Field(description="Index of the link held still (0 = the table).", examples=[1])
    delta_deg: int = Field(description="Signed rotation of the turned link, + clockwise seen from above; 0 for a "
                           "bimanual step that turns nothing (grasp, release, centring).", examples=[90])
    macro_steps: int = Field(description="Number of planned steps this motion stands for.", examples=[1])
    ends_plan: bool = Field(default=False, description="Whether this motion is the plan's last: it comes to rest in "
                            "the goal, judged as drawn; any other keeps 1.5 cm from the table's edges at rest "
                            "(`planhrc.judge`).", examples=[False])


class HelpRequestPublic(BaseModel):
    model_config = schema_config(
        "What the robot asks the human to do: bring one link to an absolute orientation.",
        {"link": 4, "to_deg": 135, "sentence": "turn link 4 to 135°"},
    )

    link: int = Field(description="Index K of the link lK the human should turn (1-based).", examples=[4])
    to_deg: int = Field(description="The absolute orientation (degrees clockwise from the robot's forward axis) "
                        "link K should have afterwards.", examples=[135])
    sentence: str = Field(description="The request in words, with why when known.",
                          examples=["turn link 4 to 135°"])


class SkillRequestPublic(BaseModel):
    model_config = schema_config(
        "A robot skill the service asks for besides the plan's rotations: it changes where the object lies or how "
        "far its links are off the orientation grid, not the state of the domain; the worker does it and perceives "
        "again.",
        {"name": "slide", "base_point_xy": [0.62, 0.05], "links": [1, 5],
         "sentence": "slide the object 12 cm towards the table's middle"},
    )

    name: Skill = Field(description="slide: slide the whole object with both arms, holding `links`, until its base "
                        "point lies at `base_point_xy`; straighten: make `turns`.", examples=["slide"])
    base_point_xy: list[float] = Field(min_length=2, max_length=2, description="Where the object's base point p1 "
                                       "should lie afterwards, [x, y] in metres in the robot's frame.",
                                       examples=[[0.62, 0.05]])
    links: list[int] = Field(description="The links the arms hold (1-based); straighten: the links turned.",
                             examples=[[1, 5]])
    sentence: str = Field(description="The request in words, with why.",
                          examples=["slide the object 12 cm towards the table's middle"])
    turns: list[tuple[int, int, float]] = Field(
        default_factory=list, exclude_if=lambda turns: not turns,  # a slide's request reads as it always has
        description="straighten: each turn [turned link, held link (0 = the table), degrees "
        "(+ clockwise seen from above)], in order, each less than one orientation step: links a turn dragged off the "
        "orientation grid back onto it (the base point stays); absent for a slide.",
        examples=[[[1, 0, -12.9], [3, 2, 15.3]]])


class DecisionPublic(BaseModel):
    model_config = schema_config(
        "What the cooperation model decided for a perception.",
        {
            "decision": "continue", "plan_id": "obj1_plan_1", "perceived_state_id": "obj1_state_2", "next_action": None,
            "matched_expected_step": 2, "reason": "the perceived state is subsumed by the expected state s^e_2: execute a_2",
        },
    )

    decision: DecisionKind = Field(
        description="goal_reached, continue (next planned action), resume (from a later or earlier expected "
        "state), replan (a new plan was made), no_plan (no goal, or no plan could be found), "
        "human_help_requested (the robot cannot act: `help` says what the human should do; the execution waits "
        "for the next perception), incomplete_perception (some links were not seen: `unseen_links`; nothing "
        "was stored or changed) or robot_skill (the plan's turns are made where the robot slides the object first, "
        "or the plan slides it before its next step: `skill` says where; the worker does it and perceives again).",
        examples=["continue", "resume"],
    )
    plan_id: str | None = Field(description="Plan being followed after the decision.", examples=["obj1_plan_1"])
    perceived_state_id: str | None = Field(description="The stored perceived State (null for an incomplete "
                                           "perception, which stores none).", examples=["obj1_state_2"])
    next_action: NextActionPublic | None = Field(
        description="Action to execute next, if any (not yet dispatched).", examples=[None]
    )
    matched_expected_step: int | None = Field(
        description="i of the expected state s^e_i that subsumes the perceived state, if any.", examples=[2]
    )
    reason: str = Field(description="Why, in words.", examples=["the perceived state is subsumed by the goal state"])
    help: list[HelpRequestPublic] | None = Field(
        default=None, description="human_help_requested: what the human should do, one item per link.",
        examples=[[{"link": 4, "to_deg": 135, "sentence": "turn link 4 to 135°"}]],
    )
    unseen_links: list[int] | None = Field(
        default=None, description="incomplete_perception: the 1-based indices of the links not seen.",
        examples=[[3, 5]],
    )
    skill: SkillRequestPublic | None = Field(
        default=None, description="robot_skill: the skill the robot does first, then it perceives again.",
        examples=[None],
    )


class RefusalFactPublic(BaseModel):
    model_config = schema_config(
        "The geometric fact behind a turn the worker refused before moving (its judge, `planhrc.judge`, from the "
        "pose it measured): which link, against what, how far, and the pose it judged from.",
        {"code": "off_table", "link": 4, "against": "the table's left edge", "distance_m": 0.04,
         "from_deg": [90.4, 134.8, 90.1, 314.6, 314.5], "base_point_xy": [0.54, 0.13]},
    )

    code: Infeasible = Field(description="off_table, inside_robot, out_of_reach or overlap.", examples=["off_table"])
    link: int = Field(ge=1, le=MAX_LINKS, description="The link concerned (1-based).", examples=[4])
    against: str = Field(default="", max_length=200, description="What it runs against: an edge of the table, "
                         "the robot's body, another link, the arms' reach.", examples=["the table's left edge"])
    distance_m: FiniteFloat = Field(default=0.0, ge=0.0, le=10.0, description="How far off, in metres (0 when not a "
                                    "distance).", examples=[0.04])
    from_deg: list[FiniteFloat] | None = Field(
        default=None, min_length=MIN_LINKS, max_length=MAX_LINKS,
        description="The measured link orientations the turn was judged from (default: the latest perception's).",
        examples=[[90.4, 134.8, 90.1, 314.6, 314.5]])
    base_point_xy: list[TableCoordinate] | None = Field(
        default=None, min_length=2, max_length=2,
        description="The measured base point it was judged at (default: the latest measured one).",
        examples=[[0.54, 0.13]])


class FeedbackCreate(BaseModel):
    model_config = schema_config(
        "A worker's report on a dispatched action. A reason is given only for an action that did not succeed.",
        {"outcome": "succeeded"},
        {"if": {"properties": {"outcome": {"const": ActionOutcome.SUCCEEDED.value}}},
         "then": {"properties": {"reason": {"type": "null"}, "refusal": {"type": "null"}}}},
    )

    outcome: ActionOutcome = Field(
        description="succeeded, failed (nothing moved) or partial (moved, but not the whole step).",
        examples=["succeeded", "failed"],
    )
    message: str = Field(default="", max_length=2000, description="Free text from the worker: the sentence "
                         "saying what happened.", examples=["gripper lost the link"])
    reason: FailureReason | None = Field(
        default=None,
        description="Why a failed or partial action did not do what it was asked (must be null for succeeded): "
        "unreachable, collision, slip, stall, grasp_lost or left_table. A repeated failure with reason "
        "unreachable, collision, slip, stall or left_table is not retried identically.",
        examples=["stall", None],
    )
    measured_deg: FiniteFloat | None = Field(
        default=None, ge=-720.0, le=720.0,
        description="The turned link's measured orientation after release (degrees clockwise), for partial, slip "
        "or stall.", examples=[95.0, None],
    )
    refusal: RefusalFactPublic | None = Field(
        default=None, description="For a turn refused before it moved (failed, left_table, collision or "
        "unreachable): the geometric fact. The service never proposes the same turn from the same state again "
        "(it remembers it in the object's log). Optional: a refusal without it is remembered from the latest "
        "perception.", examples=[None])
    hands_open: bool = Field(
        default=False, description="Bimanual objects only: after the action the robot opened both hands and took "
        "them away (its grasps are gone, the centre stays), as after a failure: e.g. a turn done, but the hands "
        "hid a link from every camera. The next plan grasps again.", examples=[False])

    @model_validator(mode="after")
    def _reason_only_for_failures(self) -> "FeedbackCreate":
        if self.outcome == ActionOutcome.SUCCEEDED and self.reason is not None:
            raise ValueError(f"reason: must be null when the outcome is succeeded, got {self.reason.value!r}")
        if self.outcome == ActionOutcome.SUCCEEDED and self.refusal is not None:
            raise ValueError("refusal: must be null when the outcome is succeeded")
        return self


class FeedbackPublic(BaseModel):
    model_config = schema_config(
        "The execution after a feedback.",
        {"action_id": "obj1_plan_1_a2", "accepted": "current",
         "execution": {"plan_id": "obj1_plan_1", "next_step": 3, "status": "ready", "dispatched_action_id": None}},
    )

    action_id: str = Field(description="The action the feedback was about.", examples=["obj1_plan_1_a2"])
    accepted: Literal["current", "late"] = Field(
        description="current: it moved the execution on; late: a perception had already moved it, the feedback "
        "is only recorded.", examples=["current"],
    )
    execution: ExecutionPublic = Field(
        description="Execution state after the feedback.",
        examples=[{"plan_id": "obj1_plan_1", "next_step": 3, "status": "ready", "dispatched_action_id": None}],
    )


class GiveUpCreate(BaseModel):
    model_config = schema_config(
        "A worker stops working on an object and says why.",
        {"reason": "repeated_failure", "message": "a_3 failed three times: link 4 stalls at 95°"},
    )

    reason: str = Field(min_length=1, max_length=64, pattern=r"^[a-z][a-z0-9_]*$",
                        description="A short machine-readable code (lower case, digits, underscores).",
                        examples=["repeated_failure"])
    message: PrintableName = Field(min_length=1, max_length=2000, description="What happened, in a sentence.",
                                   examples=["a_3 failed three times: link 4 stalls at 95°"])


class GiveUpPublic(BaseModel):
    model_config = schema_config(
        "The recorded give-up, and the help request it became.",
        {"event_seq": 12, "decision": "human_help_requested",
         "reason": "the robot stopped (repeated_failure: ...); the robot asks the human for help: turn link 4 to 135°",
         "help": [{"link": 4, "to_deg": 135, "sentence": "turn link 4 to 135° (the robot stopped ...)"}]},
    )

    event_seq: int = Field(description="Position of the worker_gave_up event in the object's log.", examples=[12])
    decision: DecisionKind | None = Field(
        default=None, description="human_help_requested: the give-up became a help request (recorded as that "
        "decision, after the worker_gave_up event); null when no goal is left to ask for.",
        examples=["human_help_requested"])
    reason: str = Field(default="", description="Why, in words: the worker's reason and what is asked.",
                        examples=["the robot stopped (repeated_failure: ...)"])
    help: list[HelpRequestPublic] = Field(
        default_factory=list, description="What the human should do to reach the goal, one item per link, "
        "upstream first; empty in a help request when no perception of the whole object is stored (the reason asks "
        "for the goal as a whole).", examples=[[{"link": 4, "to_deg": 135, "sentence": "turn link 4 to 135°"}]])

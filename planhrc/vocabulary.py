"""The words every layer shares, each defined once: `str` enums, so they compare equal to their values, serialise
as plain JSON strings and appear as enums in the service's OpenAPI schemas.

* `DecisionKind`: what the cooperation model decides after a perception;
* `ExecutionStatus`: where the execution of an object's plan stands;
* `ActionOutcome`: what a worker reports about an action it executed;
* `Accepted`: how the service took a worker's feedback;
* `FailureReason`: why an action that did not succeed failed (machine-readable; the feedback's sentence says the
  rest);
* `Skill`: a robot skill the service asks for besides the plan's rotations;
* `Remedy`: what the cooperation model does instead of retrying a failed action identically;
* `GiveUpReason`: why a worker tells the service it stops working on an object;
* `StopReason`: why a worker's run ended (its summary, the demo's results);
* `Infeasible`: why a configuration of an object is not feasible in the cell (`planhrc.geometry`);
* `PlanStatus`: how planning ended, for one planner call (the planner package uses this very enum) and for one
  run of the planning pipeline, which adds `invalid` when VAL or the replay refused the planner's plan;
* `SparqlEngineName`: which engine evaluates the knowledge service's SPARQL queries;
* `ReasoningScope`: what part of the current ABox a reasoning job gives the DL reasoner.
"""
from __future__ import annotations

from enum import StrEnum


class DecisionKind(StrEnum):
    GOAL_REACHED = "goal_reached"
    CONTINUE = "continue"
    RESUME = "resume"
    REPLAN = "replan"
    NO_PLAN = "no_plan"
    HUMAN_HELP_REQUESTED = "human_help_requested"
    INCOMPLETE_PERCEPTION = "incomplete_perception"
    ROBOT_SKILL = "robot_skill"  # the robot first makes room with a skill (`Skill`), then perceives again


class Skill(StrEnum):
    """A robot skill the service may ask for besides the plan's rotations (`DecisionKind.ROBOT_SKILL`); it does
    not change the state of the domain, only where the object lies."""

    SLIDE = "slide"  # slide the whole object with both arms, its base point to a place nearer the table's middle
    STRAIGHTEN = "straighten"  # turn links dragged off the orientation grid back onto it (each less than a step)


class ExecutionStatus(StrEnum):
    IDLE = "idle"
    READY = "ready"
    DISPATCHED = "dispatched"
    GOAL_REACHED = "goal_reached"
    NO_PLAN = "no_plan"


class ActionOutcome(StrEnum):
    SUCCEEDED = "succeeded"
    FAILED = "failed"
    PARTIAL = "partial"


class Accepted(StrEnum):
    """How a feedback was taken."""

    CURRENT = "current"  # it moved the execution on
    LATE = "late"  # a perception had already moved the execution: it is only recorded


class FailureReason(StrEnum):
    """Why an action did not do what it was asked."""

    UNREACHABLE = "unreachable"
    COLLISION = "collision"
    SLIP = "slip"
    STALL = "stall"
    GRASP_LOST = "grasp_lost"
    LEFT_TABLE = "left_table"


class Remedy(StrEnum):
    """A repeated failure is not retried identically: split the macro step, turn the other way round, re-plan,
    and when those are spent (or the robot cannot reach), ask the human."""

    SPLIT = "split"
    OTHER_WAY = "other_way"
    REPLAN = "replan"
    ASK_HUMAN = "ask_human"


class GiveUpReason(StrEnum):
    """The short code of a worker's give-up (`POST /objects/{id}/give-up`); the message says the rest."""

    UNSEEN_LINKS = "unseen_links"
    NO_HUMAN_HELP = "no_human_help"
    HUMAN_COULD_NOT_HELP = "human_could_not_help"
    REPEATED_FAILURE = "repeated_failure"
    NO_PLAN = "no_plan"
    NO_ACTION = "no_action"
    MAX_STEPS = "max_steps"


class StopReason(StrEnum):
    """Why a worker's run ended: the goal, the service's word (no plan, no action to dispatch), or the worker's
    own (links not seen, no help, giving up, out of steps)."""

    GOAL_REACHED = "goal_reached"
    NO_PLAN = "no_plan"
    NO_ACTION = "no_action"
    UNSEEN_LINKS = "unseen_links"
    NO_HUMAN_HELP = "no_human_help"
    GAVE_UP = "gave_up"
    MAX_STEPS = "max_steps"


class Infeasible(StrEnum):
    """The code of one reason a configuration is not feasible (`geometry.Infeasibility.code`)."""

    OFF_TABLE = "off_table"
    INSIDE_ROBOT = "inside_robot"
    OUT_OF_REACH = "out_of_reach"
    OVERLAP = "overlap"


class PlanStatus(StrEnum):
    """How planning ended: "unsolvable" and "timeout" are results, not exceptions. A planner call answers one of
    the first four; `invalid` is the pipeline's, for a plan that VAL or the replay refused; `unvalidated` the
    fallback chain's, for a plan no validator gave a verdict on (not asked, or none finished in time): "solved"
    from the chain means validated."""

    SOLVED = "solved"
    UNSOLVABLE = "unsolvable"
    TIMEOUT = "timeout"
    ERROR = "error"
    INVALID = "invalid"
    UNVALIDATED = "unvalidated"


# The pipeline's and the service's name for `PlanStatus` (the same enum), kept while they still say it.
PlanningStatus = PlanStatus


def one_of(enum: type[StrEnum]) -> str:
    """The allowed values of an enum for an error message: `a, b or c`."""
    values = [member.value for member in enum]
    return ", ".join(values[:-1]) + " or " + values[-1] if len(values) > 1 else values[0]


class SparqlEngineName(StrEnum):
    OXIGRAPH = "oxigraph"  # Oxigraph (Rust), in a process of its own: the default
    RDFLIB = "rdflib"  # rdflib's evaluator in the service's process: the earlier engine, kept to compare


class ReasoningScope(StrEnum):
    STATES = "states"  # each object with its goal and latest perceived state: the default
    CURRENT = "current"  # the whole current ABox, the plan with its actions and expected states too

"""The bridge's topics: name, message type and QoS of each, defined once for the bridge, the worker's link, the
tests and the documentation.

Every per-object topic lives under `/planhrc/objects/<id>/`. Latched topics (reliable + transient local) give a
late subscriber (RViz, a controller started later) the latest value; inputs are reliable + volatile, which
matches both volatile and transient-local publishers; the next action is volatile on purpose, so a controller
started late never executes an action dispatched before it was there.
"""
from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum

NAMESPACE = "/planhrc/objects"
KNOWLEDGE_NAMESPACE = "/planhrc/knowledge"
DIAGNOSTICS_TOPIC = "/diagnostics"


class Durability(StrEnum):
    VOLATILE = "volatile"
    TRANSIENT_LOCAL = "transient_local"


class Direction(StrEnum):
    IN = "in"  # the bridge subscribes
    OUT = "out"  # the bridge publishes


@dataclass(frozen=True)
class TopicSpec:
    suffix: str  # after /planhrc/objects/<id>/
    type_name: str  # package/msg/Type
    direction: Direction
    durability: Durability
    depth: int
    meaning: str

    def name(self, object_id: str) -> str:
        return f"{NAMESPACE}/{object_id}/{self.suffix}"

    @property
    def qos_text(self) -> str:
        latched = "transient local" if self.durability is Durability.TRANSIENT_LOCAL else "volatile"
        return f"reliable, {latched}, depth {self.depth}"


PERCEIVED = TopicSpec("perceived", "sensor_msgs/msg/JointState", Direction.IN, Durability.VOLATILE, 10,
                      "a perception: `name` l1..lN (plus base_x, base_y in metres when measured), `position` each "
                      "link's orientation in radians, REP 103; NaN or a missing link = not seen")
GOAL = TopicSpec("goal", "sensor_msgs/msg/JointState", Direction.IN, Durability.VOLATILE, 10,
                 "the goal configuration, every link l1..lN, radians REP 103")
FEEDBACK = TopicSpec("feedback", "std_msgs/msg/String", Direction.IN, Durability.VOLATILE, 10,
                     "the outcome of the dispatched action: the HTTP feedback body as JSON, plus `action_id` "
                     "(default: the action last dispatched here) and `request_id`")
GIVE_UP = TopicSpec("give_up", "std_msgs/msg/String", Direction.IN, Durability.VOLATILE, 10,
                    "the robot stops working on the object: JSON {reason, message, request_id}")
DECISION = TopicSpec("decision", "std_msgs/msg/String", Direction.OUT, Durability.TRANSIENT_LOCAL, 10,
                     "every decision, whoever caused it: the HTTP perception's answer as JSON, plus "
                     "`perception_stamp` (a perception from this topic) or `event_seq` (from another caller)")
NEXT_ACTION = TopicSpec("next_action", "trajectory_msgs/msg/JointTrajectory", Direction.OUT, Durability.VOLATILE,
                        10, "the action dispatched after a perception from ROS 2: joint_names [held, turned] "
                        "(l0 = the table), two points: now and the target, radians REP 103; empty = hold still")
MARKERS = TopicSpec("markers", "visualization_msgs/msg/MarkerArray", Direction.OUT, Durability.TRANSIENT_LOCAL, 1,
                    "the perceived object, the goal as a ghost, the expected state after the next action")
HELP = TopicSpec("help", "std_msgs/msg/String", Direction.OUT, Durability.TRANSIENT_LOCAL, 1,
                 "the current help request as JSON {help: [{link, to_deg, sentence}], reason}; help [] when none")
PLAN = TopicSpec("plan", "std_msgs/msg/String", Direction.OUT, Durability.TRANSIENT_LOCAL, 1,
                 "the plan being followed as JSON (the body of GET /plans/{id})")
# depth 10, not 1: it carries the answers to requests, and a writer keeping only the last sample may replace an
# answer not yet acknowledged by the next object message
OBJECT = TopicSpec("object", "std_msgs/msg/String", Direction.OUT, Durability.TRANSIENT_LOCAL, 10,
                   "the object after each change as JSON {object, goal_state, answer_to}: `answer_to` says which "
                   "request from ROS 2 was handled, and whether it was refused and why")

OBJECT_TOPICS: tuple[TopicSpec, ...] = (PERCEIVED, GOAL, FEEDBACK, GIVE_UP, DECISION, NEXT_ACTION, MARKERS, HELP,
                                        PLAN, OBJECT)
DIAGNOSTICS = ("diagnostic_msgs/msg/DiagnosticArray", "reliable, volatile, depth 10",
               "the bridge's health once a second: one status for the service, one per object")


# -- the knowledge service: questions about the whole knowledge base, not one object --------------------------------
@dataclass(frozen=True)
class KnowledgeTopicSpec(TopicSpec):
    """A topic under /planhrc/knowledge/ (`suffix`), the same for every object."""

    @property
    def full_name(self) -> str:
        return f"{KNOWLEDGE_NAMESPACE}/{self.suffix}"


def _pair(name: str, asks: str, answers: str) -> tuple[KnowledgeTopicSpec, KnowledgeTopicSpec]:
    # answers are latched (depth 10) like the object topic's: a reader matched late still gets its answer
    return (KnowledgeTopicSpec(f"{name}/request", "std_msgs/msg/String", Direction.IN, Durability.VOLATILE, 10, asks),
            KnowledgeTopicSpec(f"{name}/answer", "std_msgs/msg/String", Direction.OUT, Durability.TRANSIENT_LOCAL, 10,
                               answers))


SPARQL_REQUEST, SPARQL_ANSWER = _pair(
    "sparql", "a SPARQL query as JSON {request_id, query, accept?, default_graph_uri?, named_graph_uri?}",
    "JSON {request_id, ok, media_type, result_count, body} (body: the answer's text in that media type), or "
    "{request_id, ok: false, status, detail}")
SUBSUMPTION_REQUEST, SUBSUMPTION_ANSWER = _pair(
    "subsumption", "JSON {request_id, state_id, by_state_id}: is D(state) ⊑ D(by)?",
    "JSON {request_id, ok, subsumed, missing, differs, atoms_checked, ...} (the HTTP route's body)")
REASONING_REQUEST, REASONING_ANSWER = _pair(
    "reasoning", "JSON {request_id, reasoner: pellet|hermit, object_id?, scope?: states|current}",
    "JSON {request_id, ok, status: done|failed, consistent, inferred, seconds, ...} (the finished job's body)")
KNOWLEDGE_TOPICS: tuple[KnowledgeTopicSpec, ...] = (SPARQL_REQUEST, SPARQL_ANSWER, SUBSUMPTION_REQUEST,
                                                    SUBSUMPTION_ANSWER, REASONING_REQUEST, REASONING_ANSWER)
REASON_NOW = (f"{KNOWLEDGE_NAMESPACE}/reason_now", "std_srvs/srv/Trigger",
              "Pellet on every object now (scope states); success: the job finished and the ABox is consistent; "
              "message: the job's body as JSON")

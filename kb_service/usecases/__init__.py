"""The service's core: the cooperation loop as use cases, one module each, each one entry function that takes a
`Context` (`context`) and a frozen request and returns a frozen result (`values`). The HTTP layer (`api`) maps
requests and results to its bodies; nothing here knows HTTP.

| use case | entry | module |
|---|---|---|
| create an object | `create_object(NewObject) -> ObjectRead` | `objects` |
| set a goal | `set_goal(GoalRequest) -> GoalSet` | `goal` |
| perceive, decide, re-plan, write | `perceive(PerceptionRequest) -> Turn` | `perception`, `seen`, `refine`, `turns` |
| take the next action (the VAL gate) | `take_next_action(object_id) -> NextAction` or None | `dispatch` (with `gate`) |
| a worker's feedback | `give_feedback(FeedbackRequest) -> FeedbackResult` | `feedback` |
| a worker gives up | `give_up(GiveUpRequest) -> GaveUp` | `giving_up` |
| reads | `read_object`, `read_plan`, `list_events`, `read_health`, ... | `reads` |

Shared per-object memory (`memory`: the event-log memo, the plan views) and the owner of validation runs
(`pipeline.Validator`) are held by the `Context`; the store is reached through its interface (`store.KnowledgeStore`).
Every request that touches an object runs under that object's lock, so one object's requests are serialized
while different objects proceed in parallel; each validates its input completely before its first write, and writes
in one unit of work (`unit_of_work`), which on a store several service processes share also takes the object's lock
across them and decides again when another process wrote the object meanwhile.
"""
from .context import Context, close_context, open_context
from .dispatch import take_next_action
from .feedback import FeedbackRequest, RefusalFact, give_feedback
from .giving_up import GiveUpRequest, give_up
from .goal import GoalRequest, set_goal
from .objects import NewObject, create_object
from .perception import PerceptionRequest, perceive
from .reads import (events_after, export_ontology, list_events, list_objects, read_current_plan,
                    read_health, read_object, read_pddl, read_plan, read_problem, read_state)
from .log import EventRead
from .values import FeedbackResult, GaveUp, GoalSet, Health, NextAction, ObjectRead, PlanRead, StateRead, Turn

__all__ = [
    "Context", "EventRead", "FeedbackRequest", "FeedbackResult", "GaveUp", "GiveUpRequest", "GoalRequest", "GoalSet",
    "Health", "NewObject", "NextAction", "ObjectRead", "PerceptionRequest", "PlanRead", "RefusalFact", "StateRead",
    "Turn", "close_context", "create_object", "events_after", "export_ontology", "give_feedback",
    "give_up", "list_events", "list_objects", "open_context", "perceive", "read_current_plan", "read_health",
    "read_object", "read_pddl", "read_plan", "read_problem", "read_state", "set_goal", "take_next_action",
]

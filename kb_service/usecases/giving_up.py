"""A worker gives up on an object: recorded, and the execution left idle with nothing dispatched (the plan stays;
the next perception decides anew)."""
from __future__ import annotations

from dataclasses import dataclass

from planhrc.vocabulary import ExecutionStatus

from ..store import Execution
from .context import Context
from .log import EventKind
from .unit_of_work import object_write, read_mark, serialized
from .values import GaveUp


@dataclass(frozen=True)
class GiveUpRequest:
    object_id: str
    reason: str  # a short machine-readable code
    message: str


def give_up(context: Context, request: GiveUpRequest) -> GaveUp:
    return serialized(context, request.object_id, lambda: _give_up(context, request))


def _give_up(context: Context, request: GiveUpRequest) -> GaveUp:
    store, object_id = context.store, request.object_id
    with context.locks.hold(object_id):
        store.get_object(object_id)
        mark = read_mark(context, object_id)
        execution = store.get_execution(object_id)
        with object_write(context, object_id, mark):
            store.set_execution(object_id, Execution(execution.plan_id, None, ExecutionStatus.IDLE, None))
            event = store.add_event(object_id, EventKind.WORKER_GAVE_UP,
                                    f"the worker gave up ({request.reason}): {request.message}",
                                    {"reason": request.reason, "message": request.message,
                                     "plan_id": execution.plan_id, "dropped_action_id": execution.dispatched_action_id})
        return GaveUp(event.seq)

"""Take the next action: the motion to execute now, marked dispatched (taking it again returns the same one), once
it passed the VAL gate (`gate.val_gate`): a motion whose piece VAL refused is withheld, and the next perception
re-plans; one whose verdict does not come by the planning deadline is withheld too, and asked for again next time.

Two requests taking the next action of one object at once, on one service or on two replicas of it, dispatch it
once: one marks it dispatched, the other then finds it dispatched and answers the same action, or finds no action
when the first one's gate withheld it (`unit_of_work`: the second decides again on what the first wrote)."""
from __future__ import annotations

from planhrc.event_log import DispatchData, EventKind
from planhrc.pipeline import deadline_from
from planhrc.vocabulary import ExecutionStatus

from ..store import DeadlineError, Execution
from .actions import merges, next_action
from .context import Context
from .gate import val_gate
from .log import log_event
from .unit_of_work import object_write, read_mark, serialized
from .values import NextAction

READY, DISPATCHED = ExecutionStatus.READY, ExecutionStatus.DISPATCHED


def take_next_action(context: Context, object_id: str) -> NextAction | None:
    """The action to execute now, marked dispatched; None when there is none (no plan, done, goal reached, or
    withheld by the gate)."""
    return serialized(context, object_id, lambda: _take(context, object_id))


def _take(context: Context, object_id: str) -> NextAction | None:
    store = context.store
    with context.locks.hold(object_id):
        obj = store.get_object(object_id)
        mark = read_mark(context, object_id)
        execution = store.get_execution(object_id)
        plan, _ = context.views.get(store, execution.plan_id)
        if plan is None or execution.status not in (READY, DISPATCHED) or execution.next_step is None:
            return None
        if not 1 <= execution.next_step <= len(plan.actions):
            return None
        action = plan.actions[execution.next_step - 1]
        merge = merges(context.settings.merge_macro_steps, context.memory.of(store, object_id), plan.id)
        if execution.status == DISPATCHED and execution.dispatched_action_id == action.id:
            return next_action(merge, obj, plan, action)
        data = DispatchData(plan_id=plan.id, action_id=action.id, step=action.step)
        try:
            refusal = val_gate(context, obj, plan, action, deadline_from(context.planning))
        except DeadlineError as exc:  # nothing dispatched; the next call or perception asks again
            with object_write(context, object_id):
                log_event(store, object_id, EventKind.DISPATCH_WITHHELD, f"a_{action.step} not dispatched: {exc}", data)
            return None
        if refusal is not None:  # the next perception re-plans (the gate refuses this step again)
            with object_write(context, object_id, mark):
                store.set_execution(object_id, Execution(plan.id, execution.next_step, ExecutionStatus.IDLE, None))
                log_event(store, object_id, EventKind.DISPATCH_WITHHELD,
                          f"a_{action.step} not dispatched: {refusal}; the next perception re-plans", data)
            return None
        with object_write(context, object_id, mark):
            store.set_execution(object_id, Execution(plan.id, execution.next_step, DISPATCHED, action.id))
            log_event(store, object_id, EventKind.DISPATCHED, f"a_{action.step} ({action.spec.name}) dispatched", data)
        return next_action(merge, obj, plan, action)

"""The dispatch gate: no motion of a plan leaves (taken, or decided on by a perception) before VAL has accepted
every piece of the plan it lies in (`pipeline.gate` reads the verdicts recorded in the object's log). A verdict
still to come is waited for; one that will not come (the service restarted while VAL ran, or the verdict could
not be recorded) is asked of VAL again here, and recorded."""
from __future__ import annotations

import logging
import time

from planhrc.model import ArticulatedObject
from planhrc.pipeline import PieceVerdict, Verdict, gate
from planhrc.planner.errors import PlannerError

from ..store import DeadlineError, StoredAction, StoredPlan, ValidationError
from .actions import last_step, merges
from .context import Context
from .log import record_verdict

log = logging.getLogger(__name__)


def val_gate(context: Context, obj: ArticulatedObject, plan: StoredPlan, action: StoredAction,
             deadline_at: float) -> str | None:
    """None when VAL has accepted every piece of `plan` holding the motion that starts with `action` (plans
    validated whole before they were stored always pass); else VAL's refusal in words. Raises DeadlineError when
    no verdict comes by `deadline_at`."""
    store, validator = context.store, context.validator
    memo = context.memory.of(store, obj.ident)
    last = last_step(merges(context.settings.merge_macro_steps, memo, plan.id), obj, plan, action)
    waited: set[int] = set()
    while True:
        memo = context.memory.of(store, obj.ident)  # the verdicts recorded meanwhile
        answer = gate(memo.val, plan.id, action.step, last)
        if answer.missing is None or memo.val is None:
            return answer.refusal
        number = answer.missing
        first, end = memo.val.bounds(number)
        if number not in waited:
            done = validator.wait_piece(obj.ident, plan.id, first, deadline_at - time.monotonic())
            if done is not None:
                waited.add(number)
                if not done:
                    raise DeadlineError(f"planning: planning deadline of {context.planning.deadline_s:g} s "
                                        f"exceeded while VAL checked a_{first}..a_{end} of plan {plan.id}")
                continue
        _recheck(context, obj, plan, number, first, end, deadline_at)


def _recheck(context: Context, obj: ArticulatedObject, plan: StoredPlan, number: int, first: int, last: int,
             deadline_at: float) -> None:
    """VAL on one piece of a stored plan, built again from the store (its problem, steps and expected states),
    and its verdict recorded."""
    store = context.store
    problem = store.get_problem(plan.problem_id)
    init, goal = store.get_state(problem.init_state_id), store.get_state(problem.goal_state_id)
    _, view = context.views.get(store, plan.id)
    assert view is not None
    actions = [a.spec for a in sorted(plan.actions, key=lambda a: a.step)]
    try:  # the store's checks of the piece's steps first, as behind the answer (`perception._later_checks`)
        store.check_steps(obj.ident, actions, view.expected_states, first, last)
    except ValidationError as exc:
        refused = Verdict(False, f"the store's check refused a_{first}..a_{last}: {exc}")
        record_verdict(store, obj.ident, plan.id, PieceVerdict(number, first, last, refused, 0.0))
        return
    try:
        piece = context.validator.recheck(obj, init.atoms, goal.atoms, actions, view.expected_states, number, first,
                                          last, deadline_at)
    except PlannerError as exc:
        raise DeadlineError(f"planning: planning deadline of {context.planning.deadline_s:g} s exceeded while VAL "
                            f"checked a_{first}..a_{last} of plan {plan.id} again ({exc})") from None
    log.info("VAL checked piece %d of plan %s again: %s", number, plan.id, piece.verdict.reason)
    record_verdict(store, obj.ident, plan.id, piece)

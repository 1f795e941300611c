"""The execution cursor: where the cooperation model stands for each object (plan, next step, status, the action
handed to a worker). One side table of the knowledge base's database."""
from __future__ import annotations

from .errors import ValidationError
from .owl import QuadStore
from .records import Execution, StoredPlan
from planhrc.vocabulary import ExecutionStatus, one_of

SCHEMA = ("CREATE TABLE IF NOT EXISTS planhrc_execution (object_id TEXT PRIMARY KEY, plan_id TEXT, next_step INTEGER,"
          " status TEXT, dispatched_action_id TEXT)")


class ExecutionCursor:
    """Read and move an object's execution (the caller resolves the object and the plan)."""

    def __init__(self, quads: QuadStore) -> None:
        self.quads = quads
        quads.execute(SCHEMA)

    def read(self, object_id: str) -> Execution:
        row = self.quads.execute(
            "SELECT plan_id, next_step, status, dispatched_action_id FROM planhrc_execution WHERE object_id=?",
            (object_id,),
        ).fetchone()
        if row is None:
            return Execution(plan_id=None, next_step=None, status=ExecutionStatus.IDLE)
        plan_id, next_step, status, dispatched = row
        return Execution(plan_id, next_step, ExecutionStatus(status), dispatched)

    @staticmethod
    def check(object_id: str, execution: Execution, plan: StoredPlan | None) -> None:
        """Validate a new execution of `object_id`; `plan` is the stored plan `execution.plan_id` names."""
        if execution.status not in set(ExecutionStatus):
            raise ValidationError(f"execution.status: must be {one_of(ExecutionStatus)}, got {execution.status!r}")
        if plan is not None and plan.object_id != object_id:
            raise ValidationError(f"execution.plan_id: plan {plan.id!r} belongs to object {plan.object_id!r}")
        if execution.next_step is not None:
            if isinstance(execution.next_step, bool) or not isinstance(execution.next_step, int):
                raise ValidationError("execution.next_step: must be an integer or None")
            if plan is None:
                raise ValidationError("execution.next_step: needs a plan_id")
            if not 1 <= execution.next_step <= len(plan.actions) + 1:
                raise ValidationError(
                    f"execution.next_step: must be in 1..{len(plan.actions) + 1}, got {execution.next_step}"
                )
        if execution.dispatched_action_id is not None:
            if plan is None or execution.dispatched_action_id not in {a.id for a in plan.actions}:
                raise ValidationError(
                    f"execution.dispatched_action_id: {execution.dispatched_action_id!r} is no action of plan "
                    f"{execution.plan_id!r}"
                )

    def write(self, object_id: str, execution: Execution) -> None:
        """Write a checked execution (inside the open transaction)."""
        status = ExecutionStatus(execution.status).value
        self.quads.execute("INSERT OR REPLACE INTO planhrc_execution VALUES (?,?,?,?,?)",
                           (object_id, execution.plan_id, execution.next_step, status, execution.dispatched_action_id))

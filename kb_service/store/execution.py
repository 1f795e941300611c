"""The execution cursor: where the cooperation model stands for each object (plan, next step, status, the action
handed to a worker). One side table of the SQLite store's database (a new execution is checked by
`checks.check_execution` before)."""
from __future__ import annotations

from .owl import QuadStore
from .records import Execution
from planhrc.vocabulary import ExecutionStatus

SCHEMA = ("CREATE TABLE IF NOT EXISTS planhrc_execution (object_id TEXT PRIMARY KEY, plan_id TEXT, next_step INTEGER,"
          " status TEXT, dispatched_action_id TEXT)")


class ExecutionCursor:
    """Read and move an object's execution (the caller resolves and checks the object and the plan)."""

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

    def write(self, object_id: str, execution: Execution) -> None:
        """Write a checked execution (inside the open transaction)."""
        status = ExecutionStatus(execution.status).value
        self.quads.execute("INSERT OR REPLACE INTO planhrc_execution VALUES (?,?,?,?,?)",
                           (object_id, execution.plan_id, execution.next_step, status, execution.dispatched_action_id))

"""Errors of the planner package.

Only configuration and input problems are exceptions; "unsolvable", "timeout" and a planner's own failure
are statuses of a `PlanResult` (see `planner.result`).
"""
from __future__ import annotations

from planhrc.errors import PlanhrcError


class PlannerError(PlanhrcError):
    """Bad planner configuration, an unknown planner name, or PDDL text that cannot be read."""

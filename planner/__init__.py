"""Planner backends behind one interface: PDDL text in, `PlanResult` out.

`get_planner(name)` builds a backend from the `PLANNERS` registry; `plan_with_fallback` runs the one
fallback chain every caller uses; `plan_files` reads PDDL files;
`validate_plan` checks a plan with VAL; `ground_task` is the low-latency re-planning API of the
in-process planner (parse -> ground -> recognise -> solve; see `planner.inproc`).
"""
from .base import Planner
from .chain import plan_with_fallback
from .errors import PlannerError
from .files import plan_files
from .inproc import GroundTask, InprocPlanner, ground_task
from .registry import PLANNERS, available_planners, get_planner
from .result import PlannerAttempt, PlanResult, PlanStatus
from .validate import ValidationResult, validate_plan

__all__ = [
    "GroundTask", "InprocPlanner", "PLANNERS", "Planner", "PlannerAttempt", "PlannerError", "PlanResult", "PlanStatus",
    "ValidationResult", "available_planners", "get_planner", "ground_task", "plan_files", "plan_with_fallback", "validate_plan",
]

"""Plan from PDDL files: the entry point behind `planhrc plan`."""
from __future__ import annotations

from pathlib import Path
from typing import Any

from .errors import PlannerError
from .registry import get_planner
from .result import PlanResult


def read_pddl(path: str | Path, what: str) -> str:
    try:
        return Path(path).read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise PlannerError(f"{what}: cannot read {str(path)!r}: {exc}") from exc


def plan_files(domain_path: str | Path, problem_path: str | Path, planner_name: str = "inproc",
               timeout_s: float = 60.0, **options: Any) -> PlanResult:
    """Read both files and run the named planner. Raises PlannerError for unreadable files or a bad name."""
    if not timeout_s > 0:
        raise PlannerError(f"timeout: must be a positive number of seconds, got {timeout_s!r}")
    planner = get_planner(planner_name, **options)
    return planner.solve(read_pddl(domain_path, "domain"), read_pddl(problem_path, "problem"), timeout_s)

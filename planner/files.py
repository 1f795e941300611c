"""Plan from PDDL files: the entry point behind `planhrc plan`."""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Any

from .chain import judged, reading_warnings
from .errors import PlannerError
from .registry import get_planner
from .result import PlanResult, PlanStatus


def read_pddl(path: str | Path, what: str) -> str:
    try:
        return Path(path).read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise PlannerError(f"{what}: cannot read {str(path)!r}: {exc}") from exc


def plan_files(domain_path: str | Path, problem_path: str | Path, planner_name: str = "inproc",
               timeout_s: float = 60.0, *, validate: bool = True, **options: Any) -> PlanResult:
    """Read both files and run the named planner; its plan is checked by VAL within the same time limit (a plan
    VAL refuses comes back with status invalid), unless `validate` is False. Raises PlannerError for unreadable
    files or a bad name."""
    if not timeout_s > 0:
        raise PlannerError(f"timeout: must be a positive number of seconds, got {timeout_s!r}")
    planner = get_planner(planner_name, **options)
    domain, problem = read_pddl(domain_path, "domain"), read_pddl(problem_path, "problem")
    result = planner.solve(domain, problem, timeout_s)
    if validate and result.status is PlanStatus.SOLVED:
        result = judged(result, domain, problem, timeout_s - result.seconds)
    return replace(result, warnings=reading_warnings(domain))

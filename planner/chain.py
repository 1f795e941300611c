"""One fallback policy for every caller: try planners in order, each with the time that is left.

    plan_with_fallback(domain, problem, ("inproc", "fd-lama"), timeout_s=10.0)

A planner's answer ends the chain when it is a plan or a proof that there is none (status solved or
unsolvable); an error (the task is outside what the planner takes, a crash) or a timeout passes the task to
the next planner. The returned `PlanResult` is the deciding planner's, with `seconds` covering the whole
chain and `attempts` saying, in order, what each planner answered and why. `optimal` is the deciding
planner's own claim (only the in-process planner's proofs and the optimal Fast Downward search set it).
"""
from __future__ import annotations

import time
from typing import Sequence

from .errors import PlannerError
from .registry import PLANNERS, get_planner
from .result import PlannerAttempt, PlanResult, PlanStatus

DEFAULT_CHAIN = ("inproc", "fd-lama")
FINAL_STATUSES = frozenset({PlanStatus.SOLVED, PlanStatus.UNSOLVABLE})


def plan_with_fallback(domain: str, problem: str, planners: Sequence[str], timeout_s: float) -> PlanResult:
    """Run `planners` in order on the PDDL texts within `timeout_s` seconds in total.

    Raises PlannerError before running anything when the list is empty, a name is unknown or the time limit
    is not positive; every other outcome is a status of the returned result.
    """
    if isinstance(planners, str):
        raise PlannerError("planners: expected a sequence of planner names, got one string")
    names = tuple(planners)
    if not names:
        raise PlannerError("planners: the chain names no planner")
    if not isinstance(timeout_s, (int, float)) or not timeout_s > 0:
        raise PlannerError(f"timeout: must be a positive number of seconds, got {timeout_s!r}")
    unknown = [name for name in names if name not in PLANNERS]  # every name checked before anything runs
    if unknown:
        get_planner(unknown[0])  # raises, naming the known planners
    start = time.perf_counter()
    attempts: list[PlannerAttempt] = []
    last: PlanResult | None = None
    for name in names:
        remaining = timeout_s - (time.perf_counter() - start)
        if remaining <= 0:
            attempts.append(PlannerAttempt(name, PlanStatus.TIMEOUT, "not tried: no time left", 0.0))
            continue
        backend = get_planner(name)  # built when reached: a chain the first planner ends builds no other
        result = backend.solve(domain, problem, remaining)
        attempts.append(PlannerAttempt(backend.name, result.status, result.message, result.seconds))
        last = result
        if result.status in FINAL_STATUSES:
            break
    elapsed = time.perf_counter() - start
    if last is None:  # pragma: no cover - the first planner always has time
        return PlanResult(PlanStatus.TIMEOUT, (), elapsed, names[0], "no planner had time", None, tuple(attempts))
    if last.status in FINAL_STATUSES:
        return PlanResult(last.status, last.plan, elapsed, last.planner, last.message, last.optimal, tuple(attempts))
    status = PlanStatus.TIMEOUT if any(a.status is PlanStatus.TIMEOUT for a in attempts) else PlanStatus.ERROR
    summary = "; ".join(f"{a.planner}: {a.status.value}" + (f" ({a.message})" if a.message else "") for a in attempts)
    return PlanResult(status, (), elapsed, last.planner, f"no planner produced a plan: {summary}", None,
                      tuple(attempts))

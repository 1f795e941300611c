"""One fallback policy for every caller: try planners in order, each with the time that is left, and let only a
plan VAL accepts end the chain.

    plan_with_fallback(domain, problem, ("inproc", "fd-lama"), timeout_s=10.0)

A planner's answer ends the chain when it is a plan VAL accepts against the domain and problem *as given* (not a
normalised copy: VAL is the judge of the text the user gave) or a proof that there is none (status unsolvable).
VAL checks the plan itself, or its expansion into the actions its macros stand for when the domain's macros are
proved faithful (`planner.checking`: `PlanResult.checked_by` says which). A plan VAL refuses is an attempt with
status invalid and VAL's reason, and the task goes on to the next planner, as after an error (the task is outside
what the planner takes, a crash) or a timeout. VAL's time comes out of the chain's: a plan on which no validator
gives a verdict in the time left (VAL did not finish, or ended without one) is an attempt with status unvalidated,
its plan kept, and the task goes on; when no later planner ends the chain, that plan is the answer, with status
`unvalidated` and the reason (never "timeout" for a task a planner solved).

`validate=False` skips VAL, for speed: the answer then says so (`PlanResult.validated` is False). The returned
`PlanResult` is the deciding planner's, with `seconds` covering the whole chain (VAL included) and `attempts`
saying, in order, what each planner answered and why. `optimal` is the deciding planner's own claim (only the
in-process planner's proofs and the optimal Fast Downward search set it); it is a claim about the domain as VAL
reads it, which is also what the planners that get a normalised copy read (`planner.normalise`). The
domain's reading notes (an action declared twice: `planner.pddl`) come back as `warnings`.
"""
from __future__ import annotations

import logging
import signal
import time
from dataclasses import replace
from typing import Sequence

from .errors import PlannerError
from .inproc import parsed_domain
from .registry import PLANNERS, get_planner
from .result import PlannerAttempt, PlanResult, PlanStatus
from .checking import check_plan

log = logging.getLogger(__name__)

DEFAULT_CHAIN = ("inproc", "fd-lama")
FINAL_STATUSES = frozenset({PlanStatus.SOLVED, PlanStatus.UNSOLVABLE})


def plan_with_fallback(domain: str, problem: str, planners: Sequence[str], timeout_s: float, *,
                       validate: bool = True, validation_domain: str | None = None) -> PlanResult:
    """Run `planners` in order on the PDDL texts within `timeout_s` seconds in total, VAL included.

    VAL judges the plans against `validation_domain` when given (a caller whose planners read a stricter copy of
    the domain it answers for, as the pipeline's paper-exact domain), else against `domain`.

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
    unvalidated: PlanResult | None = None  # the first plan no validator gave a verdict on
    for name in names:
        remaining = timeout_s - (time.perf_counter() - start)
        if remaining <= 0:
            attempts.append(PlannerAttempt(name, PlanStatus.TIMEOUT, "not tried: no time left", 0.0))
            continue
        backend = get_planner(name)  # built when reached: a chain the first planner ends builds no other
        result = backend.solve(domain, problem, remaining)
        if validate and result.status is PlanStatus.SOLVED:
            result = judged(result, validation_domain or domain, problem, timeout_s - (time.perf_counter() - start))
        attempts.append(PlannerAttempt(backend.name, result.status, result.message, result.seconds))
        last = result
        if result.status is PlanStatus.UNVALIDATED and unvalidated is None:
            unvalidated = result
        if result.status in FINAL_STATUSES:
            break
    elapsed = time.perf_counter() - start
    warnings = reading_warnings(domain)
    if last is None:  # pragma: no cover - the first planner always has time
        return PlanResult(PlanStatus.TIMEOUT, (), elapsed, names[0], "no planner had time", None, tuple(attempts),
                          warnings=warnings)
    if last.status in FINAL_STATUSES:
        return replace(last, seconds=elapsed, attempts=tuple(attempts), warnings=warnings)
    if unvalidated is not None:
        return replace(unvalidated, seconds=elapsed, attempts=tuple(attempts), warnings=warnings)
    status = PlanStatus.TIMEOUT if any(a.status is PlanStatus.TIMEOUT for a in attempts) else PlanStatus.ERROR
    summary = "; ".join(f"{a.planner}: {a.status.value}" + (f" ({a.message})" if a.message else "") for a in attempts)
    return PlanResult(status, (), elapsed, last.planner, f"no planner produced a plan: {summary}", None,
                      tuple(attempts), warnings=warnings)


def judged(result: PlanResult, domain: str, problem: str, remaining_s: float) -> PlanResult:
    """A solved result checked against the texts as given (`planner.checking.check_plan`: VAL on the plan, or on its
    expansion into the actions its faithful macros stand for): validated, invalid with VAL's reason, or unvalidated
    (the plan kept) when no validator gives a verdict in the time left. The check's time is added to the planner's."""
    start = time.perf_counter()
    if remaining_s <= 0:
        return replace(result, status=PlanStatus.UNVALIDATED,
                       message=f"{result.message + '; ' if result.message else ''}no time left for a validator")
    try:
        check = check_plan(domain, problem, result.plan, timeout_s=remaining_s)
    except PlannerError as exc:  # VAL did not answer in the time left
        return replace(result, status=PlanStatus.UNVALIDATED, seconds=result.seconds + time.perf_counter() - start,
                       message=f"no validator finished in the time left: {exc}")
    seconds = result.seconds + check.seconds
    if check.valid:
        return replace(result, seconds=seconds, validated=True, checked_by=check.by.value, check_note=check.note)
    if val_crashed(check.reason):  # no verdict either way: not solved, and not said to be invalid
        log.warning("VAL ended without a verdict on the plan of %s: %s", result.planner, check.reason)
        return replace(result, status=PlanStatus.UNVALIDATED, seconds=seconds,
                       message=f"VAL ended without a verdict on its plan of {len(result.plan)} step(s) "
                               f"({' '.join(check.reason.split())}: out of memory or killed)")
    log.warning("VAL rejected the plan of %s: %s", result.planner, check.reason)
    return replace(result, status=PlanStatus.INVALID, plan=(), optimal=None, seconds=seconds,
                   message=f"VAL rejected its plan of {len(result.plan)} step(s): {check.reason}",
                   checked_by=check.by.value, check_note=check.note)


def val_crashed(reason: str) -> bool:
    """Whether VAL's "reason" says it could not check the plan rather than that the plan is wrong: SIGKILL ended it
    (`planner.validate` says "VAL exit code -9" when VAL printed no reason: killed from outside, as by the kernel
    when memory runs out), or it ran out of memory itself (`std::bad_alloc` under the address space its runs get,
    `planner.validate.VAL_ADDRESS_SPACE_BYTES`). No verdict either way. (VAL's expansion of a conditional effect over
    four angles needs gigabytes at K = 24.) Other signals count as a refusal: this VAL build, for one, ends a "Bad
    plan description!" with a segmentation fault."""
    text = reason.strip()
    return text == f"VAL exit code -{signal.SIGKILL.value}" or "std::bad_alloc" in text.splitlines()[-1:]


def reading_warnings(domain: str) -> tuple[str, ...]:
    """What a planner reading `domain` as VAL does reads differently from its text (empty when it does not
    parse: the planners said what is wrong with it). The parse is the in-process planner's, memoised."""
    try:
        return parsed_domain(domain).warnings
    except PlannerError:
        return ()

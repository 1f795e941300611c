"""VAL runs on a pipeline's plan, against the paper's exact domain: started now (`start_runs`, one process per
piece, on armed processes when given) and judged later (`judge`: the outcome VAL's verdicts make of the plan), or
both at once (`validate`, the library's). A run is a `ValCheck`: nothing here waits for VAL on a thread.

Which runs a plan needs: one on the whole plan, or for a long plan of a domain with conditional effects several
pieces at once (`whole_plan`, see `pieces`); the service's early answer checks only the first motion's pieces
before its answer (`validation`).
"""
from __future__ import annotations

import logging
import time
from dataclasses import replace
from typing import Callable, Iterable, Protocol, Sequence

from planhrc.model import ArticulatedObject
from planhrc.planner.armed import ArmedValidators
from planhrc.planner.errors import PlannerError
from planhrc.planner.fast_downward import has_conditional_effects
from planhrc.planner.validate import ValidationResult, start_validation, total_cpu, validate_plan
from planhrc.translator.translate import PddlTask
from planhrc.vocabulary import PlanningStatus

from .config import PlanningConfig, PlanOutcome, deadline_from
from .pieces import MIN_PIECE_STEPS, ValPiece, validation_pieces

log = logging.getLogger(__name__)

THE_PLAN = "the plan"


class ValCheck(Protocol):
    """A VAL run under way (`planner.validate.ValRun`): its verdict once there is one, and a way to stop it."""

    def verdict(self, timeout_s: float | None = None) -> ValidationResult | None: ...

    def cancel(self) -> None: ...


def validate(outcome: PlanOutcome, obj: ArticulatedObject | None = None, config: PlanningConfig | None = None,
             deadline_at: float | None = None) -> PlanOutcome:
    """VAL on the plan of an outcome made with `defer_validation`: the outcome, now `validated`, or an invalid
    outcome saying why VAL refused it, or a `timeout` outcome when VAL does not finish by `deadline_at`.
    Outcomes without a plan to check come back unchanged.

    With `obj` and `config.val_pieces` > 1, a long plan is checked in pieces at once (one VAL process each, see
    `validation_pieces`); the answer is the one a single run on the whole plan gives."""
    if not outcome.solved or not outcome.actions or outcome.validated or outcome.task is None:
        return outcome
    deadline_at = deadline_at if deadline_at is not None else (
        deadline_from(config) if config is not None else time.monotonic() + 60.0)
    n_pieces = config.val_pieces if config is not None and obj is not None else 1
    t = time.perf_counter()
    try:
        checks = start_runs(outcome.task, whole_plan(obj, outcome, n_pieces))
    except PlannerError as exc:  # VAL cannot run
        return val_timeout(outcome, config, THE_PLAN, str(exc), time.perf_counter() - t)
    judged = judge(outcome, checks, config, deadline_at, THE_PLAN, accepted_whole(outcome))
    assert judged is not None  # waited until the deadline
    return judged


def whole_plan(obj: ArticulatedObject | None, outcome: PlanOutcome, n_pieces: int
               ) -> list[tuple[str, tuple[str, ...]]]:
    """The (problem, steps) runs that check a whole plan: one, or for a long plan of a domain with conditional
    effects `n_pieces` pieces at once (a step costs VAL next to nothing without conditional effects, so such
    plans are checked in one run whatever their length)."""
    assert outcome.task is not None
    if obj is None or n_pieces <= 1 or len(outcome.steps) < 2 * MIN_PIECE_STEPS or not has_conditional_effects(
            outcome.task.validation_domain):
        return [(outcome.task.problem, outcome.steps)]
    return validation_pieces(obj, outcome, n_pieces)


def accepted_whole(outcome: PlanOutcome) -> PlanOutcome:
    return replace(outcome, validated=True, validated_steps=len(outcome.steps))


def start_val(task: PddlTask, steps: Sequence[str], armed: ArmedValidators | None = None) -> ValCheck:
    """One VAL run on a whole plan, started now (on an armed process of the domain when `armed` has one)."""
    if armed is not None:
        return armed.start(task.validation_domain, task.problem, steps)
    return start_validation(task.validation_domain, task.problem, steps)


def start_runs(task: PddlTask, pieces: Iterable[tuple[str, Sequence[str]]], armed: ArmedValidators | None = None
               ) -> tuple[ValCheck, ...]:
    """One VAL run per (problem, steps) piece, all started now, each as soon as `pieces` gives it (a piece built
    lazily has VAL under way on the pieces before it meanwhile)."""
    checks: list[ValCheck] = []
    try:
        for problem, steps in pieces:
            checks.append(armed.start(task.validation_domain, problem, steps) if armed is not None
                          else start_validation(task.validation_domain, problem, steps))
    except BaseException:
        for check in checks:
            check.cancel()
        raise
    return tuple(checks)


def judge(outcome: PlanOutcome, checks: Sequence[ValCheck], config: PlanningConfig | None, deadline_at: float,
          what: str, accepted: PlanOutcome, timeout_s: float | None = None) -> PlanOutcome | None:
    """The outcome VAL's verdicts on `checks` (the runs on `what`, in plan order) make of `outcome`: `accepted`
    when VAL accepted every run, else invalid naming the run VAL refused (the others stopped), or a `timeout` at
    the deadline (every run stopped). Waits up to `timeout_s` (None: until VAL answers or the deadline passes);
    None while VAL still runs within the deadline (the runs go on, to be judged again)."""
    t = time.perf_counter()
    until = deadline_at if timeout_s is None else min(deadline_at, time.monotonic() + timeout_s)
    verdicts: list[ValidationResult] = []
    for check in checks:
        verdict = _wait_verdict(check, until)
        if verdict is None:
            if timeout_s is not None and time.monotonic() < deadline_at:
                return None
            _stop(checks)
            return val_timeout(outcome, config, what, "VAL did not answer in time", time.perf_counter() - t)
        if not verdict.valid:
            _stop(checks)  # the runs still going are stopped: their CPU is not counted
            i = len(verdicts) + 1
            reason = verdict.reason if len(checks) == 1 else f"piece {i} of {len(checks)}: {verdict.reason}"
            refused = ValidationResult(False, reason, verdict.seconds, total_cpu([*verdicts, verdict]))
            return _judged(outcome, refused, lambda: outcome, what)
        verdicts.append(verdict)
    _stop(checks)  # every run answered: only their files are left to clean up
    seconds = max(v.seconds for v in verdicts)
    return _judged(outcome, ValidationResult(True, "Plan valid", seconds, total_cpu(verdicts)), lambda: accepted,
                   what)


def check_piece(domain: str, piece: ValPiece, timeout_s: float, nice: int = 0,
                on_start: Callable[[int], None] | None = None, raising: bool = False,
                armed: ArmedValidators | None = None) -> ValidationResult:
    """VAL on one piece (on `armed`'s VAL when given: a fork server's run, its start-up and the domain's parse done
    once), waited for; a VAL that does not finish within `timeout_s` (or cannot run) is a refusal saying so, or
    with `raising` the PlannerError."""
    try:
        if armed is None:
            return validate_plan(domain, piece.problem, piece.steps, timeout_s, nice=nice, on_start=on_start)
        run = armed.start(domain, piece.problem, piece.steps, nice=nice)
        if on_start is not None:
            on_start(run.pid)
        return run.result(timeout_s)
    except PlannerError as exc:
        if raising:
            raise
        return ValidationResult(False, str(exc), timeout_s)


def _stop(checks: Sequence[ValCheck]) -> None:
    for check in checks:
        check.cancel()  # a run that answered is only cleaned up; one still running is stopped


def _wait_verdict(check: ValCheck, until: float) -> ValidationResult | None:
    """VAL's answer, waited for until `until` (`time.monotonic()`), else None."""
    verdict = check.verdict(max(0.0, until - time.monotonic()))
    while verdict is None and time.monotonic() < until:  # a wait may end a little early
        verdict = check.verdict(max(0.0, until - time.monotonic()))
    return verdict


def _judged(outcome: PlanOutcome, check: ValidationResult, accepted: Callable[[], PlanOutcome], what: str
            ) -> PlanOutcome:
    """The outcome VAL's answer makes of a plan: `accepted()` when VAL accepted it, else invalid with VAL's
    reason (the time VAL took in the timings, and when known the CPU its runs used: `validate_cpu`)."""
    timings = {**outcome.timings, "validate": check.seconds}
    if check.cpu_s is not None:
        timings["validate_cpu"] = check.cpu_s
    if check.valid:
        return replace(accepted(), timings=timings)
    log.warning("plan of %s rejected by VAL: %s", outcome.planner, check.reason)
    return PlanOutcome(PlanningStatus.INVALID, f"VAL rejected {what}: {check.reason}", outcome.planner,
                       timings=timings, task=outcome.task, attempts=outcome.attempts)


def val_timeout(outcome: PlanOutcome, config: PlanningConfig | None, what: str, why: str, seconds: float
                ) -> PlanOutcome:
    limit = f"{config.deadline_s:g} s" if config is not None else "its time limit"
    return PlanOutcome(PlanningStatus.TIMEOUT, f"planning deadline of {limit} exceeded while VAL checked "
                       f"{what} ({why})", outcome.planner, timings={**outcome.timings, "validate": seconds},
                       task=outcome.task, attempts=outcome.attempts)

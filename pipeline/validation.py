"""VAL on a pipeline's plan: the whole plan (`validate`; in pieces at once for a long plan of a domain with
conditional effects), its first pieces only (`validate_first`), or started now and read later (`start_val` then
`finish_val`, `start_pieces` then `finish_first`)."""
from __future__ import annotations

import logging
import time
from dataclasses import replace
from typing import Callable, Protocol, Sequence

from planhrc.model import ArticulatedObject
from planhrc.planner.armed import ArmedValidators
from planhrc.planner.errors import PlannerError
from planhrc.planner.fast_downward import has_conditional_effects
from planhrc.planner.validate import ValidationResult, start_validation, validate_pieces, validate_plan
from planhrc.translator.translate import PddlTask
from planhrc.vocabulary import PlanningStatus

from .config import PlanningConfig, PlanOutcome, deadline_from, time_left
from .pieces import MIN_PIECE_STEPS, ValPiece, validation_pieces

log = logging.getLogger(__name__)


def validate(outcome: PlanOutcome, obj: ArticulatedObject | None = None, config: PlanningConfig | None = None,
             deadline_at: float | None = None) -> PlanOutcome:
    """VAL on the plan of an outcome made with `defer_validation`: the outcome, now `validated`, or an invalid
    outcome saying why VAL refused it, or a `timeout` outcome when VAL does not finish by `deadline_at`.
    Outcomes without a plan to check come back unchanged.

    With `obj` and `config.val_pieces` > 1, a long plan is checked in pieces at once (one VAL process each, see
    `validation_pieces`); the answer is the one a single run on the whole plan gives."""
    if not outcome.solved or not outcome.actions or outcome.validated or outcome.task is None:
        return outcome
    n_pieces = config.val_pieces if config is not None and obj is not None else 1
    return _checked(outcome, config, deadline_at, lambda left: _run_val(outcome, obj, n_pieces, left),
                    lambda: replace(outcome, validated=True, validated_steps=len(outcome.steps)), "the plan")


def validate_first(outcome: PlanOutcome, pieces: Sequence[ValPiece], config: PlanningConfig | None = None,
                   deadline_at: float | None = None, armed: ArmedValidators | None = None) -> PlanOutcome:
    """VAL on the plan's first pieces only (`early_pieces`: the first motion, in one or more pieces checked at
    once): the outcome with `validated_steps` = the last piece's last step (the rest of the plan is *not*
    validated: the caller checks the later pieces before using their steps), or an invalid or `timeout` outcome
    as in `validate`. `start_pieces` then `finish_first`, for a caller with work to do meanwhile."""
    if not outcome.solved or not outcome.actions or outcome.validated or outcome.task is None:
        return outcome
    checks = start_pieces(outcome.task, pieces, armed)
    return finish_first(outcome, pieces, checks, config, deadline_at)


def start_pieces(task: PddlTask, pieces: Sequence[ValPiece], armed: ArmedValidators | None = None
                 ) -> tuple[ValCheck, ...]:
    """One VAL run per piece, all started now (on armed processes when given), against the paper's exact domain."""
    checks: list[ValCheck] = []
    try:
        for piece in pieces:
            checks.append(armed.start(task.validation_domain, piece.problem, piece.steps) if armed is not None
                          else start_validation(task.validation_domain, piece.problem, piece.steps))
    except BaseException:
        for check in checks:
            check.cancel()
        raise
    return tuple(checks)


def finish_first(outcome: PlanOutcome, pieces: Sequence[ValPiece], checks: Sequence[ValCheck],
                 config: PlanningConfig | None, deadline_at: float | None) -> PlanOutcome:
    """The outcome once VAL has answered on every first piece (`start_pieces`): `validated_steps` up to the last
    one when all accepted, else invalid naming the piece VAL refused (the others stopped), or `timeout` at the
    deadline."""
    deadline_at = deadline_at if deadline_at is not None else (
        deadline_from(config) if config is not None else time.monotonic() + 60.0)
    what = f"its first {pieces[-1].last} steps"
    t = time.perf_counter()
    try:
        for i, check in enumerate(checks, start=1):
            verdict = _wait_verdict(check, deadline_at)
            if verdict is None:
                return _val_timeout(outcome, config, what, "VAL did not answer in time", time.perf_counter() - t)
            if not verdict.valid:
                reason = verdict.reason if len(checks) == 1 else f"piece {i} of {len(checks)}: {verdict.reason}"
                return _judged(outcome, ValidationResult(False, reason, verdict.seconds), time.perf_counter() - t,
                               lambda: outcome, what)
    finally:
        for check in checks:
            check.cancel()  # a run that answered is only cleaned up; one still running is stopped
    return _judged(outcome, ValidationResult(True, "Plan valid", 0.0), time.perf_counter() - t,
                   lambda: replace(outcome, validated_steps=pieces[-1].last), what)


def _wait_verdict(check: ValCheck, until: float) -> ValidationResult | None:
    """VAL's answer, waited for until `until` (`time.monotonic()`), else None."""
    verdict = check.verdict(max(0.0, until - time.monotonic()))
    while verdict is None and time.monotonic() < until:  # a wait may end a little early
        verdict = check.verdict(max(0.0, until - time.monotonic()))
    return verdict


def _checked(outcome: PlanOutcome, config: PlanningConfig | None, deadline_at: float | None,
             run: Callable[[float], ValidationResult], accepted: Callable[[], PlanOutcome], what: str
             ) -> PlanOutcome:
    deadline_at = deadline_at if deadline_at is not None else (
        deadline_from(config) if config is not None else time.monotonic() + 60.0)
    t = time.perf_counter()
    try:
        left = time_left(deadline_at)
        if left <= 0:
            raise PlannerError("no time left for VAL")
        check = run(left)
    except PlannerError as exc:  # VAL's time limit: the request's deadline
        return _val_timeout(outcome, config, what, str(exc), time.perf_counter() - t)
    return _judged(outcome, check, time.perf_counter() - t, accepted, what)


def _judged(outcome: PlanOutcome, check: ValidationResult, seconds: float, accepted: Callable[[], PlanOutcome],
            what: str) -> PlanOutcome:
    """The outcome VAL's answer makes of a plan: `accepted()` when VAL accepted it, else invalid with VAL's
    reason (the time VAL took in the timings, as `validate`)."""
    timings = {**outcome.timings, "validate": seconds}
    if check.valid:
        return replace(accepted(), timings=timings)
    log.warning("plan of %s rejected by VAL: %s", outcome.planner, check.reason)
    return PlanOutcome(PlanningStatus.INVALID, f"VAL rejected {what}: {check.reason}", outcome.planner,
                       timings=timings, task=outcome.task, attempts=outcome.attempts)


def _val_timeout(outcome: PlanOutcome, config: PlanningConfig | None, what: str, why: str, seconds: float
                 ) -> PlanOutcome:
    limit = f"{config.deadline_s:g} s" if config is not None else "its time limit"
    return PlanOutcome(PlanningStatus.TIMEOUT, f"planning deadline of {limit} exceeded while VAL checked "
                       f"{what} ({why})", outcome.planner, timings={**outcome.timings, "validate": seconds},
                       task=outcome.task, attempts=outcome.attempts)


class ValCheck(Protocol):
    """A VAL run under way (`planner.validate.ValRun`): its verdict once there is one, and a way to stop it."""

    def verdict(self, timeout_s: float | None = None) -> ValidationResult | None: ...

    def cancel(self) -> None: ...


def start_val(task: PddlTask, steps: Sequence[str], armed: ArmedValidators | None = None) -> ValCheck:
    """VAL started on a plan's steps as one run on the whole plan against the paper's exact domain, e.g. as soon
    as `find_plan` has them, before the expected states are replayed: it runs in its own process (on the other
    core) beside `expect` and whatever the caller does next, and `finish_val` reads its verdict. With `armed`
    (a service's), on a VAL process that has already read the domain. For domains whose plans VAL checks in one
    short run (no conditional effects); the others go through `validate`."""
    if armed is not None:
        return armed.start(task.validation_domain, task.problem, steps)
    return start_validation(task.validation_domain, task.problem, steps)


def finish_val(outcome: PlanOutcome, check: ValCheck, config: PlanningConfig | None, deadline_at: float,
               timeout_s: float | None = None) -> PlanOutcome | None:
    """The outcome of `expect` once the VAL run `start_val` began on its plan has answered (as `validate` would
    make it), waiting up to `timeout_s` (None: until VAL answers or the deadline passes); None while VAL still
    runs within the deadline. At the deadline VAL is stopped and the outcome is a `timeout`. An outcome that is
    not a plan to check stops VAL and comes back unchanged."""
    if not outcome.solved or not outcome.actions:
        check.cancel()
        return outcome
    t = time.perf_counter()
    until = deadline_at if timeout_s is None else min(deadline_at, time.monotonic() + timeout_s)
    verdict = _wait_verdict(check, until)
    if verdict is None:
        if time_left(deadline_at) > 0:
            return None
        check.cancel()
        return _val_timeout(outcome, config, "the plan", "VAL did not answer in time", time.perf_counter() - t)
    return _judged(outcome, verdict, verdict.seconds,
                   lambda: replace(outcome, validated=True, validated_steps=len(outcome.steps)), "the plan")


def _run_val(outcome: PlanOutcome, obj: ArticulatedObject | None, n_pieces: int, timeout_s: float
             ) -> ValidationResult:
    assert outcome.task is not None
    if obj is None or n_pieces <= 1 or len(outcome.steps) < 2 * MIN_PIECE_STEPS or not has_conditional_effects(
            outcome.task.validation_domain):
        return validate_plan(outcome.task.validation_domain, outcome.task.problem, outcome.steps, timeout_s)
    return validate_pieces(outcome.task.validation_domain, validation_pieces(obj, outcome, n_pieces), timeout_s)

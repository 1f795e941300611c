"""The root of every error planhrc raises, and the errors that every layer shares.

Each package keeps one root under `PlanhrcError`: `TranslationError` in the translator, `PlannerError` in the
planner, `KBError` in the service, `SimError` in the simulator, `BenchError` in the benchmarks; the shared modules
raise `PlanhrcError`'s own subclasses (`ModelError`, `TransitionError`, ...). HTTP status codes are chosen only in
the service's API layer."""
from __future__ import annotations


class PlanhrcError(Exception):
    """Root of planhrc's errors; the message names the field or value at fault."""


class DeadlineExceeded(PlanhrcError):
    """Work stopped at its time limit before it had an answer (the in-process planner's own stages, the replay of
    a plan, the store's checks of a plan). Where running out of time is an outcome to report rather than a failure,
    it is a result's status (`PlanStatus.TIMEOUT`, `PlanningStatus.TIMEOUT`), not this exception."""

"""A cooperative time limit for the in-process planner's own work (parsing, grounding, recognising, solving).

External planners are processes killed at their limit (`process.run_limited`); the in-process planner runs in
the caller's thread, so it checks the clock itself: `InprocPlanner.solve` opens `within(timeout_s)` and the
loops whose length grows with the task (grounding, recognition, the dynamic programmes) call `check()`, which
raises `planhrc.errors.DeadlineExceeded` once the limit has passed. The limit lives in a context variable, not
an argument, so that the memoised stages keep their cache keys; each thread (each request) has its own.
"""
from __future__ import annotations

import time
from contextlib import contextmanager
from contextvars import ContextVar
from typing import Iterator

from planhrc.errors import DeadlineExceeded

# The monotonic time at which the innermost `within` block ends (None: no limit). A context variable is per
# thread and per task, so concurrent requests never see each other's limit.
_ends_at: ContextVar[float | None] = ContextVar("planhrc_planner_deadline", default=None)


@contextmanager
def within(seconds: float) -> Iterator[None]:
    """Work inside the block must finish within `seconds` (a nested block cannot extend an outer one)."""
    ends = time.monotonic() + seconds
    outer = _ends_at.get()
    token = _ends_at.set(ends if outer is None else min(ends, outer))
    try:
        yield
    finally:
        _ends_at.reset(token)


def check(where: str) -> None:
    """Raise `DeadlineExceeded` naming `where` when the current limit has passed; free when none is set."""
    ends = _ends_at.get()
    if ends is not None and time.monotonic() > ends:
        raise DeadlineExceeded(f"time limit reached while {where}")

"""VAL behind the answer: a plan's later pieces checked in the background (`LaterPieces`), made and held only by
`validation`, the owner of validation runs.

With the early answer a re-plan is answered once VAL has accepted the plan's first motion; the later pieces are
checked once the plan is stored, while the answer is sent. Their VAL processes start only after the perception's
write and run at a lower priority (nice `BACKGROUND_NICE` above the service's), so that the first motion's VAL
processes, the write and the service's next requests come first: started beside the first motion instead (at the
lower priority, or as soon as the first motion was accepted), they made the answer slower (see the docs' re-planning
page). Each later piece has the store's checks of its steps (their actions and expected states: a `Precheck`, given
with the recorder) before VAL: the answer checked only the first motion's, and a piece's verdict covers both.
"""
from __future__ import annotations

import logging
import os
import signal
import threading
from typing import Callable, Sequence

from planhrc.planner.validate import ValidationResult

from .gate import PieceVerdict, Verdict
from .pieces import ValPiece
from .val_runs import check_piece

log = logging.getLogger(__name__)

BACKGROUND_NICE = 10  # the later pieces' VAL processes run this much nicer than the service
# The later pieces' thread starts its work this long after it is started: the answer it follows is still being sent
# then, and the thread's first piece (the store's checks of its steps, its problem written) is Python that would hold
# the interpreter's lock for up to its switch interval (5 ms) while the answer waits (`planhrc service-bench --parts
# history --formulation bimanual`: 2.2 ms of a 16 ms re-plan, at the median, went to that wait)
START_DELAY_S = 0.02

Recorder = Callable[[PieceVerdict], None]
# The checks of a piece's steps besides VAL (the store's, of their actions and expected states): None when they
# pass, else the refusal in words. A piece they refuse is refused without VAL.
Precheck = Callable[[int, int], "str | None"]


class LaterPieces:
    """VAL on a plan's later pieces, one process at a time, in a background thread; each verdict is handed to
    the recorder once there is one (`attach`, after the plan is stored), and `wait` returns once it is recorded.
    The pieces are given by their step ranges (`pieces`, 1-based, inclusive) and made by `build` in that thread,
    just before VAL checks them (their problems are not written on the answer's path). They are numbered after the
    `accepted` ones (the first motion's, accepted before the answer)."""

    def __init__(self, domain: str, pieces: Sequence[tuple[int, int]], build: Callable[[int, int], ValPiece],
                 timeout_s: float, accepted: Sequence[tuple[int, int]], nice: int = BACKGROUND_NICE,
                 check: Callable[..., ValidationResult] | None = None, start_delay_s: float = START_DELAY_S) -> None:
        self.domain = domain
        self.start_delay_s = start_delay_s
        self.pieces = tuple(pieces)
        self._build = build
        self.accepted = tuple(accepted)  # the step ranges of the pieces VAL accepted before the answer
        self.timeout_s = timeout_s
        self.nice = nice
        self._check = check or check_piece
        self._cond = threading.Condition()
        self._results: dict[int, ValidationResult] = {}  # index in self.pieces -> VAL's answer
        self._claimed: set[int] = set()
        self._done: set[int] = set()  # handed to the recorder (written, or failed to be)
        self._recorder: Recorder | None = None
        self._precheck: Precheck | None = None
        self._groups: set[int] = set()
        self._cancelled = False
        self._started = False

    def number(self, index: int) -> int:
        """The plan's piece number (1-based) of `self.pieces[index]`."""
        return max(1, len(self.accepted)) + index + 1

    def start(self) -> None:
        with self._cond:
            if self._started or self._cancelled:
                return
            self._started = True
        threading.Thread(target=self._run_all, name="planhrc-val-later", daemon=True).start()

    def _run_all(self) -> None:
        """The pieces one after another, in plan order (the next dispatch needs the earliest), after
        `START_DELAY_S`: one core for VAL behind the answer, the other left to the service. Run at once, on the
        absolute 20 x 12 task, they held both cores for most of the pause before a robot's next perception in the
        bench."""
        with self._cond:  # woken at once by `cancel`
            self._cond.wait_for(lambda: self._cancelled, self.start_delay_s)
        for index in range(len(self.pieces)):
            if self._cancelled:
                with self._cond:
                    self._done.update(range(index, len(self.pieces)))
                    self._cond.notify_all()
                return
            self._run(index)

    def _run(self, index: int) -> None:
        first, last = self.pieces[index]
        try:
            refusal = self._precheck(first, last) if self._precheck is not None else None
            if refusal is not None:
                result = ValidationResult(False, refusal, 0.0)
            else:
                result = self._check(self.domain, self._build(first, last), self.timeout_s, self.nice, self._group)
        except Exception as exc:  # a verdict must come whatever happens: no verdict means "refused"
            log.exception("checking a later piece failed")
            result = ValidationResult(False, f"the piece could not be checked: {type(exc).__name__}: {exc}", 0.0)
        with self._cond:
            if self._cancelled:
                self._done.add(index)
                self._cond.notify_all()
                return
            self._results[index] = result
        self._record(index)

    def _group(self, pgid: int) -> None:
        with self._cond:
            self._groups.add(pgid)
            cancelled = self._cancelled
        if cancelled:
            _kill(pgid)

    def attach(self, recorder: Recorder, precheck: Precheck | None = None) -> None:
        """From now on each verdict goes to `recorder` (those already known at once); with `precheck`, each piece
        not yet started has its steps checked by it first (see `Precheck`)."""
        with self._cond:
            self._recorder = recorder
            self._precheck = precheck
            ready = list(self._results)
        for index in ready:
            self._record(index)

    def _record(self, index: int) -> None:
        with self._cond:
            if self._recorder is None or index in self._claimed:
                return
            self._claimed.add(index)
            recorder, result = self._recorder, self._results[index]
        first, last = self.pieces[index]
        verdict = Verdict(result.valid, "Plan valid" if result.valid else result.reason)
        try:
            recorder(PieceVerdict(self.number(index), first, last, verdict, result.seconds, result.cpu_s))
        except Exception:  # the gate finds no verdict in the log and asks VAL again
            log.exception("recording the verdict of a later piece failed")
        with self._cond:
            self._done.add(index)
            self._cond.notify_all()

    def wait(self, first_step: int, timeout_s: float) -> bool:
        """Wait until the verdict of the piece starting at `first_step` is recorded (True), or `timeout_s`."""
        index = next((i for i, (first, _) in enumerate(self.pieces) if first == first_step), None)
        if index is None:
            return True
        with self._cond:
            return self._cond.wait_for(lambda: index in self._done or self._cancelled, max(0.0, timeout_s))

    def cancel(self) -> None:
        """Stop checking (the plan was replaced or the service stops): kill the VAL processes still running."""
        with self._cond:
            self._cancelled = True
            groups = list(self._groups)
            self._cond.notify_all()
        for pgid in groups:
            _kill(pgid)

    @property
    def cancelled(self) -> bool:
        return self._cancelled


def _kill(pgid: int) -> None:
    try:
        os.killpg(pgid, signal.SIGKILL)
    except (ProcessLookupError, PermissionError):
        pass

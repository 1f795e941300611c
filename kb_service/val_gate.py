"""VAL behind the answer: a plan's later pieces checked in the background, and the gate every dispatch passes.

With the early answer (setting `val_early_answer`, domains with conditional effects), a re-plan is answered once
VAL has accepted the plan's *first piece*, the first motion the robot will make, from the perceived state to the
exact expected state after it (`pipeline.validation_pieces`); the plan's later pieces are checked by
`LaterPieces` once the plan is stored, while the answer is sent. Their VAL processes start only after the
perception's write and run at a lower priority (nice `BACKGROUND_NICE` above the service's), so that the first
piece's process, the write and the service's next requests come first: started beside the first piece instead
(at the lower priority, or as soon as the first piece was accepted), they made the answer slower (see the
README's re-planning section).

Every verdict is recorded in the object's event log (`VERDICT_EVENT`, written by the orchestrator), and a step is
dispatched only once the verdict of every piece its motion lies in says *accepted* (`PieceRecord.covering`): a
pending verdict is waited for, a refused piece leads to a re-plan, and a verdict that was never recorded (the
service restarted while VAL ran) is asked of VAL again before the step goes out.
"""
from __future__ import annotations

import logging
import os
import signal
import threading
from dataclasses import dataclass, field
from typing import Any, Callable, Mapping, Sequence

from planhrc.pipeline import ValPiece
from planhrc.planner.errors import PlannerError
from planhrc.planner.validate import ValidationResult, validate_plan

log = logging.getLogger(__name__)

VERDICT_EVENT = "val_verdict"  # one per piece checked after the answer: data plan_id, piece, first_step, ...
WITHHELD_EVENT = "dispatch_withheld"  # a step not dispatched because VAL refused (or has not decided on) its piece
ACCEPTED, REFUSED = "accepted", "refused"
BACKGROUND_NICE = 10  # the later pieces' VAL processes run this much nicer than the service


@dataclass(frozen=True)
class Verdict:
    accepted: bool
    reason: str


@dataclass
class PieceRecord:
    """What the event log says of one plan checked in pieces: the pieces' step ranges (1-based, inclusive) and
    the verdicts recorded so far (piece number, 1-based -> verdict)."""

    plan_id: str
    pieces: tuple[tuple[int, int], ...]
    verdicts: dict[int, Verdict] = field(default_factory=dict)

    @classmethod
    def from_event(cls, plan_id: str, data: Mapping[str, Any]) -> "PieceRecord":
        """The record a plan's adoption event starts (`val_pieces`, `val_accepted`)."""
        record = cls(plan_id, tuple((int(a), int(b)) for a, b in data["val_pieces"]))
        for number in data.get("val_accepted", ()):
            record.verdicts[int(number)] = Verdict(True, "accepted before the answer")
        return record

    def covering(self, first_step: int, last_step: int) -> list[int]:
        """The pieces (1-based numbers) holding any of the steps first_step..last_step."""
        return [i for i, (a, b) in enumerate(self.pieces, start=1) if a <= last_step and first_step <= b]

    def bounds(self, number: int) -> tuple[int, int]:
        return self.pieces[number - 1]


def verdict_data(plan_id: str, number: int, piece: tuple[int, int], verdict: Verdict, seconds: float
                 ) -> dict[str, Any]:
    """The data of a `val_verdict` event."""
    return {"plan_id": plan_id, "piece": number, "first_step": piece[0], "last_step": piece[1],
            "verdict": ACCEPTED if verdict.accepted else REFUSED, "reason": verdict.reason,
            "seconds": round(seconds, 6)}


def verdict_of(data: Mapping[str, Any]) -> Verdict:
    return Verdict(data.get("verdict") == ACCEPTED, str(data.get("reason", "")))


def check_piece(domain: str, piece: ValPiece, timeout_s: float, nice: int = 0,
                on_start: Callable[[int], None] | None = None, raising: bool = False) -> ValidationResult:
    """VAL on one piece; a VAL that does not finish within `timeout_s` (or cannot run) is a refusal saying so,
    or with `raising` the PlannerError."""
    try:
        return validate_plan(domain, piece.problem, piece.steps, timeout_s, nice=nice, on_start=on_start)
    except PlannerError as exc:
        if raising:
            raise
        return ValidationResult(False, str(exc), timeout_s)


class LaterPieces:
    """VAL on a plan's later pieces, one process each, in background threads; each verdict is handed to the
    recorder once there is one (`attach`, after the plan is stored), and `wait` returns once it is recorded."""

    def __init__(self, domain: str, pieces: Sequence[ValPiece], timeout_s: float, nice: int = BACKGROUND_NICE,
                 check: Callable[..., ValidationResult] | None = None,
                 accepted: Sequence[tuple[int, int]] = ()) -> None:
        self.domain = domain
        self.pieces = tuple(pieces)
        self.accepted = tuple(accepted)  # the plan's pieces before these, VAL accepted before the answer (steps)
        self.timeout_s = timeout_s
        self.nice = nice
        self._check = check or check_piece
        self._cond = threading.Condition()
        self._results: dict[int, ValidationResult] = {}  # index in self.pieces -> VAL's answer
        self._claimed: set[int] = set()
        self._done: set[int] = set()  # handed to the recorder (written, or failed to be)
        self._recorder: Callable[[ValPiece, ValidationResult], None] | None = None
        self._groups: set[int] = set()
        self._cancelled = False
        self._started = False

    def start(self) -> None:
        with self._cond:
            if self._started or self._cancelled:
                return
            self._started = True
        threading.Thread(target=self._run_all, name="planhrc-val-later", daemon=True).start()

    def _run_all(self) -> None:
        """The pieces one after another, in plan order (the next dispatch needs the earliest): one core for VAL
        behind the answer, the other left to the service. At once, on the absolute 20 x 12 task (about 7 ms of
        VAL a step, 50 steps behind a first motion) they held both cores for most of the quarter second before a
        robot's next perception in the bench."""
        for index in range(len(self.pieces)):
            if self._cancelled:
                with self._cond:
                    self._done.update(range(index, len(self.pieces)))
                    self._cond.notify_all()
                return
            self._run(index)

    def _run(self, index: int) -> None:
        try:
            result = self._check(self.domain, self.pieces[index], self.timeout_s, self.nice, self._group)
        except Exception as exc:  # a verdict must come whatever happens: no verdict means "refused"
            log.exception("VAL on a later piece failed")
            result = ValidationResult(False, f"VAL could not run: {type(exc).__name__}: {exc}", 0.0)
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

    def attach(self, recorder: Callable[[ValPiece, ValidationResult], None]) -> None:
        """From now on each verdict goes to `recorder` (those already known at once)."""
        with self._cond:
            self._recorder = recorder
            ready = list(self._results)
        for index in ready:
            self._record(index)

    def _record(self, index: int) -> None:
        with self._cond:
            if self._recorder is None or index in self._claimed:
                return
            self._claimed.add(index)
            recorder, result = self._recorder, self._results[index]
        try:
            recorder(self.pieces[index], result)
        except Exception:  # the gate finds no verdict in the log and asks VAL again
            log.exception("recording the verdict of a later piece failed")
        with self._cond:
            self._done.add(index)
            self._cond.notify_all()

    def wait(self, first_step: int, timeout_s: float) -> bool:
        """Wait until the verdict of the piece starting at `first_step` is recorded (True), or `timeout_s`."""
        index = next((i for i, p in enumerate(self.pieces) if p.first == first_step), None)
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

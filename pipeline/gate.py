"""The dispatch gate's logic, pure: a step may leave only once VAL has accepted every piece of its plan that the
motion lies in.

A plan adopted with the early answer (`validation`: its first motion checked before the answer, the rest behind
it) is checked in pieces; `PieceRecord` is what is known of them: their step ranges and the verdicts recorded so
far. `gate` reads a record for one motion. Waiting for a verdict still to come, or asking VAL again for one that
was never recorded, is the caller's (`validation.Validator`).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Mapping

ACCEPTED_BEFORE_THE_ANSWER = "accepted before the answer"  # the reason of a first motion's verdicts


@dataclass(frozen=True)
class Verdict:
    accepted: bool
    reason: str


@dataclass(frozen=True)
class PieceVerdict:
    """VAL's verdict on piece `number` (1-based) of a plan, steps a_first .. a_last, VAL's seconds and CPU seconds
    (None: not known, or no VAL run)."""

    number: int
    first: int
    last: int
    verdict: Verdict
    seconds: float
    cpu_s: float | None = None


@dataclass(frozen=True)
class PieceRecord:
    """One plan checked in pieces: the pieces' step ranges (1-based, inclusive) and the verdicts known so far
    (piece number, 1-based -> verdict)."""

    plan_id: str
    pieces: tuple[tuple[int, int], ...]
    verdicts: Mapping[int, Verdict] = field(default_factory=dict)

    def with_verdict(self, number: int, verdict: Verdict) -> PieceRecord:
        return PieceRecord(self.plan_id, self.pieces, {**self.verdicts, number: verdict})

    def covering(self, first_step: int, last_step: int) -> list[int]:
        """The pieces (1-based numbers) holding any of the steps first_step..last_step."""
        return [i for i, (a, b) in enumerate(self.pieces, start=1) if a <= last_step and first_step <= b]

    def bounds(self, number: int) -> tuple[int, int]:
        return self.pieces[number - 1]


@dataclass(frozen=True)
class GateAnswer:
    """What the record says of one motion: VAL refused a piece it lies in (`refusal`, in words), or a piece it
    lies in has no verdict yet (`missing`, its number), or neither: the motion may leave (`passes`)."""

    refusal: str | None = None
    missing: int | None = None

    @property
    def passes(self) -> bool:
        return self.refusal is None and self.missing is None


def gate(record: PieceRecord | None, plan_id: str, first_step: int, last_step: int) -> GateAnswer:
    """The gate for the motion a_first_step .. a_last_step of plan `plan_id`. A plan without a record of pieces
    (validated whole before it was stored) always passes."""
    if record is None or record.plan_id != plan_id:
        return GateAnswer()
    for number in record.covering(first_step, last_step):
        verdict = record.verdicts.get(number)
        if verdict is None:
            return GateAnswer(missing=number)
        if not verdict.accepted:
            first, end = record.bounds(number)
            return GateAnswer(refusal=f"VAL refused piece {number} of plan {plan_id} (a_{first}..a_{end}): "
                                      f"{verdict.reason}")
    return GateAnswer()

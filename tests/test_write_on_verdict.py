"""The re-plan's write as the unit of work owns it (`unit_of_work.write_on_verdict`), one unit alone: VAL's verdict
read inside the write when it comes in one short run, else before; a write VAL outlasts done again once VAL
answered; a deadline passed stores nothing; VAL's runs stopped whatever fails. The verdict handle is a stand-in
(its VAL runs are the pipeline's, tested with real VAL in test_service_deadline.py and test_val_runs.py)."""
from __future__ import annotations

from types import SimpleNamespace

import pytest

from planhrc.kb_service.store import DeadlineError, ValidationError
from planhrc.kb_service.usecases import unit_of_work
from planhrc.kb_service.usecases.observing import QUIET
from planhrc.pipeline import PlannedTurn, PlanOutcome
from planhrc.vocabulary import PlanningStatus

PLANNED = PlanOutcome(PlanningStatus.SOLVED, "found", "lama")
ACCEPTED = PlanOutcome(PlanningStatus.SOLVED, "found", "lama", validated=True)


class _Verdict:
    """VAL's verdict on a plan (`pipeline.VerdictHandle`'s interface): `None` for the first `late` waits that set a
    time limit, then `final`; every wait and every cancel is logged."""

    def __init__(self, final: PlanOutcome, read_in_write: bool, late: int = 0) -> None:
        self.final, self.read_in_write, self.late = final, read_in_write, late
        self.waits: list[float | None] = []
        self.cancelled = 0

    def outcome(self, timeout_s: float | None = None) -> PlanOutcome | None:
        self.waits.append(timeout_s)
        if timeout_s is not None and self.late > 0:
            self.late -= 1
            return None
        return self.final

    def early_answer(self) -> None:
        return None

    def cancel(self) -> None:
        self.cancelled += 1


def _write_on(verdict: _Verdict, check=lambda: None):
    """`write_on_verdict` with a write that logs what it saw; the log and the write's result."""
    seen: list[str] = []

    def write(new_plan):
        seen.append("begun")
        new = new_plan()  # raises when VAL is late or the deadline passed, as inside a real write
        seen.append(new.outcome.message)
        return new

    context = SimpleNamespace(observer=QUIET)
    planned = PlannedTurn(PLANNED, verdict)
    return seen, lambda: unit_of_work.write_on_verdict(context, "obj-1", planned, check, write)


def test_one_short_run_is_read_inside_the_write_and_a_late_one_is_waited_for_outside():
    verdict = _Verdict(ACCEPTED, read_in_write=True)
    seen, run = _write_on(verdict)
    assert run().outcome is ACCEPTED
    assert seen == ["begun", "found"] and verdict.waits == [unit_of_work.OVERLAP_WAIT_S]

    late = _Verdict(ACCEPTED, read_in_write=True, late=1)
    seen, run = _write_on(late)
    assert run().outcome is ACCEPTED
    # the first write gave up after OVERLAP_WAIT_S, VAL was waited for outside it, the second write read it
    assert seen == ["begun", "begun", "found"]
    assert late.waits == [unit_of_work.OVERLAP_WAIT_S, None, None] and late.cancelled == 0


def test_other_verdicts_are_waited_for_before_the_write():
    verdict = _Verdict(ACCEPTED, read_in_write=False)
    seen, run = _write_on(verdict)
    assert run().outcome is ACCEPTED
    assert verdict.waits == [None, None] and seen == ["begun", "found"]


@pytest.mark.parametrize("read_in_write", [True, False])
def test_a_deadline_passed_raises_and_stops_val(read_in_write):
    timeout = PlanOutcome(PlanningStatus.TIMEOUT, "planning deadline of 1 s exceeded while VAL checked", "lama")
    verdict = _Verdict(timeout, read_in_write=read_in_write)
    seen, run = _write_on(verdict)
    with pytest.raises(DeadlineError, match="^planning: planning deadline of 1 s exceeded while VAL checked$"):
        run()
    assert verdict.cancelled == 1
    assert seen == (["begun"] if read_in_write else [])  # a verdict known before the write: no write begun


def test_a_failing_check_stops_val_before_any_write():
    verdict = _Verdict(ACCEPTED, read_in_write=True)

    def check():
        raise ValidationError("s^e_3 does not follow from a_2")

    seen, run = _write_on(verdict, check)
    with pytest.raises(ValidationError):
        run()
    assert verdict.cancelled == 1 and seen == [] and verdict.waits == []

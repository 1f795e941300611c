"""The service's owner of validation runs (`Validator`): every VAL process a re-plan or a dispatch needs is started,
waited for and stopped here; other modules hold a `VerdictHandle` on a plan's verdict, never a thread or a lock.

How a new plan is checked (`Validator.check`), by what VAL costs on its domain:

* **one short run** (a domain without conditional effects: VAL's fixed cost dominates): one run on the whole plan,
  started as soon as the plan's steps are known (`replan` starts it before the replay), on a VAL process armed
  with the domain. The handle says `read_in_write`: the caller begins its write meanwhile and reads the verdict
  inside it, briefly, so the write overlaps VAL on the other core;
* **the early answer** (setting `val_early_answer`, a domain with conditional effects, a plan longer than its
  first motion by a piece at least): VAL on the first motion only before the answer, in `val_pieces` pieces at
  once; the rest in `later.LaterPieces`, checked behind the answer once the plan is stored (`follow`), each
  verdict handed to the caller's recorder (the service writes it to the object's log). A plan planned elsewhere
  (a planning worker) may have its first motion's VAL started as soon as its steps are known (`start_first`: the
  first motion's steps replayed here), beside the replay of the rest; `check` keeps those runs only for an outcome
  whose steps, first actions and expected states are the ones they were made from (`FirstPieces.matches`), and
  starts them afresh otherwise;
* **otherwise** the whole plan, in `val_pieces` pieces at once for a long plan of such a domain.

The dispatch gate (`gate.gate`) reads the verdicts recorded; a verdict still to come is waited for here
(`wait_piece`), one that will never come (the service restarted while VAL ran) is asked of VAL again (`recheck`).
"""
from __future__ import annotations

import logging
import threading
from dataclasses import dataclass, replace
from functools import partial
from typing import Iterator, Sequence

from planhrc.model import ActionSpec, ArticulatedObject, State
from planhrc.transition import replay
from planhrc.planner.armed import ArmedValidators
from planhrc.planner.errors import PlannerError
from planhrc.planner.fast_downward import has_conditional_effects
from planhrc.translator.domain import read_domain_model
from planhrc.translator.translate import PddlTask, translate
from planhrc.vocabulary import PlanningStatus

from . import val_runs
from .config import PlanningConfig, PlanOutcome, problem_name, time_left
from .gate import PieceVerdict, Verdict
from .later import LaterPieces, Precheck, Recorder
from .motion import first_motion_steps, step_text
from .pieces import MIN_PIECE_STEPS, ValPiece, early_answer_first_piece, piece_bounds, piece_of

log = logging.getLogger(__name__)

# How long a later piece is, at least: cut shorter, the pieces reach fewer joints each (VAL's cost) but the extra VAL
# processes and verdict writes cost more than that saves (absolute 20 x 12, `planhrc bench --replan-only`).
LATER_PIECE_STEPS = 2 * MIN_PIECE_STEPS


@dataclass(frozen=True)
class EarlyAnswer:
    """A plan adopted before VAL checked all of it: its pieces' step ranges (1-based, inclusive) and how many of
    them, from the first, VAL accepted before the answer."""

    pieces: tuple[tuple[int, int], ...]
    accepted: int


@dataclass(frozen=True)
class FirstPieces:
    """VAL on a plan's first motion (`first` steps), started from the plan's steps and the replay of its first ones
    (`actions`, and the `states` s^e_1 .. s^e_(first+1) the pieces start and end in) before the rest was replayed:
    the runs (`checks`) on `pieces`."""

    steps: tuple[str, ...]
    actions: tuple[ActionSpec, ...]
    states: tuple[State, ...]
    first: int
    pieces: tuple[ValPiece, ...]
    checks: tuple[val_runs.ValCheck, ...]

    def matches(self, outcome: PlanOutcome, first: int | None) -> bool:
        """Whether the runs check what `outcome`'s early answer would check: the same steps, the same first motion
        (`first`, from the outcome's actions), the same first actions and expected states."""
        return (first == self.first and outcome.steps == self.steps
                and tuple(outcome.actions[:len(self.actions)]) == self.actions
                and all(outcome.expected_states[i] == state for i, state in enumerate(self.states)))

    def cancel(self) -> None:
        for check in self.checks:
            check.cancel()


class VerdictHandle:
    """VAL's verdict on one new plan, under way in VAL's own processes: `outcome(t)` waits up to t seconds (None:
    until VAL answers or the deadline passes) and gives the checked outcome, or None while VAL still runs;
    `cancel()` stops every run. A plan with nothing to check has its outcome at once (`settled`)."""

    def __init__(self, plan: PlanOutcome, checks: Sequence[val_runs.ValCheck] = (), *, what: str = val_runs.THE_PLAN,
                 accepted: PlanOutcome | None = None, config: PlanningConfig | None = None, deadline_at: float = 0.0,
                 later: LaterPieces | None = None, read_in_write: bool = False) -> None:
        self.plan = plan  # as planned, before VAL's verdict
        self.read_in_write = read_in_write  # one short run: read the verdict inside the write, briefly
        self._checks = tuple(checks)
        self._what = what
        self._accepted = accepted or plan
        self._config = config
        self._deadline_at = deadline_at
        self._later = later
        self._final: PlanOutcome | None = None if self._checks else plan
        # with the early answer: the steps checked before the answer (the first motion's), else None (every step)
        self.steps_before_answer = later.accepted[-1][1] if later is not None and later.accepted else None

    @classmethod
    def settled(cls, outcome: PlanOutcome) -> VerdictHandle:
        return cls(outcome)

    def outcome(self, timeout_s: float | None = None) -> PlanOutcome | None:
        if self._final is not None:
            return self._final
        try:
            judged = val_runs.judge(self.plan, self._checks, self._config, self._deadline_at, self._what,
                                    self._accepted, timeout_s)
        except Exception as exc:  # a failing VAL must not leave the perception without a decision
            self.cancel()
            judged = _error(self.plan, exc)
        if judged is None:
            return None
        self._final = judged
        if self._later is not None and not (judged.solved and judged.validated_steps and not judged.validated):
            self._later.cancel()
            self._later = None
        return judged

    def early_answer(self) -> EarlyAnswer | None:
        """Once `outcome` accepted the plan's first motion with the rest to check behind the answer: its pieces;
        None for a plan checked whole (or refused)."""
        later, final = self._later, self._final
        if later is None or final is None or not (final.solved and final.actions and not final.validated):
            return None
        first = later.accepted or ((1, final.validated_steps),)
        return EarlyAnswer(first + later.pieces, max(1, len(later.accepted)))

    def cancel(self) -> None:
        """Stop every VAL run of this plan (the plan is not adopted, or the request failed)."""
        for check in self._checks:
            check.cancel()
        if self._later is not None:
            self._later.cancel()


class Validator:
    """VAL for the service: armed VAL processes (`planner.armed`), the checks of new plans (`check`), the later
    pieces being checked behind an answer, one plan per object (`follow`, `stop`, `wait_piece`), and VAL asked
    again on a stored plan's piece (`recheck`). `close()` stops them all (the service stops)."""

    def __init__(self, config: PlanningConfig, *, early_answer: bool, merge_macro_steps: bool, armed: bool) -> None:
        self.config = config
        self.early_answer = early_answer and config.validate
        self.merge_macro_steps = merge_macro_steps
        self.armed = ArmedValidators() if armed and config.validate else None
        self._guard = threading.Lock()
        self._later: dict[str, tuple[str, LaterPieces]] = {}  # object id -> (plan id, its later pieces under VAL)

    def close(self) -> None:
        with self._guard:
            runs = [later for _, later in self._later.values()]
            self._later.clear()
        for later in runs:
            later.cancel()
        if self.armed is not None:
            self.armed.close()

    # -- a new plan -------------------------------------------------------------------------------------------
    def beside(self, task: PddlTask | None) -> bool:
        """Whether a plan of this task is checked by one short VAL run (VAL on, no conditional effects), which
        may start as soon as its steps are known."""
        return self.config.validate and task is not None and not has_conditional_effects(task.validation_domain)

    def start_whole(self, task: PddlTask, steps: Sequence[str]) -> val_runs.ValCheck:
        """One VAL run on a whole plan, started now (`beside`)."""
        return val_runs.start_val(task, steps, self.armed)

    def start_first(self, obj: ArticulatedObject, init: State, task: PddlTask, steps: Sequence[str],
                    deadline_at: float) -> FirstPieces | None:
        """VAL on the first motion of a plan whose steps are known and whose expected states are not yet (planned
        here or in a worker, replayed meanwhile), started now, as the early answer would start it (`check`): the
        first motion read from the steps' text (a step's motion is its action and arguments), its steps replayed
        here from `init`. None when the early answer would not check the plan so (VAL off, no early answer, no
        conditional effects, a plan short of a piece after its first motion)."""
        if not (self.early_answer and steps and has_conditional_effects(task.validation_domain)):
            return None
        first = first_motion_steps(obj, steps, self.merge_macro_steps)
        if len(steps) - first < MIN_PIECE_STEPS:
            return None
        prefix = tuple(steps[:first])
        actions, states = replay(read_domain_model(self.config.tbox_path, obj.formulation.value), init, prefix,
                                 deadline_at)
        pieces, checks = self._start_first_pieces(obj, task, steps, states, first)
        return FirstPieces(tuple(steps), actions, tuple(states[i] for i in range(first + 1)), first, pieces, checks)

    def check(self, obj: ArticulatedObject, outcome: PlanOutcome, deadline_at: float,
              started: val_runs.ValCheck | None = None, first_started: FirstPieces | None = None) -> VerdictHandle:
        """VAL on a new plan, started (or, with `started`, already running; with `first_started`, its first
        motion's runs kept when they check what the early answer would) in VAL's processes: the handle on its
        verdict. Nothing to check (no plan, VAL off, validated where it was planned): a settled handle."""
        if not (outcome.solved and outcome.actions) or not self.config.validate or outcome.validated:
            if started is not None:
                started.cancel()
            if first_started is not None:
                first_started.cancel()
            return VerdictHandle.settled(outcome)
        task = outcome.task
        assert task is not None  # a solved plan with actions was translated
        try:
            if started is not None or self.beside(task):
                started = started or self.start_whole(task, outcome.steps)
                return VerdictHandle(outcome, (started,), accepted=val_runs.accepted_whole(outcome),
                                     config=self.config, deadline_at=deadline_at, read_in_write=True)
            first = (early_answer_first_piece(obj, outcome, self.merge_macro_steps) if self.early_answer
                     else None)
            if first_started is not None and not first_started.matches(outcome, first):
                log.warning("the first motion's VAL runs started for a plan of %s do not match its outcome: "
                            "started again", obj.ident)
                first_started.cancel()
                first_started = None
            if first is not None:
                return self._check_first(obj, outcome, task, first, deadline_at, first_started)
            # cold runs: a plan checked whole here is short (or the early answer is off), not worth keeping
            # VAL processes armed with its domain beside the service
            checks = val_runs.start_runs(task, val_runs.whole_plan(obj, outcome, self.config.val_pieces))
            return VerdictHandle(outcome, checks, accepted=val_runs.accepted_whole(outcome), config=self.config,
                                 deadline_at=deadline_at)
        except Exception as exc:  # VAL could not start: the perception still gets a decision
            if started is not None:
                started.cancel()
            if first_started is not None:
                first_started.cancel()
            return VerdictHandle.settled(_error(outcome, exc))

    def _bounds(self, n_steps: int, first: int) -> list[tuple[int, int]]:
        """The early answer's pieces: the first motion (`first` steps) in `val_pieces` pieces, then the rest."""
        # the later pieces are checked on problems narrowed to the joints their steps reach (`piece_of`): the
        # shorter a piece, the fewer joints it reaches, but each costs a VAL process and a verdict's write
        rest = n_steps - first
        return piece_bounds(n_steps, self.config.val_pieces, first, max(1, self.config.val_pieces),
                            max(self.config.val_pieces, rest // LATER_PIECE_STEPS))

    def _first_bounds(self, n_steps: int, first: int) -> list[tuple[int, int]]:
        """The pieces of the first motion (`first` steps) as `_bounds` cuts them."""
        return [(a, b) for a, b in self._bounds(n_steps, first) if b <= first]

    def _start_first_pieces(self, obj: ArticulatedObject, task: PddlTask, steps: Sequence[str],
                            states: Sequence[State], first: int
                            ) -> tuple[tuple[ValPiece, ...], tuple[val_runs.ValCheck, ...]]:
        """The pieces of the first motion (`first` steps) VAL checks before the early answer, and VAL's runs on
        them: each started as soon as its piece is built, so that VAL checks a piece while the next is built."""
        built: list[ValPiece] = []

        def pieces() -> Iterator[tuple[str, tuple[str, ...]]]:
            for a, b in self._first_bounds(len(steps), first):
                built.append(piece_of(obj, task.problem, steps, states, a + 1, b, task.validation_domain))
                yield built[-1].problem, built[-1].steps

        checks = val_runs.start_runs(task, pieces(), self.armed)
        return tuple(built), checks

    def _check_first(self, obj: ArticulatedObject, outcome: PlanOutcome, task: PddlTask, first: int,
                     deadline_at: float, started: FirstPieces | None = None) -> VerdictHandle:
        """The early answer: the first motion (its first `first` steps) in `val_pieces` pieces checked at once
        (VAL's cost grows with the steps of such a domain, so pieces at once answer sooner than one run; with
        `started`, those runs already under way), the rest of the plan left to `LaterPieces`."""
        bounds = self._bounds(len(outcome.steps), first)
        if started is None:
            before, checks = self._start_first_pieces(obj, task, outcome.steps, outcome.expected_states, first)
        else:
            before, checks = started.pieces, started.checks

        def build(a: int, b: int) -> ValPiece:
            return piece_of(obj, task.problem, outcome.steps, outcome.expected_states, a, b, task.validation_domain)

        try:
            later = LaterPieces(task.validation_domain, tuple((a + 1, b) for a, b in bounds[len(before):]), build,
                                self.config.deadline_s, accepted=tuple((p.first, p.last) for p in before),
                                check=partial(val_runs.check_piece, armed=self.armed))
        except BaseException:
            for check in checks:
                check.cancel()
            raise
        return VerdictHandle(outcome, checks, what=f"its first {before[-1].last} steps",
                             accepted=replace(outcome, validated_steps=before[-1].last), config=self.config,
                             deadline_at=deadline_at, later=later)

    # -- plans behind the answer --------------------------------------------------------------------------------
    def follow(self, object_id: str, plan_id: str | None, handle: VerdictHandle | None, record: Recorder,
               precheck: Precheck | None = None) -> None:
        """The object's plan is now `plan_id` (None: it has none): stop checking the previous plan's later pieces;
        when `handle`'s plan was adopted on its early answer, check its later pieces now, behind the answer (each
        first by `precheck` when given, then by VAL), and hand each verdict to `record`."""
        later = handle._later if handle is not None and handle.early_answer() is not None else None
        with self._guard:
            previous = self._later.pop(object_id, None)
            if later is not None and plan_id is not None:
                self._later[object_id] = (plan_id, later)
        if previous is not None and previous[1] is not later:
            previous[1].cancel()
        if later is not None and plan_id is not None:
            later.attach(record, precheck)
            later.start()  # only now: the first motion's VAL and the write had the cores to themselves

    def stop(self, object_id: str) -> None:
        """The object's plan is being replaced: its later pieces need no more checking."""
        with self._guard:
            previous = self._later.pop(object_id, None)
        if previous is not None:
            previous[1].cancel()

    def wait_piece(self, object_id: str, plan_id: str, first_step: int, timeout_s: float) -> bool | None:
        """Wait until the verdict on the piece of `plan_id` starting at `first_step` is recorded (True) or
        `timeout_s` passes (False); None when no check of that plan is under way here (the verdict will not
        come: `recheck`)."""
        with self._guard:
            running = self._later.get(object_id)
        if running is None or running[0] != plan_id or running[1].cancelled:
            return None
        return running[1].wait(first_step, timeout_s)

    def recheck(self, obj: ArticulatedObject, init: State, goal: State, actions: Sequence[ActionSpec],
                expected_states: Sequence[State], number: int, first: int, last: int, deadline_at: float
                ) -> PieceVerdict:
        """VAL on piece `number` (a_first .. a_last) of a stored plan, built again from its problem's states, its
        actions in plan order and its expected states. PlannerError when VAL does not answer by `deadline_at`."""
        task = translate(obj, init, goal, read_domain_model(self.config.tbox_path, obj.formulation.value),
                         problem_name(obj))
        piece = piece_of(obj, task.problem, tuple(step_text(a) for a in actions), expected_states, first, last,
                         task.validation_domain)
        left = time_left(deadline_at)
        if left <= 0:
            raise PlannerError("no time left for VAL")
        result = val_runs.check_piece(task.validation_domain, piece, left, raising=True, armed=self.armed)
        verdict = Verdict(result.valid, "Plan valid" if result.valid else result.reason)
        return PieceVerdict(number, first, last, verdict, result.seconds, result.cpu_s)


def _error(outcome: PlanOutcome, exc: Exception) -> PlanOutcome:
    log.exception("VAL failed on a plan of %s", outcome.planner)
    return PlanOutcome(PlanningStatus.ERROR, f"{type(exc).__name__}: {exc}", outcome.planner)

"""A plan cut into pieces for VAL: each piece from an expected state to exactly the next cut's expected state, so
that VAL's verdicts on the pieces say what one run on the whole plan says (`validation_pieces`)."""
from __future__ import annotations

from dataclasses import dataclass, replace
from functools import lru_cache
from typing import Sequence

from planhrc.control import possible_control
from planhrc.model import CONTROL_PREDICATES, HAS_ORIENTATION, ArticulatedObject, Atom, State, format_atom
from planhrc.planner.fast_downward import has_conditional_effects
from planhrc.planner.scope import ProblemParts, narrow_parts, narrow_problem

from .config import PlanOutcome
from .motion import first_motion_steps


# VAL's fixed cost (start, parse, ground the problem) is what a short piece costs: a piece shorter than this is
# not worth a process of its own. Without conditional effects a step costs VAL next to nothing (a long relative
# plan checks faster in one run than in two pieces), so only plans of domains with conditional effects, whose
# steps each cost VAL much more, are cut (`planhrc bench --replan-only` shows VAL's share of a re-plan).
MIN_PIECE_STEPS = 8


def validation_pieces(obj: ArticulatedObject, outcome: PlanOutcome, n_pieces: int, first_steps: int | None = None
                      ) -> list[tuple[str, tuple[str, ...]]]:
    """Cut a solved outcome's plan into at most `n_pieces` consecutive pieces of nearly equal length, each a
    (problem, steps) pair for VAL: piece i starts from the expected state s^e_(c_i) and its goal is the *exact*
    next cut state s^e_(c_(i+1)) (every fluent atom of it, and the negation of every other one); the
    last piece's goal is the task's own goal (the first piece starts from the task's initial state). With
    `first_steps`, the first piece is the plan's first `first_steps` steps and the rest is cut as above
    (`piece_bounds`).

    Why the pieces say what one run says: hasorientation (and in the bimanual formulation the robot's control
    facts) are the only predicates any action changes, and every piece's problem has the task's objects and
    static facts (less the objects its steps cannot reach, which changes no answer of VAL's: `planner.scope`).
    Induction over the pieces: VAL's state before
    piece i is s^e_(c_i) (for i = 1 the task's init); VAL accepts piece i only if each of its steps is
    applicable in turn and the state it ends in satisfies the exact goal, i.e. *is* s^e_(c_(i+1)); so one run
    on the whole plan applies the same steps to the same states and ends where the last piece ends, in a state
    satisfying the goal. When the pieces are accepted, the whole plan is. (A piece can only be refused
    wrongly if an expected state is wrong, which makes the plan unusable anyway.) The same induction makes an
    accepted *first* piece mean: from the perceived state, its steps apply one after the other and end exactly
    in the expected state after them, whatever the later pieces' verdicts."""
    return [(p.problem, p.steps) for p in early_pieces(obj, outcome, n_pieces, first_steps)]


@dataclass(frozen=True)
class ValPiece:
    """One piece of a plan for VAL: steps a_first .. a_last (1-based, inclusive) and the problem they solve."""

    first: int
    last: int
    problem: str
    steps: tuple[str, ...]


def piece_bounds(n_steps: int, n_pieces: int, first_steps: int | None = None, first_parts: int = 1,
                 rest_pieces: int | None = None) -> list[tuple[int, int]]:
    """The pieces of a plan of `n_steps` steps as 0-based half-open (start, end) step ranges: `n_pieces` of
    nearly equal length, none shorter than MIN_PIECE_STEPS unless the plan is; with `first_steps`, the first
    `first_steps` steps as `first_parts` pieces of nearly equal length (at least one step each: they are checked
    at once before an answer, where VAL's cost per step matters more than its fixed cost), then the rest cut the
    same way into `rest_pieces` (default `n_pieces`)."""
    if first_steps is not None and 0 < first_steps < n_steps:
        rest = piece_bounds(n_steps - first_steps, n_pieces if rest_pieces is None else rest_pieces)
        parts = max(1, min(first_parts, first_steps))
        cuts = [round(i * first_steps / parts) for i in range(parts + 1)]
        return ([(cuts[i], cuts[i + 1]) for i in range(parts)]
                + [(first_steps + a, first_steps + b) for a, b in rest])
    n = min(n_pieces, max(1, n_steps // MIN_PIECE_STEPS))
    cuts = [round(i * n_steps / n) for i in range(n + 1)]
    return [(cuts[i], cuts[i + 1]) for i in range(n)]


def early_pieces(obj: ArticulatedObject, outcome: PlanOutcome, n_pieces: int, first_steps: int | None = None,
                 first_parts: int = 1, rest_pieces: int | None = None) -> tuple[ValPiece, ...]:
    """The pieces of `validation_pieces` (the first `first_steps` in `first_parts` pieces, the rest in
    `rest_pieces`), with their step ranges."""
    assert outcome.task is not None
    bounds = piece_bounds(len(outcome.steps), n_pieces, first_steps, first_parts, rest_pieces)
    return tuple(piece_of(obj, outcome.task.problem, outcome.steps, outcome.expected_states, a + 1, b,
                          outcome.task.validation_domain) for a, b in bounds)


def piece_of(obj: ArticulatedObject, task_problem: str, steps: Sequence[str], states: Sequence[State],
             first: int, last: int, domain: str | None = None) -> ValPiece:
    """The piece of a plan (`steps`, expected states `states`, task problem text) holding steps a_first .. a_last:
    from s^e_first (the task's own init for the first piece) to exactly s^e_(last+1), or to the task's goal for
    the last piece. With the validation `domain`, the problem leaves out the objects the piece's steps cannot reach
    (`planner.scope.narrow_problem`: VAL's answer is the same, and a piece late in a plan costs VAL much less)."""
    a, b = first - 1, last
    piece_steps = tuple(steps[a:b])
    whole = a == 0 and b == len(steps)  # the task's own problem
    goal = None if b == len(steps) else states[b]
    parts = None if whole else _piece_parts(obj, states[a], goal, task_problem)
    if parts is not None:
        problem = parts.text() if domain is None else narrow_parts(domain, parts, piece_steps)
    else:  # the task's problem, or a task text of another shape: written, then read again to be narrowed
        problem = task_problem if whole else _problem_text(obj, states[a], goal, task_problem)
        if domain is not None:
            problem = narrow_problem(domain, problem, piece_steps)
    return ValPiece(first, last, problem, piece_steps)


def early_answer_first_piece(obj: ArticulatedObject, outcome: PlanOutcome, merge: bool) -> int | None:
    """The length of the first piece to validate before answering, or None when the whole plan is checked
    before the answer: plans of domains without conditional effects (VAL checks them whole in a few ms) and
    plans whose rest after the first motion is shorter than MIN_PIECE_STEPS."""
    if outcome.task is None or not outcome.steps or not has_conditional_effects(outcome.task.validation_domain):
        return None
    first = first_motion_steps(obj, outcome.actions, merge)
    if len(outcome.steps) - first < MIN_PIECE_STEPS:
        return None
    return first


def _problem_text(obj: ArticulatedObject, start: State, exact_goal: State | None, task_problem: str) -> str:
    """A VAL problem with the task's objects and static facts, starting from `start`, whose goal is
    `exact_goal` exactly (each of its fluent atoms, and the negation of every other one) or, when it is None,
    the task's own goal. Written from the task's text (only the fluent lines of its init and its goal change):
    the static facts are not sorted and written again for every piece."""
    head, rest = task_problem.split(_INIT, 1)
    init, goal = rest.split(_GOAL, 1)
    static = "".join(line for line in init.splitlines(keepends=True)
                     if not line.startswith(_FLUENT_LINES) and line != _CLOSE)
    fluents = "".join(f"    {format_atom(a)}\n" for a in sorted(_fluents(start)))
    goal_text = _GOAL + (goal if exact_goal is None else "".join(line for line, _, _ in _exact_goal(obj, exact_goal)))
    return head + _INIT + static + fluents + _CLOSE + goal_text


def _exact_goal(obj: ArticulatedObject, exact_goal: State) -> list[tuple[str, bool, Atom | None]]:
    """The goal's lines (and the problem's close) for the goal `exact_goal` exactly: each of its fluent atoms, and
    the negation of every other one; each with whether it is negated and its atom, as `ProblemParts.read` reads
    them (None: the close's lines)."""
    wanted = _fluents(exact_goal)
    return ([(f"    {format_atom(a)}\n", False, a) for a in sorted(wanted)]
            + [(f"    (not {format_atom(a)})\n", True, a) for a in (
                (HAS_ORIENTATION, o, j) for j in obj.joints for o in obj.orientation_names)
               if a not in wanted]
            + [(f"    (not {format_atom(a)})\n", True, a) for a in sorted(possible_control(obj) - wanted)]
            + [("  ))\n", False, None), (")\n", False, None)])


def _piece_parts(obj: ArticulatedObject, start: State, exact_goal: State | None, task_problem: str
                 ) -> ProblemParts | None:
    """The parts (`planner.scope.ProblemParts`) of the problem `_problem_text` writes, built from the task's parts
    (read once for all the pieces of its plans) and the states, without writing that text and reading it again;
    None for a task text of another shape (`_problem_text` is then written and read)."""
    task = _task_parts(task_problem)
    if task is None:
        return None
    parts, static = task
    init = static + [(f"    {format_atom(a)}", a) for a in sorted(_fluents(start))]
    if exact_goal is None:
        return replace(parts, init=init)
    return replace(parts, init=init, goal=_exact_goal(obj, exact_goal))


@lru_cache(maxsize=8)
def _task_parts(task_problem: str) -> tuple[ProblemParts, list[tuple[str, Atom]]] | None:
    """A task problem's parts and its static init facts (every init fact but the fluents), or None when the parts
    do not give the text back, or the text has lines between its init and its goal (`_problem_text` would move
    them): kept for the last few tasks, whose plans' pieces are built from them."""
    parts = ProblemParts.read(task_problem)
    if parts is None or parts.middle or parts.text() != task_problem:
        return None
    return parts, [(line, atom) for line, atom in parts.init if not line.startswith(_FLUENT_LINES)]


# The parts of a problem written by `translator.problem.write_problem` that `_problem_text` cuts at.
_INIT, _GOAL, _CLOSE = "  (:init\n", "  (:goal (and\n", "  )\n"
_FLUENT_PREDICATES = frozenset({HAS_ORIENTATION}) | CONTROL_PREDICATES
_FLUENT_LINES = tuple(f"    ({name} " for name in sorted(_FLUENT_PREDICATES)) + tuple(
    f"    ({name})" for name in sorted(_FLUENT_PREDICATES))


def _fluents(state: State) -> State:
    return frozenset(a for a in state if a[0] in _FLUENT_PREDICATES)

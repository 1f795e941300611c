"""A VAL problem for some steps without the objects those steps cannot reach (`narrow_problem`): VAL answers it as it
answers the problem it came from, and costs less.

Why: VAL instantiates a quantified effect for every object of the quantified types at every step. The absolute
domain's `(forall (?j2 - joint ?o3 ?o4 - orientation) (when (and (affected ?j2 ?l1 ?j1) ...) ...))` costs VAL
joints x orientations² instances per step, whatever the step: on a piece of a plan that turns only the last few
joints, most of them are joints the step cannot move. A plan turns the joints roughly in chain order, so the later a
piece of it, the fewer joints its steps can reach.

What is dropped, and why VAL's answer stays the same. Read from the domain as VAL reads it (`planner.pddl`): every
quantified variable of every conditional effect must be bound by a positive literal of its condition on a static
predicate (no effect changes it) whose other arguments are the action's parameters (`affected ?j2 ?l1 ?j1`); else
nothing is dropped. The objects a step *reaches* are its arguments and, per quantified variable, the values the
problem's static facts give that literal under the step's arguments. An object of a quantified type that no step
reaches is dropped, with every fact and goal literal naming it, provided that every goal literal naming it holds in
the initial state (else the problem is kept whole: VAL must refuse it as the whole one would). Then, step by step:

* an instance of a conditional effect whose quantified variable is a dropped object needs a static fact the problem
  does not have (that object is not reached), so it never fires: no fact naming a dropped object ever changes;
* every precondition and every condition of the other instances names only the step's arguments and kept objects,
  whose facts are the same in both problems: each step applies in one exactly when it applies in the other, with
  the same effects;
* the goal literals naming dropped objects held initially and their facts never change, so they hold at the end;
  the others are the narrowed problem's goal.

So VAL accepts the steps on the narrowed problem exactly when it accepts them on the whole one. Then the objects of
the quantified types that no relaxed run of the steps ever holds (an orientation no joint holds or is turned to,
bound through a fluent fact rather than a static one: `planner.held`, with its own argument) are dropped from that
problem the same way. The problem text is read line by line as `translator.problem.write_problem` writes it (the
objects of a type on one line, one fact per line); a text of another shape is kept whole.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import Sequence

from planhrc.model import EQUALITY, Atom

from .errors import PlannerError
from .held import Facts, Relaxed, held_objects, relaxed_of
from .operators import read_operators

_OBJECTS, _INIT, _GOAL, _CLOSE = "  (:objects\n", "  (:init\n", "  (:goal (and\n", "  )\n"


@dataclass(frozen=True)
class _Reach:
    """How a step of one action reaches objects of a quantified type: its parameters of that type (positions), and
    per quantified variable a static literal binding it: (predicate, the variable's position in it, for every other
    position the action parameter it holds)."""

    parameters: tuple[int, ...]
    literals: tuple[tuple[str, int, tuple[tuple[int, int], ...]], ...]


@dataclass(frozen=True)
class _Scope:
    types: frozenset[str]  # the quantified types: objects of these may be dropped
    reach: dict[str, dict[str, _Reach]]  # action -> type -> how a step reaches its objects


@dataclass(frozen=True)
class ProblemParts:
    """A problem's text cut where `narrow_problem` edits it: its objects by type, its init facts and its goal
    literals, each with its line and read once; `text()` is the text they were read from. A caller that writes a
    problem from parts of another (`pipeline.pieces`) builds its parts directly rather than writing the text and
    reading it again."""

    head: str
    objects_text: str  # the objects' lines, as read
    objects: dict[str, list[str]]
    between: str
    init: list[tuple[str, Atom]]  # (line, fact)
    middle: str
    goal: list[tuple[str, bool, Atom | None]]  # (line with its end, negated, atom; None: not a literal's line)

    @classmethod
    def read(cls, problem: str) -> ProblemParts | None:
        try:
            head, rest = problem.split(_OBJECTS, 1)
            objects_text, rest = rest.split(_CLOSE, 1)
            between, rest = rest.split(_INIT, 1)
            init_text, rest = rest.split(_CLOSE, 1)
            middle, goal_and_tail = rest.split(_GOAL, 1)
        except ValueError:
            return None
        objects: dict[str, list[str]] = {}
        for line in objects_text.splitlines():
            names, dash, kind = line.rpartition(" - ")
            if dash:
                objects[kind.strip()] = names.split()
        goal: list[tuple[str, bool, Atom | None]] = []
        for line in goal_and_tail.splitlines(keepends=True):
            text = line.strip()
            negated = text.startswith("(not ")
            goal.append((line, negated, _atom(text[5:-1] if negated else text) if line.startswith("    (") else None))
        return cls(head, objects_text, objects, between, [(line, _atom(line)) for line in init_text.splitlines()],
                   middle, goal)

    def text(self) -> str:
        """The problem's text, as `read` cuts it: the text read, for a text of the shape `write_problem` writes."""
        return (self.head + _OBJECTS + self.objects_text + _CLOSE + self.between + _INIT
                + "".join(f"{line}\n" for line, _ in self.init) + _CLOSE + self.middle + _GOAL
                + "".join(line for line, _, _ in self.goal))

    def goal_holds_initially(self, dropped: set[str], before: set[str]) -> bool:
        """Whether every goal literal naming an object of `dropped` (and none of `before`, dropped already) holds
        in the initial state."""
        named = [(negated, atom) for _, negated, atom in self.goal
                 if atom is not None and not dropped.isdisjoint(atom[1:]) and before.isdisjoint(atom[1:])]
        if not named:
            return True
        init = {atom for _, atom in self.init}
        return all((atom in init) != negated for negated, atom in named)

    def without(self, dropped: set[str]) -> str:
        """The problem's text without the objects `dropped` and every fact and goal literal naming them."""
        kept_objects = "".join(
            f"    {' '.join(n for n in names if n not in dropped)} - {kind}\n" for kind, names in self.objects.items()
            if any(n not in dropped for n in names))
        kept_init = "".join(f"{line}\n" for line, atom in self.init if dropped.isdisjoint(atom[1:]))
        kept_goal = "".join(line for line, _, atom in self.goal if atom is None or dropped.isdisjoint(atom[1:]))
        return (self.head + _OBJECTS + kept_objects + _CLOSE + self.between + _INIT + kept_init + _CLOSE
                + self.middle + _GOAL + kept_goal)


def narrow_problem(domain: str, problem: str, steps: Sequence[str]) -> str:
    """`problem` without the objects of quantified types that `steps` cannot reach (see the module's note), then
    without those of the rest no relaxed run of the steps ever holds (`planner.held`), or `problem` itself when
    nothing can be dropped or the domain, the text or a step does not allow it."""
    if not steps:
        return problem
    read = ProblemParts.read(problem)
    if read is None:
        return problem
    return narrow_parts(domain, read, steps, problem)


def narrow_parts(domain: str, read: ProblemParts, steps: Sequence[str], text: str | None = None) -> str:
    """`narrow_problem` on a problem's parts: the narrowed text, or the whole problem's (`text`, else
    `read.text()`) when nothing can be dropped."""
    def whole() -> str:
        return text if text is not None else read.text()

    if not steps:
        return whole()
    scope, relaxed = _scope_of(domain), relaxed_of(domain)
    if scope is None and relaxed is None:
        return whole()
    # the static facts (of the predicates no action changes), indexed once for both narrowings
    fluent = read_operators(domain).fluent
    statics = _static_facts("\n".join(line for line, atom in read.init if atom and atom[0] not in fluent))
    dropped: set[str] = set()
    if scope is not None:
        unreached = _unreached(scope, read, steps, statics)
        if unreached is None:
            return whole()  # a step VAL refuses on the whole problem
        if unreached and read.goal_holds_initially(unreached, set()):
            dropped |= unreached
    if relaxed is not None:
        never = _never_held(relaxed, read, steps, dropped, statics)
        if never and read.goal_holds_initially(never, dropped):
            dropped |= never
    return read.without(dropped) if dropped else whole()


def _unreached(scope: _Scope, read: ProblemParts, steps: Sequence[str], statics: Facts) -> set[str] | None:
    """The objects of the scope's types that no step reaches (by the problem's `statics`); None when a step is not
    an action of the domain or lacks arguments."""
    reached: dict[str, set[str]] = {kind: set() for kind in scope.types}
    for step in steps:
        name, *args = step.strip().strip("()").lower().split()
        by_type = scope.reach.get(name)
        if by_type is None:
            return None
        for kind, reach in by_type.items():
            try:
                reached[kind].update(args[i] for i in reach.parameters)
                for predicate, pos, others in reach.literals:
                    fixed = [(at - 1, args[param]) for at, param in others]
                    first_at, first_value = fixed[0] if fixed else (None, "")
                    reached[kind].update(values[pos - 1] for values in statics.matching(predicate, first_at,
                                                                                       first_value)
                                         if len(values) == len(others) + 1
                                         and all(values[at] == value for at, value in fixed))
            except IndexError:
                return None
    return {name for kind in scope.types for name in read.objects.get(kind, ()) if name not in reached[kind]}


def _never_held(relaxed: Relaxed, read: ProblemParts, steps: Sequence[str], dropped: set[str], static: Facts
                ) -> set[str]:
    """The objects of the relaxed run's types, of the problem without `dropped`, that the run does not keep."""
    initial = [atom for _, atom in read.init if atom and atom[0] in relaxed.fluent and dropped.isdisjoint(atom[1:])]
    objects = {kind: [n for n in names if n not in dropped] for kind, names in read.objects.items()}
    kept = held_objects(relaxed, static, initial, steps, objects)
    if kept is None:
        return set()
    return {name for kind in relaxed.types for name in objects.get(kind, ()) if name not in kept}


@lru_cache(maxsize=8)
def _static_facts(lines: str) -> Facts:
    """A problem's static facts (`lines`, as the problem writes them), indexed, for both narrowings. Kept for the
    last few problems: the pieces of a plan, and an object's re-plans, share their static facts (20,000 lines of an
    absolute 200-link problem)."""
    return Facts(_atom(line) for line in lines.splitlines())


def _atom(text: str) -> tuple[str, ...]:
    """`(pred a b)` -> ('pred', 'a', 'b'): a fact or goal line as `write_problem` writes it."""
    return tuple(text.strip().strip("()").split())


@lru_cache(maxsize=8)
def _scope_of(domain: str) -> _Scope | None:
    """What `narrow_problem` needs of a domain, or None when its quantified effects are not all bound by static
    literals on the action's parameters (nothing is then dropped)."""
    try:
        read = read_operators(domain)
    except PlannerError:
        return None
    operators, fluent = read.operators, read.fluent
    types = {kind for op in operators for block in op.effects for _, kind in block.variables}
    if not types or any(parent in types for _, parent in read.types):
        return None  # no quantified effect, or a subtype a quantifier also ranges over
    literals: dict[tuple[str, str], list[tuple[str, int, tuple[tuple[int, int], ...]]]] = {}
    for op in operators:
        names = [var for var, _ in op.parameters]
        for block in op.effects:
            for var, kind in block.variables:
                bound = next((lit for lit in block.condition if not lit.negated and lit.predicate != EQUALITY
                              and lit.predicate not in fluent and lit.args.count(var) == 1
                              and all(a == var or a in names for a in lit.args)), None)
                if bound is None:  # (orientations: bound through a fluent: none dropped here, `held`)
                    types.discard(kind)
                    continue
                pos = bound.args.index(var) + 1
                others = tuple((at, names.index(a)) for at, a in enumerate(bound.args, start=1) if a != var)
                literals.setdefault((op.name, kind), []).append((bound.predicate, pos, others))
    if not types:
        return None
    reach = {op.name: {kind: _Reach(tuple(i for i, (_, t) in enumerate(op.parameters) if t == kind),
                                    tuple(literals.get((op.name, kind), ()))) for kind in types}
             for op in operators}
    return _Scope(frozenset(types), reach)

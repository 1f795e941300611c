"""The objects some steps may ever name in a true fact (`held_objects`): a relaxed run of the steps, which keeps every
fact once made true, tells which objects of a quantified type VAL never needs for them (`planner.scope`).

Why this narrowing is separate from `scope`'s: there an object is dropped when no step's static facts reach it
(a joint upstream of every turn). An orientation is reached by every turn of the bimanual and absolute domains'
`(forall (?j2 - joint ?o3 ?o4 - orientation) (when (and (affected ?j2 ?l1 ?j1) (hasorientation ?o3 ?j2)
(orientationord ?o3 ?o4)) ...))`: it is bound through a fluent fact, not a static one. What bounds it instead is
the run: an orientation no joint ever holds, no turn ever makes a joint hold and no step names plays no part in
the steps' check, and VAL instantiates the quantified effect over joints x orientations² at every step whatever
it plays.

The relaxed run. F_0 is the problem's initial fluent facts; step t adds to F_(t-1) every add effect of the step
whose condition's positive literals (equality aside) hold in F_(t-1) and the static facts, for every binding of
the effect's quantified variables (objects of their types). Nothing is ever deleted, no precondition is asked.
The kept objects are the steps' arguments, every object of a fact of F_k and every object of a binding found.

Why VAL answers the problem without the other objects (of the quantified types; with every fact and goal literal
naming them) as it answers the whole one, when every goal literal naming them holds initially (else the caller
keeps the problem whole): by induction over the steps, the whole problem's state before step t has its fluent
facts in F_(t-1) (each was initial or added by an effect instance that fired, whose positive condition held in
that state, hence in F_(t-2) and the static facts: the relaxed run found its binding). So

* an instance of a quantified effect binding a dropped object never fires in the whole problem: had it fired,
  its condition's positive literals would have held in F and the static facts, and the relaxed run would have
  kept every object of its binding. This needs every quantified variable to occur in a positive literal of its
  condition (other than equality), else no object of its type is dropped;
* no fluent fact naming a dropped object ever holds in the whole problem (it would be in F), and the narrowed
  problem has exactly the whole one's facts on kept objects: every precondition (a conjunction of literals on the
  step's arguments, all kept: `planner.operators` reads no quantified precondition) and every condition of the
  other instances has the same truth in both, so each step applies in one exactly when it applies in the other,
  with the same effects on kept objects;
* a goal literal naming a dropped object: its fact's truth at the end is its truth initially (static facts never
  change; a fluent fact on a dropped object never holds), and that literal held initially.

So VAL accepts the steps on the narrowed problem exactly when it accepts them on the whole one, right steps and
wrong ones alike. The run reads the validation domain's text (`planner.pddl`) and joins its own facts; it does not
use the replay's grounding (`planhrc.transition`), whose expected states VAL is there to check.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import Iterable, Iterator, Mapping, Sequence

from planhrc.model import EQUALITY, Atom, Literal

from .errors import PlannerError
from .operators import read_operators


@dataclass(frozen=True)
class _Block:
    """An effect block of an action: its quantified variables, its condition's positive literals (equality aside)
    and its add effects."""

    variables: tuple[str, ...]
    condition: tuple[Literal, ...]
    add: tuple[Atom, ...]


@dataclass(frozen=True)
class Relaxed:
    """What the relaxed run needs of a domain: the quantified types whose objects may be dropped, the fluent
    predicates, and per action its parameters and effect blocks."""

    types: frozenset[str]
    fluent: frozenset[str]
    actions: Mapping[str, tuple[tuple[str, ...], tuple[_Block, ...]]]


class Facts:
    """Facts found by predicate and by one argument (`matching`): a problem's static facts, or the facts of a
    relaxed run, which only grows (`add`)."""

    def __init__(self, atoms: Iterable[Atom] = ()) -> None:
        self._all: dict[str, list[tuple[str, ...]]] = {}
        self._by: dict[tuple[str, int, str], list[tuple[str, ...]]] = {}
        self._seen: set[Atom] = set()
        for atom in atoms:
            self.add(atom)

    def add(self, atom: Atom) -> bool:
        """Add a fact; False when it was there."""
        if atom in self._seen:
            return False
        self._seen.add(atom)
        values = atom[1:]
        self._all.setdefault(atom[0], []).append(values)
        for pos, value in enumerate(values):
            self._by.setdefault((atom[0], pos, value), []).append(values)
        return True

    def matching(self, predicate: str, pos: int | None, value: str) -> Sequence[tuple[str, ...]]:
        """The facts of `predicate` (their arguments) whose argument `pos` (0-based) is `value`; all of them when
        `pos` is None."""
        if pos is None:
            return self._all.get(predicate, ())
        return self._by.get((predicate, pos, value), ())


@lru_cache(maxsize=8)
def relaxed_of(domain: str) -> Relaxed | None:
    """The domain read for the relaxed run, or None when no object can be dropped by it (no quantified effect, a
    subtype a quantifier ranges over, a quantified variable of every type in no positive literal, or a domain the
    in-process reader refuses)."""
    try:
        read = read_operators(domain)
    except PlannerError:
        return None
    operators, fluent = read.operators, read.fluent
    types = {kind for op in operators for block in op.effects for _, kind in block.variables}
    if not types or any(parent in types for _, parent in read.types):
        return None
    actions: dict[str, tuple[tuple[str, ...], tuple[_Block, ...]]] = {}
    for op in operators:
        blocks = []
        for block in op.effects:
            positive = tuple(lit for lit in block.condition if not lit.negated and lit.predicate != EQUALITY)
            for var, kind in block.variables:
                if not any(var in lit.args for lit in positive):
                    types.discard(kind)  # its instances are not bound by the run: every object of the type stays
            blocks.append(_Block(tuple(var for var, _ in block.variables), positive, block.add))
        actions[op.name] = (tuple(var for var, _ in op.parameters), tuple(blocks))
    return Relaxed(frozenset(types), fluent, actions) if types else None


def held_objects(relaxed: Relaxed, static: Facts, initial: Iterable[Atom],
                 steps: Sequence[str], objects: Mapping[str, Sequence[str]]) -> set[str] | None:
    """The objects the relaxed run of `steps` keeps (see the module's note), from the problem's `static` facts,
    its `initial` fluent facts and its `objects` by type; None when a step is not an action of the domain or lacks
    arguments (VAL says so on the whole problem). Stops as soon as every object of the droppable types is kept (a
    large object's initial facts name every orientation: nothing to run)."""
    droppable = {name for kind in relaxed.types for name in objects.get(kind, ())}
    held = Facts()
    kept: set[str] = set()
    for atom in initial:
        held.add(atom)
        kept.update(atom[1:])
    for step in steps:
        kept.update(step.strip().strip("()").lower().split()[1:])
    if droppable <= kept:
        return kept
    for step in steps:
        name, *args = step.strip().strip("()").lower().split()
        action = relaxed.actions.get(name)
        if action is None or len(args) < len(action[0]):
            return None
        parameters, blocks = action
        binding = dict(zip(parameters, args))
        added: list[Atom] = []
        for block in blocks:
            for found in _bindings(block.condition, binding, relaxed.fluent, static, held):
                kept.update(found[v] for v in block.variables)
                added.extend(tuple(found.get(term, term) for term in atom) for atom in block.add)
        for atom in added:
            if held.add(atom):
                kept.update(atom[1:])
        if droppable <= kept:
            return kept
    return kept


def _bindings(condition: Sequence[Literal], binding: Mapping[str, str], fluent: frozenset[str], static: Facts,
              held: Facts) -> Iterator[dict[str, str]]:
    """Every extension of `binding` under which each literal of `condition` is a static or a held fact."""
    if not condition:
        yield dict(binding)
        return
    # the literal with the most terms already bound first: the join stays small
    best = max(range(len(condition)), key=lambda i: sum(not a.startswith("?") or a in binding
                                                        for a in condition[i].args))
    literal, rest = condition[best], (*condition[:best], *condition[best + 1:])
    pos = next((i for i, a in enumerate(literal.args) if not a.startswith("?") or a in binding), None)
    facts = held if literal.predicate in fluent else static
    for values in facts.matching(literal.predicate, pos,
                                 "" if pos is None else binding.get(literal.args[pos], literal.args[pos])):
        if len(values) != len(literal.args):
            continue
        extended = dict(binding)
        for term, value in zip(literal.args, values):
            bound = extended.get(term, term if not term.startswith("?") else None)
            if bound is None:
                extended[term] = value
            elif bound != value:
                break
        else:
            yield from _bindings(rest, extended, fluent, static, held)

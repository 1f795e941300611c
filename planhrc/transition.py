"""The paper's state-transition equations, driven by the action schemas of the TBox.

`ground_action` instantiates a schema with a plan step's arguments in a given state: pre, eff-, eff+ and the
conditional effects whose `forall` variables have a binding satisfying `when` in that state.
`apply` is eq. (statetransitioncond): s' = (s \\ (eff- ∪ C-)) ∪ (eff+ ∪ C+). `replay` gives the expected states
s^e_1 .. s^e_{N+1} of a plan (`ExpectedStates`: the first state and what each step changes, each state made whole
when it is first read). Inputs are never changed: states are frozensets.
"""
from __future__ import annotations

import operator
import threading
import time
from functools import lru_cache
from dataclasses import dataclass, replace
from typing import AbstractSet, Any, Callable, Iterator, Mapping, Sequence, overload

from planhrc.errors import DeadlineExceeded, PlanhrcError
from planhrc.grounding import holds, instantiate, substitute
from planhrc.model import (EQUALITY, ActionSchemaSpec, ActionSpec, Atom, CondEffect, ConditionalEffect,
                           DomainModelSpec, Literal, State)


class TransitionError(PlanhrcError):
    """A plan step does not match a schema or is not applicable in the state it is applied to."""


# The atoms of a state as grounding reads them: a `State`, or the one set `replay` changes in place step by step.
Atoms = AbstractSet[Atom]


def parse_step(step: str) -> tuple[str, tuple[str, ...]]:
    """'(rotateclockwise l2 l1 j1 deg_0 deg_90)' -> ('rotateclockwise', ('l2', ...))."""
    tokens = step.strip().strip("()").lower().split()
    if not tokens:
        raise TransitionError(f"plan step {step!r} is empty")
    return tokens[0], tuple(tokens[1:])


class StateIndex:
    """The atoms of a state by predicate and by (predicate, argument position, value), for the joins of
    `_bindings`; `moved` updates it by what one action changed instead of indexing the next state anew. A
    (predicate, position) is indexed when a join first looks it up, and kept up to date from then on: a join reads
    a few (an absolute step's: `affected` by its link, `hasorientation` by its joint, `orientationord` by its first
    value), and every other position of 20,000 static facts and of each change was indexed for nothing."""

    def __init__(self, state: Atoms) -> None:
        self.state = state
        self._by_pred: dict[str, set[Atom]] = {}
        self._by_arg: dict[tuple[str, int, str], set[Atom]] = {}
        self._positions: dict[str, tuple[int, ...]] = {}  # predicate -> its indexed positions
        for atom in state:
            self._by_pred.setdefault(atom[0], set()).add(atom)

    def _add(self, atom: Atom) -> None:
        self._by_pred.setdefault(atom[0], set()).add(atom)
        for pos in self._positions.get(atom[0], ()):
            if pos + 1 < len(atom):
                self._by_arg.setdefault((atom[0], pos, atom[pos + 1]), set()).add(atom)

    def _discard(self, atom: Atom) -> None:
        self._by_pred.get(atom[0], set()).discard(atom)
        for pos in self._positions.get(atom[0], ()):
            if pos + 1 < len(atom):
                self._by_arg.get((atom[0], pos, atom[pos + 1]), set()).discard(atom)

    def by_arg(self, predicate: str, pos: int, value: str) -> set[Atom] | None:
        """The atoms of `predicate` whose argument `pos` (0-based) is `value` (None: none ever was)."""
        if pos not in self._positions.get(predicate, ()):
            self._index(predicate, pos)
        return self._by_arg.get((predicate, pos, value))

    def by_pred(self, predicate: str) -> set[Atom] | None:
        return self._by_pred.get(predicate)

    def _index(self, predicate: str, pos: int) -> None:
        self._positions[predicate] = (*self._positions.get(predicate, ()), pos)
        for atom in self._by_pred.get(predicate, ()):
            if pos + 1 < len(atom):
                self._by_arg.setdefault((predicate, pos, atom[pos + 1]), set()).add(atom)

    def moved(self, state: Atoms, change: "Change | None" = None) -> "StateIndex":
        """This index, changed in place to describe `state` (which differs from the old one by few atoms);
        `change` (from `apply_change`) says by which, instead of comparing two whole states (and must, when `state`
        is the indexed set itself, changed in place)."""
        removed, added = (self.state - state, state - self.state) if change is None else change
        for atom in removed:
            self._discard(atom)
        for atom in added:
            self._add(atom)
        self.state = state
        return self

    def candidates(self, lit: Literal, binding: Mapping[str, str]) -> set[Atom] | frozenset[Atom]:
        """The atoms `lit` may match under `binding`: the one atom it names when every argument is bound, else
        those agreeing with its most selective bound argument."""
        if all(var in binding for var in lit.args):
            atom = (lit.predicate,) + tuple(binding[var] for var in lit.args)
            return frozenset((atom,)) if atom in self.state else frozenset()
        best: set[Atom] | None = None
        for pos, var in enumerate(lit.args):
            if var in binding:
                found = self.by_arg(lit.predicate, pos, binding[var])
                if found is None:
                    return frozenset()
                if best is None or len(found) < len(best):
                    best = found
        return best if best is not None else self._by_pred.get(lit.predicate, frozenset())


def _bindings(
    literals: Sequence[Literal], variables: Sequence[str], binding: dict[str, str], index: StateIndex
) -> Iterator[dict[str, str]]:
    """Every extension of `binding` to `variables` under which all `literals` hold in the indexed state.

    Positive non-equality literals are matched against the state's atoms first (a join that takes next the
    literal with the fewest candidates under the variables bound so far); the remaining literals are then
    checked. This enumerates exactly the satisfying bindings of a `when` condition, each once: a binding of
    every literal's variables determines the atoms its positive literals match."""
    positives = [lit for lit in literals if not lit.negated and lit.predicate != EQUALITY]
    others = [lit for lit in literals if lit.negated or lit.predicate == EQUALITY]
    state = index.state

    def extend(todo: tuple[int, ...], current: dict[str, str]) -> Iterator[dict[str, str]]:
        if not todo:  # the positive literals hold: each was matched against an atom of the state
            if all(v in current for v in variables) and all(holds(lit, current, state) for lit in others):
                yield dict(current)
            return
        pick, atoms = min(((i, index.candidates(positives[i], current)) for i in todo), key=lambda c: len(c[1]))
        lit = positives[pick]
        rest = tuple(i for i in todo if i != pick)
        for atom in atoms:
            if len(atom) != len(lit.args) + 1:
                continue
            new = dict(current)
            ok = True
            for var, value in zip(lit.args, atom[1:]):
                if new.setdefault(var, value) != value:
                    ok = False
                    break
            if ok:
                yield from extend(rest, new)

    yield from extend(tuple(range(len(positives))), dict(binding))


class _JoinPlan:
    """How `ground_action` enumerates the bindings of a conditional effect's `when` (the `_bindings` of it), fixed
    once per condition and set of variables bound at the start (the schema's parameters): the positive literals in
    an order that takes next the one with the most arguments bound so far (a tie: the earlier), each matched through
    the index on its first bound argument, checked on its other bound ones, binding the rest; then the negative and
    equality literals checked. It enumerates the same bindings as `_bindings` (any order of the join enumerates
    exactly the satisfying bindings, each once), without choosing the order anew at every step of the join: the
    joins of a replay of a large absolute plan (hundreds of bindings a step) were most of its time."""

    def __init__(self, literals: Sequence[Literal], bound: frozenset[str]) -> None:
        positives = [lit for lit in literals if not lit.negated and lit.predicate != EQUALITY]
        self.others = tuple(lit for lit in literals if lit.negated or lit.predicate == EQUALITY)
        known = set(bound)
        matches = []
        while positives:
            lit = max(positives, key=lambda p: sum(1 for var in p.args if var in known))
            positives.remove(lit)
            key = next(((pos, var) for pos, var in enumerate(lit.args) if var in known), None)
            checks: list[tuple[int, str]] = []
            binds: list[tuple[str, int]] = []
            repeats: list[tuple[int, str]] = []
            for pos, var in enumerate(lit.args, start=1):
                if key is not None and pos == key[0] + 1:
                    continue  # the index's key: matched by the look-up
                if var in known:
                    checks.append((pos, var))
                elif any(var == other for other, _ in binds):
                    repeats.append((pos, var))
                else:
                    binds.append((var, pos))
            known.update(lit.args)
            matches.append((lit.predicate, len(lit.args) + 1, key, tuple(checks), tuple(binds), tuple(repeats),
                            lit.args))
        self.matches = tuple(matches)
        self.binds_all = set(bound) | known  # every variable a binding has once the join is through

    def bindings(self, binding: Mapping[str, str], variables: Sequence[str], index: StateIndex
                 ) -> list[dict[str, str]]:
        matches, others, state = self.matches, self.others, index.state
        by_arg, by_pred = index.by_arg, index.by_pred
        current = dict(binding)  # extended and undone in place along the join
        last = len(matches)
        found: list[dict[str, str]] = []

        def extend(depth: int) -> None:
            if depth == last:
                for lit in others:
                    if not holds(lit, current, state):
                        return
                found.append(dict(current))
                return
            predicate, arity, key, checks, binds, repeats, args = matches[depth]
            if not binds:  # every argument bound: one atom, in the state or not
                if (predicate, *[current[var] for var in args]) in state:
                    extend(depth + 1)
                return
            atoms = by_pred(predicate) if key is None else by_arg(predicate, key[0], current[key[1]])
            if not atoms:
                return
            for atom in atoms:  # the index does not change while a step is ground
                if len(atom) != arity:
                    continue
                for pos, var in checks:
                    if atom[pos] != current[var]:
                        break
                else:
                    for var, pos in binds:
                        current[var] = atom[pos]
                    for pos, var in repeats:
                        if atom[pos] != current[var]:
                            break
                    else:
                        extend(depth + 1)
            for var, _ in binds:
                current.pop(var, None)

        if any(v not in self.binds_all for v in variables):
            return []  # a variable no literal binds: no binding of every one of them
        extend(0)
        return found


AtomMaker = Callable[[Mapping[str, str]], Atom]


def _atom_maker(lit: Literal) -> AtomMaker:
    """`instantiate(lit, binding)` as one call that picks the arguments' values at once (KeyError: one unbound)."""
    predicate, args = lit.predicate, lit.args
    if not args:
        return lambda binding: (predicate,)
    if len(args) == 1:
        (only,) = args
        return lambda binding: (predicate, binding[only])
    pick = operator.itemgetter(*args)
    return lambda binding: (predicate, *pick(binding))


@lru_cache(maxsize=64)
def _effect_makers(ce: ConditionalEffect) -> tuple[tuple[AtomMaker, ...], tuple[AtomMaker, ...], tuple[AtomMaker, ...]]:
    """The atoms a ground conditional effect needs, deletes and adds, each as a maker of it from a binding."""
    return (tuple(_atom_maker(lit) for lit in ce.when if lit.predicate != EQUALITY and not lit.negated),
            tuple(_atom_maker(lit) for lit in ce.effects if lit.negated),
            tuple(_atom_maker(lit) for lit in ce.effects if not lit.negated))


@lru_cache(maxsize=64)
def _join_plan(literals: tuple[Literal, ...], bound: frozenset[str]) -> _JoinPlan:
    return _JoinPlan(literals, bound)


def find_schema(domain: DomainModelSpec, name: str) -> ActionSchemaSpec:
    for schema in domain.actions:
        if schema.name == name:
            return schema
    raise TransitionError(f"action {name!r} is not a schema of domain {domain.name}")


def ground_action(domain: DomainModelSpec, step: str, state: Atoms, index: StateIndex | None = None) -> ActionSpec:
    """The ground action of a plan step in `state`; raises TransitionError when it is not applicable.
    `index` (of this very state) saves indexing it again, e.g. along a plan (`replay`)."""
    name, args = parse_step(step)
    schema = find_schema(domain, name)
    if len(args) != len(schema.parameters):
        raise TransitionError(f"{step}: {name} takes {len(schema.parameters)} arguments, got {len(args)}")
    binding = {var: value for (var, _), value in zip(schema.parameters, args)}
    for lit in schema.precondition:
        if not holds(lit, binding, state):
            raise TransitionError(f"{step}: precondition {substitute(lit, binding).pddl()} does not hold")
    try:
        pre = frozenset(instantiate(lit, binding) for lit in schema.precondition
                        if lit.predicate != EQUALITY and not lit.negated)
        eff_neg = frozenset(instantiate(lit, binding) for lit in schema.effects if lit.negated)
        eff_pos = frozenset(instantiate(lit, binding) for lit in schema.effects if not lit.negated)
        conds = []
        atoms = index if index is not None and index.state is state else None
        for ce in schema.conditional_effects:
            variables = [v for v, _ in ce.variables]
            atoms = atoms or StateIndex(state)
            needs, deletes, adds = _effect_makers(ce)
            for b in _join_plan(ce.when, frozenset(binding)).bindings(binding, variables, atoms):
                conds.append(CondEffect(when=frozenset([make(b) for make in needs]),
                                        eff_neg=frozenset([make(b) for make in deletes]),
                                        eff_pos=frozenset([make(b) for make in adds])))
    except KeyError as exc:  # a schema's literal names a variable that is neither a parameter nor a forall's
        raise TransitionError(f"{step}: variable {exc.args[0]} of schema {name} is unbound") from None
    conds.sort(key=_cond_order)
    return ActionSpec(name=name, params=args, pre=pre, eff_neg=eff_neg, eff_pos=eff_pos, cond_eff=tuple(conds))


def _cond_order(ce: CondEffect) -> tuple[list[Atom], list[Atom], list[Atom]]:
    """The order of an action's conditional effects: by what they add, then delete, then need (total: the same
    action is the same value however its bindings were enumerated)."""
    return _in_order(ce.eff_pos), _in_order(ce.eff_neg), _in_order(ce.when)


def _in_order(atoms: frozenset[Atom]) -> list[Atom]:
    """`sorted(atoms)`, without sorting a single atom (a large absolute step has hundreds of such effects)."""
    return sorted(atoms) if len(atoms) > 1 else list(atoms)


def apply(state: State, action: ActionSpec) -> State:
    """s' = (s \\ (eff- ∪ C-)) ∪ (eff+ ∪ C+), with C± the effects of the conditional effects that fired."""
    return apply_change(state, action)[0]


Change = tuple[frozenset[Atom], frozenset[Atom]]  # the atoms one action removed from a state and added to it


def apply_change(state: State, action: ActionSpec) -> tuple[State, Change]:
    """`apply`, and what it changed: for a state of many static facts, the change is a handful of atoms that a
    `StateIndex` follows without comparing the two states whole."""
    removed, added = change_of(state, action)
    return frozenset((state - removed) | added), (removed, added)


def change_of(state: Atoms, action: ActionSpec) -> Change:
    """What `apply(state, action)` removes from `state` and adds to it, without making the new state (for a
    state of many static facts, a copy of them all)."""
    neg = set(action.eff_neg)
    pos = set(action.eff_pos)
    for ce in action.cond_eff:
        if ce.when <= state:
            neg |= ce.eff_neg
            pos |= ce.eff_pos
    return frozenset(a for a in neg if a in state and a not in pos), frozenset(a for a in pos if a not in state)


def change_between(before: State, after: State, action: ActionSpec | None = None) -> Change:
    """(removed, added) such that `after` is `(before - removed) | added`, for states a plan's replay made (`after`
    is `apply(before, action)`): what `action` changes, a few atoms looked at where comparing two states whole looks
    at all their static facts. The change is checked against the states' sizes and the changed atoms only, not
    every atom; when it does not fit, or without an action, the two states are compared whole."""
    if action is not None:
        removed, added = change_of(before, action)
        if (len(before) - len(removed) + len(added) == len(after) and removed.isdisjoint(after)
                and added <= after):
            return removed, added
    return before - after, after - before


def changes_along(states: Sequence[State], actions: Sequence[ActionSpec]) -> tuple[Change, ...]:
    """`change_between` each state and the next; the actions are used as the steps between them when there is one
    per step (a plan's replay), else the states are compared whole."""
    steps: Sequence[ActionSpec | None] = actions if len(actions) == len(states) - 1 else (None,) * (len(states) - 1)
    return tuple(change_between(before, after, step) for before, after, step in zip(states, states[1:], steps))


def changes_of(states: Sequence[State], actions: Sequence[ActionSpec]) -> tuple[Change, ...]:
    """What each step of a plan changes: the replay's own changes (`ExpectedStates`), else `changes_along`."""
    return states.changes if isinstance(states, ExpectedStates) else changes_along(states, actions)


@dataclass(frozen=True)
class _Conditional:
    """A step of a schema with conditional effects, ground once for the static facts it was ground with: its
    action without conditional effects, what its precondition needs of the fluents, and each binding of its
    conditional effects that the static facts allow, with what that binding needs of the fluents (in the order
    `ground_action` sorts them)."""

    statics: frozenset[Atom]
    action: ActionSpec
    present: frozenset[Atom]
    absent: frozenset[Atom]
    candidates: tuple[tuple[frozenset[Atom], frozenset[Atom], CondEffect], ...]


class Grounder:
    """`ground_action` for one domain, remembering what a step grounds to.

    A step of a schema without conditional effects grounds to the same action in every state where it applies:
    a step seen before costs a look-up and a check of its precondition, not a grounding. A step with conditional
    effects is ground once per set of static facts (predicates no action changes): the bindings of its `forall`
    variables the static facts allow are kept, and in each state only their fluent conditions are checked (on
    the absolute 20 x 12 task a step's one `when` ranges over 20 joints x 12 x 12 orientations). A step is kept from
    its second grounding on: keeping costs several groundings, and most steps of one long plan are ground once (the
    600 steps of an absolute 200 x 12 plan), while a re-planning object's steps come back plan after plan. Either way the
    action is the one `ground_action` gives; a step whose precondition fails takes `ground_action`'s path (for its
    message), and so does a conditional effect whose variables the static facts do not all bind. Get one per
    domain from `grounder(domain)`; it holds at most `LIMIT` steps.

    Keeping the bindings pays only while they are few: their number grows with joints x orientations, while the
    bindings `ground_action` enumerates in a state (a join over the state's atoms) grow with the joints alone. A step
    whose static bindings exceed `MAX_CANDIDATES` (the absolute 50 x 36 or 200 x 12 tasks) is not kept: building
    them cost tens of times what grounding the step in its state costs, and a re-plan of such a task met its
    deadline in the replay instead of answering."""

    LIMIT = 50_000
    MAX_CANDIDATES = 512

    def __init__(self, domain: DomainModelSpec) -> None:
        self.domain = domain
        self._plain = {s.name for s in domain.actions if not s.conditional_effects}
        self._fluent = frozenset(
            lit.predicate for s in domain.actions
            for lit in s.effects + tuple(e for ce in s.conditional_effects for e in ce.effects))
        self._seen: dict[str, tuple[ActionSpec, frozenset[Atom], frozenset[Atom]]] = {}
        self._conditional: dict[str, _Conditional | None] = {}  # None: not cacheable, always `ground_action`
        self._once: set[str] = set()  # conditional steps ground once so far (kept from their second grounding on)
        self._static_index: StateIndex | None = None
        self._last_statics: frozenset[Atom] | None = None  # `statics`' last answer
        # (schema, the values of the parameters its conditional effects name) -> (statics, their bindings)
        self._bindings_of: dict[tuple[str, tuple[str, ...]], tuple[frozenset[Atom], tuple[
            tuple[frozenset[Atom], frozenset[Atom], CondEffect], ...]]] = {}

    def statics(self, state: Atoms) -> frozenset[Atom]:
        """The atoms of `state` no action of the domain changes (the same along a plan): the set this returned last
        time when it is equal. What is kept for one problem's static facts (their index, the steps' bindings) is
        then found by identity, where comparing the sets cost a full pass over them (20,000 facts of an absolute
        200 x 12 task) at every step ground a second time: most of a planning worker's replay of such a plan, whose
        facts come unpickled, each job's its own objects."""
        fluent = self._fluent
        made = frozenset(a for a in state if a[0] not in fluent)
        last = self._last_statics
        if last is not None and last == made:
            return last
        self._last_statics = made
        return made

    def ground(self, step: str, state: Atoms, index: StateIndex | None = None,
               statics: frozenset[Atom] | None = None) -> ActionSpec:
        """`ground_action(domain, step, state, index)`; `statics` (`self.statics(state)`, when the caller has it)
        saves working it out for a step with conditional effects."""
        known = self._seen.get(step)
        if known is not None:
            action, present, absent = known
            if present <= state and absent.isdisjoint(state):
                return action
            return ground_action(self.domain, step, state, index)  # raises, naming the failing precondition
        if step in self._conditional:
            return self._ground_conditional(step, state, index, statics)
        action = ground_action(self.domain, step, state, index)
        if action.name in self._plain:
            self._remember(step, action)
        elif step not in self._once:
            if len(self._once) >= self.LIMIT:
                self._once.clear()
            self._once.add(step)
        elif len(self._conditional) < self.LIMIT:
            self._once.discard(step)
            self._conditional[step] = self._compile(action, self.statics(state) if statics is None else statics)
        return action

    def _ground_conditional(self, step: str, state: Atoms, index: StateIndex | None,
                            statics: frozenset[Atom] | None) -> ActionSpec:
        entry = self._conditional[step]
        statics = self.statics(state) if statics is None and entry is not None else statics
        if entry is None or (entry.statics is not statics and entry.statics != statics):
            action = ground_action(self.domain, step, state, index)
            if entry is not None:  # other static facts (another problem's): ground for these from now on
                self._conditional[step] = self._compile(action, statics if statics is not None else
                                                        self.statics(state))
            return action
        if not (entry.present <= state and entry.absent.isdisjoint(state)):
            return ground_action(self.domain, step, state, index)  # raises, naming the failing precondition
        fired = tuple(ce for present, absent, ce in entry.candidates
                      if present <= state and absent.isdisjoint(state))
        return replace(entry.action, cond_eff=fired)

    def _compile(self, action: ActionSpec, statics: frozenset[Atom]) -> _Conditional | None:
        """What `_ground_conditional` needs of a step, or None when some conditional effect has a variable no
        static literal binds (its bindings would have to range over every object)."""
        schema = find_schema(self.domain, action.name)
        binding = {var: value for (var, _), value in zip(schema.parameters, action.params)}
        fluent = self._fluent
        present = frozenset(instantiate(lit, binding) for lit in schema.precondition
                            if not lit.negated and lit.predicate != EQUALITY and lit.predicate in fluent)
        absent = frozenset(instantiate(lit, binding) for lit in schema.precondition
                           if lit.negated and lit.predicate != EQUALITY and lit.predicate in fluent)
        # the bindings depend on the parameters the conditional effects name, not on the step's others (a turn's
        # orientations, its grippers): steps that differ only in those share them
        named = sorted({a for ce in schema.conditional_effects for lit in (*ce.when, *ce.effects) for a in lit.args
                        if a in binding})
        key = (schema.name, tuple(binding[a] for a in named))
        shared = self._bindings_of.get(key)
        if shared is not None and (shared[0] is statics or shared[0] == statics):
            return _Conditional(statics, replace(action, cond_eff=()), present, absent, shared[1])
        candidates = self._candidates(schema, binding, statics)
        if candidates is None:
            return None
        if len(self._bindings_of) >= self.LIMIT:
            self._bindings_of.clear()
        self._bindings_of[key] = (statics, candidates)
        return _Conditional(statics, replace(action, cond_eff=()), present, absent, candidates)

    def _candidates(self, schema: ActionSchemaSpec, binding: dict[str, str], statics: frozenset[Atom]
                    ) -> tuple[tuple[frozenset[Atom], frozenset[Atom], CondEffect], ...] | None:
        """Each binding of the schema's conditional effects under `binding` that the static facts allow, with what
        it needs of the fluents, in the order `ground_action` sorts them; None when a conditional effect has a
        variable no static literal binds, or there are more than `MAX_CANDIDATES`."""
        fluent = self._fluent
        static_index = self._index_of(statics)
        candidates: list[tuple[frozenset[Atom], frozenset[Atom], CondEffect]] = []
        for ce in schema.conditional_effects:
            variables = [v for v, _ in ce.variables]
            static_lits = [lit for lit in ce.when if lit.predicate == EQUALITY or lit.predicate not in fluent]
            bound = {a for lit in static_lits if not lit.negated and lit.predicate != EQUALITY for a in lit.args}
            if any(v not in bound and v not in binding for v in variables):
                return None
            # every binding is one choice of an atom per positive static literal: their product bounds how many
            # there are, known before any is built
            most = 1
            for lit in static_lits:
                if not lit.negated and lit.predicate != EQUALITY:
                    most *= len(static_index.candidates(lit, binding))
            if len(candidates) + most > self.MAX_CANDIDATES:
                return None
            for b in _bindings(static_lits, variables, binding, static_index):
                when = frozenset(instantiate(lit, b) for lit in ce.when
                                 if lit.predicate != EQUALITY and not lit.negated)
                candidates.append((
                    frozenset(instantiate(lit, b) for lit in ce.when if not lit.negated and lit.predicate in fluent
                              and lit.predicate != EQUALITY),
                    frozenset(instantiate(lit, b) for lit in ce.when if lit.negated and lit.predicate in fluent
                              and lit.predicate != EQUALITY),
                    CondEffect(when=when,
                               eff_neg=frozenset(instantiate(lit, b) for lit in ce.effects if lit.negated),
                               eff_pos=frozenset(instantiate(lit, b) for lit in ce.effects if not lit.negated))))
        candidates.sort(key=lambda c: _cond_order(c[2]))
        return tuple(candidates)

    def _index_of(self, statics: frozenset[Atom]) -> StateIndex:
        """The index of the static facts (one problem's, the same for every step of its plans), kept."""
        kept = self._static_index
        if kept is None or (kept.state is not statics and kept.state != statics):
            kept = self._static_index = StateIndex(statics)
        return kept

    def _remember(self, step: str, action: ActionSpec) -> None:
        schema = find_schema(self.domain, action.name)
        binding = {var: value for (var, _), value in zip(schema.parameters, action.params)}
        # (in)equalities depend on the arguments alone: they held when the step was ground, they hold again
        absent = frozenset(instantiate(lit, binding) for lit in schema.precondition
                           if lit.negated and lit.predicate != EQUALITY)
        if len(self._seen) >= self.LIMIT:
            self._seen.clear()
        self._seen[step] = (action, action.pre, absent)


@lru_cache(maxsize=8)
def grounder(domain: DomainModelSpec) -> Grounder:
    """The `Grounder` of a domain (one per domain value)."""
    return Grounder(domain)


class ExpectedStates(Sequence[State]):
    """A plan's expected states s^e_1 .. s^e_{N+1}, kept as the first one and what each step changes (`Change`s, in
    order): a state is made whole only when it is read.

    A state of a large object is mostly static facts: the 600 states of an absolute 200 x 12 plan are 12 million
    atoms, and making them whole (a copy of 20,700 atoms each) was most of a re-plan's time, twice (the planning
    worker's replay and the service's unpacking), before anything read more than the first few; kept, they were
    600 MB that every full pass of the garbage collector walked. Read as a sequence, it is the tuple of those
    states (equal to it, item by item); pickled, it is the first state and the changes.

    Reading is made for a reader that goes forward (the checks of a plan's steps, one piece after another): one set
    follows the reads, changed in place by the changes between two of them, and each state read is one copy of it;
    the last few states read are kept (`KEPT`), the first and the last always (the last as given, the replay's, or
    made once). A reader that asks which states a state subsumes asks `matching_states`, which makes none whole."""

    KEPT = 4

    def __init__(self, first: State, changes: Sequence[Change], last: State | None = None) -> None:
        self.first = first if isinstance(first, frozenset) else frozenset(first)
        self.changes = tuple(changes)
        self._last = last if last is not None or self.changes else self.first
        self._recent: dict[int, State] = {}
        self._cursor: set[Atom] | None = None  # the state at `_at`, changed in place as reads go forward
        self._at = 0
        self._lock = threading.Lock()

    def __len__(self) -> int:
        return len(self.changes) + 1

    @overload
    def __getitem__(self, i: int) -> State: ...

    @overload
    def __getitem__(self, i: slice) -> tuple[State, ...]: ...

    def __getitem__(self, i: int | slice) -> State | tuple[State, ...]:
        if isinstance(i, slice):
            return tuple(self[k] for k in range(*i.indices(len(self))))
        k = operator.index(i)
        k = k + len(self) if k < 0 else k
        if not 0 <= k < len(self):
            raise IndexError(f"expected state {i} of {len(self)}")
        if k == 0:
            return self.first
        if k == len(self.changes) and self._last is not None:
            return self._last
        return self._make(k)

    def __iter__(self) -> Iterator[State]:
        for k in range(len(self)):
            yield self[k]

    def __eq__(self, other: object) -> bool:
        if isinstance(other, ExpectedStates) and other.first == self.first and other.changes == self.changes:
            return True
        return (isinstance(other, Sequence) and not isinstance(other, str) and len(other) == len(self)
                and all(a == b for a, b in zip(self, other)))

    __hash__ = None  # type: ignore[assignment]  # equal to a tuple of the same states, whose hash it cannot give

    def __repr__(self) -> str:
        return f"ExpectedStates({len(self)} states of {len(self.first)} atoms at first)"

    def __reduce__(self) -> tuple[Any, ...]:
        return ExpectedStates, (self.first, self.changes)

    def _make(self, k: int) -> State:
        """State k whole: the cursor moved to it (from the nearest state kept before it when it is past k)."""
        with self._lock:
            kept = self._recent.get(k)
            if kept is not None:
                return kept
            if self._cursor is None or self._at > k:
                self._at = max((j for j in self._recent if j < k), default=0)
                self._cursor = set(self._recent[self._at] if self._at else self.first)
            cursor = self._cursor
            for removed, added in self.changes[self._at:k]:
                cursor -= removed
                cursor |= added
            self._at = k
            state = frozenset(cursor)
            if k == len(self.changes):
                self._last = state
            else:
                if len(self._recent) >= self.KEPT:
                    del self._recent[next(iter(self._recent))]
                self._recent[k] = state
            return state


def frozen_states(states: Sequence[State]) -> Sequence[State]:
    """States as an immutable value: a tuple or `ExpectedStates` as it is (the same object), anything else as a
    tuple (`tuple(...)` on `ExpectedStates` would make every state whole)."""
    return states if isinstance(states, (tuple, ExpectedStates)) else tuple(states)


def matching_states(perceived: State, states: Sequence[State]) -> Iterator[int]:
    """The indices of the states that `perceived` is subsumed by (`is_subsumed(perceived, state)`: every atom of the
    state is perceived), the latest first. For `ExpectedStates` no state is made whole: the atoms of each state that
    are not perceived follow from the first state's by the changes (those a step removes are no longer missing,
    those it adds and are not perceived are)."""
    if not isinstance(states, ExpectedStates):
        for i in range(len(states) - 1, -1, -1):
            if states[i] <= perceived:
                yield i
        return
    missing = set(states.first - perceived)
    subsumed = [not missing]
    for removed, added in states.changes:
        missing -= removed
        missing.update(a for a in added if a not in perceived)
        subsumed.append(not missing)
    for i in range(len(subsumed) - 1, -1, -1):
        if subsumed[i]:
            yield i


def replay(domain: DomainModelSpec, init: State, plan: Sequence[str], deadline_at: float | None = None
           ) -> tuple[tuple[ActionSpec, ...], ExpectedStates]:
    """Ground every step in turn and return the actions and the expected states s^e_1 .. s^e_{N+1}; past
    `deadline_at` (`time.monotonic()`) `DeadlineExceeded` is raised instead (the plan is neither accepted nor
    refused). The states are one set changed in place by each step's change (`change_of`, what `apply` removes and
    adds), kept as those changes: `ExpectedStates` makes a state whole only when it is read."""
    first = frozenset(init)
    state = set(first)  # the state the next step applies in
    actions: list[ActionSpec] = []
    changes: list[Change] = []
    conditional = any(s.conditional_effects for s in domain.actions)
    index = StateIndex(state) if conditional else None
    g = grounder(domain)
    statics = g.statics(first) if conditional else None  # no action changes them: the same in every state
    for k, step in enumerate(plan, 1):
        if deadline_at is not None and time.monotonic() > deadline_at:
            raise DeadlineExceeded(f"replay stopped at its deadline after {k - 1} of {len(plan)} steps")
        action = g.ground(step, state, index, statics)
        actions.append(action)
        removed, added = change = change_of(state, action)
        state -= removed
        state |= added
        changes.append(change)
        if index is not None:
            index.moved(state, change)
    return tuple(actions), ExpectedStates(first, changes, frozenset(state))

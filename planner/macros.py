"""Macro actions checked through what they stand for: which actions of a domain are exactly a sequence of its other
actions (`macro_report`, once per domain text), and a plan's expansion into those actions (`MacroReport.expand`).

VAL checks a macro step of the bimanual files by expanding its conditional effect over a joint and four angles
(K^4 instances per joint: seconds per step at K = 24); the same step written as the three one-step turns it stands
for costs VAL next to nothing. A plan whose macros are *faithful* (each one's precondition and effects are exactly
those of its sequence, in every state a plan can reach) is valid exactly when its expansion is, so VAL on the
expansion gives the plan's verdict.

**The proof** is symbolic, on the schemas, for every way the macro's parameters may coincide (each partition of its
parameters of one type): the macro and its sequence are run on a state nothing is known of, and must need the same
literals of that state and leave the same values. It reads three kinds of predicate:

* *static* ones (in no effect) and equality: facts of the problem, the same before and after;
* *state variables* (`_state_variables`): a predicate whose every add is paired, in the same effect, with the delete
  of the value its condition pins for the same owner (``(angle_joint ?a1 ?j)`` -> ``(angle_joint ?a2 ?j)``), and
  whose adds in one action go to owners that provably differ. Such a predicate keeps at most one value per owner in
  every reachable state once the problem's init does;
* any other changing predicate is a plain boolean fact.

A conditional effect is read when it *moves* one state variable of each owner it quantifies over along static
relations (``forall ?js ?a3 ?a4: when (affected ?js ?l ?j) (angle_joint ?a3 ?js) (angle-before ?a3 ?a4): ?a3 ->
?a4``): a guard of static literals on the owner, and a word of relation steps (forward, or backward) from the
pinned value to the new one. It must provably never touch the owners the parameters name (a guard such as
``(not (= ?js ?joint))``); on every other owner the sequence's moves, under one guard, make one word, which must
be the macro's. Words compose and cancel as the steps of a bijection do, which is what the problem must then give:
**premises**, checked on each problem (`MacroReport.premises`): every relation a word uses is a bijection of its
value type's objects, and the init holds at most one value per owner of every state variable (each one of that
type). Where a premise fails, the plan goes to VAL as it is.

Anything outside this reading (disjunctions, a conditional effect on a boolean fact, a guard that reads a changing
predicate, more than `MAX_PARTITIONS` cases of coinciding parameters) proves nothing: the action is no macro here,
and a plan that uses it goes to VAL whole. A macro candidate (an action whose effects, with its parameters all
different, are those of a sequence of other actions: `_candidates`) that is not faithful is reported with the first
difference found (`MacroReport.unfaithful`).
"""
from __future__ import annotations

import itertools
import logging
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Iterator, Mapping, Sequence

from planhrc.model import EQUALITY, Atom, Literal, format_atom

from .errors import PlannerError
from .operators import EffectBlock, Operator, normalise_domain
from .pddl import Domain, Problem, parse_domain

log = logging.getLogger(__name__)

MAX_STEPS = 4  # the longest sequence a macro is looked for as
MAX_SKIPPED = 2  # a candidate's sequence may need this many plain facts its macro does not (reported, not faithful)
MAX_PARTITIONS = 20_000  # cases of coinciding parameters the proof runs through, at most
MAX_CANDIDATES = 8  # sequences a macro is checked against, at most
MAX_VISITS = 2_000  # steps the search for a macro's sequences tries, at most (then it stops: nothing proved)


# -- what the check hands out -----------------------------------------------------------------------------------
@dataclass(frozen=True)
class Expansion:
    """A faithful macro: the actions it stands for, each with the macro's parameters (by index) it passes on."""

    macro: str
    arity: int
    steps: tuple[tuple[str, tuple[int, ...]], ...]

    def expand(self, args: Sequence[str]) -> tuple[str, ...]:
        """The ground steps a ground macro step `(macro *args)` stands for."""
        return tuple("(" + " ".join((name, *(args[i] for i in indices))) + ")" for name, indices in self.steps)

    def describe(self, parameters: Sequence[str]) -> str:
        return "; ".join(self.expand(parameters))


@dataclass(frozen=True)
class ExpandedPlan:
    """A plan with its faithful macro steps replaced by their steps: `origin[i]` is the plan step (0-based) that
    expanded step i comes from."""

    steps: tuple[str, ...]
    origin: tuple[int, ...]
    macro_steps: int  # how many steps of the plan were macros


@dataclass(frozen=True)
class MacroReport:
    """What `macro_report` proved of one domain: its faithful macros, the candidates that are not, and the premises
    a problem must meet for the proof to hold of it (see the module's note)."""

    faithful: Mapping[str, Expansion] = field(default_factory=dict)
    unfaithful: Mapping[str, str] = field(default_factory=dict)  # macro -> the first difference found
    bijections: tuple[tuple[str, frozenset[str]], ...] = ()  # (static relation, the types of its objects)
    variables: tuple[tuple[str, int, frozenset[str]], ...] = ()  # (predicate, value position, the value's types)
    note: str = ""  # why nothing was proved, when the domain is outside what the proof reads

    def expand(self, plan: Sequence[str]) -> ExpandedPlan | None:
        """The plan with every step of a faithful macro replaced by its steps; None when no step is one."""
        steps: list[str] = []
        origin: list[int] = []
        macros = 0
        for i, text in enumerate(plan):
            parts = text.strip().strip("()").split()
            expansion = self.faithful.get(parts[0].lower()) if parts else None
            if expansion is None or len(parts) - 1 != expansion.arity:
                steps.append(text)
                origin.append(i)
                continue
            macros += 1
            for step in expansion.expand(parts[1:]):
                steps.append(step)
                origin.append(i)
        return ExpandedPlan(tuple(steps), tuple(origin), macros) if macros else None

    def premises(self, problem: Problem) -> str | None:
        """None when `problem` meets the proof's premises (its static relations and its init), else which it
        does not meet, in words."""
        objects: dict[str, set[str]] = {}
        for name, type_name in problem.objects:
            objects.setdefault(type_name, set()).add(name)
        for relation, types in self.bijections:
            values = set().union(*(objects.get(t, set()) for t in types))
            pairs = [a[1:] for a in problem.init if a[0] == relation]
            forward: dict[str, set[str]] = {}
            backward: dict[str, set[str]] = {}
            for pair in pairs:
                if len(pair) != 2 or not set(pair) <= values:
                    return f"{format_atom((relation, *pair))} is not between two objects of its type"
                forward.setdefault(pair[0], set()).add(pair[1])
                backward.setdefault(pair[1], set()).add(pair[0])
            for value in sorted(values):
                if len(forward.get(value, ())) != 1 or len(backward.get(value, ())) != 1:
                    return f"{relation} does not give every {'/'.join(sorted(types))} exactly one next and one previous"
        for name, position, types in self.variables:
            allowed = set().union(*(objects.get(t, set()) for t in types)) if types else None
            owners: dict[tuple[str, ...], str] = {}
            for atom in problem.init:
                if atom[0] != name or len(atom) <= position + 1:
                    continue
                owner = atom[1:1 + position] + atom[2 + position:]
                value = atom[1 + position]
                if owner in owners:
                    return f"the init gives {name} two values for {' '.join(owner) or 'its one owner'}"
                if allowed is not None and value not in allowed:
                    return f"the init's {format_atom(atom)} holds a value of another type"
                owners[owner] = value
        return None


@lru_cache(maxsize=32)
def macro_report(domain_text: str) -> MacroReport:
    """The macros of a domain (its text, as VAL reads it), proved once per text in a process. A text that does
    not parse proves nothing."""
    try:
        domain = parse_domain(domain_text)
    except PlannerError as exc:
        return MacroReport(note=f"the domain does not parse: {exc}")
    return analyse(domain)


def analyse(domain: Domain) -> MacroReport:
    """`macro_report` on a parsed domain."""
    if any(parent not in ("object", "") for _, parent in domain.types):
        return MacroReport(note="types below types other than object: not read by the macro check")
    try:
        operators = normalise_domain(domain)
    except PlannerError as exc:
        return MacroReport(note=str(exc))
    theory = _Theory.of(domain, operators)
    faithful: dict[str, Expansion] = {}
    unfaithful: dict[str, str] = {}
    for macro in operators:
        found = _prove(theory, macro, [op for op in operators if op.name != macro.name])
        if isinstance(found, Expansion):
            faithful[macro.name] = found
        elif found is not None:
            unfaithful[macro.name] = found
            log.info("action %s is not a faithful macro: %s", macro.name, found)
    if not faithful:
        return MacroReport(unfaithful=unfaithful)
    variables = tuple((name, position, theory.value_types.get(name, frozenset()))
                      for name, position in sorted(theory.svs.items()))
    return MacroReport(faithful, unfaithful, tuple(sorted(theory.relations(), key=lambda u: (u[0], sorted(u[1])))),
                       variables)


# -- the domain as the proof reads it ---------------------------------------------------------------------------
@dataclass(frozen=True)
class _Move:
    """A conditional effect moving one state variable of every owner it quantifies over (see the module's note):
    `owner` holds the operator's parameters and one quantified variable, `var`."""

    predicate: str
    owner: tuple[str, ...]
    var: str
    guard: frozenset[Literal]
    word: tuple[tuple[str, int], ...]
    value_types: frozenset[str]
    var_type: str


class _NotRead(Exception):
    """Outside what the proof reads: nothing is proved of the action."""


@dataclass
class _Theory:
    fluents: frozenset[str]
    svs: dict[str, int]  # state variable predicate -> value position
    moves: dict[tuple[str, int], _Move | str]  # (operator, block index) -> its move, or why it is none
    value_types: dict[str, frozenset[str]]

    @classmethod
    def of(cls, domain: Domain, operators: Sequence[Operator]) -> _Theory:
        fluents = frozenset(atom[0] for op in operators for block in op.effects for atom in block.add + block.delete)
        arity = {name: len(args) for name, args in domain.predicates}
        svs: dict[str, int] = {}
        for name in sorted(fluents):
            for position in range(arity.get(name, 0)):
                if all(_keeps_one_value(op, name, position, fluents) for op in operators):
                    svs[name] = position
                    break
        while True:  # a state variable keeps one value only if every conditional change of it is a move
            moves: dict[tuple[str, int], _Move | str] = {}
            for op in operators:
                for index, block in enumerate(op.effects):
                    if block.variables or block.condition:
                        moves[(op.name, index)] = _move_of(op, block, svs, fluents)
            unread = {atom[0] for (name, index), move in moves.items() if isinstance(move, str)
                      for atom in _block(operators, name, index).add if atom[0] in svs}
            if not unread:
                break
            svs = {name: position for name, position in svs.items() if name not in unread}
        value_types: dict[str, set[str]] = {}
        for move in moves.values():
            if isinstance(move, _Move):
                value_types.setdefault(move.predicate, set()).update(move.value_types)
        return cls(fluents, svs, moves, {k: frozenset(v) for k, v in value_types.items()})

    def relations(self) -> set[tuple[str, frozenset[str]]]:
        """The static relations every move of the domain steps along, with their value types: each must be a
        bijection for a move to leave one value per owner (a premise of every proof)."""
        return {(relation, move.value_types) for move in self.moves.values() if isinstance(move, _Move)
                for relation, _ in move.word}


def _block(operators: Sequence[Operator], name: str, index: int) -> EffectBlock:
    return next(op for op in operators if op.name == name).effects[index]


def _keeps_one_value(op: Operator, name: str, position: int, fluents: frozenset[str]) -> bool:
    """Whether `op` keeps at most one value per owner of `name` (value at `position`): every add paired with the
    delete of a pinned value of the same owner, and no two adds on owners that may be the same."""
    owners: list[tuple[tuple[str, ...], EffectBlock]] = []
    for block in op.effects:
        adds = [a for a in block.add if a[0] == name]
        dels = [d for d in block.delete if d[0] == name]
        if not adds and not dels:
            continue
        if len(adds) != len(dels):
            return False
        pins = set(block.condition) | (set(op.precondition) if not block.variables and not block.condition else set())
        for add in adds:
            owner = _owner(add, position)
            paired = [d for d in dels if _owner(d, position) == owner]
            if len(paired) != 1 or Literal(name, paired[0][1:]) not in pins:
                return False
            if block.variables and not (paired[0][1 + position] in dict(block.variables)
                                        and add[1 + position] in dict(block.variables)):
                return False
            owners.append((owner, block))
    for (first, block_a), (second, block_b) in itertools.combinations(owners, 2):
        if block_a.variables and block_b.variables:
            return False  # two quantified moves of one predicate: not read
        if not _differ(first, second, op, block_a if block_a.variables else block_b):
            return False
    return True


def _owner(atom: Atom, position: int) -> tuple[str, ...]:
    return atom[1:1 + position] + atom[2 + position:]


def _differ(first: tuple[str, ...], second: tuple[str, ...], op: Operator, block: EffectBlock) -> bool:
    """Whether two owners provably name different objects: at some position, terms an inequality of the
    precondition (or of the quantified block's condition) keeps apart."""
    apart = {lit.args for lit in (*op.precondition, *block.condition) if lit.predicate == EQUALITY and lit.negated}
    return any(a != b and ((a, b) in apart or (b, a) in apart) for a, b in zip(first, second))


def _move_of(op: Operator, block: EffectBlock, svs: Mapping[str, int], fluents: frozenset[str]) -> _Move | str:
    """The move a conditional effect makes (see `_Move`), or why it is none."""
    where = f"a conditional effect of {op.name}"
    variables = dict(block.variables)
    if any(v in dict(op.parameters) for v in variables):
        return f"{where} quantifies over a variable named as a parameter"
    if not variables or len(block.add) != 1 or len(block.delete) != 1 or block.add[0][0] != block.delete[0][0]:
        return f"{where} is not one quantified change of one predicate"
    added, deleted = block.add[0], block.delete[0]
    name = added[0]
    if name not in svs:
        return f"{where} changes {name}, which is no state variable"
    position = svs[name]
    owner = _owner(added, position)
    if owner != _owner(deleted, position) or Literal(name, deleted[1:]) not in block.condition:
        return f"{where} does not move the value its condition pins"
    quantified = [t for t in owner if t in variables]
    if len(quantified) != 1:
        return f"{where} does not quantify over exactly one owner variable"
    var = quantified[0]
    start, end = deleted[1 + position], added[1 + position]
    chain: list[Literal] = []
    guard: list[Literal] = []
    for lit in block.condition:
        if lit == Literal(name, deleted[1:]):
            continue
        in_chain = [t for t in lit.args if t in variables and t != var]
        if lit.predicate in fluents:
            return f"{where} reads {lit.predicate}, which changes, in its condition"
        if in_chain:
            if lit.negated or lit.predicate == EQUALITY or len(lit.args) != 2 or len(in_chain) != 2:
                return f"{where} relates its values by {lit.pddl()}, not by a step of a static relation"
            chain.append(lit)
        else:
            if any(t in variables and t != var for t in lit.args):
                return f"{where} has a quantified variable outside its owner and its values"
            if lit.predicate == EQUALITY and all(t in variables for t in lit.args):
                return f"{where} compares two quantified variables"
            guard.append(lit)
    word: list[tuple[str, int]] = []
    current, left = start, list(chain)
    seen = {start}
    while left:
        step = next(((lit, 1) for lit in left if lit.args[0] == current), None) or next(
            ((lit, -1) for lit in left if lit.args[1] == current), None)
        if step is None:
            return f"{where}: its static literals do not lead from {start} to {end} one step at a time"
        lit, direction = step
        left.remove(lit)
        current = lit.args[1] if direction == 1 else lit.args[0]
        if current in seen:
            return f"{where}: its static literals go round in a circle"
        seen.add(current)
        word.append((lit.predicate, direction))
    value_vars = set(variables) - {var}
    if current != end or seen != value_vars or not word:
        return f"{where}: its static literals do not lead from {start} to {end} through every value variable"
    value_types = frozenset(variables[v] for v in value_vars)
    return _Move(name, owner, var, frozenset(guard), tuple(word), value_types, variables[var])


# -- the proof ----------------------------------------------------------------------------------------------------
Cond = tuple[str, tuple[str, ...], str, bool]  # (kind "v"/"b"/"s", atom or owner, value, positive)
_FALSE = None


@dataclass
class _Run:
    """A symbolic run of actions on an unknown state: what they need of it and what they leave."""

    conds: set[Cond] = field(default_factory=set)
    facts: dict[Atom, bool] = field(default_factory=dict)  # boolean atoms the run set
    values: dict[tuple[str, tuple[str, ...]], str] = field(default_factory=dict)  # state variables the run set
    others: dict[tuple[str, tuple[str, ...]], list[tuple[frozenset[Literal], tuple[tuple[str, int], ...]]]] = \
        field(default_factory=dict)  # moves of owners no parameter names: (predicate, owner pattern) -> steps
    never: bool = False  # some precondition is false whatever the state


def _run(theory: _Theory, steps: Sequence[tuple[Operator, Mapping[str, str]]], constants: Mapping[str, str]
         ) -> _Run:
    run = _Run()
    for op, binding in steps:
        for lit in op.precondition:
            got = _value_of(theory, run, lit, binding)
            if got is False:
                run.never = True
            elif got is not True:
                run.conds.add(got)
        adds: list[Atom] = []
        dels: list[Atom] = []
        for index, block in enumerate(op.effects):
            if not block.variables and not block.condition:
                for atom in block.delete:
                    if atom[0] not in theory.svs:
                        dels.append(_bind(atom, binding))
                for atom in block.add:
                    ground = _bind(atom, binding)
                    if ground[0] in theory.svs:
                        position = theory.svs[ground[0]]
                        run.values[(ground[0], _owner(ground, position))] = ground[1 + position]
                    else:
                        adds.append(ground)
                continue
            move = theory.moves[(op.name, index)]
            if isinstance(move, str):
                raise _NotRead(move)
            _moved(run, move, binding, constants, op.name)
        for atom in dels:
            run.facts[atom] = False
        for atom in adds:
            run.facts[atom] = True
    return run


def _moved(run: _Run, move: _Move, binding: Mapping[str, str], constants: Mapping[str, str], op: str) -> None:
    """Record a move on the owners no parameter names; refuse one that may move a parameter's own variable."""
    guard = [Literal(lit.predicate, tuple(binding.get(t, t) for t in lit.args), lit.negated) for lit in move.guard]
    for constant, type_name in constants.items():
        if move.var_type not in (type_name, "object") and type_name != "object":
            continue  # a parameter of another type is never the owner
        if not any(lit.predicate == EQUALITY and lit.negated and set(lit.args) == {move.var, constant}
                   for lit in guard):
            if any(lit.predicate == EQUALITY and not lit.negated and set(lit.args) == {move.var, constant}
                   for lit in guard):
                continue
            raise _NotRead(f"a conditional effect of {op} may move the {move.predicate} of a parameter")
    if any(lit.predicate == EQUALITY and not lit.negated and move.var in lit.args for lit in guard):
        return  # it fires on a parameter's owner only, which the loop above refused
    generic = frozenset(Literal(lit.predicate, tuple("?o" if t == move.var else t for t in lit.args), lit.negated)
                        for lit in guard if not (lit.predicate == EQUALITY and move.var in lit.args))
    pattern = tuple("?o" if t == move.var else binding.get(t, t) for t in move.owner)
    run.others.setdefault((move.predicate, pattern), []).append((generic, move.word))


def _bind(atom: Atom, binding: Mapping[str, str]) -> Atom:
    return (atom[0], *(binding.get(t, t) for t in atom[1:]))


def _value_of(theory: _Theory, run: _Run, lit: Literal, binding: Mapping[str, str]) -> bool | Cond:
    args = tuple(binding.get(t, t) for t in lit.args)
    if lit.predicate == EQUALITY:
        return (args[0] == args[1]) != lit.negated
    atom = (lit.predicate, *args)
    if lit.predicate in theory.svs:
        position = theory.svs[lit.predicate]
        owner, value = _owner(atom, position), atom[1 + position]
        known = run.values.get((lit.predicate, owner))
        if known is not None:
            return (known == value) != lit.negated
        return ("v", (lit.predicate, *owner), value, not lit.negated)
    if lit.predicate in theory.fluents:
        fact = run.facts.get(atom)
        if fact is not None:
            return fact != lit.negated
        return ("b", atom, "", not lit.negated)
    return ("s", atom, "", not lit.negated)


def _normal(conds: set[Cond]) -> frozenset[Cond] | None:
    """The conditions without those the others imply (one value per owner); None when they cannot all hold."""
    out = set(conds)
    for kind, key, value, positive in conds:
        if (kind, key, value, not positive) in conds:
            return _FALSE
        if kind == "v" and positive:
            if any(k == "v" and o == key and v != value and p for k, o, v, p in conds):
                return _FALSE
            out -= {c for c in conds if c[0] == "v" and c[1] == key and c[2] != value and not c[3]}
    return frozenset(out)


def _reduced(word: Sequence[tuple[str, int]]) -> tuple[tuple[str, int], ...]:
    """A word of relation steps with a step and its inverse next to each other cancelled (a bijection's)."""
    out: list[tuple[str, int]] = []
    for step in word:
        if out and out[-1][0] == step[0] and out[-1][1] == -step[1]:
            out.pop()
        else:
            out.append(step)
    return tuple(out)


def _others(run: _Run) -> dict[tuple[str, tuple[str, ...]], tuple[frozenset[Literal], tuple[tuple[str, int], ...]]]:
    """What a run does to the owners no parameter names: per (predicate, owner pattern), one guard and one word
    (its moves under different guards are not read)."""
    out = {}
    for key, moves in run.others.items():
        guards = {guard for guard, _ in moves}
        if len(guards) != 1:
            raise _NotRead(f"moves of {key[0]} under different conditions")
        word = _reduced([step for _, w in moves for step in w])
        if word:
            out[key] = (guards.pop(), word)
    return out


def _difference(theory: _Theory, macro: _Run, sequence: _Run) -> str | None:
    """The first difference between the macro's run and its sequence's on the same case, in words; None if none."""
    need_m, need_s = (_FALSE if r.never else _normal(r.conds) for r in (macro, sequence))
    if need_m is _FALSE and need_s is _FALSE:
        return None
    if need_m != need_s:
        if need_m is _FALSE or need_s is _FALSE:
            return f"the {'macro' if need_m is _FALSE else 'expansion'} never applies where the other may"
        extra_s, extra_m = sorted(need_s - need_m), sorted(need_m - need_s)
        if extra_s:
            return f"its expansion needs {_said(extra_s[0])}, which the macro does not"
        return f"the macro needs {_said(extra_m[0])}, which its expansion does not"
    assert need_m is not None
    for atom in sorted(set(macro.facts) | set(sequence.facts)):
        left, right = (_fact_after(r, need_m, atom) for r in (macro, sequence))
        if left != right:
            return f"after it {format_atom(atom)} is {_truth(left)} for the macro, {_truth(right)} for its expansion"
    for key in sorted(set(macro.values) | set(sequence.values)):
        value_m, value_s = (_value_after(r, need_m, key) for r in (macro, sequence))
        if value_m != value_s:
            return (f"after it {key[0]} of {' '.join(key[1]) or 'its owner'} is {value_m or 'unchanged'} for the "
                    f"macro, {value_s or 'unchanged'} for its expansion")
    moves_m, moves_s = _others(macro), _others(sequence)
    for key in sorted(set(moves_m) | set(moves_s)):
        if moves_m.get(key) != moves_s.get(key):
            return (f"on the other owners of {key[0]} the macro {_said_move(moves_m.get(key))}, its expansion "
                    f"{_said_move(moves_s.get(key))}")
    return None


def _fact_after(run: _Run, need: frozenset[Cond], atom: Atom) -> bool | None:
    if atom in run.facts:
        return run.facts[atom]
    if ("b", atom, "", True) in need:
        return True
    if ("b", atom, "", False) in need:
        return False
    return None


def _value_after(run: _Run, need: frozenset[Cond], key: tuple[str, tuple[str, ...]]) -> str | None:
    if key in run.values:
        return run.values[key]
    return next((value for kind, owner, value, positive in need
                 if kind == "v" and positive and owner == (key[0], *key[1])), None)


def _truth(value: bool | None) -> str:
    return "unchanged" if value is None else "true" if value else "false"


def _said(cond: Cond) -> str:
    kind, key, value, positive = cond
    if kind == "v":
        said = f"({key[0]} of {' '.join(key[1:]) or 'its one owner'} = {value})"
        return said if positive else f"(not {said})"
    return format_atom(key) if positive else f"(not {format_atom(key)})"


def _said_move(move: tuple[frozenset[Literal], tuple[tuple[str, int], ...]] | None) -> str:
    if move is None:
        return "moves none"
    guard, word = move
    steps = " ".join(f"{name}{'' if d == 1 else '^-1'}" for name, d in word)
    return f"moves each along {steps} where {' '.join(lit.pddl() for lit in sorted(guard, key=Literal.pddl))}"


def _partitions(items: Sequence[int]) -> Iterator[list[list[int]]]:
    if not items:
        yield []
        return
    first, rest = items[0], items[1:]
    for smaller in _partitions(rest):  # the finest first: every parameter different
        yield [[first], *smaller]
        for i in range(len(smaller)):
            yield smaller[:i] + [[first, *smaller[i]]] + smaller[i + 1:]


def _cases(macro: Operator) -> Iterator[dict[int, int]]:
    """Every way the macro's parameters may coincide: parameter index -> the index of its class's first member."""
    by_type: dict[str, list[int]] = {}
    for i, (_, type_name) in enumerate(macro.parameters):
        by_type.setdefault(type_name, []).append(i)
    groups = [list(_partitions(indices)) for indices in by_type.values()]
    for choice in itertools.product(*groups):
        classes: dict[int, int] = {}
        for partition in choice:
            for block in partition:
                for i in block:
                    classes[i] = min(block)
        yield classes


def _case_count(macro: Operator) -> int:
    count = 1
    by_type: dict[str, int] = {}
    for _, type_name in macro.parameters:
        by_type[type_name] = by_type.get(type_name, 0) + 1
    for n in by_type.values():
        count *= _bell(n)
    return count


def _bell(n: int) -> int:
    row = [1]
    for _ in range(n):
        nxt = [row[-1]]
        for value in row:
            nxt.append(nxt[-1] + value)
        row = nxt
    return row[0]


def _check(theory: _Theory, macro: Operator, expansion: Expansion, operators: Mapping[str, Operator]) -> str | None:
    """None when `expansion` is faithful to `macro` in every case; else the first difference, in words."""
    if _case_count(macro) > MAX_PARTITIONS:
        return f"its {len(macro.parameters)} parameters may coincide in too many ways to check"
    names = [name for name, _ in macro.parameters]
    for classes in _cases(macro):
        constants = {names[c]: macro.parameters[c][1] for c in classes.values()}
        macro_binding = {names[i]: names[c] for i, c in classes.items()}
        steps = []
        for name, indices in expansion.steps:
            op = operators[name]
            steps.append((op, {p: macro_binding[names[i]] for (p, _), i in zip(op.parameters, indices)}))
        try:
            difference = _difference(theory, _run(theory, [(macro, macro_binding)], constants),
                                     _run(theory, steps, constants))
        except _NotRead as exc:
            return f"not read: {exc}"
        if difference is not None:
            same = [f"{names[i]} = {names[c]}" for i, c in sorted(classes.items()) if i != c]
            return difference + (f" (where {', '.join(same)})" if same else "")
    return None


# -- finding what a macro may stand for -------------------------------------------------------------------------
def _prove(theory: _Theory, macro: Operator, others: Sequence[Operator]) -> Expansion | str | None:
    """The macro's faithful expansion, or the first difference of its best candidate, or None (no candidate: an
    action of its own)."""
    operators = {op.name: op for op in others} | {macro.name: macro}
    first_difference: str | None = None
    for tried, expansion in enumerate(_candidates(theory, macro, others)):
        difference = _check(theory, macro, expansion, operators)
        if difference is None:
            return expansion
        if first_difference is None:
            first_difference = (f"as {expansion.describe([p for p, _ in macro.parameters])}: {difference}")
        if tried + 1 >= MAX_CANDIDATES or any(isinstance(m, str) for (name, _), m in theory.moves.items()
                                              if name == macro.name):
            break  # no other reading of the same macro would be read
    return first_difference


def _candidates(theory: _Theory, macro: Operator, others: Sequence[Operator]) -> Iterator[Expansion]:
    """Sequences of 2 to MAX_STEPS other actions whose effects, with the macro's parameters all different, are the
    macro's: shortest first, those that need no literal the macro does not give first."""
    names = [p for p, _ in macro.parameters]
    index = {p: i for i, p in enumerate(names)}
    changes = _changed(macro)  # a step that changes anything else is not looked at (its changes would show)
    others = [op for op in others if _changed(op) <= changes]
    start = _Known.of(theory, macro.precondition)
    target = start.after(theory, [(macro, {p: p for p in names})]).canonical(theory)
    seen: set[tuple[tuple[str, tuple[int, ...]], ...]] = set()
    visits = [MAX_VISITS]
    for budget in range(MAX_SKIPPED + 1):
        for length in range(2, MAX_STEPS + 1):
            for steps in _sequences(theory, macro, others, start, length, budget, frozenset(), visits):
                key = tuple((op.name, tuple(index[binding[p]] for p, _ in op.parameters)) for op, binding in steps)
                if key in seen or start.after(theory, steps).canonical(theory) != target:
                    continue
                seen.add(key)
                yield Expansion(macro.name, len(names), key)


def _changed(op: Operator) -> frozenset[str]:
    return frozenset(atom[0] for block in op.effects for atom in block.add + block.delete)


Step = tuple[Operator, Mapping[str, str]]


def _sequences(theory: _Theory, macro: Operator, others: Sequence[Operator], known: _Known, length: int,
               budget: int, skipped: frozenset[Literal], visits: list[int],
               visited: frozenset[_Known] = frozenset()) -> Iterator[list[Step]]:
    """Sequences of `length` steps from `known`, each changing what is known to something not known before; at
    most `visits[0]` steps tried in all (shared by the calls for one macro)."""
    if length == 0:
        yield []
        return
    visited = visited | {known}
    for op in others:
        for binding, missed in _bindings(theory, op, macro, known, budget - len(skipped), skipped):
            visits[0] -= 1
            if visits[0] < 0:
                return
            after = known.after(theory, [(op, binding)])
            if after in visited:
                continue
            for rest in _sequences(theory, macro, others, after, length - 1, budget, skipped | missed, visits,
                                   visited):
                yield [(op, binding), *rest]


def _bindings(theory: _Theory, op: Operator, macro: Operator, known: _Known, budget: int,
              skipped: frozenset[Literal]) -> Iterator[tuple[dict[str, str], frozenset[Literal]]]:
    """Bindings of `op`'s parameters to the macro's under which its positive precondition holds in `known`, but
    for at most `budget` literals more than those already `skipped` (returned: the literals missed)."""
    types = dict(op.parameters)
    macro_types = dict(macro.parameters)
    positive = [lit for lit in op.precondition if not lit.negated and lit.predicate != EQUALITY]
    # only a plain fact may be missed (a macro that forgot a grasp): a missed value or static fact is another action
    skippable = {lit for lit in positive if lit.predicate in theory.fluents and lit.predicate not in theory.svs}

    def extend(i: int, binding: dict[str, str], missed: frozenset[Literal]) -> Iterator[
            tuple[dict[str, str], frozenset[Literal]]]:
        if i == len(positive):
            free = [p for p, _ in op.parameters if p not in binding]
            choices = [[m for m, t in macro.parameters if t == types[p]] for p in free]
            # bindings that keep the action's parameters apart first (the reading a macro's author meant)
            for values in sorted(itertools.product(*choices),
                                 key=lambda v: -len(set(v) | set(binding.values()))):
                whole = {**binding, **dict(zip(free, values))}
                lost = frozenset(Literal(l.predicate, tuple(whole[t] for t in l.args), l.negated)
                                 for l in missed) - skipped
                if len(lost) <= budget:
                    yield whole, lost
            return
        lit = positive[i]
        for atom in known.true:
            if atom[0] != lit.predicate or len(atom) != len(lit.args) + 1:
                continue
            trial = dict(binding)
            if all(trial.setdefault(t, a) == a and macro_types.get(a) == types.get(t)
                   for t, a in zip(lit.args, atom[1:])):
                yield from extend(i + 1, trial, missed)
        if len(missed) < budget and lit in skippable:
            yield from extend(i + 1, binding, missed | {lit})

    return extend(0, {}, frozenset())


@dataclass(frozen=True)
class _Known:
    """What is known true and false, with the macro's parameters all different: its precondition, then effects."""

    true: frozenset[Atom]
    false: frozenset[Atom]

    @classmethod
    def of(cls, theory: _Theory, precondition: Sequence[Literal]) -> _Known:
        true = frozenset(lit.atom for lit in precondition if not lit.negated and lit.predicate != EQUALITY)
        false = frozenset(lit.atom for lit in precondition if lit.negated and lit.predicate != EQUALITY)
        return cls(true, false)

    def canonical(self, theory: _Theory) -> tuple[frozenset[Atom], frozenset[Atom]]:
        """What is known, without the false values of owners whose value is known (one value per owner)."""
        valued = {(a[0], _owner(a, theory.svs[a[0]])) for a in self.true if a[0] in theory.svs}
        false = frozenset(a for a in self.false
                          if not (a[0] in theory.svs and (a[0], _owner(a, theory.svs[a[0]])) in valued))
        return self.true, false

    def after(self, theory: _Theory, steps: Sequence[Step]) -> _Known:
        true, false = set(self.true), set(self.false)
        for op, binding in steps:
            adds = [_bind(a, binding) for b in op.effects if not b.variables and not b.condition for a in b.add]
            dels = [_bind(a, binding) for b in op.effects if not b.variables and not b.condition for a in b.delete]
            for atom in dels:
                true.discard(atom)
                false.add(atom)
            for atom in adds:
                if atom[0] in theory.svs:  # the owner's other values are false now
                    position = theory.svs[atom[0]]
                    owner = _owner(atom, position)
                    for other in [t for t in true if t[0] == atom[0] and _owner(t, position) == owner]:
                        true.discard(other)
                        false.add(other)
                false.discard(atom)
                true.add(atom)
        return _Known(frozenset(true), frozenset(false))


"""Grounding: a parsed domain and problem -> ground actions over objects, static facts evaluated.

Three analyses on the lifted task come first, as in any grounder:

* **static predicates** appear in no effect; their facts are fixed by the problem's init.
* **relevant predicates** appear in a precondition, an effect condition or the goal; effects on the others
  (bookkeeping no action reads) are dropped.
* **state variables**: a changing predicate whose every add is paired, in the same effect, with a delete that
  differs in exactly one argument (its *value* position) keeps one value per tuple of its other arguments
  (the *owner*), e.g. ``(hasorientation ?o ?j)``: owner ``?j``, value ``?o``. The variables are the owners
  with a value in the init.

Parameters at a value position (and parameters sharing a static atom only with them, like ``?o2`` in
``(orientationord ?o1 ?o2)``) are *value parameters*; every other parameter is *structural*. Grounding
binds the structural parameters by joining the static facts and the variables' owners (so a binding
that no static fact supports is never built), evaluates every literal over structural parameters alone
(positive or negative static facts, equality, types), and leaves the literals that mention a value
parameter to recognition. One `GroundAction` therefore stands for the family of ground actions that differ
only in their value arguments; its size is independent of the number of values, which keeps grounding
polynomial (200 links x 72 orientations in well under a second).
"""
from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Iterator, Mapping

from planhrc.grounding import bind_atom, holds, substitute
from planhrc.model import EQUALITY, Atom, Literal

from .deadline import check as check_deadline
from .errors import PlannerError
from .operators import EffectBlock, Operator, normalise_domain
from .pddl import Domain, Problem, format_sexpr

log = logging.getLogger(__name__)


class OutsideFamilyError(PlannerError):
    """The task is readable but not one the in-process planner solves; the message says precisely why."""


@dataclass(frozen=True)
class StateVariablePredicate:
    name: str
    arity: int
    value_position: int

    def owner(self, atom: Atom) -> tuple[str, ...]:
        args = atom[1:]
        return args[:self.value_position] + args[self.value_position + 1:]

    def value(self, atom: Atom) -> str:
        return atom[1 + self.value_position]


@dataclass(frozen=True)
class GroundEffect:
    variables: tuple[tuple[str, str], ...]  # forall value variables, still free, with their types
    condition: tuple[Literal, ...]  # literals left for recognition
    add: tuple[Atom, ...]
    delete: tuple[Atom, ...]


@dataclass(frozen=True)
class GroundAction:
    """A ground action up to its value parameters (left as ``?names`` in its literals and effects)."""

    operator: str
    parameters: tuple[str, ...]  # the schema's parameter names, in order
    binding: tuple[tuple[str, str], ...]  # structural parameter -> object
    value_parameters: tuple[tuple[str, str], ...]  # (?name, type)
    precondition: tuple[Literal, ...]  # literals left for recognition
    effects: tuple[GroundEffect, ...]


@dataclass(frozen=True)
class GroundedProblem:
    domain_name: str
    problem_name: str
    objects: tuple[tuple[str, str], ...]
    static_predicates: frozenset[str]
    static_facts: frozenset[Atom]
    state_predicates: tuple[StateVariablePredicate, ...]
    variables: tuple[tuple[str, tuple[str, ...]], ...]  # (predicate, owner), sorted
    actions: tuple[GroundAction, ...]
    type_objects: tuple[tuple[str, frozenset[str]], ...]  # each type with its objects (subtypes included)
    control_predicates: frozenset[str] = frozenset()  # changing predicates that are not cyclic variables

    def objects_of(self, type_name: str) -> frozenset[str]:
        return dict(self.type_objects).get(type_name, frozenset())


# -- lifted analyses ---------------------------------------------------------------------------------------
def static_predicates(domain: Domain, operators: tuple[Operator, ...]) -> frozenset[str]:
    changing = {atom[0] for op in operators for block in op.effects for atom in block.add + block.delete}
    return frozenset(name for name, _ in domain.predicates if name not in changing)


def find_state_predicates(operators: tuple[Operator, ...], changing: frozenset[str],
                          arity: Mapping[str, int]) -> tuple[tuple[StateVariablePredicate, ...], dict[str, str]]:
    """The value position of every changing predicate that has one, and why each other one has none."""
    candidates: dict[str, set[int]] = {name: set(range(arity[name])) for name in changing}
    why_not: dict[str, str] = {}
    for op in operators:
        for block in op.effects:
            for name in changing:
                adds = [a for a in block.add if a[0] == name]
                dels = [d for d in block.delete if d[0] == name]
                for atoms, others, verb in ((adds, dels, "adds"), (dels, adds, "deletes")):
                    for atom in atoms:
                        positions = {_single_difference(atom, other) for other in others} - {None}
                        if not positions and name not in why_not:
                            why_not[name] = (f"action {op.name} {verb} {format_sexpr(atom)} with no matching "
                                             f"{'delete' if verb == 'adds' else 'add'} that differs in one argument: "
                                             f"{name} is not a state variable with one value")
                        candidates[name] &= positions
    out = []
    for name in sorted(changing):
        if name in why_not:
            continue
        if len(candidates[name]) != 1:
            why_not[name] = f"predicate {name}: its actions do not agree on which argument is the value"
            continue
        out.append(StateVariablePredicate(name, arity[name], candidates[name].pop()))
    return tuple(out), why_not


def split_cyclic(domain: Domain, operators: tuple[Operator, ...], state: tuple[StateVariablePredicate, ...],
                 statics: frozenset[str]) -> tuple[tuple[StateVariablePredicate, ...], dict[str, str]]:
    """The state variables whose values some action steps along a static relation (``(next ?a1 ?a2)`` between
    the current value and another of the same type), and why each other one is control (``(centred ?j)``,
    whose actions relate its values to links, not to each other)."""
    cyclic, why_not = [], {}
    for pred in state:
        if any(_steps_values(op, pred, statics, state) for op in operators):
            cyclic.append(pred)
        else:
            why_not[pred.name] = (f"{pred.name}: no action relates two of its values by a static relation; it is "
                                  "part of the control, not a cycle of values")
    return tuple(cyclic), why_not


def _steps_values(op: Operator, pred: StateVariablePredicate, statics: frozenset[str],
                  state: tuple[StateVariablePredicate, ...]) -> bool:
    """Whether `op` relates a value term of `pred` to another term of the same type through a static binary
    literal, the other term being no owner (no argument of a changing atom outside a value position)."""
    types = dict(op.parameters + tuple(v for block in op.effects for v in block.variables))
    values = {pred.value(atom) for atom in _atoms_of(op) if atom[0] == pred.name}
    value_of = {p.name: p.value_position for p in state}
    owners = {arg for atom in _atoms_of(op) if atom[0] not in statics and atom[0] != EQUALITY
              for i, arg in enumerate(atom[1:]) if value_of.get(atom[0]) != i}
    literals = list(op.precondition) + [lit for block in op.effects for lit in block.condition]
    for lit in literals:
        if lit.predicate not in statics or lit.predicate == EQUALITY or len(lit.args) != 2:
            continue
        a, b = lit.args
        for mine, other in ((a, b), (b, a)):
            if mine in values and other.startswith("?") and other not in owners and types.get(mine) == types.get(
                    other):
                return True
    return False


def _single_difference(a: Atom, b: Atom) -> int | None:
    if len(a) != len(b):
        return None
    diff = [i for i in range(1, len(a)) if a[i] != b[i]]
    return diff[0] - 1 if len(diff) == 1 else None


# -- grounding ---------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class LiftedTask:
    """The analyses of one domain for one set of goal predicates (compared by identity: built once, cached)."""

    domain: Domain
    operators: tuple[Operator, ...]
    static_predicates: frozenset[str]
    state_predicates: tuple[StateVariablePredicate, ...]  # the cyclic ones
    control_predicates: frozenset[str] = frozenset()  # every other changing predicate (`planner.product`)
    control_reasons: tuple[tuple[str, str], ...] = ()  # (predicate, why it is control, not a cyclic variable)

    def owners(self, init: frozenset[Atom]) -> frozenset[tuple[str, tuple[str, ...]]]:
        """(predicate, owner) of every state-variable atom of an init: which variables have a value."""
        by_name = {p.name: p for p in self.state_predicates}
        return frozenset((a[0], by_name[a[0]].owner(a)) for a in init if a[0] in by_name)

    def static_facts(self, init: frozenset[Atom]) -> frozenset[Atom]:
        return frozenset(a for a in init if a[0] in self.static_predicates)


def analyse(domain: Domain, goal_predicates: frozenset[str]) -> LiftedTask:
    """Normal form, static, relevant and state-variable predicates of `domain` (raises when outside)."""
    operators = normalise_domain(domain)
    arity = {name: len(args) for name, args in domain.predicates}
    for op in operators:
        for atom in _atoms_of(op):
            if atom[0] != EQUALITY and atom[0] not in arity:
                raise OutsideFamilyError(f"action {op.name}: predicate {atom[0]} is not declared")
            if atom[0] != EQUALITY and len(atom) - 1 != arity[atom[0]]:
                raise OutsideFamilyError(f"action {op.name}: {format_sexpr(atom)} has {len(atom) - 1} argument(s), "
                                         f"{atom[0]} takes {arity[atom[0]]}")
    for name in goal_predicates:
        if name not in arity:
            raise OutsideFamilyError(f"goal: predicate {name} is not declared")
    statics = static_predicates(domain, operators)
    names = {lit.predicate for op in operators for lit in op.precondition}
    names |= {lit.predicate for op in operators for block in op.effects for lit in block.condition}
    relevant = frozenset(names | goal_predicates)
    operators = tuple(_drop_irrelevant(op, relevant) for op in operators)
    changing = frozenset({atom[0] for op in operators for b in op.effects for atom in b.add + b.delete})
    state, not_variables = find_state_predicates(operators, changing, arity)
    cyclic, not_cyclic = split_cyclic(domain, operators, state, statics)
    reasons = {**not_variables, **not_cyclic}
    return LiftedTask(domain, operators, statics, cyclic, frozenset(reasons), tuple(sorted(reasons.items())))


def ground(domain: Domain, problem: Problem) -> GroundedProblem:
    """Ground every action of `domain` on `problem`'s objects and static facts."""
    lifted = analyse(domain, frozenset(a[0] for a in problem.goal))
    return ground_lifted(lifted, problem.name, problem.objects, lifted.static_facts(problem.init),
                         owner_values(lifted, problem.init))


def owner_values(lifted: LiftedTask, init: frozenset[Atom]) -> frozenset[tuple[str, tuple[str, ...]]]:
    """Which variables have a value in `init`; OutsideFamilyError when one has several."""
    by_name = {p.name: p for p in lifted.state_predicates}
    seen: dict[tuple[str, tuple[str, ...]], list[str]] = {}
    for atom in init:
        pred = by_name.get(atom[0])
        if pred is not None:
            seen.setdefault((pred.name, pred.owner(atom)), []).append(pred.value(atom))
    for (name, owner), values in sorted(seen.items()):
        if len(values) > 1:
            raise OutsideFamilyError(f"init: {name} gives {' '.join(owner) or 'its variable'} "
                                     f"{len(values)} values ({', '.join(sorted(values))}); expected one")
    return frozenset(seen)


def ground_lifted(lifted: LiftedTask, problem_name: str, objects: tuple[tuple[str, str], ...],
                  static_facts: frozenset[Atom], owners: frozenset[tuple[str, tuple[str, ...]]]) -> GroundedProblem:
    """Grounding proper: depends only on the objects, the static facts and which variables have a value."""
    domain = lifted.domain
    by_name = {p.name: p for p in lifted.state_predicates}
    known = {name for name, _ in objects}
    for atom in sorted(static_facts):
        for arg in atom[1:]:
            if arg not in known:
                raise OutsideFamilyError(f"init: {format_sexpr(atom)} names {arg}, which is not an object")
    variables = tuple(sorted(owners))
    table: dict[str, set[tuple[str, ...]]] = {p.name: set() for p in lifted.state_predicates}
    for name, owner in variables:
        table[name].add(owner)
    facts = FactIndex(static_facts, {name: frozenset(rows) for name, rows in table.items()})
    objects_of = _objects_by_type(domain, objects)
    actions: list[GroundAction] = []
    for op in lifted.operators:
        actions.extend(_ground_operator(op, by_name, lifted.static_predicates, facts, objects_of))
    log.debug("grounded %s/%s: %d state variables, %d ground actions (up to values)", domain.name, problem_name,
              len(variables), len(actions))
    return GroundedProblem(domain.name, problem_name, objects, lifted.static_predicates, static_facts,
                           lifted.state_predicates, variables, tuple(actions),
                           tuple(sorted((t, frozenset(objs)) for t, objs in objects_of.items())),
                           lifted.control_predicates)


def _atoms_of(op: Operator) -> Iterator[Atom]:
    for lit in op.precondition:
        yield lit.atom
    for block in op.effects:
        for lit in block.condition:
            yield lit.atom
        yield from block.add
        yield from block.delete


def _drop_irrelevant(op: Operator, relevant: frozenset[str]) -> Operator:
    blocks = []
    for block in op.effects:
        add = tuple(a for a in block.add if a[0] in relevant)
        delete = tuple(a for a in block.delete if a[0] in relevant)
        if add or delete:
            blocks.append(EffectBlock(block.variables, block.condition, add, delete))
    return Operator(op.name, op.parameters, op.precondition, tuple(blocks))


def _objects_by_type(domain: Domain, objects: tuple[tuple[str, str], ...]) -> dict[str, tuple[str, ...]]:
    types = {t for t, _ in domain.types} | {p for _, p in domain.types} | {t for _, t in objects} | {"object"}
    out = {}
    for t in types:
        below = domain.subtypes(t) | ({t2 for _, t2 in objects} if t == "object" else set())
        out[t] = tuple(name for name, t2 in objects if t2 in below)
    return out


class FactIndex:
    """Static facts and variable owners, indexed on demand by (relation, bound argument positions)."""

    def __init__(self, static_facts: frozenset[Atom], owners: Mapping[str, frozenset[tuple[str, ...]]]) -> None:
        self._tuples: dict[str, list[tuple[str, ...]]] = {}
        for atom in static_facts:
            self._tuples.setdefault(atom[0], []).append(atom[1:])
        for name, table in owners.items():
            self._tuples["owner:" + name] = sorted(table)
        self.static = static_facts
        self._index: dict[tuple[str, tuple[int, ...]], dict[tuple[str, ...], list[tuple[str, ...]]]] = {}

    def size(self, relation: str) -> int:
        return len(self._tuples.get(relation, ()))

    def lookup(self, relation: str, positions: tuple[int, ...], key: tuple[str, ...]) -> list[tuple[str, ...]]:
        index = self._index.get((relation, positions))
        if index is None:
            index = {}
            for row in self._tuples.get(relation, ()):
                index.setdefault(tuple(row[i] for i in positions), []).append(row)
            self._index[(relation, positions)] = index
        return index.get(key, [])


def _value_parameters(op: Operator, by_name: Mapping[str, StateVariablePredicate],
                      statics: frozenset[str]) -> frozenset[str]:
    """Parameters and forall variables at a value position, closed over static atoms shared only with them."""
    value: set[str] = set()
    owner: set[str] = set()
    static_atoms: list[Atom] = []
    for atom in _atoms_of(op):
        pred = by_name.get(atom[0])
        if pred is not None:
            value.add(pred.value(atom))
            owner.update(pred.owner(atom))
        elif atom[0] in statics and atom[0] != EQUALITY:
            static_atoms.append(atom)
        elif atom[0] != EQUALITY:  # a control atom: its arguments are bound, like owners
            owner.update(atom[1:])
    changed = True
    while changed:
        changed = False
        for atom in static_atoms:
            args = set(atom[1:])
            if args & value and not args <= value:
                if args & owner:
                    raise OutsideFamilyError(f"action {op.name}: {format_sexpr(atom)} relates a value to an owner")
                value |= args
                changed = True
    both = value & owner
    if both:
        raise OutsideFamilyError(f"action {op.name}: {', '.join(sorted(both))} is both a value and an owner")
    return frozenset(value)


def _ground_operator(op: Operator, by_name: Mapping[str, StateVariablePredicate], statics: frozenset[str],
                     facts: FactIndex, objects_of: Mapping[str, tuple[str, ...]]) -> Iterator[GroundAction]:
    values = _value_parameters(op, by_name, statics)
    names = tuple(var for var, _ in op.parameters)
    for var, t in op.parameters + tuple(v for b in op.effects for v in b.variables):
        if t not in objects_of:
            raise OutsideFamilyError(f"action {op.name}: {var} has unknown type {t}")
    structural = [(var, t) for var, t in op.parameters if var not in values]
    value_params = tuple((var, t) for var, t in op.parameters if var in values)
    where = f"action {op.name}"
    plan = compile_join(structural, op.precondition, by_name, statics, objects_of, frozenset(), where, facts)
    blocks = []
    for block in op.effects:
        free = [(var, t) for var, t in block.variables if var not in values]
        blocks.append((compile_join(free, block.condition, by_name, statics, objects_of,
                                    frozenset(v for v, _ in structural), f"{where}: effect", facts),
                       tuple((var, t) for var, t in block.variables if var in values),
                       tuple(lit for lit in block.condition if _left(lit, values, by_name, statics)), block))
    pre = tuple(lit for lit in op.precondition if _left(lit, values, by_name, statics))
    for binding in plan.run(facts, {}):
        check_deadline(f"grounding {where}")
        effects: list[GroundEffect] = []
        for block_plan, block_values, left, block in blocks:
            for inner in block_plan.run(facts, dict(binding)):
                effects.append(GroundEffect(block_values, tuple(substitute(lit, inner) for lit in left),
                                            tuple(bind_atom(a, inner) for a in block.add),
                                            tuple(bind_atom(a, inner) for a in block.delete)))
        yield GroundAction(op.name, names, tuple((var, binding[var]) for var, _ in structural), value_params,
                           tuple(substitute(lit, binding) for lit in pre), tuple(effects))


def _left(lit: Literal, values: frozenset[str], by_name: Mapping[str, StateVariablePredicate],
          statics: frozenset[str]) -> bool:
    """Whether a literal is left for recognition: it reads a state variable or the control part, or mentions a
    value parameter."""
    return (lit.predicate in by_name or bool(set(lit.args) & values)
            or (lit.predicate != EQUALITY and lit.predicate not in statics))


def _is_var(term: str) -> bool:
    return term.startswith("?")


@dataclass(frozen=True)
class _Step:
    relation: str
    positions: tuple[int, ...]  # row positions whose values are known before the step
    key: tuple[str, ...]  # the terms (bound variables or objects) at those positions
    new: tuple[tuple[int, str], ...]  # (row position, variable) bound by the step
    same: tuple[tuple[int, int], ...]  # a variable repeated in the row: those positions must agree
    checks: tuple[Literal, ...]  # literals whose terms are all bound after the step


@dataclass(frozen=True)
class JoinPlan:
    """How to enumerate the bindings of some parameters: relation steps, then parameters no relation binds."""

    first_checks: tuple[Literal, ...]
    steps: tuple[_Step, ...]
    free: tuple[str, ...]  # parameters no relation binds: they range over their type's objects
    allowed: tuple[tuple[str, frozenset[str]], ...]
    late_checks: tuple[Literal, ...]  # literals over free parameters

    def run(self, facts: FactIndex, binding: dict[str, str]) -> Iterator[dict[str, str]]:
        if not all(holds(lit, binding, facts.static) for lit in self.first_checks):
            return
        yield from self._step(0, facts, binding, dict(self.allowed))

    def _step(self, i: int, facts: FactIndex, binding: dict[str, str],
              allowed: Mapping[str, frozenset[str]]) -> Iterator[dict[str, str]]:
        if i == len(self.steps):
            yield from self._enumerate(0, facts, binding, allowed)
            return
        step = self.steps[i]
        key = tuple(binding[t] if _is_var(t) else t for t in step.key)
        last = i + 1 == len(self.steps) and not self.free and not self.late_checks
        for row in facts.lookup(step.relation, step.positions, key):
            if step.same and any(row[a] != row[b] for a, b in step.same):
                continue
            ok = True
            for pos, var in step.new:
                if row[pos] not in allowed[var]:
                    ok = False
                    break
                binding[var] = row[pos]
            if not ok or (step.checks and not all(holds(lit, binding, facts.static) for lit in step.checks)):
                continue
            if last:
                yield dict(binding)
            else:
                yield from self._step(i + 1, facts, binding, allowed)
        for _, var in step.new:
            binding.pop(var, None)

    def _enumerate(self, i: int, facts: FactIndex, binding: dict[str, str],
                   allowed: Mapping[str, frozenset[str]]) -> Iterator[dict[str, str]]:
        if i == len(self.free):
            if all(holds(lit, binding, facts.static) for lit in self.late_checks):
                yield dict(binding)
            return
        var = self.free[i]
        for obj in sorted(allowed[var]):
            binding[var] = obj
            yield from self._enumerate(i + 1, facts, binding, allowed)
        binding.pop(var, None)


def compile_join(params: list[tuple[str, str]], literals: tuple[Literal, ...],
                 by_name: Mapping[str, StateVariablePredicate], statics: frozenset[str],
                 objects_of: Mapping[str, tuple[str, ...]], given: frozenset[str], where: str,
                 facts: FactIndex) -> JoinPlan:
    """Plan the enumeration of `params` (extending bindings of the `given` variables) that satisfy the
    literals over structural terms.

    Positive static literals and the owners of positive state-variable literals are joined relation by
    relation, most-bound first (then the smaller relation); negative static literals and equality are
    checked as soon as their terms are bound; parameters no relation binds range over their type's objects.
    """
    wanted = {var for var, _ in params}
    relations: list[tuple[str, tuple[str, ...]]] = []
    checks: list[Literal] = []
    for lit in literals:
        pred = by_name.get(lit.predicate)
        if pred is not None:
            if not lit.negated:  # only owners with a value can be read (owner terms are never value parameters)
                relations.append(("owner:" + pred.name, pred.owner(lit.atom)))
            continue
        terms = lit.args
        if lit.predicate != EQUALITY and lit.predicate not in statics:
            continue  # reads the control part, which changes: left for `planner.product`, bound by type here
        if any(_is_var(t) and t not in wanted and t not in given for t in terms):
            continue  # mentions a value parameter: left for recognition
        if lit.predicate == EQUALITY or lit.negated:
            checks.append(lit)
        else:
            relations.append((lit.predicate, terms))
    bound = set(given)

    def ready(lit: Literal) -> bool:
        return all(not _is_var(t) or t in bound for t in lit.args)

    first = tuple(lit for lit in checks if ready(lit))
    pending = [lit for lit in checks if lit not in first]
    steps = []
    rest = list(relations)
    while rest:
        rest.sort(key=lambda rel: (-sum(1 for t in rel[1] if not _is_var(t) or t in bound), facts.size(rel[0])))
        relation, terms = rest.pop(0)
        positions = tuple(i for i, t in enumerate(terms) if not _is_var(t) or t in bound)
        new: list[tuple[int, str]] = []
        same: list[tuple[int, int]] = []
        first_pos: dict[str, int] = {}
        for i, t in enumerate(terms):
            if i in positions:
                continue
            if t in first_pos:
                same.append((first_pos[t], i))
            else:
                first_pos[t] = i
                new.append((i, t))
        bound |= {t for _, t in new}
        now = tuple(lit for lit in pending if ready(lit))
        pending = [lit for lit in pending if lit not in now]
        steps.append(_Step(relation, positions, tuple(terms[i] for i in positions), tuple(new), tuple(same), now))
    unbound = tuple(var for var, _ in params if var not in bound)
    allowed = tuple((var, frozenset(objects_of[t])) for var, t in params)
    return JoinPlan(first, tuple(steps), unbound, allowed, tuple(pending))



"""Recognition: is the grounded task a set of cyclic counters that every action adds a fixed vector to?

The family the in-process planner solves optimally (`planner.cyclic`):

* the values of every state variable lie on one cycle ``v_0 -> v_1 -> ... -> v_(K-1) -> v_0`` given by a
  static binary relation of the init (``orientationord``, ``AngleOrd``, ...);
* every ground action's precondition only *pins* variables' current values (``(hasorientation ?o1 ?j1)``),
  and its other value arguments follow from the pinned ones along the cycle (``(orientationord ?o1 ?o2)``:
  ``?o2`` is one step after ``?o1``), so for every state exactly one member of the action's family applies;
* every effect moves a variable from its current value to the value a fixed number of steps on, and every
  conditional effect fires for all values alike (its condition pins a value the same way).

Then each ground action adds a fixed vector modulo K to the variables. `recognise` computes those vectors
(`Axis`) or raises `OutsideFamilyError` saying which action, literal or fact breaks the family.

The changing predicates that are not cyclic variables (grippers' ``(free ?g)``, a working position
``(in-centre ?j)``: `planner.ground.split_cyclic`) are the *control part*: their literals stay ground in the
axis (`control_pre`, `control_add`, `control_del`), to be planned over by `planner.product`. An action changes
the cyclic variables or the control, not both, and a conditional effect neither reads nor changes the control.
Static literals over values (``(not (= ?o1 ?o2))``, a unary static predicate on a value) are evaluated for
all K values: always true is dropped, never true removes the action, sometimes true is outside the family; a
positive literal of a static predicate the init has no fact of never holds (a 45-degree macro where the
orientation set has no 45-degree steps).
"""
from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Mapping, Sequence

from planhrc.grounding import holds
from planhrc.model import EQUALITY, Atom, Literal, natural_key

from .deadline import check as check_deadline
from .ground import GroundAction, GroundedProblem, OutsideFamilyError, StateVariablePredicate
from .pddl import format_sexpr

log = logging.getLogger(__name__)

Term = tuple[int, int]  # (variable index, offset): "the current value of that variable, `offset` steps on"


@dataclass(frozen=True)
class Axis:
    """One ground action family: applicable in every state, adds `effect` (mod K) to the variables."""

    action: str
    parameters: tuple[str, ...]
    binding: tuple[tuple[str, str], ...]  # structural parameter -> object
    values: tuple[tuple[str, int, int], ...]  # value parameter -> (variable index, offset)
    effect: tuple[tuple[int, int], ...]  # (variable index, step mod K), by variable index
    pinned: tuple[int, ...]  # variables the precondition pins, in precondition order
    # The control part (`planner.product`): ground literals the action needs, ground atoms it adds and deletes.
    # An action changes the cyclic variables or the control, never both.
    control_pre: tuple[Literal, ...] = ()
    control_add: tuple[Atom, ...] = ()
    control_del: tuple[Atom, ...] = ()

    @property
    def moves_control(self) -> bool:
        return bool(self.control_add or self.control_del)

    def format(self, state: Sequence[int], cycle: Sequence[str]) -> str:
        """The concrete ground action applicable in `state` (current value index per variable)."""
        k = len(cycle)
        args = dict(self.binding)
        for name, var, offset in self.values:
            args[name] = cycle[(state[var] + offset) % k]
        return "(" + " ".join([self.action] + [args[p] for p in self.parameters]) + ")"


@dataclass(frozen=True)
class CyclicTask:
    domain_name: str
    problem_name: str
    state_predicates: tuple[StateVariablePredicate, ...]
    variables: tuple[tuple[str, tuple[str, ...]], ...]  # (predicate, owner)
    cycle: tuple[str, ...]
    cycle_relation: str
    axes: tuple[Axis, ...]
    static_predicates: frozenset[str]
    static_facts: frozenset[Atom]
    control_predicates: frozenset[str] = frozenset()


class _Never(Exception):
    """The action (or conditional effect) can never apply: drop it."""


def recognise(grounded: GroundedProblem, init: frozenset[Atom]) -> CyclicTask:
    """Decide membership of the family on the grounded task; OutsideFamilyError says precisely why not."""
    if not grounded.variables:
        raise OutsideFamilyError("no state variable has a value in the init: nothing for the in-process planner "
                                 "to count")
    by_name = {p.name: p for p in grounded.state_predicates}
    init_values = {by_name[a[0]].value(a) for a in init if a[0] in by_name}
    relations = _value_relations(grounded, by_name)
    cycle, cycle_relation = _find_cycle(grounded, relations, init_values)
    k = len(cycle)
    rotations = {cycle_relation: 1}
    for name in relations - {cycle_relation}:
        step = _rotation_step(grounded.static_facts, name, cycle)
        if step is not None:
            rotations[name] = step
    index = {(pred, owner): i for i, (pred, owner) in enumerate(grounded.variables)}
    context = _Context(grounded, by_name, index, cycle, rotations)
    axes = []
    for action in grounded.actions:
        check_deadline("recognising the ground actions")
        try:
            axis = context.axis(action)
        except _Never:
            continue
        if axis.effect or axis.moves_control:
            axes.append(axis)
    log.debug("recognised %s/%s: %d variables, K=%d, %d axes", grounded.domain_name, grounded.problem_name,
              len(grounded.variables), k, len(axes))
    return CyclicTask(grounded.domain_name, grounded.problem_name, grounded.state_predicates, grounded.variables,
                      cycle, cycle_relation, tuple(axes), grounded.static_predicates, grounded.static_facts,
                      grounded.control_predicates)


def _value_relations(grounded: GroundedProblem, by_name: Mapping[str, StateVariablePredicate]) -> frozenset[str]:
    """Static binary predicates that relate two value terms somewhere in the ground actions."""
    names = set()
    for action in grounded.actions:
        literals = list(action.precondition) + [lit for eff in action.effects for lit in eff.condition]
        for lit in literals:
            if lit.predicate not in by_name and lit.predicate != EQUALITY and len(lit.args) == 2 and all(
                    t.startswith("?") for t in lit.args):
                names.add(lit.predicate)
    return frozenset(names)


def _successors(facts: frozenset[Atom], name: str) -> dict[str, list[str]]:
    succ: dict[str, list[str]] = {}
    for atom in sorted(a for a in facts if a[0] == name):
        succ.setdefault(atom[1], []).append(atom[2])
    return succ


def _find_cycle(grounded: GroundedProblem, relations: frozenset[str], values: set[str]) -> tuple[tuple[str, ...], str]:
    reasons = []
    for name in sorted(relations):
        cycle_or_reason = _single_cycle(_successors(grounded.static_facts, name), name)
        if isinstance(cycle_or_reason, str):
            reasons.append(cycle_or_reason)
            continue
        missing = values - set(cycle_or_reason)
        if missing:
            reasons.append(f"{name}: value(s) {', '.join(sorted(missing))} of the init are not on its cycle")
            continue
        return cycle_or_reason, name
    if not reasons:
        preds = ", ".join(p.name for p in grounded.state_predicates)
        raise OutsideFamilyError(f"no static relation between two values orders the values of {preds}: "
                                 "the actions do not step along a cycle")
    raise OutsideFamilyError("; ".join(reasons))


def _single_cycle(succ: Mapping[str, list[str]], name: str) -> tuple[str, ...] | str:
    if not succ:
        return f"{name}: no facts in the init"
    for a, bs in succ.items():
        if len(bs) > 1:
            return f"{name}: {a} has {len(bs)} successors; it must be a single cycle over the values"
    nxt = {a: bs[0] for a, bs in succ.items()}
    if set(nxt.values()) != set(nxt):
        return f"{name}: must be a single cycle over the values (it does not wrap around)"
    start = min(nxt, key=natural_key)
    cycle = [start]
    while nxt[cycle[-1]] != start:
        cycle.append(nxt[cycle[-1]])
    if len(cycle) != len(nxt):
        return f"{name}: forms several cycles, expected a single cycle over the values"
    return tuple(cycle)


def _rotation_step(facts: frozenset[Atom], name: str, cycle: tuple[str, ...]) -> int | None:
    """m when the relation is exactly {(v, v + m)} on the cycle, else None."""
    k = len(cycle)
    pos = {v: i for i, v in enumerate(cycle)}
    pairs = [a[1:] for a in facts if a[0] == name]
    if len(pairs) != k or any(a not in pos or b not in pos for a, b in pairs):
        return None
    steps = {(pos[b] - pos[a]) % k for a, b in pairs}
    if len(steps) != 1 or len({a for a, _ in pairs}) != k:
        return None
    return steps.pop()


class _Context:
    def __init__(self, grounded: GroundedProblem, by_name: Mapping[str, StateVariablePredicate],
                 index: Mapping[tuple[str, tuple[str, ...]], int], cycle: tuple[str, ...],
                 rotations: Mapping[str, int]) -> None:
        self.grounded = grounded
        self.by_name = by_name
        self.index = index
        self.cycle = cycle
        self.k = len(cycle)
        self.rotations = rotations
        self.type_objects = dict(grounded.type_objects)
        # static predicates without a single fact: a positive literal of one never holds (a bimanual object whose
        # orientation set has no 45-degree steps has no `orientationord45` facts, so its macros never apply)
        self.factless = grounded.static_predicates - {atom[0] for atom in grounded.static_facts}

    def _fail(self, action: GroundAction, why: str) -> OutsideFamilyError:
        args = dict(action.binding)
        shown = " ".join(args.get(p, p) for p in action.parameters)
        return OutsideFamilyError(f"action ({action.operator} {shown}): {why}; the in-process planner only "
                                  "solves tasks where every action adds a fixed step to cyclic variables or "
                                  "changes only the control part")

    def _check_types(self, action: GroundAction, params: Sequence[tuple[str, str]]) -> None:
        values = set(self.cycle)
        for name, type_name in params:
            objs = self.type_objects.get(type_name, frozenset())
            if not values <= objs:
                raise self._fail(action, f"{name} - {type_name} cannot take every value of the cycle")

    def axis(self, action: GroundAction) -> Axis:
        self._check_types(action, action.value_parameters)
        env: dict[str, Term] = {}
        control = self.grounded.control_predicates
        control_pre = tuple(lit for lit in action.precondition if lit.predicate in control)
        pinned = self._resolve(action, [lit for lit in action.precondition if lit.predicate not in control], env,
                               conditional=False)
        unresolved = [name for name, _ in action.value_parameters if name not in env]
        if unresolved:
            raise self._fail(action, f"{', '.join(unresolved)} is not fixed by the current values")
        steps: dict[int, int] = {}
        control_add: list[Atom] = []
        control_del: list[Atom] = []
        for effect in action.effects:
            self._check_types(action, effect.variables)
            reads = [lit.pddl() for lit in effect.condition if lit.predicate in control]
            if reads:
                raise self._fail(action, f"a conditional effect reads the control part ({reads[0]})")
            local = dict(env)
            try:
                self._resolve(action, effect.condition, local, conditional=True)
            except _Never:
                continue
            free = [name for name, _ in effect.variables if name not in local]
            if free:
                raise self._fail(action, f"conditional effect: {', '.join(free)} is not fixed by the current values")
            adds = [a for a in effect.add if a[0] in control]
            dels = [a for a in effect.delete if a[0] in control]
            if (adds or dels) and (effect.condition or effect.variables):
                raise self._fail(action, "a conditional effect changes the control part")
            control_add += adds
            control_del += dels
            changed = self._effect_steps(action, [a for a in effect.add if a[0] not in control],
                                         [a for a in effect.delete if a[0] not in control], local)
            for var, step in changed.items():
                if steps.setdefault(var, step) != step:
                    raise self._fail(action, f"gives {self._name(var)} two different new values")
        values = tuple((name, *env[name]) for name, _ in action.value_parameters)
        effect_vector = tuple(sorted((v, s) for v, s in steps.items() if s % self.k))
        if effect_vector and (control_add or control_del):
            raise self._fail(action, "changes both cyclic values and the control part")
        return Axis(action.operator, action.parameters, action.binding, values, effect_vector, tuple(pinned),
                    control_pre, tuple(sorted(set(control_add))), tuple(sorted(set(control_del))))

    def _name(self, var: int) -> str:
        pred, owner = self.grounded.variables[var]
        return f"({pred} _ {' '.join(owner)})" if len(self.grounded.state_predicates) > 1 else " ".join(owner)

    def _variable(self, atom: Atom) -> tuple[StateVariablePredicate, int | None]:
        pred = self.by_name[atom[0]]
        return pred, self.index.get((pred.name, pred.owner(atom)))

    def _resolve(self, action: GroundAction, literals: Sequence[Literal], env: dict[str, Term],
                 conditional: bool) -> list[int]:
        """Bind value parameters from pins and rotations; evaluate the rest. Raises _Never when the literals
        can never hold together, OutsideFamilyError when whether they hold depends on the state."""
        where = "conditional effect: " if conditional else ""
        pinned: list[int] = []
        rest: list[Literal] = []
        for lit in literals:
            if lit.predicate not in self.by_name:
                rest.append(lit)
                continue
            atom = lit.atom
            pred, var = self._variable(atom)
            if lit.negated:
                raise self._fail(action, f"{where}{lit.pddl()} asks a variable NOT to have a value")
            if var is None:
                raise _Never()
            term = pred.value(atom)
            if term not in env:
                env[term] = (var, 0)
            elif env[term][0] != var:
                raise self._fail(action, f"{where}{lit.pddl()} compares {self._name(var)} with "
                                         f"{self._name(env[term][0])}, which depends on the state")
            elif env[term][1] % self.k:
                raise _Never()
            pinned.append(var)
        progress = True
        while progress:
            progress = False
            for lit in list(rest):
                name = lit.predicate
                if name in self.rotations and not lit.negated:
                    a, b = lit.args
                    m = self.rotations[name]
                    if a in env and b not in env:
                        env[b] = (env[a][0], env[a][1] + m)
                    elif b in env and a not in env:
                        env[a] = (env[b][0], env[b][1] - m)
                    else:
                        continue
                    rest.remove(lit)
                    progress = True
        for lit in rest:
            if lit.predicate in self.factless and not lit.negated:
                raise _Never()
            terms = [t for t in lit.args if t.startswith("?")]
            missing = [t for t in terms if t not in env]
            if missing:
                raise self._fail(action, f"{where}{', '.join(missing)} in {lit.pddl()} is not fixed by the "
                                         "current values")
            bases = {env[t][0] for t in terms}
            if len(bases) > 1:
                raise self._fail(action, f"{where}{lit.pddl()} relates the values of "
                                         f"{' and '.join(self._name(b) for b in sorted(bases))}, which depends on "
                                         "the state")
            truth = {self._holds(lit, env, base) for base in range(self.k)}
            if truth == {False}:
                raise _Never()
            if truth == {True, False}:
                raise self._fail(action, f"{where}{lit.pddl()} holds for some values only, which depends on "
                                         "the state")
        return pinned

    def _holds(self, lit: Literal, env: Mapping[str, Term], base: int) -> bool:
        values = {t: self.cycle[(base + env[t][1]) % self.k] for t in lit.args if t.startswith("?")}
        return holds(lit, values, self.grounded.static_facts)

    def _effect_steps(self, action: GroundAction, add: Sequence[Atom], delete: Sequence[Atom],
                      env: Mapping[str, Term]) -> dict[int, int]:
        deleted: dict[int, int] = {}
        for atom in delete:
            pred, var = self._variable(atom)
            term = env.get(pred.value(atom))
            if var is None or term is None or term[0] != var or term[1] % self.k:
                raise self._fail(action, f"deletes {format_sexpr(atom)}, which is not the variable's current value")
            deleted[var] = 0
        steps: dict[int, int] = {}
        for atom in add:
            pred, var = self._variable(atom)
            term = env.get(pred.value(atom))
            if var is None:
                raise self._fail(action, f"adds {format_sexpr(atom)} to something without a value in the init")
            if term is None or term[0] != var:
                raise self._fail(action, f"adds {format_sexpr(atom)}, whose value is not a fixed step from "
                                         f"{self._name(var)}'s current value")
            if var not in deleted:
                raise self._fail(action, f"adds {format_sexpr(atom)} without deleting the current value")
            if steps.setdefault(var, term[1] % self.k) != term[1] % self.k:
                raise self._fail(action, f"gives {self._name(var)} two different new values")
        for var in deleted:
            if var not in steps:
                raise self._fail(action, f"deletes the value of {self._name(var)} without adding a new one")
        return steps

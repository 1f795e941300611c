"""The paper's state-transition equations, driven by the action schemas of the TBox.

`ground_action` instantiates a schema with a plan step's arguments in a given state: pre, eff-, eff+ and the
conditional effects whose `forall` variables have a binding satisfying `when` in that state.
`apply` is eq. (statetransitioncond): s' = (s \\ (eff- ∪ C-)) ∪ (eff+ ∪ C+). `replay` gives the expected states
s^e_1 .. s^e_{N+1} of a plan. Inputs are never changed: states are frozensets.
"""
from __future__ import annotations

from typing import Iterator, Mapping, Sequence

from planhrc.errors import PlanhrcError
from planhrc.model import ActionSchemaSpec, ActionSpec, Atom, CondEffect, DomainModelSpec, Literal, State


class TransitionError(PlanhrcError):
    """A plan step does not match a schema or is not applicable in the state it is applied to."""


def parse_step(step: str) -> tuple[str, tuple[str, ...]]:
    """'(rotateclockwise l2 l1 j1 deg_0 deg_90)' -> ('rotateclockwise', ('l2', ...))."""
    tokens = step.strip().strip("()").lower().split()
    if not tokens:
        raise TransitionError(f"plan step {step!r} is empty")
    return tokens[0], tuple(tokens[1:])


def _instantiate(lit: Literal, binding: Mapping[str, str]) -> Atom:
    try:
        return (lit.predicate,) + tuple(binding[a] for a in lit.args)
    except KeyError as exc:
        raise TransitionError(f"variable {exc.args[0]} of {lit.pddl()} is unbound") from None


def _holds(lit: Literal, binding: Mapping[str, str], state: State) -> bool:
    if lit.predicate == "=":
        value = binding[lit.args[0]] == binding[lit.args[1]]
    else:
        value = _instantiate(lit, binding) in state
    return value != lit.negated


def _bindings(
    literals: Sequence[Literal], variables: Sequence[str], binding: dict[str, str], state: State
) -> Iterator[dict[str, str]]:
    """Every extension of `binding` to `variables` under which all `literals` hold in `state`.

    Positive non-equality literals are matched against the state's atoms first (a join); the remaining
    literals are then checked. This enumerates exactly the satisfying bindings of a `when` condition."""
    positives = [lit for lit in literals if not lit.negated and lit.predicate != "="]
    by_pred: dict[str, list[Atom]] = {}
    for atom in state:
        by_pred.setdefault(atom[0], []).append(atom)

    def extend(i: int, current: dict[str, str]) -> Iterator[dict[str, str]]:
        if i == len(positives):
            if all(v in current for v in variables) and all(_holds(lit, current, state) for lit in literals):
                yield dict(current)
            return
        lit = positives[i]
        for atom in by_pred.get(lit.predicate, ()):
            if len(atom) != len(lit.args) + 1:
                continue
            new = dict(current)
            ok = True
            for var, value in zip(lit.args, atom[1:]):
                if new.setdefault(var, value) != value:
                    ok = False
                    break
            if ok:
                yield from extend(i + 1, new)

    yield from extend(0, dict(binding))


def find_schema(domain: DomainModelSpec, name: str) -> ActionSchemaSpec:
    for schema in domain.actions:
        if schema.name == name:
            return schema
    raise TransitionError(f"action {name!r} is not a schema of domain {domain.name}")


def ground_action(domain: DomainModelSpec, step: str, state: State) -> ActionSpec:
    """The ground action of a plan step in `state`; raises TransitionError when it is not applicable."""
    name, args = parse_step(step)
    schema = find_schema(domain, name)
    if len(args) != len(schema.parameters):
        raise TransitionError(f"{step}: {name} takes {len(schema.parameters)} arguments, got {len(args)}")
    binding = {var: value for (var, _), value in zip(schema.parameters, args)}
    for lit in schema.precondition:
        if not _holds(lit, binding, state):
            raise TransitionError(f"{step}: precondition {_render(lit, binding)} does not hold")
    pre = frozenset(_instantiate(lit, binding) for lit in schema.precondition if lit.predicate != "=" and not lit.negated)
    eff_neg = frozenset(_instantiate(lit, binding) for lit in schema.effects if lit.negated)
    eff_pos = frozenset(_instantiate(lit, binding) for lit in schema.effects if not lit.negated)
    conds = []
    for ce in schema.conditional_effects:
        variables = [v for v, _ in ce.variables]
        for b in _bindings(ce.when, variables, binding, state):
            conds.append(
                CondEffect(
                    when=frozenset(_instantiate(lit, b) for lit in ce.when if lit.predicate != "=" and not lit.negated),
                    eff_neg=frozenset(_instantiate(lit, b) for lit in ce.effects if lit.negated),
                    eff_pos=frozenset(_instantiate(lit, b) for lit in ce.effects if not lit.negated),
                )
            )
    conds.sort(key=lambda c: sorted(c.eff_pos))
    return ActionSpec(name=name, params=args, pre=pre, eff_neg=eff_neg, eff_pos=eff_pos, cond_eff=tuple(conds))


def _render(lit: Literal, binding: Mapping[str, str]) -> str:
    return Literal(lit.predicate, tuple(binding.get(a, a) for a in lit.args), lit.negated).pddl()


def apply(state: State, action: ActionSpec) -> State:
    """s' = (s \\ (eff- ∪ C-)) ∪ (eff+ ∪ C+), with C± the effects of the conditional effects that fired."""
    neg = set(action.eff_neg)
    pos = set(action.eff_pos)
    for ce in action.cond_eff:
        if ce.when <= state:
            neg |= ce.eff_neg
            pos |= ce.eff_pos
    return frozenset((state - neg) | pos)


def replay(domain: DomainModelSpec, init: State, plan: Sequence[str]) -> tuple[tuple[ActionSpec, ...], tuple[State, ...]]:
    """Ground every step in turn and return the actions and the expected states s^e_1 .. s^e_{N+1}."""
    states = [frozenset(init)]
    actions = []
    for step in plan:
        action = ground_action(domain, step, states[-1])
        actions.append(action)
        states.append(apply(states[-1], action))
    return tuple(actions), tuple(states)

"""Action schemas in one normal form: a conjunction of literals as precondition, effects as flat blocks.

    (forall (?v ...) (when (and l1 l2 ...) (and (p ...) (not (q ...)))))  ->  EffectBlock(vars, cond, add, delete)

Plain effects are the block with no variables and no condition; nested `and`, `forall` and `when` are flattened.
Literals are `planhrc.model.Literal`, the type of the TBox's schemas. Anything beyond STRIPS with negative
literals, equality and conditional effects (`or`, `exists`, `imply`, numeric fluents) raises
`UnsupportedPddlError`, naming the action and the construct.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

from planhrc.model import EQUALITY, Atom, Literal

from .errors import PlannerError
from .pddl import ActionSchema, Domain, SExpr, format_sexpr, parse_domain, parse_typed_list


class UnsupportedPddlError(PlannerError):
    """The PDDL uses a construct the in-process planner does not read."""


@dataclass(frozen=True)
class EffectBlock:
    variables: tuple[tuple[str, str], ...]  # forall variables with their types
    condition: tuple[Literal, ...]
    add: tuple[Atom, ...]
    delete: tuple[Atom, ...]


@dataclass(frozen=True)
class Operator:
    name: str
    parameters: tuple[tuple[str, str], ...]
    precondition: tuple[Literal, ...]
    effects: tuple[EffectBlock, ...]


def normalise_domain(domain: Domain) -> tuple[Operator, ...]:
    return tuple(normalise_action(action) for action in domain.actions)


@dataclass(frozen=True)
class DomainOperators:
    """A domain's text read once for the narrowings of VAL's problems (`planner.scope`, `planner.held`): its
    declared types (type, parent), its operators and the predicates some operator changes."""

    types: tuple[tuple[str, str], ...]
    operators: tuple[Operator, ...]
    fluent: frozenset[str]


@lru_cache(maxsize=8)
def read_operators(text: str) -> DomainOperators:
    """`text` parsed and normalised, kept for the last few domains; PlannerError when it is outside what is read
    here."""
    domain = parse_domain(text)
    operators = normalise_domain(domain)
    fluent = frozenset(atom[0] for op in operators for block in op.effects for atom in block.add + block.delete)
    return DomainOperators(domain.types, operators, fluent)


def normalise_action(schema: ActionSchema) -> Operator:
    where = f"action {schema.name}"
    precondition = tuple(literals(schema.precondition, f"{where}: precondition"))
    blocks: list[EffectBlock] = []
    _effect_blocks(schema.effect, (), (), blocks, f"{where}: effect")
    return Operator(schema.name, schema.parameters, precondition, tuple(blocks))


def literals(expr: SExpr, where: str) -> list[Literal]:
    """A conjunction of literals (possibly nested `and`s) as a flat list."""
    if isinstance(expr, tuple) and expr and expr[0] == "and":
        out: list[Literal] = []
        for part in expr[1:]:
            out.extend(literals(part, where))
        return out
    if isinstance(expr, tuple) and len(expr) == 2 and expr[0] == "not":
        atom = _atom(expr[1], where)
        return [Literal(atom[0], atom[1:], negated=True)]
    atom = _atom(expr, where)
    return [Literal(atom[0], atom[1:])]


def _atom(expr: SExpr, where: str) -> Atom:
    if isinstance(expr, tuple) and expr and all(isinstance(e, str) for e in expr) and expr[0] not in (
            "and", "or", "not", "imply", "exists", "forall", "when"):
        return tuple(str(e) for e in expr)
    raise UnsupportedPddlError(f"{where}: {format_sexpr(expr)} is not a literal (only conjunctions of literals "
                               "are read here)")


def _effect_blocks(expr: SExpr, variables: tuple[tuple[str, str], ...], condition: tuple[Literal, ...],
                   out: list[EffectBlock], where: str) -> None:
    if not isinstance(expr, tuple) or not expr:
        raise UnsupportedPddlError(f"{where}: expected an effect, got {format_sexpr(expr)}")
    head = expr[0]
    if head == "and":
        adds: list[Atom] = []
        dels: list[Atom] = []
        for part in expr[1:]:
            if isinstance(part, tuple) and part and part[0] in ("forall", "when", "and"):
                _effect_blocks(part, variables, condition, out, where)
            else:
                (dels if isinstance(part, tuple) and part and part[0] == "not" else adds).append(
                    _effect_atom(part, where))
        if adds or dels:
            out.append(EffectBlock(variables, condition, tuple(adds), tuple(dels)))
        return
    if head == "forall":
        if len(expr) != 3 or not isinstance(expr[1], tuple):
            raise UnsupportedPddlError(f"{where}: expected (forall (?v - type ...) effect)")
        bound = parse_typed_list(expr[1], f"{where}: forall")
        _effect_blocks(expr[2], variables + bound, condition, out, where)
        return
    if head == "when":
        if len(expr) != 3:
            raise UnsupportedPddlError(f"{where}: expected (when condition effect)")
        cond = tuple(literals(expr[1], f"{where}: when"))
        inner = expr[2]
        if isinstance(inner, tuple) and inner and inner[0] in ("forall", "when"):
            raise UnsupportedPddlError(f"{where}: nested forall/when inside when is not read here")
        _effect_blocks(inner if isinstance(inner, tuple) and inner and inner[0] == "and" else ("and", inner),
                       variables, condition + cond, out, where)
        return
    _effect_blocks(("and", expr), variables, condition, out, where)


def _effect_atom(expr: SExpr, where: str) -> Atom:
    if isinstance(expr, tuple) and len(expr) == 2 and expr[0] == "not":
        expr = expr[1]
    atom = _atom(expr, where)
    if atom[0] == EQUALITY:
        raise UnsupportedPddlError(f"{where}: an effect cannot assert equality")
    return atom

"""A small PDDL reader for the rotation domain family: s-expressions -> frozen domain and problem values.

It reads typed STRIPS with negative preconditions, equality, `forall` and `when` (the requirements `:strips`,
`:typing`, `:equality`, `:negative-preconditions`, `:conditional-effects` and `:adl` name nothing more for the
files of this family); it keeps preconditions and effects as nested tuples of lower-case strings and leaves their
meaning to the caller (`planner.inproc`). Bad text raises `PlannerError` with a message that says what was
expected where.

It reads a file as VAL reads it, where the field's files differ from the grammar:

* A name never starts with '-' (VAL's lexer: a name is a letter or '_', then letters, digits, '-' and '_'), so
  ``?j -joint`` is ``?j - joint``: a token that starts with '-' and a letter is the dash and a type name.
* An action declared twice: VAL takes the first declaration and ignores the later ones without a word (a plan
  that uses the later parameter list is a "Bad plan description!"). So does this reader, and it says so:
  `Domain.warnings` names each ignored declaration, and the planners that read the text themselves get a
  normalised copy without it (`planner.normalise`).
"""
from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Union, cast

from planhrc.model import Atom

from .errors import PlannerError

log = logging.getLogger(__name__)

SExpr = Union[str, tuple["SExpr", ...]]


@dataclass(frozen=True)
class ActionSchema:
    name: str
    parameters: tuple[tuple[str, str], ...]  # (?var, type), in declaration order
    precondition: SExpr
    effect: SExpr


@dataclass(frozen=True)
class Domain:
    name: str
    requirements: tuple[str, ...]
    types: tuple[tuple[str, str], ...]  # (type, parent type)
    predicates: tuple[tuple[str, tuple[tuple[str, str], ...]], ...]  # (name, ((?var, type), ...))
    actions: tuple[ActionSchema, ...]
    warnings: tuple[str, ...] = ()  # what was read differently from the text (an action declared again)

    def subtypes(self, type_name: str) -> frozenset[str]:
        """`type_name` and every type declared (transitively) below it."""
        out = {type_name}
        changed = True
        while changed:
            changed = False
            for child, parent in self.types:
                if parent in out and child not in out:
                    out.add(child)
                    changed = True
        return frozenset(out)


@dataclass(frozen=True)
class Problem:
    name: str
    domain_name: str
    objects: tuple[tuple[str, str], ...]  # (name, type), in declaration order
    init: frozenset[Atom]
    goal: frozenset[Atom]

    def objects_of(self, types: frozenset[str] | set[str]) -> tuple[str, ...]:
        return tuple(name for name, t in self.objects if t in types)


# -- s-expressions ---------------------------------------------------------------------------------------
def tokenize(text: str) -> list[str]:
    """Parentheses and names, comments dropped; ``-joint`` is two tokens, '-' and 'joint' (`split_dash`)."""
    if ";" in text:
        text = "\n".join(line.split(";", 1)[0] for line in text.splitlines())
    tokens = text.replace("(", " ( ").replace(")", " ) ").split()
    if not _starts_a_token_with_a_dash(text):  # the usual text: every dash stands apart or inside a name
        return tokens
    return [part for token in tokens for part in split_dash(token)]


def _starts_a_token_with_a_dash(text: str) -> bool:
    """Whether a token of `text` starts with '-' and goes on (`-joint`, `-5`): only those may need `split_dash`."""
    i = text.find("-")
    while i != -1:
        if (i == 0 or text[i - 1].isspace() or text[i - 1] in "()") and i + 1 < len(text) \
                and not (text[i + 1].isspace() or text[i + 1] in "()"):
            return True
        i = text.find("-", i + 1)
    return False


def split_dash(token: str) -> tuple[str, ...]:
    """``-name`` -> ('-', 'name'): no PDDL name starts with '-', and VAL reads the dash of a typed list there."""
    if len(token) > 1 and token[0] == "-" and (token[1].isalpha() or token[1] == "_"):
        return ("-", token[1:])
    return (token,)


def parse_sexpr(text: str, what: str = "PDDL") -> SExpr:
    """Parse exactly one s-expression; names are lower-cased (PDDL is case-insensitive)."""
    tokens = tokenize(text.lower())
    if not tokens:
        raise PlannerError(f"{what}: the text is empty")
    stack: list[list[SExpr]] = [[]]
    top = stack[0]
    for tok in tokens:
        if tok == "(":
            top = []
            stack.append(top)
        elif tok == ")":
            if len(stack) == 1:
                raise PlannerError(f"{what}: unbalanced ')'")
            done = tuple(stack.pop())
            top = stack[-1]
            top.append(done)
        else:
            top.append(tok)
    if len(stack) != 1:
        raise PlannerError(f"{what}: {len(stack) - 1} unclosed '('")
    if len(top) != 1 or not isinstance(top[0], tuple):
        raise PlannerError(f"{what}: expected one parenthesised (define ...) form, got {len(top)} top-level items")
    return top[0]


def parse_typed_list(items: tuple[SExpr, ...], what: str) -> tuple[tuple[str, str], ...]:
    """`a b - t c - u d` -> ((a, t), (b, t), (c, u), (d, object))."""
    out: list[tuple[str, str]] = []
    pending: list[str] = []
    i = 0
    while i < len(items):
        item = items[i]
        if not isinstance(item, str):
            raise PlannerError(f"{what}: expected a name, got {format_sexpr(item)}")
        if item == "-":
            if i + 1 >= len(items) or not isinstance(items[i + 1], str):
                raise PlannerError(f"{what}: '-' must be followed by a type name")
            if not pending:
                raise PlannerError(f"{what}: type '{items[i + 1]}' has no names before it")
            out.extend((name, items[i + 1]) for name in pending)  # type: ignore[misc]
            pending = []
            i += 2
            continue
        pending.append(item)
        i += 1
    out.extend((name, "object") for name in pending)
    return tuple(out)


def format_sexpr(expr: SExpr) -> str:
    if isinstance(expr, str):
        return expr
    return "(" + " ".join(format_sexpr(e) for e in expr) + ")"


def _sections(define: SExpr, kind: str, what: str) -> tuple[str, list[tuple[SExpr, ...]]]:
    if not isinstance(define, tuple) or len(define) < 2 or define[0] != "define":
        raise PlannerError(f"{what}: expected (define ({kind} NAME) ...)")
    head = define[1]
    if not isinstance(head, tuple) or len(head) != 2 or head[0] != kind or not isinstance(head[1], str):
        raise PlannerError(f"{what}: expected ({kind} NAME) after define, got {format_sexpr(head)}")
    sections = []
    for sec in define[2:]:
        if not isinstance(sec, tuple) or not sec or not isinstance(sec[0], str) or not sec[0].startswith(":"):
            raise PlannerError(f"{what}: expected a (:section ...), got {format_sexpr(sec)}")
        sections.append(sec)
    return head[1], sections


# -- domain ------------------------------------------------------------------------------------------------
def parse_domain(text: str) -> Domain:
    what = "domain"
    name, sections = _sections(parse_sexpr(text, what), "domain", what)
    requirements: tuple[str, ...] = ()
    types: tuple[tuple[str, str], ...] = ()
    predicates: list[tuple[str, tuple[tuple[str, str], ...]]] = []
    actions: list[ActionSchema] = []
    warnings: list[str] = []
    for sec in sections:
        key = sec[0]
        if key == ":requirements":
            requirements = tuple(str(r) for r in sec[1:])
        elif key == ":types":
            types = parse_typed_list(sec[1:], f"{what} {name}: :types")
        elif key == ":predicates":
            for pred in sec[1:]:
                if not isinstance(pred, tuple) or not pred or not isinstance(pred[0], str):
                    raise PlannerError(f"{what} {name}: bad predicate declaration {format_sexpr(pred)}")
                predicates.append((pred[0], parse_typed_list(pred[1:], f"{what} {name}: predicate {pred[0]}")))
        elif key == ":action":
            action = _parse_action(sec, f"{what} {name}")
            if any(a.name == action.name for a in actions):
                warnings.append(f"action {action.name} is declared again; as VAL does, the first declaration is "
                                "the action and this one is ignored")
                log.warning("%s %s: %s", what, name, warnings[-1])
                continue
            actions.append(action)
        elif key in (":constants", ":functions", ":derived", ":durative-action"):
            raise PlannerError(f"{what} {name}: section {key} is not supported by this reader")
        else:
            raise PlannerError(f"{what} {name}: unknown section {key}")
    if not actions:
        raise PlannerError(f"{what} {name}: declares no action")
    return Domain(name, requirements, types, tuple(predicates), tuple(actions), tuple(warnings))


def _parse_action(sec: tuple[SExpr, ...], what: str) -> ActionSchema:
    if len(sec) < 2 or not isinstance(sec[1], str):
        raise PlannerError(f"{what}: :action needs a name")
    name = sec[1]
    fields: dict[str, SExpr] = {}
    rest = sec[2:]
    if len(rest) % 2:
        raise PlannerError(f"{what}: action {name}: expected :keyword value pairs")
    for key, value in zip(rest[::2], rest[1::2]):
        if key not in (":parameters", ":precondition", ":effect"):
            raise PlannerError(f"{what}: action {name}: unknown field {format_sexpr(key)}")
        fields[str(key)] = value
    params_expr = fields.get(":parameters", ())
    if not isinstance(params_expr, tuple):
        raise PlannerError(f"{what}: action {name}: :parameters must be a list")
    params = parse_typed_list(params_expr, f"{what}: action {name}: :parameters")
    for var, _ in params:
        if not var.startswith("?"):
            raise PlannerError(f"{what}: action {name}: parameter {var!r} must start with '?'")
    if ":effect" not in fields:
        raise PlannerError(f"{what}: action {name}: has no :effect")
    return ActionSchema(name, params, fields.get(":precondition", ("and",)), fields[":effect"])


# -- problem -----------------------------------------------------------------------------------------------
def parse_problem(text: str) -> Problem:
    what = "problem"
    name, sections = _sections(parse_sexpr(text, what), "problem", what)
    domain_name = ""
    objects: tuple[tuple[str, str], ...] = ()
    init: set[Atom] = set()
    goal: frozenset[Atom] | None = None
    for sec in sections:
        key = sec[0]
        if key == ":domain":
            if len(sec) != 2 or not isinstance(sec[1], str):
                raise PlannerError(f"{what} {name}: expected (:domain NAME)")
            domain_name = sec[1]
        elif key == ":objects":
            objects = parse_typed_list(sec[1:], f"{what} {name}: :objects")
        elif key == ":init":
            for atom in sec[1:]:
                init.add(_ground_atom(atom, f"{what} {name}: :init"))
        elif key == ":goal":
            if len(sec) != 2:
                raise PlannerError(f"{what} {name}: :goal takes exactly one formula")
            goal = _goal_atoms(sec[1], f"{what} {name}: :goal")
        elif key in (":requirements",):
            continue
        else:
            raise PlannerError(f"{what} {name}: section {key} is not supported by this reader")
    if not domain_name:
        raise PlannerError(f"{what} {name}: has no (:domain NAME)")
    if goal is None:
        raise PlannerError(f"{what} {name}: has no :goal")
    names = [n for n, _ in objects]
    if len(set(names)) != len(names):
        dup = sorted({n for n in names if names.count(n) > 1})
        raise PlannerError(f"{what} {name}: objects declared twice: {', '.join(dup)}")
    known = set(names)
    named = {arg for atom in init for arg in atom[1:]} | {arg for atom in goal for arg in atom[1:]}
    if not named <= known:  # name the first such atom, in a fixed order
        for atom in sorted(init | goal):
            for arg in atom[1:]:
                if arg not in known:
                    raise PlannerError(f"{what} {name}: atom {format_sexpr(atom)} names {arg!r}, which is not an "
                                       "object")
    return Problem(name, domain_name, objects, frozenset(init), goal)


def _ground_atom(expr: SExpr, what: str) -> Atom:
    if not isinstance(expr, tuple) or not expr or expr[0] in _CONNECTIVES:
        raise PlannerError(f"{what}: expected a ground atom (pred obj ...), got {format_sexpr(expr)}")
    for e in expr:
        if not isinstance(e, str) or e.startswith("?"):
            raise PlannerError(f"{what}: expected a ground atom (pred obj ...), got {format_sexpr(expr)}")
    return cast(Atom, expr)  # a tuple of names, checked above


_CONNECTIVES = frozenset({"not", "and", "or", "="})


def _goal_atoms(expr: SExpr, what: str) -> frozenset[Atom]:
    """A goal must be a positive atom or a conjunction of positive atoms."""
    if isinstance(expr, tuple) and expr and expr[0] == "and":
        return frozenset(_ground_atom(e, what) for e in expr[1:])
    return frozenset({_ground_atom(expr, what)})

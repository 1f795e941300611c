"""TBox -> PDDL domain.

`read_domain_model` queries the TBox (RDF, read with rdflib) for the DomainModel of a formulation: its
requirements, types, the predicate classes its schemas use (name, parameters, argument order) and the
action schemas (parameters, preconditions, effects, conditional effects) described as individuals.
`write_domain` writes it to a stream; `get_domain` is the string wrapper. The output is deterministic:
every list is ordered by the `position` the TBox gives it.
"""
from __future__ import annotations

import io
import os
from functools import lru_cache
from pathlib import Path
from typing import TextIO, cast

from rdflib import Graph, Namespace, URIRef
from rdflib import Literal as RDFLiteral
from rdflib.namespace import OWL, RDF

from planhrc.model import EQUALITY, ActionSchemaSpec, ConditionalEffect, DomainModelSpec, Literal, PredicateSpec

from .errors import TranslationError

__all__ = ["ActionSchemaSpec", "ConditionalEffect", "DomainModelSpec", "Literal", "PredicateSpec", "get_domain",
           "domain_text", "read_domain_model", "write_domain"]

PLAN = Namespace("http://planhrc.org/ontology/planhrc.owl#")


class _TBox:
    """Read helpers over the TBox graph; every missing value raises TranslationError naming the node."""

    def __init__(self, graph: Graph) -> None:
        self.g = graph
        self.arg_order: dict[str, tuple[int, ...]] = {}
        self.predicate_params: dict[str, str] = {}
        for cls in graph.subjects(RDF.type, OWL.Class):
            name = graph.value(cls, PLAN.pddlName)
            order = graph.value(cls, PLAN.pddlArgumentOrder)
            params = graph.value(cls, PLAN.pddlParameters)
            if name is not None and order is not None and params is not None:
                self.arg_order[str(name)] = tuple(int(a.removeprefix("arg")) for a in str(order).split())
                self.predicate_params[str(name)] = str(params)

    def one(self, node: URIRef, prop: URIRef) -> str:
        value = self.g.value(node, prop)
        if value is None:
            raise TranslationError(f"TBox: {node} has no {prop.split('#')[-1]}")
        return str(value)

    def position(self, node: URIRef) -> int:
        return int(self.one(node, PLAN.position))

    def ordered(self, node: URIRef, prop: URIRef) -> list[URIRef]:
        return sorted((cast(URIRef, o) for o in self.g.objects(node, prop)), key=self.position)

    def variable(self, node: URIRef) -> tuple[str, str]:
        return self.one(node, PLAN.pddlName), self.one(node, PLAN.typeName)

    def literal(self, node: URIRef, negated: bool | None = None) -> Literal:
        pred = self.one(node, PLAN.predicateName)
        owl_args = {}
        for i in (1, 2, 3):
            v = self.g.value(node, PLAN[f"argVar{i}"])
            if v is not None:
                owl_args[i] = self.one(cast(URIRef, v), PLAN.pddlName)
        if pred == EQUALITY:
            order: tuple[int, ...] = (1, 2)
        else:
            if pred not in self.arg_order:
                raise TranslationError(f"TBox: no Predicate class has pddlName {pred!r} (used by {node})")
            order = self.arg_order[pred]
        try:
            args = tuple(owl_args[i] for i in order)
        except KeyError as exc:
            raise TranslationError(f"TBox: {node} lacks argument arg{exc.args[0]} of {pred}") from exc
        if negated is None:
            flag = self.g.value(node, PLAN.negated)
            negated = bool(flag.toPython()) if isinstance(flag, RDFLiteral) else False
        return Literal(pred, args, negated)

    def effects(self, node: URIRef, neg_prop: URIRef, pos_prop: URIRef) -> tuple[Literal, ...]:
        negs = [cast(URIRef, n) for n in self.g.objects(node, neg_prop)]
        poss = [cast(URIRef, n) for n in self.g.objects(node, pos_prop)]
        items = [(self.position(n), self.literal(n, negated=True)) for n in negs]
        items += [(self.position(n), self.literal(n, negated=False)) for n in poss]
        return tuple(lit for _, lit in sorted(items, key=lambda x: (x[0], x[1].negated is False)))


def read_domain_model(tbox_path: Path | str, formulation: str) -> DomainModelSpec:
    """The DomainModel individual `<formulation>_domain` of the TBox, as an immutable value (read again when the
    file changes)."""
    path = os.fspath(tbox_path)
    return _read_domain_model_cached(_resolved(path), os.stat(path).st_mtime_ns, formulation)


@lru_cache(maxsize=32)
def _resolved(path: str) -> str:
    """The file's absolute path (resolved once per name: every re-plan reads the model)."""
    return str(Path(path).resolve())


@lru_cache(maxsize=8)
def _read_domain_model_cached(path: str, _mtime: int, formulation: str) -> DomainModelSpec:
    graph = Graph()
    try:
        graph.parse(path, format="xml")
    except Exception as exc:  # rdflib raises many parser types
        raise TranslationError(f"TBox: cannot parse {path}: {exc}") from exc
    tb = _TBox(graph)
    dm = PLAN[f"{formulation}_domain"]
    if (dm, RDF.type, PLAN.DomainModel) not in graph:
        raise TranslationError(f"formulation: the TBox has no DomainModel {formulation}_domain")
    actions = []
    used_predicates: list[str] = []
    for schema in tb.ordered(dm, PLAN.hasSchema):
        params = tuple(tb.variable(v) for v in tb.ordered(schema, PLAN.hasParameter))
        pre = tuple(tb.literal(a) for a in tb.ordered(schema, PLAN.precondition))
        effects = tb.effects(schema, PLAN.deleteEffect, PLAN.addEffect)
        conds = []
        for ce in tb.ordered(schema, PLAN.conditionalEffect):
            conds.append(
                ConditionalEffect(
                    variables=tuple(tb.variable(v) for v in tb.ordered(ce, PLAN.forallVariable)),
                    when=tuple(tb.literal(a) for a in tb.ordered(ce, PLAN.whenCondition)),
                    effects=tb.effects(ce, PLAN.effNeg_a, PLAN.effPos_a),
                )
            )
        for lit in pre + effects + tuple(x for c in conds for x in c.when + c.effects):
            if lit.predicate != EQUALITY and lit.predicate not in used_predicates:
                used_predicates.append(lit.predicate)
        actions.append(
            ActionSchemaSpec(tb.one(schema, PLAN.describesActionName), params, pre, effects, tuple(conds))
        )
    if not actions:
        raise TranslationError(f"TBox: DomainModel {formulation}_domain has no action schema")
    return DomainModelSpec(
        name=tb.one(dm, PLAN.pddlName),
        requirements=tb.one(dm, PLAN.pddlRequirements),
        types=tb.one(dm, PLAN.pddlTypes),
        predicates=tuple(PredicateSpec(p, tb.predicate_params[p]) for p in used_predicates),
        actions=tuple(actions),
    )


def _params(variables: tuple[tuple[str, str], ...]) -> str:
    return " ".join(f"{name} - {type_}" for name, type_ in variables)


def _conjunction(out: TextIO, literals: tuple[Literal, ...], indent: str, tail: str) -> None:
    out.write("(and\n")
    for i, lit in enumerate(literals):
        close = tail if i == len(literals) - 1 else ""
        out.write(f"{indent}{lit.pddl()}{close}\n")


def write_domain(out: TextIO, spec: DomainModelSpec, name: str | None = None, drop_guard: bool = False) -> None:
    """Write the PDDL domain. `drop_guard` omits preconditions that are not in the paper's figures
    (the `(affected ?j1 ?l1 ?j1)` guard), giving the paper's exact schema for validation."""
    out.write(f"(define (domain {name or spec.name})\n")
    out.write(f"  (:requirements {spec.requirements})\n")
    out.write(f"  (:types {spec.types})\n")
    out.write("  (:predicates\n")
    for i, pred in enumerate(spec.predicates):
        close = ")" if i == len(spec.predicates) - 1 else ""
        out.write(f"    ({pred.name} {pred.parameters}){close}\n")
    for ai, action in enumerate(spec.actions):
        last_action = ai == len(spec.actions) - 1
        pre = tuple(lit for lit in action.precondition if not (drop_guard and _is_guard(lit)))
        out.write(f"  (:action {action.name}\n")
        out.write(f"    :parameters ({_params(action.parameters)})\n")
        out.write("    :precondition ")
        _conjunction(out, pre, "      ", ")")
        out.write("    :effect ")
        end = ")))" if last_action else "))"
        if not action.conditional_effects:
            _conjunction(out, action.effects, "      ", end)
            continue
        _conjunction(out, action.effects, "      ", "")
        for ci, ce in enumerate(action.conditional_effects):
            ce_end = end if ci == len(action.conditional_effects) - 1 else ""
            out.write(f"      (forall ({_params(ce.variables)})\n")
            out.write("        (when ")
            _conjunction(out, ce.when, "            ", ")")
            out.write("          ")
            _conjunction(out, ce.effects, "            ", ")))" + ce_end)


def _is_guard(lit: Literal) -> bool:
    return lit.predicate == "affected" and len(lit.args) == 3 and lit.args[0] == lit.args[2]


def get_domain(tbox_path: Path | str, formulation: str, paper_exact: bool = False) -> str:
    """The PDDL domain of a formulation; `paper_exact` gives the paper's absolute schema (no guard)."""
    return domain_text(read_domain_model(tbox_path, formulation), paper_exact, formulation == "absolute")


@lru_cache(maxsize=16)
def domain_text(model: DomainModelSpec, paper_exact: bool = False, absolute: bool = False) -> str:
    """The PDDL domain of a domain model; `paper_exact` drops the guard the paper's absolute figures lack, and
    names the absolute domain `…-paper` (the other formulations have no such figure: their domain is the same).
    Pure, so each model's text is written once."""
    buf = io.StringIO()
    name = f"{model.name}-paper" if paper_exact and absolute else None
    write_domain(buf, model, name=name, drop_guard=paper_exact and absolute)
    return buf.getvalue()

"""One literal type and one binding of literals for both grounders: the replay's (the TBox's schemas) and the
in-process planner's (parsed PDDL)."""
from __future__ import annotations

import pytest

from planhrc.grounding import bind_atom, holds, instantiate, substitute
from planhrc.model import EQUALITY, Literal
from planhrc.paths import default_tbox_path
from planhrc.planner.operators import normalise_domain
from planhrc.planner.pddl import parse_domain
from planhrc.translator.domain import get_domain, read_domain_model

STATE = frozenset({("connected", "j1", "l1"), ("connected", "j1", "l2")})


def test_a_binding_replaces_the_terms_it_names_and_keeps_the_others():
    lit = Literal("connected", ("?j", "l2"), negated=True)
    assert substitute(lit, {"?j": "j1", "?x": "l9"}) == Literal("connected", ("j1", "l2"), negated=True)
    assert bind_atom(("affected", "?j2", "?l", "?j"), {"?l": "l1"}) == ("affected", "?j2", "l1", "?j")
    assert substitute(lit, {}).pddl() == "(not (connected ?j l2))"


def test_instantiating_needs_every_term_bound():
    assert instantiate(Literal("connected", ("?j", "?l")), {"?j": "j1", "?l": "l1"}) == ("connected", "j1", "l1")
    with pytest.raises(KeyError, match=r"\?l"):
        instantiate(Literal("connected", ("?j", "?l")), {"?j": "j1"})


@pytest.mark.parametrize("lit,binding,expected", [
    (Literal("connected", ("?j", "?l")), {"?j": "j1", "?l": "l2"}, True),
    (Literal("connected", ("?j", "?l")), {"?j": "j1", "?l": "l3"}, False),
    (Literal("connected", ("?j", "?l"), negated=True), {"?j": "j1", "?l": "l3"}, True),
    (Literal("connected", ("j1", "?l")), {"?l": "l1"}, True),  # an object term stays itself
    (Literal(EQUALITY, ("?a", "?b")), {"?a": "l1", "?b": "l1"}, True),
    (Literal(EQUALITY, ("?a", "?b"), negated=True), {"?a": "l1", "?b": "l1"}, False),
    (Literal(EQUALITY, ("?a", "l2")), {"?a": "l2"}, True),
])
def test_a_literal_holds_where_its_bound_atom_is_true(lit, binding, expected):
    assert holds(lit, binding, STATE) is expected


@pytest.mark.parametrize("formulation", ["relative", "absolute"])
def test_the_planner_reads_the_tboxs_own_literals_back_from_its_pddl(formulation):
    """The domain the translator writes from the TBox's schemas, parsed by the planner, gives the very same
    literal values: one type for both readers."""
    model = read_domain_model(default_tbox_path(), formulation)
    parsed = {op.name: op for op in normalise_domain(parse_domain(get_domain(default_tbox_path(), formulation)))}
    for schema in model.actions:
        op = parsed[schema.name]
        assert op.precondition == schema.precondition
        conditions = {block.condition for block in op.effects if block.variables}
        assert conditions == {ce.when for ce in schema.conditional_effects}

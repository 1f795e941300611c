"""Binding the terms of literals to objects, and testing bound literals against a set of atoms.

The one implementation of this step for both grounders: the replay (`planhrc.transition`, which grounds the TBox's
schemas for a plan's steps) and the in-process planner (`planner.ground`, which grounds parsed PDDL over a problem's
objects). A term that the binding does not name is kept as it is: an object, or a variable left for later.
"""
from __future__ import annotations

from typing import Container, Mapping

from planhrc.model import EQUALITY, Atom, Literal

# Tuples are built from list comprehensions here: cheaper than from generators, and these run once per literal of
# every binding that either grounder enumerates.


def bind_atom(atom: Atom, binding: Mapping[str, str]) -> Atom:
    """`atom` with the terms that `binding` names replaced by their objects."""
    return (atom[0], *[binding.get(term, term) for term in atom[1:]])


def substitute(lit: Literal, binding: Mapping[str, str]) -> Literal:
    """`lit` with the terms that `binding` names replaced by their objects."""
    return Literal(lit.predicate, tuple([binding.get(term, term) for term in lit.args]), lit.negated)


def instantiate(lit: Literal, binding: Mapping[str, str]) -> Atom:
    """The ground atom of `lit` under a binding of every one of its terms; KeyError (the term) when one is
    unbound."""
    return (lit.predicate, *[binding[term] for term in lit.args])


def holds(lit: Literal, binding: Mapping[str, str], atoms: Container[Atom]) -> bool:
    """Whether `lit` holds under `binding` where exactly `atoms` are true (equality compares the bound terms)."""
    if lit.predicate == EQUALITY:
        first, second = lit.args
        value = binding.get(first, first) == binding.get(second, second)
    else:
        value = (lit.predicate, *[binding.get(term, term) for term in lit.args]) in atoms
    return value != lit.negated

"""Write a PDDL problem from an object, an initial state and a (possibly partial) goal state.

One core function writes to a stream; `get_problem` is the thin string wrapper. Every collection is sorted
so the same input gives byte-identical text.
"""
from __future__ import annotations

import io
from typing import Iterable, TextIO

from planhrc.model import HAS_ORIENTATION, ArticulatedObject, Atom, Formulation, format_atom, natural_key

from .errors import TranslationError

DOMAIN_NAMES = {Formulation.RELATIVE: "planhrc-relative", Formulation.ABSOLUTE: "planhrc-absolute",
                Formulation.BIMANUAL: "planhrc-bimanual"}


def write_problem(
    out: TextIO,
    obj: ArticulatedObject,
    init: Iterable[Atom],
    goal: Iterable[Atom],
    problem_name: str,
    domain_name: str | None = None,
) -> None:
    init_atoms = frozenset(init) | obj.static_atoms()
    goal_atoms = sorted(frozenset(goal))
    if not goal_atoms:
        raise TranslationError("goal: the goal state asserts no predicate")
    objects = {"link": obj.all_links, "joint": obj.joints, "orientation": obj.orientation_names,
               "gripper": obj.grippers}
    known = {name for names in objects.values() for name in names}
    every = init_atoms | frozenset(goal_atoms)
    if not {arg for atom in every for arg in atom[1:]} <= known:  # name the first such atom, in a fixed order
        for atom in sorted(every):
            for arg in atom[1:]:
                if arg not in known:
                    raise TranslationError(f"state: atom {format_atom(atom)} names {arg!r}, which is not part of "
                                           f"{obj.ident}")
    for atom in goal_atoms:
        if atom[0] != HAS_ORIENTATION:
            raise TranslationError(f"goal: only hasorientation atoms may be goals, got {format_atom(atom)}")
    out.write(f"(define (problem {problem_name.lower()})\n")
    out.write(f"  (:domain {domain_name or DOMAIN_NAMES[obj.formulation]})\n")
    out.write("  (:objects\n")
    for type_name in ("link", "joint", "orientation", "gripper"):
        names = sorted(objects[type_name], key=natural_key)
        if not names:  # no gripper but in the bimanual formulation
            continue
        out.write(f"    {' '.join(names)} - {type_name}\n")
    out.write("  )\n")
    out.write("  (:init\n")
    for atom in sorted(init_atoms, key=_atom_key):
        out.write(f"    {format_atom(atom)}\n")
    out.write("  )\n")
    out.write("  (:goal (and\n")
    for atom in sorted(goal_atoms, key=_atom_key):
        out.write(f"    {format_atom(atom)}\n")
    out.write("  ))\n)\n")


def get_problem(obj: ArticulatedObject, init: Iterable[Atom], goal: Iterable[Atom], problem_name: str,
                domain_name: str | None = None) -> str:
    buf = io.StringIO()
    write_problem(buf, obj, init, goal, problem_name, domain_name)
    return buf.getvalue()


def _atom_key(atom: Atom) -> tuple[object, ...]:
    return (atom[0],) + tuple(natural_key(a) for a in atom[1:])

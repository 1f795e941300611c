"""The individuals that describe a PDDL action schema in the TBox: its variables and its atom patterns.

Both `build_tbox` (the relative and absolute domain models) and `bimanual` (the bimanual one) describe their
schemas with these two makers, so every domain model is read the same way by `translator.domain`.
"""
from __future__ import annotations

from typing import Any, Mapping, Sequence

from owlready2 import Thing


class Patterns:
    """Makes `Variable` and `AtomPattern` individuals of the TBox being built (`ns`: its classes by name)."""

    def __init__(self, ns: Mapping[str, Any]) -> None:
        self._variable = ns["Variable"]
        self._atom = ns["AtomPattern"]

    def var(self, prefix: str, name: str, type_name: str, pos: int) -> Thing:
        v = self._variable(f"{prefix}_var_{name}")
        v.pddlName = [f"?{name}"]
        v.typeName = type_name
        v.position = pos
        return v

    def atom(self, prefix: str, tag: str, pos: int, pred: str, args: Sequence[Thing], negated: bool = False) -> Thing:
        """args are given in OWL argument order (arg1, arg2, arg3)."""
        a = self._atom(f"{prefix}_{tag}_{pos}")
        a.predicateName = pred
        a.negated = negated
        a.position = pos
        for i, v in enumerate(args, start=1):
            setattr(a, f"argVar{i}", v)
        return a

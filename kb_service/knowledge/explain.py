"""Subsumption between two stored states, D(a) ⊑ D(b), with the reason when it does not hold: the atoms of `b`
that `a` does not entail. The check is the cooperation model's own (`planhrc.model.is_subsumed`); a state's atoms
are what its description is made of, so a missing atom is exactly a missing conjunct
(`kb_service.subsumption`, whose agreement with the DL reasoners a test shows).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from planhrc.model import HAS_ORIENTATION, Atom, format_atom, is_subsumed, natural_key

from ..store.interface import Reads


@dataclass(frozen=True)
class Subsumption:
    state_id: str
    by_state_id: str
    subsumed: bool
    missing: tuple[Atom, ...]  # atoms of `by` that `state` does not assert, in natural order
    differs: tuple[tuple[str, str | None, str], ...]  # joint, its orientation in `state` (or None), in `by`
    atoms_checked: int

    def public(self) -> dict[str, Any]:
        return {
            "state_id": self.state_id, "by_state_id": self.by_state_id, "subsumed": self.subsumed,
            "missing": [format_atom(a) for a in self.missing],
            "differs": [{"joint": j, "has": has, "wants": wants} for j, has, wants in self.differs],
            "atoms_checked": self.atoms_checked,
        }


def explain_subsumption(store: Reads, state_id: str, by_state_id: str) -> Subsumption:
    """Is the state `state_id` subsumed by `by_state_id`, and if not, why not."""
    state = store.get_state(state_id)
    by = store.get_state(by_state_id)
    missing = tuple(sorted(by.atoms - state.atoms, key=lambda a: tuple(natural_key(x) for x in a)))
    has = {a[2]: a[1] for a in state.atoms if a[0] == HAS_ORIENTATION}
    differs = tuple((a[2], has.get(a[2]), a[1]) for a in missing if a[0] == HAS_ORIENTATION)
    return Subsumption(state.id, by.id, is_subsumed(state.atoms, by.atoms), missing, differs, len(by.atoms))

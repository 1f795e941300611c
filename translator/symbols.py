"""SymbolTable: ontology individual IRIs <-> PDDL names, one-to-one."""
from __future__ import annotations

from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Iterable, Mapping

from .errors import SymbolError

ABOX_IRI = "http://planhrc.org/abox#"


@dataclass(frozen=True)
class SymbolTable:
    to_pddl_map: Mapping[str, str] = field(default_factory=dict)
    to_iri_map: Mapping[str, str] = field(default_factory=dict)

    @classmethod
    def from_names(cls, names: Iterable[str], base_iri: str = ABOX_IRI) -> "SymbolTable":
        to_pddl: dict[str, str] = {}
        to_iri: dict[str, str] = {}
        for name in names:
            pddl = name.lower()
            iri = base_iri + name
            if pddl in to_iri and to_iri[pddl] != iri:
                raise SymbolError(f"names: {name!r} and {to_iri[pddl]!r} map to the same PDDL name {pddl!r}")
            to_pddl[iri] = pddl
            to_iri[pddl] = iri
        return cls(MappingProxyType(to_pddl), MappingProxyType(to_iri))

    def to_pddl(self, iri: str) -> str:
        try:
            return self.to_pddl_map[iri]
        except KeyError:
            raise SymbolError(f"IRI {iri!r} has no PDDL name in this task") from None

    def to_iri(self, pddl_name: str) -> str:
        try:
            return self.to_iri_map[pddl_name.lower()]
        except KeyError:
            raise SymbolError(f"PDDL name {pddl_name!r} names no individual of this task") from None

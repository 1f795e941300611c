"""The owlready2 adapter: what the store relies on in owlready2 still holds, and nothing else relies on it."""
import re
from pathlib import Path

import pytest

from planhrc.kb_service.store import owl
from planhrc.kb_service.store.owl import OwlInternalsError, check_internals

ROOT = Path(__file__).resolve().parents[1]
# Markers of owlready2 internals: its tables, storids, literal encoding, private modules and attributes.
INTERNALS = re.compile(r"_abbreviate|_to_rdf|_to_python|_subprocess_kargs|_PELLET_CLASSPATH|graph\.db\b|graph\.c\b"
                       r"|owlready2\.base|\bFROM (objs|datas|resources)\b|\bINTO (objs|datas|resources)\b|current_resource")


def test_owlready2_still_works_the_way_the_store_relies_on():
    """Fails loudly, naming the assumption, if an owlready2 upgrade changes a table, a storid or an encoding."""
    check_internals()


def test_a_changed_internal_is_reported_by_name(monkeypatch):
    monkeypatch.setattr(owl.owlready2.reasoning, "_PELLET_CLASSPATH", None)
    with pytest.raises(OwlInternalsError, match="_PELLET_CLASSPATH"):
        check_internals()


def test_only_the_adapter_touches_owlready2_internals():
    sources = [p for folder in ("planhrc", "kb_service", "translator", "planner", "robot_sim")
               for p in (ROOT / folder).rglob("*.py")]
    offenders = sorted(str(p.relative_to(ROOT)) for p in sources
                       if p != Path(owl.__file__).resolve() and INTERNALS.search(p.read_text()))
    assert offenders == []

"""What the knowledge service asks of every backend (run once per backend): a revision that changes with each
commit, each object's current roots, and inferred facts kept apart from the asserted ones and across a reopen."""
from __future__ import annotations

import pytest

from planhrc.kb_service.store import NotFoundError, ValidationError
from planhrc.model import make_object, perceive
from tests.store_backends import kb, place  # noqa: F401 (fixtures)

LINE = "<http://planhrc.org/abox#obj1_j1> <http://planhrc.org/ontology/planhrc.owl#turns> " \
       "<http://planhrc.org/abox#obj1_l2> .\n"


def test_revision_and_roots_follow_the_writes(kb):  # noqa: F811
    obj = make_object("obj1", "relative", 3, 4)
    start = kb.revision()
    kb.create_object(obj)
    assert kb.revision() != start
    assert kb.current_roots("obj1") == ("obj1",)
    state = kb.add_perception(perceive(obj, [0.0, 90.0, 90.0]))
    kb.add_event("obj1", "replan", "test", {"perceived_state_id": state.id})
    after = kb.revision()
    assert state.id in kb.current_roots("obj1")
    assert kb.revision() == after  # reads change nothing
    with pytest.raises(NotFoundError):
        kb.current_roots("obj9")


def test_inferred_facts_are_kept_apart_and_replaced_by_scope(kb, place):  # noqa: F811
    kb.create_object(make_object("obj1", "relative", 3, 4))
    triples = kb.triple_count()
    exported = "".join(kb.export_lines("all"))
    assert kb.replace_inferred("obj1", [LINE]) == 1
    assert kb.replace_inferred("all", [LINE, LINE.replace("j1", "j2")]) == 2
    assert sorted(kb.inferred_lines()) == sorted([LINE, LINE, LINE.replace("j1", "j2")])
    assert kb.triple_count() == triples and "".join(kb.export_lines("all")) == exported
    assert kb.replace_inferred("obj1", []) == 0
    with pytest.raises(ValidationError, match="scope"):
        kb.replace_inferred("", [LINE])
    with pytest.raises(ValidationError, match=r"lines\[0\]"):
        kb.replace_inferred("all", ["not a triple"])
    kb.close()
    with place.open() as again:
        assert sorted(again.inferred_lines()) == sorted([LINE, LINE.replace("j1", "j2")])

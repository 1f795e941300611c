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


def _vm_steps(db, read) -> int:
    """SQLite virtual-machine steps (in hundreds) that `read()` takes on `db`."""
    steps = [0]

    def count() -> int:
        steps[0] += 1
        return 0

    db.set_progress_handler(count, 100)
    try:
        read()
    finally:
        db.set_progress_handler(None, 0)
    return steps[0]


@pytest.mark.parametrize("read", ["reachable", "ntriple_lines", "delete_individuals"])
def test_reads_of_a_few_individuals_cost_the_same_however_full_their_context(read):
    """The export's walk from an object's current individuals, its N-Triples of them and the compaction's deletes
    read through the subject/object indexes: their cost does not grow with the rest of the context (SQLite's
    planner, left alone, read these through the index on `c`, i.e. the whole ABox history)."""
    iri = "http://planhrc.org/probe#"

    def cost(history: int) -> int:
        store = owl.QuadStore(None)
        try:
            c = store.context(iri)
            p = store.storid(iri + "p")
            mine = store.allocate([f"{iri}mine{n}" for n in range(120)])
            store.insert_objs(c, [(a, p, b) for a, b in zip(mine, mine[1:])])  # a chain: several rounds
            past = store.allocate([f"{iri}past{n}" for n in range(2 * history)])
            store.insert_objs(c, [(past[n], p, past[n + history]) for n in range(history)])
            store.insert_datas(c, [(s, p, 1) for s in past[:history]])
            db = store.db
            reads = {"reachable": lambda: owl.reachable(db, c, mine[:1]),
                     "ntriple_lines": lambda: list(owl.ntriple_lines(
                         db, f"t.c = ? AND t.s IN ({','.join('?' * len(mine))})", [c, *mine], by_subject=True)),
                     "delete_individuals": lambda: owl.delete_individuals(db, c, mine)}
            return _vm_steps(db, reads[read])
        finally:
            store.world.close()

    small, large = cost(1_000), cost(30_000)
    assert large < 1.3 * small + 20, (small, large)

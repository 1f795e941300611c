"""What the knowledge service reads of a PostgreSQL store that several processes share (replicas): the revision
changes with every process's commits and with nothing else, the SPARQL graph of one process follows another's
writes, and two processes replacing one scope of inferred facts at once leave one set. What every backend does alike
is `tests/test_store_knowledge_reads.py`."""
from __future__ import annotations

import threading
from collections.abc import Iterator

import pytest
from rdflib import RDF, URIRef

from planhrc.kb_service.knowledge.graph import KnowledgeGraph
from planhrc.kb_service.store import ABOX_IRI, TBOX_IRI, ValidationError, open_store
from planhrc.model import make_object, perceive
from planhrc.paths import default_tbox_path

TBOX = default_tbox_path()
LINE = "<http://planhrc.org/abox#obj1_j1> <http://planhrc.org/ontology/planhrc.owl#turns> " \
       "<http://planhrc.org/abox#obj1_l2> .\n"


@pytest.fixture
def pg_url(pg_cluster) -> Iterator[str]:
    url = pg_cluster.database()
    yield url
    pg_cluster.drop(url)


def test_the_revision_changes_when_another_process_commits_and_not_before(pg_url):
    with open_store(pg_url, TBOX) as one, open_store(pg_url, TBOX) as two:
        one.create_object(make_object("obj1", "relative", 3, 4))
        seen = two.revision()
        with one.transaction():
            one.add_event("obj1", "k", "", {})
            # Not before the commit: a reader that saw a new number with the old data would keep that data.
            assert two.revision() == seen
        assert two.revision() != seen
        seen = two.revision()
        two.replace_inferred("all", [LINE])
        assert one.revision() != seen


def test_reads_a_rolled_back_write_and_a_transaction_that_wrote_nothing_leave_the_revision(pg_url):
    with open_store(pg_url, TBOX) as one, open_store(pg_url, TBOX) as two:
        obj = make_object("obj1", "relative", 3, 4)
        one.create_object(obj)
        seen = one.revision()
        with pytest.raises(ValidationError):
            with one.transaction():
                one.add_perception(perceive(obj, [0.0, 90.0, 90.0]))
                one.add_event("obj1", "k", "", {"x": object()})  # refused: the perception is rolled back too
        with one.transaction():
            one.lock_object("obj1")  # a lock, no write: the transaction has no id, and is not counted
        two.list_events("obj1")
        two.current_roots("obj1")
        list(two.inferred_lines())
        "".join(two.export_lines("all"))
        two.settle()
        assert one.revision() == two.revision() == seen


def test_the_sparql_graph_of_one_process_follows_the_writes_of_another(pg_url):
    with open_store(pg_url, TBOX) as one, open_store(pg_url, TBOX) as two:
        obj = make_object("obj1", "relative", 3, 4)
        one.create_object(obj)
        graph = KnowledgeGraph(two, TBOX)
        with graph.lock:
            graph.refresh()
            abox = graph.contents()["abox"]
        assert (URIRef(ABOX_IRI + "obj1"), RDF.type, URIRef(TBOX_IRI + "ArticulatedObject")) in abox
        for angles in ([0.0, 90.0, 90.0], [0.0, 0.0, 180.0]):
            state = one.add_perception(perceive(obj, angles))
            one.add_event("obj1", "replan", "", {"perceived_state_id": state.id})
            with graph.lock:
                graph.refresh()
                abox = graph.contents()["abox"]
            perceived = {s for s, p, o in abox if p == RDF.type and o == URIRef(TBOX_IRI + "PerceivedState")}
            assert perceived == {URIRef(ABOX_IRI + state.id)}  # the latest one only: the current ABox
        read = graph.objects_read
        with graph.lock:
            graph.refresh()  # nothing committed since: nothing read again
        assert graph.objects_read == read


def test_two_processes_replacing_one_scope_at_once_leave_one_set(pg_url):
    other = LINE.replace("j1", "j2")
    with open_store(pg_url, TBOX) as one, open_store(pg_url, TBOX) as two:
        replaced = threading.Event()

        def second() -> None:
            two.replace_inferred("all", [other])
            replaced.set()

        thread = threading.Thread(target=second)
        with one.transaction():
            one.replace_inferred("all", [LINE])
            thread.start()
            assert not replaced.wait(0.5)  # the scope's lock: the second waits for the first's commit
        thread.join(10)
        assert replaced.is_set()
        assert list(one.inferred_lines()) == list(two.inferred_lines()) == [other]

"""The RDF/XML and Turtle exports, written from the store's N-Triples lines as they are read: rdflib reads each back
to the same graph as the N-Triples (isomorphic, blank nodes included) on a real store's export with lines added for
what the store's own facts may not hold (literals with a datatype or a language, escapes, a property IRI whose local
name is not an XML name); an IRI no RDF/XML element can name is refused in one line; the writer hands on its first
piece before it has read every line."""
from __future__ import annotations

import pytest
import rdflib
from rdflib.compare import isomorphic

from planhrc.kb_service.store import ValidationError
from planhrc.kb_service.store.export import export_pieces
from planhrc.kb_service.store.facade import PREFIXES
from tests.test_sparql_engines import store  # noqa: F401 (the fixture: a real store of two objects)

EXTRA = [
    '<http://planhrc.org/abox#obj1> <http://www.w3.org/2000/01/rdf-schema#label> "rod"@en .\n',
    '<http://planhrc.org/abox#obj1> <http://www.w3.org/2000/01/rdf-schema#label> "Stab"@de-AT .\n',
    '<http://planhrc.org/abox#obj1> <http://www.w3.org/2000/01/rdf-schema#comment> '
    '"a \\"quoted\\" <b> & \\\\ back\\nslash\\r\\n\ttab é 🤖" .\n',
    '<http://planhrc.org/abox#obj1> <http://example.org/p/1st> "12"^^<http://www.w3.org/2001/XMLSchema#integer> .\n',
    '<http://planhrc.org/abox#obj1> <http://example.org/ns#weight> "2.5"^^<http://www.w3.org/2001/XMLSchema#decimal> .\n',
    '<http://planhrc.org/abox#obj1> <http://example.org/ns#when> '
    '"2026-11-26T12:00:00Z"^^<http://www.w3.org/2001/XMLSchema#dateTime> .\n',
    '<http://planhrc.org/abox#obj1> <http://example.org/ns#plain> "x"^^<http://www.w3.org/2001/XMLSchema#string> .\n',
    '<http://planhrc.org/abox#obj1> <http://example.org/a-b.c#d> <http://example.org/x?y=1&z=2> .\n',
    '_:b9 <http://example.org/ns#of> <http://planhrc.org/abox#obj1> .\n',
    '<http://planhrc.org/abox#obj1> <http://example.org/ns#has> _:b9 .\n',
]


@pytest.fixture(scope="module")
def lines(store):
    return list(store[0].export_lines("all")) + EXTRA


@pytest.mark.parametrize("fmt,rdflib_format", [("xml", "xml"), ("turtle", "turtle")])
def test_rdflib_reads_the_same_graph_as_the_ntriples(lines, fmt, rdflib_format):
    expected = rdflib.Graph().parse(data="".join(lines), format="nt")
    text = "".join(export_pieces(iter(lines), fmt, PREFIXES))
    got = rdflib.Graph().parse(data=text, format=rdflib_format)
    assert len(got) == len(expected) > 1000
    assert isomorphic(got, expected)
    assert any(isinstance(s, rdflib.BNode) for s in expected.subjects())  # the TBox's blank nodes came through


def test_prefixes_and_the_fallback_for_names_that_are_not_xml_names(lines):
    xml = "".join(export_pieces(iter(lines), "xml", PREFIXES))
    assert 'xmlns:planhrc="http://planhrc.org/ontology/planhrc.owl#"' in xml and "<planhrc:madeof " in xml
    assert '<st xmlns="http://example.org/p/1" rdf:datatype=' in xml  # the local name "1st" is not an XML name
    turtle = "".join(export_pieces(iter(lines), "turtle", PREFIXES))
    assert "@prefix abox: <http://planhrc.org/abox#> ." in turtle and "abox:obj1 " in turtle


@pytest.mark.parametrize("line,words", [
    ('<http://e/s> <http://example.org/p/> "x" .\n', "<http://example.org/p/> ends in no XML name"),
    ('<http://e/s> <http://e/p> "bell \\u0007" .\n', "U+0007 cannot be written in XML"),
    ('<http://e/s> <http://e/p> "no end .\n', "not an N-Triples line"),
])
def test_what_rdfxml_cannot_carry_is_refused_in_one_line(line, words):
    with pytest.raises(ValidationError) as err:
        "".join(export_pieces(iter([line]), "xml", PREFIXES))
    assert words in str(err.value) and "\n" not in str(err.value)


def test_turtle_carries_what_rdfxml_cannot():
    line = '<http://e/s> <http://example.org/p/> "bell \\u0007" .\n'
    text = "".join(export_pieces(iter([line]), "turtle", PREFIXES))
    assert isomorphic(rdflib.Graph().parse(data=text, format="turtle"), rdflib.Graph().parse(data=line, format="nt"))


@pytest.mark.parametrize("fmt", ["xml", "turtle"])
def test_the_first_piece_comes_before_the_last_line_is_read(lines, fmt):
    read = 0

    def counted():
        nonlocal read
        for line in lines * 20:
            read += 1
            yield line

    pieces = export_pieces(counted(), fmt, PREFIXES)
    written = ""
    while len(written) < 100_000:
        written += next(pieces)
    assert read < len(lines) * 20 / 4

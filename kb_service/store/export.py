"""RDF export of the whole ontology (TBox + ABox) as RDF/XML or Turtle."""
from __future__ import annotations

from .errors import ValidationError

FORMATS = ("xml", "turtle")


def export_rdf(ntriples: bytes, fmt: str, prefixes: dict[str, str]) -> bytes:
    """N-Triples re-serialised by rdflib as RDF/XML (`xml`) or Turtle (`turtle`), with readable prefixes."""
    import rdflib

    if fmt not in FORMATS:
        raise ValidationError(f"fmt: must be 'xml' or 'turtle', got {fmt!r}")
    graph = rdflib.Graph()
    graph.parse(data=ntriples, format="nt")
    for prefix, iri in prefixes.items():
        graph.bind(prefix, iri)
    out = graph.serialize(format=fmt)
    return out.encode("utf-8") if isinstance(out, str) else out

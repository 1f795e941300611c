"""RDF/XML and Turtle written straight from the store's N-Triples lines, as they are read: the export costs one pass
over the lines and holds one subject's lines at a time, however large the store.

The lines are the store's own (`owl.ntriple_lines`): IRIs, blank nodes `_:bN`, literals with a datatype or a
language. Consecutive lines about one subject make one `rdf:Description` (Turtle: one subject with `;`); a
subject whose lines are not consecutive gets two, which RDF/XML and Turtle both allow. A property IRI is written
with the export's prefix when its local name is an XML name; else as an element of the IRI's longest namespace
whose rest is one (`<local xmlns="namespace">`), as RDF/XML allows; an IRI that ends in no XML name at all (e.g. in
`/`) cannot be a property element, and the export says so (N-Triples and Turtle carry every IRI).
"""
from __future__ import annotations

import re
from typing import Iterable, Iterator, Mapping

from .errors import ValidationError

RDF_NS = "http://www.w3.org/1999/02/22-rdf-syntax-ns#"
RDF_TYPE = RDF_NS + "type"
STANDARD = {"rdf": RDF_NS, "rdfs": "http://www.w3.org/2000/01/rdf-schema#",
            "xsd": "http://www.w3.org/2001/XMLSchema#"}

_IRI = r"<([^>]*)>"
_BNODE = r"_:([^\s]+)"
_LITERAL = r'"((?:[^"\\]|\\.)*)"(?:\^\^<([^>]*)>|@([A-Za-z0-9-]+))?'
_LINE = re.compile(rf"(?:{_IRI}|{_BNODE})\s+{_IRI}\s+(?:{_IRI}|{_BNODE}|{_LITERAL})\s*\.\s*$")
_ESCAPE = re.compile(r"\\(u[0-9A-Fa-f]{4}|U[0-9A-Fa-f]{8}|.)")
_SIMPLE = {"t": "\t", "b": "\b", "n": "\n", "r": "\r", "f": "\f", '"': '"', "'": "'", "\\": "\\"}
# XML 1.0 names without a colon (NCName), and the characters an XML document may hold at all
_START = ("A-Z_a-z\u00c0-\u00d6\u00d8-\u00f6\u00f8-\u02ff\u0370-\u037d\u037f-\u1fff\u200c-\u200d\u2070-\u218f"
          "\u2c00-\u2fef\u3001-\ud7ff\uf900-\ufdcf\ufdf0-\ufffd\U00010000-\U000effff")
_NCNAME = re.compile(f"[{_START}][{_START}\\-.0-9\u00b7\u0300-\u036f\u203f-\u2040]*")
_NAME_TAIL = re.compile(f"[{_START}][{_START}\\-.0-9\u00b7\u0300-\u036f\u203f-\u2040]*$")
_NOT_XML = re.compile("[^\t\n\r\u0020-\ud7ff\ue000-\ufffd\U00010000-\U0010ffff]")
_PN_LOCAL = re.compile(r"[A-Za-z0-9_](?:[A-Za-z0-9_.-]*[A-Za-z0-9_-])?")

Term = tuple[str, str, str | None, str | None]  # kind ("iri", "bnode", "literal"), value, datatype, language


def _unescape(text: str) -> str:
    def one(m: re.Match[str]) -> str:
        code = m.group(1)
        if code[0] in "uU" and len(code) > 1:
            return chr(int(code[1:], 16))
        return _SIMPLE.get(code, "\\" + code)

    return _ESCAPE.sub(one, text) if "\\" in text else text


def parse_line(line: str) -> tuple[Term, str, Term] | None:
    """One N-Triples line as (subject, predicate IRI, object); None for a blank or comment line."""
    m = _LINE.match(line)
    if m is None:
        if not line.strip() or line.lstrip().startswith("#"):
            return None
        raise ValidationError(f"export: not an N-Triples line: {line.strip()[:200]!r}")
    s_iri, s_bnode, p, o_iri, o_bnode, text, datatype, lang = m.groups()
    subject: Term = ("iri", _unescape(s_iri), None, None) if s_iri is not None else ("bnode", s_bnode, None, None)
    obj: Term
    if o_iri is not None:
        obj = ("iri", _unescape(o_iri), None, None)
    elif o_bnode is not None:
        obj = ("bnode", o_bnode, None, None)
    else:
        obj = ("literal", _unescape(text), _unescape(datatype) if datatype else None, lang)
    return subject, _unescape(p), obj


def _grouped(lines: Iterable[str]) -> Iterator[tuple[Term, list[tuple[str, Term]]]]:
    """Runs of consecutive triples about one subject."""
    subject: Term | None = None
    run: list[tuple[str, Term]] = []
    for line in lines:
        triple = parse_line(line)
        if triple is None:
            continue
        if triple[0] != subject:
            if subject is not None:
                yield subject, run
            subject, run = triple[0], []
        run.append((triple[1], triple[2]))
    if subject is not None:
        yield subject, run


# -- RDF/XML ----------------------------------------------------------------------------------------------------
def _xml(text: str, attribute: bool = False) -> str:
    bad = _NOT_XML.search(text)
    if bad:
        raise ValidationError(f"export: the character U+{ord(bad.group(0)):04X} cannot be written in XML; ask for "
                              "N-Triples or Turtle")
    text = text.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;").replace("\r", "&#13;")
    if attribute:
        text = text.replace('"', "&quot;").replace("\n", "&#10;").replace("\t", "&#9;")
    return text


class _Names:
    """Property IRIs as element names: `prefix:local`, else `local` with its namespace declared on the element."""

    def __init__(self, prefixes: Mapping[str, str]) -> None:
        self.prefixes = sorted(prefixes.items(), key=lambda kv: -len(kv[1]))  # the longest namespace first
        self.known: dict[str, tuple[str, str]] = {}

    def element(self, iri: str) -> tuple[str, str]:
        """(the opening tag's name and declarations, the closing tag's name)."""
        found = self.known.get(iri)
        if found is None:
            found = self.known[iri] = self._split(iri)
        return found

    def _split(self, iri: str) -> tuple[str, str]:
        for prefix, namespace in self.prefixes:
            if iri.startswith(namespace) and _NCNAME.fullmatch(iri[len(namespace):]):
                name = f"{prefix}:{iri[len(namespace):]}"
                return name, name
        tail = _NAME_TAIL.search(iri)
        # the longest XML name the IRI ends with; a name may not begin with a digit, '-' or '.'
        if tail is None:
            raise ValidationError(f"export: the property <{iri}> ends in no XML name, so RDF/XML cannot carry it; "
                                  "ask for N-Triples or Turtle")
        local = tail.group(0)
        return f'{local} xmlns="{_xml(iri[:-len(local)], True)}"', local


def _node_ids() -> Iterator[str]:
    n = 0
    while True:
        n += 1
        yield f"b{n}"


def write_rdfxml(lines: Iterable[str], prefixes: Mapping[str, str]) -> Iterator[str]:
    """The triples of `lines` as an RDF/XML document, in pieces (a response gathers them into larger ones)."""
    declared = {**STANDARD, **prefixes}
    names = _Names(declared)
    node_ids: dict[str, str] = {}  # the store's blank node labels as XML names (rdf:nodeID must be one)
    fresh = _node_ids()

    def node_id(label: str) -> str:
        if label not in node_ids:
            node_ids[label] = next(fresh)
        return node_ids[label]

    def parts() -> Iterator[str]:
        yield '<?xml version="1.0" encoding="utf-8"?>\n<rdf:RDF'
        for prefix, namespace in declared.items():
            yield f'\n   xmlns:{prefix}="{_xml(namespace, True)}"'
        yield ">\n"
        for subject, run in _grouped(lines):
            if subject[0] == "iri":
                yield f'  <rdf:Description rdf:about="{_xml(subject[1], True)}">\n'
            else:
                yield f'  <rdf:Description rdf:nodeID="{node_id(subject[1])}">\n'
            for predicate, (kind, value, datatype, lang) in run:
                opening, closing = names.element(predicate)
                if kind == "iri":
                    yield f'    <{opening} rdf:resource="{_xml(value, True)}"/>\n'
                elif kind == "bnode":
                    yield f'    <{opening} rdf:nodeID="{node_id(value)}"/>\n'
                else:
                    extra = (f' xml:lang="{_xml(lang, True)}"' if lang else
                             f' rdf:datatype="{_xml(datatype, True)}"' if datatype else "")
                    yield f"    <{opening}{extra}>{_xml(value)}</{closing}>\n"
            yield "  </rdf:Description>\n"
        yield "</rdf:RDF>\n"

    return parts()


# -- Turtle -----------------------------------------------------------------------------------------------------
_TURTLE_ESCAPES = str.maketrans({"\\": "\\\\", '"': '\\"', "\n": "\\n", "\r": "\\r", "\t": "\\t"})


def write_turtle(lines: Iterable[str], prefixes: Mapping[str, str]) -> Iterator[str]:
    """The triples of `lines` as Turtle, in pieces."""
    declared = {**STANDARD, **prefixes}
    by_length = sorted(declared.items(), key=lambda kv: -len(kv[1]))
    known: dict[str, str] = {}

    def iri(value: str) -> str:
        found = known.get(value)
        if found is None:
            found = f"<{value}>".replace("\\", "\\u005C")  # the store's IRIs hold no other character to escape
            for prefix, namespace in by_length:
                if value.startswith(namespace) and _PN_LOCAL.fullmatch(value[len(namespace):]):
                    found = f"{prefix}:{value[len(namespace):]}"
                    break
            if len(known) < 100_000:  # the vocabulary, mostly; the individuals come and go
                known[value] = found
        return found

    def term(t: Term) -> str:
        kind, value, datatype, lang = t
        if kind == "iri":
            return iri(value)
        if kind == "bnode":
            return f"_:{value}"
        text = f'"{value.translate(_TURTLE_ESCAPES)}"'
        return f"{text}@{lang}" if lang else f"{text}^^{iri(datatype)}" if datatype else text

    def parts() -> Iterator[str]:
        for prefix, namespace in declared.items():
            yield f"@prefix {prefix}: <{namespace}> .\n"
        yield "\n"
        for subject, run in _grouped(lines):
            rows = [f"{'a' if p == RDF_TYPE else iri(p)} {term(o)}" for p, o in run]
            yield f"{term(subject)} " + " ;\n    ".join(rows) + " .\n"

    return parts()


WRITERS = {"xml": write_rdfxml, "turtle": write_turtle}

"""What a SPARQL query's text says about what it reads, found without evaluating it: its form (SELECT, ASK,
CONSTRUCT, DESCRIBE, or an update), the graphs its `FROM` and `FROM NAMED` clauses name, and whether it calls
`SERVICE`.

The engine that evaluates a query (Oxigraph) would follow `SERVICE` over HTTP and reads `FROM` only as a dataset
description; the endpoint decides both itself, so it reads them here from the query's tokens: comments, string
literals and IRIs are taken out first, so a keyword inside one of them is not a keyword. Keywords are matched
without regard to case, as SPARQL does. Anything malformed is left for the engine's parser to refuse.
"""
from __future__ import annotations

import re
from dataclasses import dataclass

FORMS = ("SELECT", "ASK", "CONSTRUCT", "DESCRIBE")
UPDATES = ("INSERT", "DELETE", "LOAD", "CLEAR", "CREATE", "DROP", "COPY", "MOVE", "ADD", "WITH")

# SPARQL 1.1's terminals that can hide a keyword: comments, the four string forms, IRIs (IRIREF). The long string
# forms come first so that '''...''' is not read as three short strings.
_OPAQUE = re.compile(
    r"""(?P<comment>\#[^\n\r]*)
      | (?P<long1>'''(?:[^'\\]|\\.|'(?!''))*''')
      | (?P<long2>\"\"\"(?:[^"\\]|\\.|"(?!""))*\"\"\")
      | (?P<short1>'(?:[^'\\\n\r]|\\.)*')
      | (?P<short2>"(?:[^"\\\n\r]|\\.)*")
      | (?P<iri><[^<>"{}|^`\\\x00-\x20]*>)""", re.VERBOSE | re.DOTALL)
_WORD = re.compile(r"[A-Za-z_][A-Za-z0-9_-]*")
# BASE <iri> and PREFIX name: <iri> declarations (IRIs already replaced by their markers)
_PROLOGUE = re.compile(r"\s*(?:(?:BASE\s*\x00\d+\x00|PREFIX\s*[^\s:]*:\s*\x00\d+\x00)\s*)*", re.IGNORECASE)
_PREFIX = re.compile(r"PREFIX\s+([A-Za-z][\w.-]*)?:\s*\x00(\d+)\x00", re.IGNORECASE)
_FROM = re.compile(r"FROM\s+(NAMED\s+)?(?:\x00(\d+)\x00|([A-Za-z][\w.-]*)?:([\w.-]*))", re.IGNORECASE)
# A keyword is a word that no '?', '$', ':' or name character touches (`?service` and `ex:service` are names;
# `SERVICE:x` is a keyword before a prefixed name to Oxigraph's parser, so a ':' after it still counts).
_SERVICE = re.compile(r"(?<![\w?$:.-])SERVICE(?![\w-])", re.IGNORECASE)


@dataclass(frozen=True)
class QueryText:
    """The parts of a query's text the endpoint acts on."""

    form: str | None  # one of FORMS, an update keyword, or None when no form was recognised
    from_graphs: tuple[str, ...]  # FROM <iri> (prefixed names resolved with the query's own PREFIXes)
    from_named: tuple[str, ...]  # FROM NAMED <iri>
    service: bool  # the query calls SERVICE

    @property
    def is_update(self) -> bool:
        return self.form in UPDATES


def read_query_text(text: str, prefixes: dict[str, str]) -> QueryText:
    """Read `text` (`prefixes`: the ones the endpoint knows without a PREFIX line)."""
    iris: list[str] = []

    def hide(m: re.Match[str]) -> str:
        if m.group("iri") is not None:
            iris.append(m.group("iri")[1:-1])
            return f" \x00{len(iris) - 1}\x00 "
        return " " if m.group("comment") is not None else ' "" '

    bare = _OPAQUE.sub(hide, text)
    known = dict(prefixes)
    known.update({(m.group(1) or ""): iris[int(m.group(2))] for m in _PREFIX.finditer(bare)})
    from_graphs: list[str] = []
    from_named: list[str] = []
    for m in _FROM.finditer(bare):
        named, index, prefix, local = m.groups()
        if index is not None:
            iri = iris[int(index)]
        else:
            iri = known.get(prefix or "", f"{prefix or ''}:") + local
        (from_named if named else from_graphs).append(iri)
    return QueryText(_form(bare), tuple(from_graphs), tuple(from_named), bool(_SERVICE.search(bare)))


def _form(bare: str) -> str | None:
    """The first keyword after the prologue (BASE and PREFIX declarations)."""
    prologue = _PROLOGUE.match(bare)  # it matches the empty text too
    word = _WORD.match(bare, prologue.end() if prologue else 0)
    name = word.group(0).upper() if word else None
    return name if name in FORMS or name in UPDATES else None

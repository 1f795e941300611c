"""State subsumption D(s1) ⊑ D(s2), two ways.

* `subsumes_fast`: the hot path. A state is a set of ground atoms and D(s) is the conjunction, over its atoms,
  of ∃madeof.(PredicateClass ⊓ ∃arg1.{a} ⊓ ∃arg2.{b} …); such a conjunction implies another exactly when it
  has every conjunct of the other, so the check is `s2 ⊆ s1` (= `planhrc.model.is_subsumed`).
* `dl_subsumption`: the same question asked of a DL reasoner, for a whole batch of pairs in one reasoner run,
  in a fresh world holding the TBox. Two encodings: "unsat" (default; Q_i ⊑ D(s1_i) ⊓ ¬D(s2_i), one
  `pellet unsat` run, Q_i unsatisfiable ⇔ subsumed: one satisfiability test per pair) and "classify" (named
  S_i ≡ D(s1_i), G_i ≡ D(s2_i), classified through owlready2, S_i ⊑ G_i read from the inferred hierarchy;
  any reasoner, but classification does many more tests, so keep its batches small). Used by tests and
  benchmarks to show that both formulations agree; a JVM start per call keeps it off the per-perception path.
"""
from __future__ import annotations

import logging
import random
import re
import statistics
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterable, Sequence

import owlready2
from owlready2 import AllDifferent, And, Not, OneOf, Thing, World

from planhrc.model import HAS_ORIENTATION, Atom, State, is_subsumed, make_object
from planhrc.paths import default_tbox_path

from .reasoner import drop_builtin_rules, reason_in_place, run_pellet
from .store import ABOX_IRI, PREDICATES, TBOX_IRI
from .store.errors import ReasonerError, ValidationError

log = logging.getLogger(__name__)


def subsumes_fast(s1: State, s2: State) -> bool:
    """D(s1) ⊑ D(s2): every atom of s2 is an atom of s1."""
    return is_subsumed(s1, s2)


def _owl_args(atom: Atom) -> list[tuple[str, str]]:
    """(property, individual name) of an atom, in OWL argument order (hasorientation (o, j) -> arg1 j, arg2 o)."""
    spec = PREDICATES.get(atom[0])
    if spec is None:
        raise ValidationError(f"atom {atom!r}: unknown predicate {atom[0]!r}")
    _, _, props, _ = spec
    if len(atom) - 1 != len(props):
        raise ValidationError(f"atom {atom!r}: {atom[0]} takes {len(props)} arguments")
    return sorted(zip(props, atom[1:]))


def describe_state(atoms: Iterable[Atom]) -> str:
    """D(s) in Manchester syntax: one `madeof some (...)` conjunct per atom, sorted."""
    parts = []
    for atom in sorted(atoms):
        cls = PREDICATES[atom[0]][0] if atom[0] in PREDICATES else atom[0]
        inner = " and ".join([cls] + [f"({prop} some {{{name}}})" for prop, name in _owl_args(atom)])
        parts.append(f"(madeof some ({inner}))")
    return " and ".join(parts) if parts else "owl:Thing"


_TYPE_CLASS = {"link": "Link", "joint": "Joint", "orientation": "Orientation", "gripper": "Gripper"}
METHODS = ("unsat", "classify")


def _individual_types(pairs: Sequence[tuple[State, State]]) -> dict[str, str]:
    types: dict[str, str] = {}
    for s1, s2 in pairs:
        for atom in s1 | s2:
            _, arg_types, _, _ = PREDICATES[atom[0]]
            for name, typ in zip(atom[1:], arg_types):
                if types.setdefault(name, typ) != typ:
                    raise ValidationError(f"atoms: {name!r} is used both as a {types[name]} and as a {typ}")
    return types


class _Describer:
    """Builds D(s) in a world, naming shared sub-expressions so that a batch stays small.

    * an atom a is C_a = PredicateClass ⊓ ∃arg1.{x} ⊓ ∃arg2.{y} … (arguments in OWL order);
    * every distinct set X of non-`hasorientation` atoms (the object's static facts) gets a named class
      `B_k ≡ ⊓_{a∈X} ∃madeof.C_a`;
    * D(s) = B(X_s) ⊓ ⊓_{a ∈ s, hasorientation} ∃madeof.C_a.
    B_k is a definition (an equivalence), so D(s) denotes the same class as the flat conjunction; it only spares
    the reasoner from parsing and absorbing the same ~260 static conjuncts hundreds of times (with 300 flat
    definitions Pellet spends minutes in absorption). Naming every C_a as well was measured slower (nominal
    absorption), so atoms stay anonymous.
    """

    def __init__(self, world: World, tbox: Any, abox: Any, individuals: dict[str, Thing]) -> None:
        self.tbox, self.abox, self.individuals = tbox, abox, individuals
        self.block_classes: dict[State, Any] = {}

    def _named(self, prefix: str, n: int, expr: Any) -> Any:
        cls: Any = type(f"{prefix}_{n}", (Thing,), {"namespace": self.abox})
        cls.equivalent_to.append(expr)
        return cls

    def atom_class(self, atom: Atom) -> Any:
        """PredicateClass ⊓ ∃arg1.{x} ⊓ … as a fresh construct (an RDF blank node must not be shared)."""
        pred = getattr(self.tbox, PREDICATES[atom[0]][0])
        parts = [getattr(self.tbox, prop).some(OneOf([self.individuals[name]])) for prop, name in _owl_args(atom)]
        return And([pred] + parts)

    def describe(self, atoms: frozenset[Atom]) -> Any:
        madeof = self.tbox.madeof
        static = frozenset(a for a in atoms if a[0] != HAS_ORIENTATION)
        conjuncts = []
        if static:
            block = self.block_classes.get(static)
            if block is None:
                expr = And([madeof.some(self.atom_class(a)) for a in sorted(static)])
                block = self.block_classes[static] = self._named("B", len(self.block_classes), expr)
            conjuncts.append(block)
        conjuncts += [madeof.some(self.atom_class(a)) for a in sorted(atoms - static)]
        if not conjuncts:
            return Thing
        return conjuncts[0] if len(conjuncts) == 1 else And(conjuncts)


def dl_subsumption(
    pairs: Sequence[tuple[frozenset[Atom], frozenset[Atom]]],
    reasoner: str = "pellet",
    tbox_path: Path | str | None = None,
    timeout_s: float = 600.0,
    method: str = "unsat",
) -> list[bool]:
    """For each (s1, s2): does the reasoner find D(s1) ⊑ D(s2)? One reasoner run for the whole batch.

    method "unsat" (Pellet only): one class Q_i ⊑ D(s1_i) ⊓ ¬D(s2_i) per pair and one `pellet unsat` run;
    D(s1_i) ⊑ D(s2_i) exactly when Q_i is unsatisfiable. Only |pairs| satisfiability tests, no taxonomy.
    method "classify" (Pellet or HermiT, through owlready2): named S_i ≡ D(s1_i), G_i ≡ D(s2_i); the reasoner
    classifies them and S_i ⊑ G_i is read from the inferred hierarchy. Exact but quadratic: small batches only.
    """
    if method not in METHODS:
        raise ValidationError(f"method: must be one of {', '.join(METHODS)}, got {method!r}")
    if method == "unsat" and reasoner != "pellet":
        raise ReasonerError(f"method 'unsat' runs Pellet only, not {reasoner!r}; use method='classify'")
    pairs = [(frozenset(a), frozenset(b)) for a, b in pairs]
    if not pairs:
        return []
    world = World()
    try:
        with open(Path(tbox_path or default_tbox_path()), "rb") as f:
            tbox = world.get_ontology(TBOX_IRI).load(fileobj=f)
        drop_builtin_rules(world)  # the SWRL rules play no part in subsumption between state descriptions
        abox = world.get_ontology(ABOX_IRI)
        with abox:
            individuals = {}
            for name, typ in sorted(_individual_types(pairs).items()):
                individuals[name] = getattr(tbox, _TYPE_CLASS[typ])(name)
            if len(individuals) > 1:
                AllDifferent(list(individuals.values()))
            describer = _Describer(world, tbox, abox, individuals)
            if method == "classify":
                classes: list[tuple[Any, Any]] = []
                for i, (s1, s2) in enumerate(pairs):
                    s_cls: Any = type(f"S_{i}", (Thing,), {"namespace": abox})
                    g_cls: Any = type(f"G_{i}", (Thing,), {"namespace": abox})
                    s_cls.equivalent_to.append(describer.describe(s1))
                    g_cls.equivalent_to.append(describer.describe(s2))
                    classes.append((s_cls, g_cls))
            else:
                for i, (s1, s2) in enumerate(pairs):
                    q_cls: Any = type(f"Q_{i}", (Thing,), {"namespace": abox})
                    q_cls.is_a.append(And([describer.describe(s1), Not(describer.describe(s2))]))
        if method == "unsat":
            unsat = _pellet_unsatisfiable(world, timeout_s)
            return [f"Q_{i}" in unsat for i in range(len(pairs))]
        consistent, _ = reason_in_place(world, reasoner, timeout_s)
        if not consistent:
            raise ReasonerError(f"{reasoner}: the state descriptions are inconsistent")
        return [g in s.ancestors() or g in s.equivalent_to for s, g in classes]
    finally:
        world.close()


_UNSAT_NAME = re.compile(r"\b(Q_\d+)\b")


def _pellet_unsatisfiable(world: World, timeout_s: float) -> set[str]:
    """Names of the unsatisfiable named classes of `world`, by one `pellet unsat` run (OWL API loader)."""
    proc = run_pellet(world, ["unsat", "-v", "--loader", "OWLAPIv3", "--ignore-imports"], timeout_s, "pellet",
                      file_name="batch.owl")
    timer = proc.stderr[proc.stderr.find("Timer summary"):] if "Timer summary" in proc.stderr else ""
    log.debug("pellet unsat: %s", timer)
    if proc.returncode != 0:
        raise ReasonerError(f"pellet unsat failed ({proc.returncode}): {proc.stderr[-2000:]}")
    if "Found" not in proc.stdout and "No unsatisfiable" not in proc.stdout:
        log.warning("unexpected output of pellet unsat: %s", proc.stdout[:500])
    return set(_UNSAT_NAME.findall(proc.stdout))


# -- benchmark ---------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class BenchReport:
    runs: int
    atoms_s1: int
    atoms_s2: int
    p50_us: float
    p95_us: float
    mean_us: float


def bench_subsumption(runs: int = 10_000, links: int = 20, orientations: int = 12, seed: int = 1) -> BenchReport:
    """Time one in-process `subsumes_fast` check: a complete 20-link absolute state against an equal complete
    state built separately (the worst case: every atom of s2 is looked up in s1)."""
    rng = random.Random(seed)
    obj = make_object("bench", "absolute", links, orientations)
    values = [rng.choice(obj.orientation_degrees) for _ in obj.joints]
    s1 = obj.state(values)
    s2 = obj.state(list(values))
    samples = []
    clock = time.perf_counter_ns
    for _ in range(runs):
        t0 = clock()
        subsumes_fast(s1, s2)
        samples.append(clock() - t0)
    samples.sort()
    return BenchReport(
        runs=runs, atoms_s1=len(s1), atoms_s2=len(s2),
        p50_us=samples[len(samples) // 2] / 1000.0,
        p95_us=samples[int(len(samples) * 0.95)] / 1000.0,
        mean_us=statistics.fmean(samples) / 1000.0,
    )

"""Immutable values shared by every stage: articulated objects, ground atoms and states.

Conventions (see CONVENTIONS.md): orientations are integer degrees in [0, 360), clockwise
seen from above; K allowed orientations are {0, step, 2*step, ...} with step = 360 / K.

* Relative formulation: links l1..lN, joints j1..j(N-1); jK joins lK and lK+1 and carries the angle of
  lK+1 relative to lK, (theta[K+1] - theta[K]) mod 360.
* Absolute formulation: links l0 (virtual, the table) and l1..lN, joints j1..jN; jK joins lK-1 and lK and
  carries the absolute orientation of lK. Turning lK about jK (holding lK-1) moves lK..lN, so jK changes and
  so does every jM with M > K: Affected(jM, lK, jK). Our objects also assert the reflexive
  Affected(jK, lK, jK), which names lK as the link that turns about jK (the paper's schema ignores it in its
  conditional effect because of `(not (= ?j2 ?j1))`).
* Bimanual formulation: links l1..lN, joints j1..j(N-1); jK joins lK and lK+1 and carries the orientation of
  lK+1 measured from l1, (theta[K+1] - theta[1]) mod 360. Two grippers turn lK+1 about jK while they hold lK
  still, so jK and every jM with M > K change: Affected(jM, lK+1, jK), the reflexive one included. Its states
  also hold the robot's control facts (what the grippers hold, which joint is at the centre: `planhrc.control`).

A ground atom is a PDDL-style tuple ``(predicate, arg, ...)`` with lower-case names, e.g.
``("hasorientation", "deg_90", "obj1_j3")``. A state is a ``frozenset`` of atoms.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass
from enum import Enum
from functools import cached_property, lru_cache
from typing import Iterable, Sequence

from planhrc.errors import PlanhrcError

Atom = tuple[str, ...]
State = frozenset[Atom]

CONNECTED = "connected"
HAS_ORIENTATION = "hasorientation"
ORIENTATION_ORD = "orientationord"
AFFECTED = "affected"
ORIENTATION_ORD45 = "orientationord45"  # bimanual: o2 lies 45 degrees clockwise of o1
KEEPER = "keeper"  # bimanual: the gripper that keeps the upstream link still
FREE, HOLDING, IN_CENTRE = "free", "holding", "incentre"  # bimanual: the robot's control facts
CONTROL_PREDICATES = frozenset({FREE, HOLDING, IN_CENTRE})
GRIPPERS = ("left", "right")  # Baxter's grippers, as PDDL objects of a bimanual task
KEEPING_GRIPPER = "left"
MACRO_DEG = 45  # the bimanual turn macro
EQUALITY = "="  # the predicate of a literal `(= ?a ?b)`


class ModelError(PlanhrcError):
    """Invalid object description or configuration; the message names the offending field."""


class Formulation(str, Enum):
    RELATIVE = "relative"
    ABSOLUTE = "absolute"
    BIMANUAL = "bimanual"


def orientation_values(k: int) -> tuple[int, ...]:
    """The K allowed orientations in degrees, ascending."""
    if k < 2 or 360 % k != 0:
        raise ModelError(f"orientations: 360 must be divisible by K and K >= 2, got {k}")
    step = 360 // k
    return tuple(i * step for i in range(k))


def orientation_name(deg: int) -> str:
    return f"deg_{deg}"


def snap_angle(angle: float, k: int) -> int:
    """Snap a continuous angle (any real, degrees) to the nearest allowed orientation; ties go to the smaller."""
    if not math.isfinite(angle):
        raise ModelError(f"angle must be finite, got {angle!r}")
    step = 360 // k
    a = angle % 360.0
    lower = int(a // step) * step
    upper = lower + step
    choice = lower if (a - lower) <= (upper - a) else upper
    return int(choice) % 360


def relative_from_absolute(link_orientations: Sequence[int]) -> tuple[int, ...]:
    """Relative angle of link K+1 with respect to link K, for K = 1..N-1: (theta[K+1] - theta[K]) mod 360."""
    return tuple((b - a) % 360 for a, b in zip(link_orientations, link_orientations[1:]))


def absolute_from_relative(first: int, relative: Sequence[int]) -> tuple[int, ...]:
    """Link orientations from the first link's orientation and the relative joint angles."""
    out = [first % 360]
    for r in relative:
        out.append((out[-1] + r) % 360)
    return tuple(out)


@dataclass(frozen=True)
class ArticulatedObject:
    """An articulated object: an ordered chain of links, its joints and its allowed orientation set."""

    ident: str
    formulation: Formulation
    link_lengths_m: tuple[float, ...]
    orientations: int
    name: str = ""

    def __post_init__(self) -> None:
        if not self.ident or not self.ident.replace("_", "").isalnum() or not self.ident[0].isalpha():
            raise ModelError(f"ident: must start with a letter and be alphanumeric, got {self.ident!r}")
        if self.ident != self.ident.lower():
            raise ModelError(f"ident: must be lower case, got {self.ident!r}")
        if len(self.link_lengths_m) < 2:
            raise ModelError(f"links: an articulated object needs at least 2 links, got {len(self.link_lengths_m)}")
        for i, length in enumerate(self.link_lengths_m):
            if not math.isfinite(length) or length <= 0:
                raise ModelError(f"links[{i}].length_m: must be a positive finite number, got {length!r}")
        orientation_values(self.orientations)

    # -- names ---------------------------------------------------------------------------------------
    @property
    def n_links(self) -> int:
        return len(self.link_lengths_m)

    @property
    def step(self) -> int:
        return 360 // self.orientations

    def link(self, k: int) -> str:
        return f"{self.ident}_l{k}"

    def joint(self, k: int) -> str:
        return f"{self.ident}_j{k}"

    @property
    def links(self) -> tuple[str, ...]:
        """Real links l1..lN in chain order."""
        return tuple(self.link(k) for k in range(1, self.n_links + 1))

    @property
    def all_links(self) -> tuple[str, ...]:
        """Links as PDDL objects: the absolute formulation adds the virtual ground link l0."""
        if self.formulation is Formulation.ABSOLUTE:
            return (self.link(0),) + self.links
        return self.links

    @property
    def joint_indices(self) -> tuple[int, ...]:
        if self.formulation is Formulation.ABSOLUTE:
            return tuple(range(1, self.n_links + 1))
        return tuple(range(1, self.n_links))

    @property
    def joints(self) -> tuple[str, ...]:
        return tuple(self.joint(k) for k in self.joint_indices)

    @property
    def n_joints(self) -> int:
        return len(self.joint_indices)

    @property
    def orientation_degrees(self) -> tuple[int, ...]:
        return orientation_values(self.orientations)

    @property
    def orientation_names(self) -> tuple[str, ...]:
        return tuple(orientation_name(d) for d in self.orientation_degrees)

    @property
    def grippers(self) -> tuple[str, ...]:
        """The robot's grippers as objects of its tasks (bimanual formulation only)."""
        return GRIPPERS if self.formulation is Formulation.BIMANUAL else ()

    @property
    def has_macros(self) -> bool:
        """Whether 45 degrees is several steps of the orientation set (bimanual 45-degree turns)."""
        return self.formulation is Formulation.BIMANUAL and MACRO_DEG % self.step == 0 and MACRO_DEG > self.step

    def joint_links(self, k: int) -> tuple[str, str]:
        """(upstream link, downstream link) joined by joint k."""
        if self.formulation is Formulation.ABSOLUTE:
            return self.link(k - 1), self.link(k)
        return self.link(k), self.link(k + 1)

    # -- static facts ----------------------------------------------------------------------------------
    def connected_atoms(self) -> frozenset[Atom]:
        atoms = set()
        for k in self.joint_indices:
            up, down = self.joint_links(k)
            atoms.add((CONNECTED, self.joint(k), up))
            atoms.add((CONNECTED, self.joint(k), down))
        return frozenset(atoms)

    def ord_atoms(self) -> frozenset[Atom]:
        names = self.orientation_names
        return frozenset((ORIENTATION_ORD, names[i], names[(i + 1) % len(names)]) for i in range(len(names)))

    def affected_atoms(self) -> frozenset[Atom]:
        """Affected(jM, l, jK) for M >= K, l the link that turns about jK (absolute and bimanual formulations);
        see the module docstring."""
        if self.formulation is Formulation.RELATIVE:
            return frozenset()
        atoms = set()
        for k in self.joint_indices:
            turned = self.joint_links(k)[1]
            for m in self.joint_indices:
                if m >= k:
                    atoms.add((AFFECTED, self.joint(m), turned, self.joint(k)))
        return frozenset(atoms)

    def robot_atoms(self) -> frozenset[Atom]:
        """Bimanual: which gripper keeps the upstream link, and the 45-degree steps where K allows them."""
        if self.formulation is not Formulation.BIMANUAL:
            return frozenset()
        atoms: set[Atom] = {(KEEPER, KEEPING_GRIPPER)}
        if self.has_macros:
            names, m = self.orientation_names, MACRO_DEG // self.step
            atoms |= {(ORIENTATION_ORD45, names[i], names[(i + m) % len(names)]) for i in range(len(names))}
        return frozenset(atoms)

    def static_atoms(self) -> frozenset[Atom]:
        return self._static_atoms

    @cached_property
    def _static_atoms(self) -> frozenset[Atom]:  # worked out once per object: every state and problem holds them
        return self.connected_atoms() | self.ord_atoms() | self.affected_atoms() | self.robot_atoms()

    # -- configurations --------------------------------------------------------------------------------
    def check_joint_values(self, values: Sequence[int | float], field: str = "joint_angles_deg") -> tuple[int, ...]:
        if len(values) != self.n_joints:
            raise ModelError(f"{field}: expected {self.n_joints} values (one per joint), got {len(values)}")
        allowed = set(self.orientation_degrees)
        out = []
        for i, v in enumerate(values):
            if isinstance(v, float) and not v.is_integer():
                raise ModelError(f"{field}[{i}]: {v} is not one of the allowed orientations {sorted(allowed)}")
            iv = int(v)
            if iv not in allowed:
                raise ModelError(f"{field}[{i}]: {v} is not one of the allowed orientations {sorted(allowed)}")
            out.append(iv)
        return tuple(out)

    def partial_configuration_atoms(self, values: Sequence[float | None], field: str = "goal") -> frozenset[Atom]:
        """HasOrientation atoms of a (possibly partial) goal: one value per joint, None leaves a joint free.

        Values are degrees taken modulo 360 and must be allowed orientations exactly (a goal is not snapped)."""
        if len(values) != self.n_joints:
            raise ModelError(f"{field}: expected {self.n_joints} values (one per joint), got {len(values)}")
        allowed = set(self.orientation_degrees)
        atoms = set()
        for i, (k, v) in enumerate(zip(self.joint_indices, values)):
            if v is None:
                continue
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise ModelError(f"{field}[{i}]: must be a finite number, got {v!r}")
            degrees = float(v) % 360
            if degrees not in allowed:
                raise ModelError(f"{field}[{i}]: {v} is not one of the allowed orientations {sorted(allowed)}")
            atoms.add((HAS_ORIENTATION, orientation_name(int(degrees)), self.joint(k)))
        if not atoms:
            raise ModelError(f"{field}: at least one joint needs a value")
        return frozenset(atoms)

    def joint_values_from_links(self, link_orientations: Sequence[int]) -> tuple[int, ...]:
        """Joint values carried by the formulation, from every real link's absolute orientation."""
        if len(link_orientations) != self.n_links:
            raise ModelError(
                f"link_orientations_deg: expected {self.n_links} values (one per link), got {len(link_orientations)}"
            )
        if self.formulation is Formulation.ABSOLUTE:
            return tuple(int(v) % 360 for v in link_orientations)
        if self.formulation is Formulation.BIMANUAL:
            return tuple((int(v) - int(link_orientations[0])) % 360 for v in link_orientations[1:])
        return relative_from_absolute([int(v) % 360 for v in link_orientations])

    def configuration_atoms(self, joint_values: Sequence[int]) -> frozenset[Atom]:
        values = self.check_joint_values(joint_values)
        return frozenset(
            (HAS_ORIENTATION, orientation_name(v), self.joint(k)) for k, v in zip(self.joint_indices, values)
        )

    def state(self, joint_values: Sequence[int], control: Iterable[Atom] | None = None) -> State:
        """A complete state: static facts plus one orientation per joint; a bimanual one also holds the robot's
        control facts (`control`, default: both grippers free, the middle joint at the centre)."""
        atoms = self.static_atoms() | self.configuration_atoms(joint_values)
        if self.formulation is not Formulation.BIMANUAL:
            return atoms
        return atoms | (self.initial_control() if control is None else frozenset(control))

    def initial_control(self) -> frozenset[Atom]:
        """The robot's control facts before it has done anything (bimanual): both grippers free, the middle joint
        at the centre. `planhrc.control` follows them from there."""
        if self.formulation is not Formulation.BIMANUAL:
            return frozenset()
        return frozenset({(FREE, g) for g in GRIPPERS} | {(IN_CENTRE, self.joint(max(1, self.n_links // 2)))})

    def joint_values_of(self, state: Iterable[Atom]) -> dict[int, int]:
        """Joint index -> degrees for every HasOrientation atom of the state (partial states give partial maps)."""
        index = {self.joint(k): k for k in self.joint_indices}
        out: dict[int, int] = {}
        for atom in state:
            if atom[0] == HAS_ORIENTATION and atom[2] in index:
                out[index[atom[2]]] = int(atom[1].split("_", 1)[1])
        return out

    def link_orientations_of(self, state: Iterable[Atom], first_link_deg: int = 0) -> tuple[int, ...]:
        """Absolute link orientations of a complete state (relative: l1 is placed at `first_link_deg`)."""
        values = self.joint_values_of(state)
        if len(values) != self.n_joints:
            raise ModelError("state: not a complete configuration (a joint has no orientation)")
        ordered = [values[k] for k in self.joint_indices]
        if self.formulation is Formulation.ABSOLUTE:
            return tuple(ordered)
        if self.formulation is Formulation.BIMANUAL:
            return (first_link_deg % 360,) + tuple((first_link_deg + v) % 360 for v in ordered)
        return absolute_from_relative(first_link_deg, ordered)


def make_object(
    ident: str,
    formulation: Formulation | str,
    links: int | Sequence[float],
    orientations: int,
    name: str = "",
    default_length_m: float = 0.155,
) -> ArticulatedObject:
    """Build an object from a link count (all of `default_length_m`) or a list of link lengths."""
    if isinstance(links, bool):
        raise ModelError("links: must be an integer count or a list of lengths")
    lengths = (default_length_m,) * links if isinstance(links, int) else tuple(float(x) for x in links)
    try:
        form = Formulation(formulation)
    except ValueError as exc:
        raise ModelError(f"formulation: must be one of {', '.join(f.value for f in Formulation)}, got "
                         f"{formulation!r}") from exc
    return ArticulatedObject(ident=ident, formulation=form, link_lengths_m=lengths, orientations=orientations, name=name)


def is_subsumed(s1: State, s2: State) -> bool:
    """D(s1) ⊑ D(s2): every atom that s2 asserts is asserted by s1 (s2 may be partial)."""
    return s2 <= s1


_DIGITS = re.compile(r"(\d+)")
NATURAL_KEYS_KEPT = 50_000  # names, i.e. about a hundred 20 x 12 objects' links, joints and orientations


@lru_cache(maxsize=NATURAL_KEYS_KEPT)
def natural_key(name: str) -> tuple[tuple[int, int | str], ...]:
    """Sort key that orders the numbers inside names by value: `obj1_l2` before `obj1_l10`, `deg_30` before
    `deg_120`. The one natural sort of the project. Kept for the names last used (a re-plan sorts the same few
    hundred names of its object each time: 12,000 keys per 20 x 12 re-plan)."""
    return tuple((0, int(part)) if part.isdigit() else (1, part) for part in _DIGITS.split(name) if part)


def format_atom(atom: Atom) -> str:
    return "(" + " ".join(atom) + ")"


# -- the TBox's action schemas, as values (read from the TBox by the translator) ----------------------------
@dataclass(frozen=True)
class Literal:
    """A literal of an action schema, as the TBox describes it and as the in-process planner parses PDDL:
    predicate and terms (variables `?x`, or objects), possibly negated. `planhrc.grounding` binds it."""

    predicate: str  # PDDL predicate name or EQUALITY
    args: tuple[str, ...]  # terms in PDDL argument order
    negated: bool = False

    @property
    def atom(self) -> Atom:
        """`(predicate, *args)`: the atom the literal asserts or denies, its terms unbound."""
        return (self.predicate, *self.args)

    def pddl(self) -> str:
        core = format_atom(self.atom)
        return f"(not {core})" if self.negated else core


@dataclass(frozen=True)
class ConditionalEffect:
    variables: tuple[tuple[str, str], ...]  # (name, type)
    when: tuple[Literal, ...]
    effects: tuple[Literal, ...]


@dataclass(frozen=True)
class ActionSchemaSpec:
    name: str
    parameters: tuple[tuple[str, str], ...]
    precondition: tuple[Literal, ...]
    effects: tuple[Literal, ...]
    conditional_effects: tuple[ConditionalEffect, ...]


@dataclass(frozen=True)
class PredicateSpec:
    name: str
    parameters: str  # e.g. "?o - orientation ?j - joint"


@dataclass(frozen=True)
class DomainModelSpec:
    """The DomainModel of one formulation as the TBox describes it."""

    name: str
    requirements: str
    types: str
    predicates: tuple[PredicateSpec, ...]
    actions: tuple[ActionSchemaSpec, ...]


# -- ground actions -----------------------------------------------------------------------------------------
@dataclass(frozen=True)
class CondEffect:
    """A ground conditional effect: when `when` holds, delete `eff_neg` and add `eff_pos`."""

    when: frozenset[Atom]
    eff_neg: frozenset[Atom]
    eff_pos: frozenset[Atom]


@dataclass(frozen=True)
class ActionSpec:
    """A ground action: PDDL name, arguments, pre, eff-, eff+ and conditional effects."""

    name: str
    params: tuple[str, ...]
    pre: frozenset[Atom]
    eff_neg: frozenset[Atom]
    eff_pos: frozenset[Atom]
    cond_eff: tuple[CondEffect, ...] = ()


# -- perceptions ------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Perception:
    """One perception of an object, validated and snapped once, where it enters (`perceive`).

    `raw_deg` are the observed link orientations as reported, `snapped_deg` the nearest allowed orientation of
    each link, `joint_values` what the formulation's joints carry and `atoms` the complete perceived state."""

    object_id: str
    raw_deg: tuple[float, ...]
    snapped_deg: tuple[int, ...]
    joint_values: tuple[int, ...]
    atoms: State


def perceive(obj: ArticulatedObject, link_orientations_deg: object,
             field: str = "link_orientations_deg", control: Iterable[Atom] | None = None) -> Perception:
    """Validate observed link orientations (one finite number per link) and snap them to allowed values; a
    bimanual object's state takes the robot's `control` facts (`ArticulatedObject.state`)."""
    if isinstance(link_orientations_deg, (str, bytes)) or not isinstance(link_orientations_deg, Sequence):
        raise ModelError(f"{field}: expected a sequence of numbers")
    if len(link_orientations_deg) != obj.n_links:
        raise ModelError(f"{field}: expected {obj.n_links} values (one per link), got {len(link_orientations_deg)}")
    raw: list[float] = []
    for i, v in enumerate(link_orientations_deg):
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise ModelError(f"{field}[{i}]: must be a finite number, got {v!r}")
        raw.append(float(v))
    snapped = tuple(snap_angle(v, obj.orientations) for v in raw)
    joint_values = obj.joint_values_from_links(snapped)
    return Perception(obj.ident, tuple(raw), snapped, joint_values, obj.state(joint_values, control))

"""The ABox of the knowledge base: objects, states, problems and plans, over the planHRC TBox.

The ontology lives in an owlready2 `World` backed by SQLite. The TBox file is loaded into the world once; every
ABox individual goes into the ontology `http://planhrc.org/abox#` with a readable IRI whose fragment is the PDDL
name (`obj42_l3`, `obj42_j3`, `deg_90`) or a name built from it (`obj42_state_7`, `obj42_ho_j3_90`,
`obj42_connected_j3_l2`, `obj42_plan_2_a5`). A ground predicate is one individual of its object, whichever
states and actions it belongs to (as the paper writes `has_orientation_j1_45`): a state is the set of
predicate individuals it is `madeof`, so a new state costs its `madeof` links, not new predicates.

Writes go straight into owlready2's quad tables (`objs`, `datas`) in one SQLite transaction, after the whole
input has been validated; a write either commits completely or not at all. Nothing here loads ABox individuals
as owlready2 Python objects, so owlready2's entity cache never goes stale. Records read back are cached (they
are immutable). Every table access goes through the owlready2 adapter (`owl.QuadStore`). What is not ontology
knowledge (events, the execution cursor, idempotent responses) has its own module (`events`, `execution`,
`responses`); `knowledge_base.KnowledgeBase` puts them together, in the same SQLite database and transactions.
"""
from __future__ import annotations

import hashlib
import logging
import threading
import time
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterable, Iterator, Self, Sequence, TypeVar

from planhrc.model import (
    AFFECTED,
    CONNECTED,
    HAS_ORIENTATION,
    ORIENTATION_ORD,
    ArticulatedObject,
    Atom,
    Formulation,
    ModelError,
    Perception,
    format_atom,
    natural_key,
    orientation_name,
    perceive,
)

from .errors import ConflictError, DeadlineError, KBError, NotFoundError, ValidationError
from .journal import JournalEntry, PlanJournal, PlanWriter
from .owl import NAMED_INDIVIDUAL, RDF_TYPE, QuadStore, World
from .records import (
    STATE_KINDS,
    ActionSpec,
    CondEffect,
    StoredAction,
    StoredPlan,
    StoredProblem,
    StoredState,
)

log = logging.getLogger(__name__)
T = TypeVar("T")

TBOX_IRI = "http://planhrc.org/ontology/planhrc.owl#"
ABOX_IRI = "http://planhrc.org/abox#"

STATE_CLASSES = {
    "perceived": "PerceivedState",
    "expected": "ExpectedState",
    "goal": "GoalState",
    "initial": "InitialState",
}
COMPLETE_KINDS = frozenset({"perceived", "expected", "initial"})
ACTION_CLASSES = {"rotateclockwise": "RotateClockwise", "rotateanticlockwise": "RotateAntiClockwise"}

# PDDL predicate -> (OWL class, PDDL argument types, OWL property of each PDDL argument, IRI tag).
# The property order matches the TBox annotation pddlArgumentOrder (a test checks it).
PREDICATES: dict[str, tuple[str, tuple[str, ...], tuple[str, ...], str]] = {
    CONNECTED: ("Connected", ("joint", "link"), ("arg1", "arg2"), "connected"),
    HAS_ORIENTATION: ("HasOrientation", ("orientation", "joint"), ("arg2", "arg1"), "ho"),
    ORIENTATION_ORD: ("OrientationOrd", ("orientation", "orientation"), ("arg1", "arg2"), "ord"),
    AFFECTED: ("Affected", ("joint", "link", "joint"), ("arg1", "arg2", "arg3"), "affected"),
}
PREDICATE_OF_CLASS = {v[0]: k for k, v in PREDICATES.items()}

_TBOX_TERMS = (
    "ArticulatedObject Link Joint Orientation Connected HasOrientation OrientationOrd Affected LinkOrientation "
    "CondPredicate RotateClockwise RotateAntiClockwise State PerceivedState ExpectedState GoalState InitialState "
    "Problem Plan degrees lengthM chainIndex formulation objectName isVirtual hasLink hasJoint allowedOrientation "
    "nextLink arg1 arg2 arg3 forall when effNeg_a effPos_a params pre effNeg effPos condEff stepIndex paramList "
    "nextAction madeof observes stateOf aboutObject observedDegrees createdAt init goal solves expectedState "
    "plannerName position staticFactOf includesStaticFacts"
).split()

# Records and storids cached past this many entries are dropped after a commit (they are re-read on demand).
CACHE_LIMIT = 5_000

_TABLES = (
    "CREATE TABLE IF NOT EXISTS planhrc_meta (key TEXT PRIMARY KEY, value TEXT)",
    "CREATE TABLE IF NOT EXISTS planhrc_counter (name TEXT PRIMARY KEY, value INTEGER)",
)



def _short(obj: ArticulatedObject, name: str) -> str:
    """Short form of an argument inside an IRI fragment: `obj1_j3` -> `j3`, `deg_90` -> `90`."""
    if name.startswith("deg_"):
        return name[4:]
    return name[len(obj.ident) + 1:]


def atom_fragment(obj: ArticulatedObject, prefix: str, atom: Atom) -> str:
    """IRI fragment of a reified predicate: prefix + tag + arguments in OWL argument order."""
    _, _, props, tag = PREDICATES[atom[0]]
    by_prop = sorted(zip(props, atom[1:]))
    return "_".join([prefix, tag] + [_short(obj, name) for _, name in by_prop])


class _ObjectInfo:
    """An object and the lookups validation needs (names -> PDDL type, static facts)."""

    def __init__(self, obj: ArticulatedObject):
        self.obj = obj
        self.joints = obj.joints
        self.types: dict[str, str] = {}
        for name in obj.all_links:
            self.types[name] = "link"
        for name in obj.joints:
            self.types[name] = "joint"
        for name in obj.orientation_names:
            self.types[name] = "orientation"
        self.static = obj.static_atoms()
        self.static_fragment = {atom: atom_fragment(obj, obj.ident, atom) for atom in self.static}
        self.shared_stored: set[str] = set()  # object-level HasOrientation individuals known to be stored
        # every well-formed HasOrientation atom of the object, with the name of its individual
        self.orientation_atom_name: dict[Atom, str] = {
            (HAS_ORIENTATION, o, j): atom_fragment(obj, obj.ident, (HAS_ORIENTATION, o, j))
            for j in obj.joints for o in obj.orientation_names
        }
        self.orientation_atoms = frozenset(self.orientation_atom_name)


class _Batch:
    """Triples collected during a write, flushed in one go."""

    def __init__(self, kb: "Abox"):
        self.kb = kb
        self.new_iris: list[str] = []
        self.objs: list[tuple[str | int, int, str | int]] = []
        self.datas: list[tuple[str | int, int, Any]] = []
        self.shared: set[str] = set()  # object-level predicate individuals this batch creates

    def individual(self, name: str, *classes: str) -> str:
        self.new_iris.append(name)
        self.objs.append((name, RDF_TYPE, NAMED_INDIVIDUAL))
        for cls in classes:
            self.objs.append((name, RDF_TYPE, self.kb._t[cls]))
        return name

    def rel(self, s: str, prop: str, o: str | int) -> None:
        self.objs.append((s, self.kb._t[prop], o))

    def data(self, s: str, prop: str, value: Any) -> None:
        self.datas.append((s, self.kb._t[prop], value))


class Abox:
    """TBox + ABox in one owlready2 World on SQLite; every method is thread safe (one RLock)."""

    def __init__(self, path: str | None, tbox_path: Path | str):
        self._lock = threading.RLock()
        self._path = path
        self._tbox_path = Path(tbox_path)
        if not self._tbox_path.is_file():
            raise KBError(f"tbox_path: no such file {self._tbox_path}")
        self._q = QuadStore(path)
        self._closed = False
        try:
            if path:
                self._q.use_wal()
            for sql in _TABLES:
                self._q.execute(sql)
            self._journal = PlanJournal(self._q)
            self._load_tbox()
            self._c = self._q.context(ABOX_IRI)
            self._t = {term: self._q.storid(TBOX_IRI + term) for term in _TBOX_TERMS}
            self._q.commit()
        except Exception:
            self._q.world.close()
            raise
        self._depth = 0
        # /health reads these without a query: counted once at open, then kept by every commit.
        self._triples = self._q.count()
        self._n_objects = len(self._q.subjects(RDF_TYPE, self._t["ArticulatedObject"], self._c))
        self._pending = [0, 0]  # triples, objects written by the open transaction
        self._iri_sid: dict[str, int] = {}
        self._sid_name: dict[int, str] = {}
        self._objects: dict[str, _ObjectInfo] = {}
        self._states: dict[str, StoredState] = {}
        self._problems: dict[str, StoredProblem] = {}
        self._plans: dict[str, StoredPlan] = {}
        self._actions: dict[str, StoredAction] = {}
        # Plans adopted but whose triples are not written yet (see `journal`): answered from here meanwhile.
        self._held: dict[str, StoredPlan | StoredAction | StoredState] = {}
        self._unwritten: dict[str, JournalEntry] = {}  # committed, oldest first
        self._adopted: list[JournalEntry] = []  # journalled by the open transaction
        try:
            for entry in self._journal.entries():  # left by a process that stopped before writing them out
                self._hold(entry)
                self._unwritten[entry.plan_id] = entry
            if self._unwritten:
                log.info("store: writing out %d journalled plan(s) left by the last run", len(self._unwritten))
                self.settle()
        except Exception:
            self._q.world.close()
            raise
        self._writer = PlanWriter(self._write_one)

    # -- life cycle -------------------------------------------------------------------------------------
    def _load_tbox(self) -> None:
        data = self._tbox_path.read_bytes()
        digest = hashlib.sha256(data).hexdigest()
        row = self._q.execute("SELECT value FROM planhrc_meta WHERE key='tbox_sha256'").fetchone()
        if row is None or row[0] != digest:
            if row is not None:
                log.warning("TBox %s changed since this database was written: reloading it", self._tbox_path)
            self._q.load_ontology(TBOX_IRI, data, reload=row is not None)
            self._q.execute("INSERT OR REPLACE INTO planhrc_meta VALUES ('tbox_sha256', ?)", (digest,))

    @property
    def world(self) -> World:
        """The owlready2 world (read it under `lock`; reasoners work on copies), with every plan written out."""
        self.settle()
        return self._q.world

    @property
    def lock(self) -> threading.RLock:
        return self._lock

    @property
    def tbox_path(self) -> Path:
        return self._tbox_path

    def close(self) -> None:
        writer = getattr(self, "_writer", None)
        if writer is not None:
            writer.close()  # before the lock: the thread may be waiting for it
        with self._lock:
            if not self._closed:
                try:
                    self.settle()
                except Exception:  # the rows stay in the journal; the next open writes them out
                    log.exception("store: writing out journalled plans at close failed")
                self._closed = True
                self._q.close()

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- low level --------------------------------------------------------------------------------------
    def _sid(self, name: str) -> int | None:
        """Storid of an existing ABox individual, or None."""
        sid = self._iri_sid.get(name)
        if sid is None:
            sid = self._q.storid(ABOX_IRI + name, False) or None
            if sid is not None:
                self._iri_sid[name] = sid
                self._sid_name[sid] = name
        return sid

    def _names(self, sids: Iterable[int]) -> None:
        """Fill the storid -> name cache for these storids in one query."""
        missing = [s for s in set(sids) if s not in self._sid_name]
        for sid, iri in self._q.iris(missing).items():
                name = iri[len(ABOX_IRI):] if iri.startswith(ABOX_IRI) else iri
                self._sid_name[sid] = name
                self._iri_sid.setdefault(name, sid)

    def _is_a(self, sid: int, cls: str) -> bool:
        return self._q.has(sid, RDF_TYPE, self._t[cls])

    def _types(self, sid: int) -> set[int]:
        return set(self._q.objects(sid, RDF_TYPE))

    def _obj1(self, sid: int, prop: str) -> int | None:
        return self._q.object(sid, self._t[prop])

    def _ref(self, sid: int, prop: str) -> int:
        """The one object of a property every record of its kind has; a missing one is a damaged store."""
        found = self._q.object(sid, self._t[prop])
        if found is None:
            raise KBError(f"store: record {self._sid_name.get(sid, sid)} has no {prop}")
        return found

    def _objn(self, sid: int, prop: str) -> list[int]:
        return self._q.objects(sid, self._t[prop])

    def _data1(self, sid: int, prop: str) -> Any:
        return self._q.data(sid, self._t[prop])

    def _next_counter(self, name: str) -> int:
        return self._reserve_counter(name, 1)

    def _reserve_counter(self, name: str, count: int) -> int:
        """Take `count` consecutive values of a counter at once (two statements, whatever `count`); the first."""
        row = self._q.execute("SELECT value FROM planhrc_counter WHERE name=?", (name,)).fetchone()
        first = (row[0] if row else 0) + 1
        self._q.execute("INSERT OR REPLACE INTO planhrc_counter VALUES (?, ?)", (name, first + count - 1))
        return first

    def _flush(self, batch: _Batch) -> None:
        """Allocate storids for the new individuals and insert every triple (inside the open transaction)."""
        names = batch.new_iris
        if names:
            for sid, name in zip(self._q.allocate([ABOX_IRI + name for name in names]), names):
                self._iri_sid[name] = sid
                self._sid_name[sid] = name

        known = self._iri_sid

        def resolve(x: str | int) -> int:
            if isinstance(x, int):
                return x
            sid = known.get(x)
            if sid is not None:
                return sid
            sid = self._sid(x)
            if sid is None:
                raise KBError(f"internal: individual {x!r} was neither stored nor created")
            return sid

        self._q.insert_objs(self._c, [(resolve(s), p, resolve(o)) for s, p, o in batch.objs])
        self._q.insert_datas(self._c, [(resolve(s), p, value) for s, p, value in batch.datas])
        self._pending[0] += len(batch.objs) + len(batch.datas)

    def _commit(self) -> None:
        self._q.commit()
        self._triples += self._pending[0]
        self._n_objects += self._pending[1]
        self._pending = [0, 0]
        if self._adopted:
            for entry in self._adopted:
                self._unwritten[entry.plan_id] = entry
            self._adopted = []
            self._writer.poke()
        if len(self._sid_name) + len(self._states) > CACHE_LIMIT:
            self._drop_caches()  # records refill from the database on demand: memory stays flat as history grows

    def _write(self, fill: Callable[[], T]) -> T:
        """Run `fill()` (which adds triples / side-table rows) in one transaction; roll back on any error.
        Inside `transaction()` it only adds to the open transaction, which commits or rolls back as a whole."""
        if self._depth:
            return fill()
        try:
            result = fill()
            self._commit()
            return result
        except BaseException:
            self._q.rollback()
            self._forget_uncommitted()
            raise

    @contextmanager
    def transaction(self) -> Iterator[None]:
        """Every write inside the block is one transaction: all of them commit together at the end, or, when
        anything in the block raises (a refused write included), none does and the store is as before."""
        with self._lock:
            self._check_open()
            if self._depth:
                self._depth += 1
                try:
                    yield
                finally:
                    self._depth -= 1
                return
            self._depth = 1
            try:
                yield
                self._commit()
            except BaseException:
                self._q.rollback()
                self._forget_uncommitted()
                raise
            finally:
                self._depth = 0

    def _forget_uncommitted(self) -> None:
        # Storids handed out in a rolled-back transaction are invalid, and records cached during it were never
        # stored: drop every cache (they refill from the database on demand).
        self._pending = [0, 0]
        for entry in self._adopted:
            self._release(entry)
        self._adopted = []
        self._drop_caches()

    def _drop_caches(self) -> None:
        self._iri_sid.clear()
        self._sid_name.clear()
        self._objects.clear()
        self._states.clear()
        self._problems.clear()
        self._plans.clear()
        self._actions.clear()

    def _check_open(self) -> None:
        if self._closed:
            raise KBError("knowledge base: closed")

    # -- objects ----------------------------------------------------------------------------------------
    def new_object_id(self) -> str:
        """A fresh object id `objN`; N is never handed out twice, even across restarts."""
        with self._lock:
            self._check_open()

            def fill() -> str:
                while True:
                    ident = f"obj{self._next_counter('object')}"
                    if self._sid(ident) is None:
                        return ident

            return self._write(fill)

    def create_object(self, obj: ArticulatedObject) -> None:
        with self._lock:
            self._check_open()
            if not isinstance(obj, ArticulatedObject):
                raise ValidationError(f"object: expected an ArticulatedObject, got {type(obj).__name__}")
            clashes = [n for n in (obj.ident,) + obj.all_links + obj.joints if self._sid(n) is not None]
            if clashes:
                raise ConflictError(f"object.ident: {obj.ident!r} already exists (IRI {ABOX_IRI}{clashes[0]})")
            info = _ObjectInfo(obj)

            def fill() -> None:
                b = _Batch(self)
                o = b.individual(obj.ident, "ArticulatedObject")
                b.data(o, "formulation", obj.formulation.value)
                b.data(o, "objectName", obj.name)
                b.data(o, "createdAt", time.time())
                previous = None
                for k, link in enumerate(obj.all_links):
                    index = int(link.rsplit("_l", 1)[1])
                    b.individual(link, "Link")
                    b.data(link, "chainIndex", index)
                    if index == 0:
                        b.data(link, "isVirtual", True)
                    else:
                        b.data(link, "lengthM", float(obj.link_lengths_m[index - 1]))
                        b.data(link, "isVirtual", False)
                    b.rel(o, "hasLink", link)
                    if previous is not None:
                        b.rel(previous, "nextLink", link)
                    previous = link
                for k in obj.joint_indices:
                    joint = obj.joint(k)
                    b.individual(joint, "Joint")
                    b.data(joint, "chainIndex", k)
                    b.rel(o, "hasJoint", joint)
                for deg, name in zip(obj.orientation_degrees, obj.orientation_names):
                    sid = self._sid(name)
                    if sid is None or not self._is_a(sid, "Orientation"):
                        b.individual(name, "Orientation")
                        b.data(name, "degrees", deg)
                    b.rel(o, "allowedOrientation", name)
                for atom in sorted(info.static):
                    name = self._add_predicate(b, info, info.static_fragment[atom], atom)
                    b.rel(name, "staticFactOf", obj.ident)
                self._flush(b)
                self._pending[1] += 1

            self._write(fill)
            self._objects[obj.ident] = info

    def _shared_predicate(self, b: _Batch, info: _ObjectInfo, atom: Atom) -> str:
        """The object's individual for a HasOrientation atom, created in this batch on first use."""
        name = info.orientation_atom_name[atom]
        if name in info.shared_stored or name in b.shared:
            return name
        if self._sid(name) is not None:
            info.shared_stored.add(name)
            return name
        b.shared.add(name)
        return self._add_predicate(b, info, name, atom)

    def _add_predicate(self, b: _Batch, info: _ObjectInfo, name: str, atom: Atom) -> str:
        cls, _, props, _ = PREDICATES[atom[0]]
        b.individual(name, cls)
        for prop, arg in zip(props, atom[1:]):
            b.rel(name, prop, arg)
        return name

    def _info(self, object_id: str, field: str | None = None) -> _ObjectInfo:
        """The object's info; unknown -> ValidationError naming `field` (writes) or NotFoundError (reads)."""
        info = self._objects.get(object_id) if isinstance(object_id, str) else None
        if info is None and isinstance(object_id, str):
            obj = self._load_object(object_id)
            if obj is not None:
                info = self._objects[object_id] = _ObjectInfo(obj)
        if info is None:
            if field is None:
                raise NotFoundError(f"object_id: no object {object_id!r}")
            raise ValidationError(f"{field}: no object {object_id!r}")
        return info

    def _load_object(self, ident: str) -> ArticulatedObject | None:
        sid = self._sid(ident)
        if sid is None or not self._is_a(sid, "ArticulatedObject"):
            return None
        links = self._objn(sid, "hasLink")
        lengths: dict[int, float] = {}
        for link in links:
            if self._data1(link, "isVirtual"):
                continue
            lengths[int(self._data1(link, "chainIndex"))] = float(self._data1(link, "lengthM"))
        n_orient = len(self._objn(sid, "allowedOrientation"))
        return ArticulatedObject(
            ident=ident,
            formulation=Formulation(self._data1(sid, "formulation")),
            link_lengths_m=tuple(lengths[k] for k in sorted(lengths)),
            orientations=n_orient,
            name=self._data1(sid, "objectName") or "",
        )

    def get_object(self, object_id: str) -> ArticulatedObject:
        with self._lock:
            self._check_open()
            return self._info(object_id).obj

    def list_objects(self) -> tuple[ArticulatedObject, ...]:
        with self._lock:
            self._check_open()
            sids = self._q.subjects(RDF_TYPE, self._t["ArticulatedObject"], self._c)
            self._names(sids)
            idents = sorted((self._sid_name[s] for s in sids), key=natural_key)
            return tuple(self._info(i).obj for i in idents)

    # -- validation helpers -----------------------------------------------------------------------------
    def _check_atom(self, info: _ObjectInfo, atom: Any, field: str) -> Atom:
        if not isinstance(atom, tuple) or not atom or not all(isinstance(x, str) for x in atom):
            raise ValidationError(f"{field}: an atom is a tuple of names, got {atom!r}")
        spec = PREDICATES.get(atom[0])
        if spec is None:
            raise ValidationError(f"{field}: atom {format_atom(atom)}: unknown predicate {atom[0]!r}")
        _, types, _, _ = spec
        if len(atom) - 1 != len(types):
            raise ValidationError(
                f"{field}: atom {format_atom(atom)}: {atom[0]} takes {len(types)} arguments, got {len(atom) - 1}"
            )
        for i, (arg, typ) in enumerate(zip(atom[1:], types), start=1):
            got = info.types.get(arg)
            if got is None:
                raise ValidationError(
                    f"{field}: atom {format_atom(atom)}: argument {i} {arg!r} is no {typ} of object {info.obj.ident!r}"
                )
            if got != typ:
                raise ValidationError(
                    f"{field}: atom {format_atom(atom)}: argument {i} {arg!r} is a {got}, expected a {typ}"
                )
        return atom

    def _check_state_atoms(self, info: _ObjectInfo, kind: str, atoms: Any, field: str) -> dict[str, Atom]:
        """Validate a state's atoms; returns joint -> its hasorientation atom."""
        if not isinstance(atoms, (set, frozenset)):
            raise ValidationError(f"{field}: expected a frozenset of atoms, got {type(atoms).__name__}")
        if not atoms:
            raise ValidationError(f"{field}: a state needs at least one atom")
        static = info.static
        # The common case in a few set operations: every atom is a static fact or a well-formed hasorientation
        # atom of the object, one per joint (a complete state: every joint). Anything else takes the path below,
        # which finds the first error in a fixed order.
        rest_set = frozenset(atoms) - static
        if rest_set <= info.orientation_atoms:
            by_joint = {atom[2]: atom for atom in rest_set}
            if len(by_joint) == len(rest_set) and (kind not in COMPLETE_KINDS or len(by_joint) == len(info.joints)):
                return by_joint
        by_joint = {}
        # Static facts of the object are valid by construction; only the rest needs checking. Sorting the rest
        # makes the first error reported the same on every run.
        well_formed = info.orientation_atom_name
        rest = [atom for atom in atoms if atom not in static]
        try:
            rest.sort()
        except TypeError:
            rest.sort(key=repr)
        for atom in rest:
            if atom not in well_formed:
                self._check_atom(info, atom, field)
            if atom[0] == HAS_ORIENTATION:
                joint = atom[2]
                if joint in by_joint:
                    raise ValidationError(
                        f"{field}: two orientations for joint {joint!r} in one state: "
                        f"{format_atom(by_joint[joint])} and {format_atom(atom)}"
                    )
                by_joint[joint] = atom
            elif atom not in info.static:
                raise ValidationError(f"{field}: atom {format_atom(atom)} is not a fact of object {info.obj.ident!r}")
        if kind in COMPLETE_KINDS:
            missing = [j for j in info.joints if j not in by_joint]
            if missing:
                raise ValidationError(
                    f"{field}: a {kind} state is complete but has no orientation for joint(s) {', '.join(missing)}"
                )
        return by_joint

    def _check_observation(
        self, info: _ObjectInfo, kind: str, by_joint: dict[str, Atom], values: Any
    ) -> Perception | None:
        if values is None:
            return None
        obj = info.obj
        field = "link_orientations_deg"
        if kind != "perceived":
            raise ValidationError(f"{field}: only perceived states carry observed link orientations, not {kind!r}")
        try:
            perception = perceive(obj, values, field)
        except ModelError as exc:
            raise ValidationError(str(exc)) from None
        for k, deg in zip(obj.joint_indices, perception.joint_values):
            atom = by_joint.get(obj.joint(k))
            if atom is not None and atom[1] != orientation_name(deg):
                raise ValidationError(
                    f"{field}: the observation gives {orientation_name(deg)} for joint {obj.joint(k)}, "
                    f"but atoms say {format_atom(atom)}"
                )
        return perception

    # -- states -----------------------------------------------------------------------------------------
    def _add_state_triples(
        self, b: _Batch, info: _ObjectInfo, kind: str, atoms: frozenset[Atom],
        observation: Perception | None, step: int | None, created_at: float,
        state_id: str | None = None, order: _StateOrder | None = None,
    ) -> str:
        obj = info.obj
        state_id = state_id or f"{obj.ident}_state_{self._next_counter(obj.ident + ':state')}"
        s = b.individual(state_id, STATE_CLASSES[kind])
        b.rel(s, "stateOf", obj.ident)
        b.data(s, "createdAt", created_at)
        if step is not None:
            b.data(s, "stepIndex", step)
        compact, linked = order or _state_order(info, atoms)
        if compact:
            b.data(s, "includesStaticFacts", True)
        for atom in linked:
            if atom[0] == HAS_ORIENTATION:
                pred = self._shared_predicate(b, info, atom)
            else:
                pred = info.static_fragment[atom]
            b.rel(s, "madeof", pred)
        if observation is not None:
            for k, (value, deg) in enumerate(zip(observation.raw_deg, observation.snapped_deg), start=1):
                p = b.individual(f"{state_id}_lo_l{k}", "LinkOrientation")
                b.rel(p, "arg1", obj.link(k))
                b.rel(p, "arg2", orientation_name(deg))
                b.data(p, "observedDegrees", value)
                b.rel(s, "observes", p)
        return state_id

    def add_state(
        self,
        object_id: str,
        kind: str,
        atoms: frozenset[Atom],
        link_orientations_deg: Sequence[float] | None = None,
    ) -> StoredState:
        with self._lock:
            self._check_open()
            info = self._info(object_id, "object_id")
            if kind not in STATE_KINDS:
                raise ValidationError(f"kind: must be one of {', '.join(STATE_KINDS)}, got {kind!r}")
            by_joint = self._check_state_atoms(info, kind, atoms, "atoms")
            observation = self._check_observation(info, kind, by_joint, link_orientations_deg)
            atoms = frozenset(atoms)
            created = time.time()

            def fill() -> str:
                b = _Batch(self)
                state_id = self._add_state_triples(b, info, kind, atoms, observation, None, created)
                self._flush(b)
                return state_id

            state_id = self._write(fill)
            record = StoredState(
                id=state_id, object_id=info.obj.ident, kind=kind, atoms=atoms, created_at=created,
                link_orientations_deg=observation.raw_deg if observation else None,
            )
            self._states[state_id] = record
            return record

    def add_perception(self, perception: Perception) -> StoredState:
        """Store a perceived state from a perception validated and snapped where it entered (`model.perceive`)."""
        with self._lock:
            self._check_open()
            if not isinstance(perception, Perception):
                raise ValidationError(f"perception: expected a Perception, got {type(perception).__name__}")
            info = self._info(perception.object_id, "perception.object_id")
            if len(perception.snapped_deg) != info.obj.n_links or len(perception.raw_deg) != info.obj.n_links:
                raise ValidationError(f"perception: expected {info.obj.n_links} link orientations")
            created = time.time()

            def fill() -> str:
                b = _Batch(self)
                state_id = self._add_state_triples(b, info, "perceived", perception.atoms, perception, None, created)
                self._flush(b)
                return state_id

            state_id = self._write(fill)
            record = StoredState(id=state_id, object_id=info.obj.ident, kind="perceived", atoms=perception.atoms,
                                 created_at=created, link_orientations_deg=perception.raw_deg)
            self._states[state_id] = record
            return record

    def _predicate_atoms(self, pred_sids: Sequence[int]) -> dict[int, Atom]:
        """Atoms of reified predicate individuals, read with a few queries."""
        out: dict[int, Atom] = {}
        if not pred_sids:
            return out
        class_of = {self._t[cls]: pddl for cls, pddl in PREDICATE_OF_CLASS.items()}
        props = {self._t["arg1"]: "arg1", self._t["arg2"]: "arg2", self._t["arg3"]: "arg3"}
        kinds: dict[int, str] = {}
        args: dict[int, dict[str, int]] = {}
        sids = list(dict.fromkeys(pred_sids))
        for s, p, o in self._q.triples_of(sids, [RDF_TYPE, *props]):
            if p == RDF_TYPE:
                if o in class_of:
                    kinds[s] = class_of[o]
            else:
                args.setdefault(s, {})[props[p]] = o
        self._names(o for d in args.values() for o in d.values())
        for s in sids:
            pddl = kinds.get(s)
            if pddl is None:
                raise KBError(f"internal: predicate individual {s} has no predicate class")
            _, _, order, _ = PREDICATES[pddl]
            out[s] = (pddl,) + tuple(self._sid_name[args[s][prop]] for prop in order)
        return out

    def _load_state(self, state_id: str) -> StoredState | None:
        sid = self._sid(state_id)
        if sid is None:
            return None
        types = self._types(sid)
        kind = next((k for k, cls in STATE_CLASSES.items() if self._t[cls] in types), None)
        if kind is None:
            return None
        obj_sid = self._ref(sid, "stateOf")
        self._names([obj_sid])
        atoms = frozenset(self._predicate_atoms(self._objn(sid, "madeof")).values())
        if self._data1(sid, "includesStaticFacts"):
            atoms |= self._info(self._sid_name[obj_sid]).static
        observed = None
        lo = self._objn(sid, "observes")
        if lo:
            values: dict[int, float] = {}
            for p in lo:
                link = self._ref(p, "arg1")
                values[int(self._data1(link, "chainIndex"))] = float(self._data1(p, "observedDegrees"))
            observed = tuple(values[k] for k in sorted(values))
        return StoredState(
            id=state_id, object_id=self._sid_name[obj_sid], kind=kind, atoms=atoms,
            created_at=float(self._data1(sid, "createdAt")), link_orientations_deg=observed,
        )

    def get_state(self, state_id: str) -> StoredState:
        with self._lock:
            self._check_open()
            record = self._states.get(state_id) or _held(self._held, state_id, StoredState)
            if record is None:
                record = self._load_state(state_id) if isinstance(state_id, str) else None
                if record is None:
                    raise NotFoundError(f"state_id: no state {state_id!r}")
                self._states[state_id] = record
            return record

    # -- problems ---------------------------------------------------------------------------------------
    def add_problem(self, object_id: str, init_state_id: str, goal_state_id: str) -> StoredProblem:
        with self._lock:
            self._check_open()
            info = self._info(object_id, "object_id")
            states = {}
            for field, sid in (("init_state_id", init_state_id), ("goal_state_id", goal_state_id)):
                try:
                    st = self.get_state(sid)
                except NotFoundError:
                    raise ValidationError(f"{field}: no state {sid!r}") from None
                if st.object_id != info.obj.ident:
                    raise ValidationError(f"{field}: state {sid!r} belongs to object {st.object_id!r}")
                states[field] = st
            if states["init_state_id"].kind not in COMPLETE_KINDS:
                raise ValidationError(
                    f"init_state_id: the initial state must be complete (perceived, initial or expected), "
                    f"{init_state_id!r} is a {states['init_state_id'].kind} state"
                )
            created = time.time()

            def fill() -> str:
                b = _Batch(self)
                pid = f"{info.obj.ident}_problem_{self._next_counter(info.obj.ident + ':problem')}"
                b.individual(pid, "Problem")
                b.rel(pid, "aboutObject", info.obj.ident)
                b.rel(pid, "init", init_state_id)
                b.rel(pid, "goal", goal_state_id)
                b.data(pid, "createdAt", created)
                self._flush(b)
                return pid

            pid = self._write(fill)
            record = StoredProblem(pid, info.obj.ident, init_state_id, goal_state_id, created)
            self._problems[pid] = record
            return record

    def _load_problem(self, problem_id: str) -> StoredProblem | None:
        sid = self._sid(problem_id)
        if sid is None or not self._is_a(sid, "Problem"):
            return None
        refs = [self._ref(sid, p) for p in ("aboutObject", "init", "goal")]
        self._names(refs)
        o, i, g = (self._sid_name[r] for r in refs)
        return StoredProblem(problem_id, o, i, g, float(self._data1(sid, "createdAt")))

    def get_problem(self, problem_id: str) -> StoredProblem:
        with self._lock:
            self._check_open()
            record = self._problems.get(problem_id)
            if record is None:
                record = self._load_problem(problem_id) if isinstance(problem_id, str) else None
                if record is None:
                    raise NotFoundError(f"problem_id: no problem {problem_id!r}")
                self._problems[problem_id] = record
            return record

    def _latest_by_counter(self, object_id: str, kind: str) -> str | None:
        """The newest `<object>_<kind>_<n>`: n is the object's counter (one row read, whatever the history)."""
        ident = self._info(object_id).obj.ident
        row = self._q.execute("SELECT value FROM planhrc_counter WHERE name=?", (f"{ident}:{kind}",)).fetchone()
        return f"{ident}_{kind}_{row[0]}" if row and row[0] else None

    def latest_problem(self, object_id: str) -> StoredProblem | None:
        with self._lock:
            self._check_open()
            pid = self._latest_by_counter(object_id, "problem")
            return self.get_problem(pid) if pid else None

    # -- plans ------------------------------------------------------------------------------------------
    def _check_action(self, info: _ObjectInfo, i: int, spec: Any) -> None:
        field = f"actions[{i}]"
        if not isinstance(spec, ActionSpec):
            raise ValidationError(f"{field}: expected an ActionSpec, got {type(spec).__name__}")
        if spec.name not in ACTION_CLASSES:
            raise ValidationError(f"{field}.name: must be one of {', '.join(ACTION_CLASSES)}, got {spec.name!r}")
        if not isinstance(spec.params, tuple) or not spec.params:
            raise ValidationError(f"{field}.params: expected a non-empty tuple of names")
        for k, p in enumerate(spec.params):
            if not isinstance(p, str) or p not in info.types:
                raise ValidationError(f"{field}.params[{k}]: {p!r} is no link, joint or orientation of object "
                                      f"{info.obj.ident!r}")
        for part in ("pre", "eff_neg", "eff_pos"):
            atoms = getattr(spec, part)
            if not isinstance(atoms, (set, frozenset)):
                raise ValidationError(f"{field}.{part}: expected a frozenset of atoms")
            self._check_atoms(info, atoms, f"{field}.{part}")
        if not isinstance(spec.cond_eff, tuple):
            raise ValidationError(f"{field}.cond_eff: expected a tuple of CondEffect")
        for c, ce in enumerate(spec.cond_eff):
            if not isinstance(ce, CondEffect):
                raise ValidationError(f"{field}.cond_eff[{c}]: expected a CondEffect, got {type(ce).__name__}")
            for part in ("when", "eff_neg", "eff_pos"):
                atoms = getattr(ce, part)
                if not isinstance(atoms, (set, frozenset)):
                    raise ValidationError(f"{field}.cond_eff[{c}].{part}: expected a frozenset of atoms")
                self._check_atoms(info, atoms, f"{field}.cond_eff[{c}].{part}")

    def _check_atoms(self, info: _ObjectInfo, atoms: set[Any] | frozenset[Any], field: str) -> None:
        """`_check_atom` on each atom that is not one of the object's known facts (its static facts and its
        well-formed hasorientation atoms, valid by construction), in a fixed order (the first error is the same
        on every run)."""
        rest = [a for a in atoms if a not in info.static and a not in info.orientation_atom_name]
        for atom in sorted(rest, key=repr):
            self._check_atom(info, atom, field)

    def check_plan(self, object_id: str, actions: Sequence[ActionSpec],
                   expected_states: Sequence[frozenset[Atom]], deadline_at: float | None = None) -> CheckedPlan:
        """Validate a plan of an object (its writing order is worked out later, by the store's writer): the part
        of `add_plan` that needs neither the database nor the store's lock, so a caller can do it while something else runs (the
        service: while VAL checks the plan). Hand the result to `add_plan(..., checked=...)` with the same
        `actions` and `expected_states` objects. Past `deadline_at` (`time.monotonic()`) a DeadlineError is
        raised: a caller's request deadline bounds the check of a huge plan too."""
        with self._lock:  # only to look the object up
            self._check_open()
            info = self._info(object_id, "object_id")
        return _check_plan(self, info, tuple(actions), tuple(expected_states), deadline_at)

    def add_plan(
        self,
        problem_id: str,
        planner: str,
        actions: Sequence[ActionSpec],
        expected_states: Sequence[frozenset[Atom]],
        checked: CheckedPlan | None = None,
    ) -> StoredPlan:
        with self._lock:
            self._check_open()
            try:
                problem = self.get_problem(problem_id)
            except NotFoundError:
                raise ValidationError(f"problem_id: no problem {problem_id!r}") from None
            info = self._info(problem.object_id, "problem_id")
            if not isinstance(planner, str) or not planner:
                raise ValidationError("planner: must be a non-empty string")
            actions = tuple(actions)
            expected_states = tuple(expected_states)
            if (checked is None or checked.object_id != info.obj.ident or checked.actions is not actions
                    or checked.expected_states is not expected_states):
                checked = _check_plan(self, info, actions, expected_states)
            created = time.time()
            ident = info.obj.ident

            def fill() -> JournalEntry:
                plan_id = f"{ident}_plan_{self._next_counter(ident + ':plan')}"
                first_state = self._reserve_counter(ident + ":state", len(expected_states))
                entry = JournalEntry(plan_id, ident, problem_id, planner, created, first_state, actions,
                                     expected_states)
                self._journal.append(entry)  # the triples follow (`_write_one`); the row is the plan meanwhile
                self._adopted.append(entry)
                return entry

            return self._hold(self._write(fill))

    def _hold(self, entry: JournalEntry) -> StoredPlan:
        """Answer for a journalled plan from memory until its triples are written."""
        ident = entry.object_id
        actions = tuple(StoredAction(f"{entry.plan_id}_a{step}", step, spec)
                        for step, spec in enumerate(entry.actions, start=1))
        state_ids = tuple(f"{ident}_state_{entry.first_state + i}" for i in range(len(entry.expected_states)))
        for sid, atoms in zip(state_ids, entry.expected_states):
            self._held[sid] = StoredState(sid, ident, "expected", frozenset(atoms), entry.created_at)
        for a in actions:
            self._held[a.id] = a
        record = StoredPlan(entry.plan_id, ident, entry.problem_id, entry.planner, actions, state_ids,
                            entry.created_at)
        self._held[entry.plan_id] = record
        return record

    def _release(self, entry: JournalEntry) -> list[StoredPlan | StoredAction | StoredState]:
        """Stop answering for a plan from memory (its triples are written, or its transaction rolled back)."""
        plan = self._held.pop(entry.plan_id, None)
        if not isinstance(plan, StoredPlan):  # never held: its transaction failed before `_hold`
            return []
        ids = [*(a.id for a in plan.actions), *plan.expected_state_ids]  # the names `_hold` gave them
        return [plan, *(r for r in (self._held.pop(i, None) for i in ids) if r is not None)]

    def settle(self) -> None:
        """Write out every journalled plan's triples now (readers of the triples themselves call this first).
        Inside an open transaction it does nothing: the plans it adopted are written after it commits."""
        with self._lock:
            if self._depth:
                return
            while self._unwritten:
                self._materialise(next(iter(self._unwritten.values())))

    def _write_one(self) -> bool:
        """The writer thread's step: write out the oldest journalled plan; whether more are left."""
        with self._lock:
            if self._closed or self._depth or not self._unwritten:
                return False
            self._materialise(next(iter(self._unwritten.values())))
            return bool(self._unwritten)

    def _materialise(self, entry: JournalEntry) -> None:
        """A journalled plan's triples, and its journal row deleted, in one transaction. The plan was checked
        when it was adopted (`add_plan`); here its atoms are only put in writing order."""
        info = self._info(entry.object_id)
        action_orders = [_action_order(spec) for spec in entry.actions]
        state_orders = [_state_order(info, frozenset(atoms)) for atoms in entry.expected_states]
        plan_id, created = entry.plan_id, entry.created_at

        def fill() -> None:
            b = _Batch(self)
            b.individual(plan_id, "Plan")
            b.rel(plan_id, "aboutObject", entry.object_id)
            b.rel(plan_id, "solves", entry.problem_id)
            b.data(plan_id, "plannerName", entry.planner)
            b.data(plan_id, "createdAt", created)
            previous = None
            for step, (spec, order) in enumerate(zip(entry.actions, action_orders), start=1):
                aid = f"{plan_id}_a{step}"
                self._add_action_triples(b, info, aid, step, spec, order)
                b.rel(plan_id, "madeof", aid)
                if previous:
                    b.rel(previous, "nextAction", aid)
                previous = aid
            for step, (atoms, state_order) in enumerate(zip(entry.expected_states, state_orders), start=1):
                sid = self._add_state_triples(b, info, "expected", atoms, None, step, created,
                                              f"{entry.object_id}_state_{entry.first_state + step - 1}", state_order)
                b.rel(plan_id, "expectedState", sid)
            self._flush(b)
            self._journal.remove(plan_id)

        self._write(fill)
        del self._unwritten[plan_id]
        for record in self._release(entry):  # now cached like any record read back
            if isinstance(record, StoredPlan):
                self._plans[record.id] = record
            elif isinstance(record, StoredAction):
                self._actions[record.id] = record
            else:
                self._states[record.id] = record

    def _add_action_triples(self, b: _Batch, info: _ObjectInfo, aid: str, step: int, spec: ActionSpec,
                            order: _ActionOrder | None = None) -> None:
        b.individual(aid, ACTION_CLASSES[spec.name])
        b.data(aid, "stepIndex", step)
        b.data(aid, "paramList", " ".join(spec.params))
        b.rel(aid, "aboutObject", info.obj.ident)
        for p in dict.fromkeys(spec.params):
            b.rel(aid, "params", p)
        made: dict[Atom, str] = {}

        def pred(atom: Atom) -> str:
            name = info.static_fragment.get(atom) or made.get(atom)
            if name is None and atom[0] == HAS_ORIENTATION:
                name = made[atom] = self._shared_predicate(b, info, atom)
            if name is None:
                name = made[atom] = self._add_predicate(b, info, atom_fragment(info.obj, aid, atom), atom)
            return name

        parts, conds = order or _action_order(spec)
        for atoms, prop in zip(parts, ("pre", "effNeg", "effPos")):
            for atom in atoms:
                b.rel(aid, prop, pred(atom))
        for c, (quantified, ce_parts) in enumerate(conds, start=1):
            cid = b.individual(f"{aid}_ce{c}", "CondPredicate")
            b.data(cid, "position", c)
            b.rel(aid, "condEff", cid)
            for name in quantified:
                b.rel(cid, "forall", name)
            for atoms, prop in zip(ce_parts, ("when", "effNeg_a", "effPos_a")):
                for atom in atoms:
                    b.rel(cid, prop, pred(atom))

    def _load_action(self, action_id: str) -> StoredAction | None:
        sid = self._sid(action_id)
        if sid is None:
            return None
        types = self._types(sid)
        name = next((n for n, cls in ACTION_CLASSES.items() if self._t[cls] in types), None)
        if name is None:
            return None
        parts: dict[str, list[int]] = {p: self._objn(sid, p) for p in ("pre", "effNeg", "effPos")}
        ces = sorted(self._objn(sid, "condEff"), key=lambda c: int(self._data1(c, "position")))
        ce_parts = [{p: self._objn(c, p) for p in ("when", "effNeg_a", "effPos_a")} for c in ces]
        every = [s for lst in parts.values() for s in lst] + [s for d in ce_parts for lst in d.values() for s in lst]
        atoms = self._predicate_atoms(every)

        def fs(sids: list[int]) -> frozenset[Atom]:
            return frozenset(atoms[s] for s in sids)

        spec = ActionSpec(
            name=name,
            params=tuple((self._data1(sid, "paramList") or "").split()),
            pre=fs(parts["pre"]), eff_neg=fs(parts["effNeg"]), eff_pos=fs(parts["effPos"]),
            cond_eff=tuple(CondEffect(fs(d["when"]), fs(d["effNeg_a"]), fs(d["effPos_a"])) for d in ce_parts),
        )
        return StoredAction(action_id, int(self._data1(sid, "stepIndex")), spec)

    def get_action(self, action_id: str) -> StoredAction:
        with self._lock:
            self._check_open()
            record = self._actions.get(action_id) or _held(self._held, action_id, StoredAction)
            if record is None:
                record = self._load_action(action_id) if isinstance(action_id, str) else None
                if record is None:
                    raise NotFoundError(f"action_id: no action {action_id!r}")
                self._actions[action_id] = record
            return record

    def _load_plan(self, plan_id: str) -> StoredPlan | None:
        sid = self._sid(plan_id)
        if sid is None or not self._is_a(sid, "Plan"):
            return None
        refs = [self._ref(sid, "aboutObject"), self._ref(sid, "solves")]
        action_sids = self._objn(sid, "madeof")
        state_sids = self._objn(sid, "expectedState")
        self._names(refs + action_sids + state_sids)
        actions = sorted((self.get_action(self._sid_name[a]) for a in action_sids), key=lambda a: a.step)
        states = sorted(state_sids, key=lambda s: int(self._data1(s, "stepIndex")))
        return StoredPlan(
            id=plan_id, object_id=self._sid_name[refs[0]], problem_id=self._sid_name[refs[1]],
            planner=self._data1(sid, "plannerName"), actions=tuple(actions),
            expected_state_ids=tuple(self._sid_name[s] for s in states),
            created_at=float(self._data1(sid, "createdAt")),
        )

    def get_plan(self, plan_id: str) -> StoredPlan:
        with self._lock:
            self._check_open()
            record = self._plans.get(plan_id) or _held(self._held, plan_id, StoredPlan)
            if record is None:
                record = self._load_plan(plan_id) if isinstance(plan_id, str) else None
                if record is None:
                    raise NotFoundError(f"plan_id: no plan {plan_id!r}")
                self._plans[plan_id] = record
            return record

    def latest_plan(self, object_id: str) -> StoredPlan | None:
        with self._lock:
            self._check_open()
            pid = self._latest_by_counter(object_id, "plan")
            return self.get_plan(pid) if pid else None

    def triple_count(self) -> int:
        """Triples stored (kept by every commit: no scan, no lock)."""
        self._check_open()
        return self._triples

    def plans_to_write(self) -> int:
        """Committed plans whose triples are not written yet (no lock)."""
        self._check_open()
        return len(self._unwritten)

    def object_count(self) -> int:
        """Objects stored (kept by every commit: no scan, no lock)."""
        self._check_open()
        return self._n_objects


def _held(held: dict[str, Any], ident: Any, cls: type[T]) -> T | None:
    record = held.get(ident) if isinstance(ident, str) else None
    return record if isinstance(record, cls) else None


# Writing order of a state: (lists only its non-static atoms?, the atoms it links with madeof, sorted).
_StateOrder = tuple[bool, tuple[Atom, ...]]
# Writing order of an action: its pre, eff-, eff+ sorted, and per conditional effect (forall names, (when, eff-,
# eff+) sorted).
_ActionOrder = tuple[tuple[tuple[Atom, ...], ...],
                     tuple[tuple[tuple[str, ...], tuple[tuple[Atom, ...], ...]], ...]]


def _state_order(info: _ObjectInfo, atoms: frozenset[Atom]) -> _StateOrder:
    # A state with all of its object's static facts lists only the rest: the static facts are linked to the
    # object once (staticFactOf) and the TBox's SWRL rule derives the state's madeof links to them.
    compact = info.static <= atoms
    return compact, tuple(sorted(a for a in atoms if a[0] == HAS_ORIENTATION or not compact))


def _action_order(spec: ActionSpec) -> _ActionOrder:
    parts = tuple(tuple(sorted(getattr(spec, part))) for part in ("pre", "eff_neg", "eff_pos"))
    params = set(spec.params)
    conds = tuple((tuple(sorted({a for atom in ce.eff_neg | ce.eff_pos for a in atom[1:]} - params)),
                   tuple(tuple(sorted(getattr(ce, part))) for part in ("when", "eff_neg", "eff_pos")))
                  for ce in spec.cond_eff)
    return parts, conds


@dataclass(frozen=True)
class CheckedPlan:
    """A plan's actions and expected states, validated against their object (`Abox.check_plan`). Their writing
    order is worked out when the triples are written (`Abox._materialise`), off the answer's path."""

    object_id: str
    actions: tuple[ActionSpec, ...]
    expected_states: tuple[frozenset[Atom], ...]


def _check_plan(abox: Abox, info: _ObjectInfo, actions: tuple[ActionSpec, ...],
                expected_states: tuple[frozenset[Atom], ...], deadline_at: float | None = None) -> CheckedPlan:
    """Every check `add_plan` makes on the actions and states (pure: reads only `info`), stopped with a
    DeadlineError once `deadline_at` has passed."""
    if len(expected_states) != len(actions) + 1:
        raise ValidationError(
            f"expected_states: a plan of {len(actions)} actions needs {len(actions) + 1} expected states "
            f"(s^e_1 .. s^e_N+1), got {len(expected_states)}"
        )
    for i, spec in enumerate(actions):
        abox._check_action(info, i, spec)
    for i, atoms in enumerate(expected_states):
        if deadline_at is not None and time.monotonic() > deadline_at:
            raise DeadlineError(f"planning: the deadline passed while the store checked expected state {i + 1} of "
                                f"{len(expected_states)}")
        abox._check_state_atoms(info, "expected", atoms, f"expected_states[{i}]")
    return CheckedPlan(info.obj.ident, actions, expected_states)

"""Records read back from the PostgreSQL ABox's rows, through one cache per kind (`cache.RecordCache`): the
store's identity map, as `reads.Records` is the SQLite store's (a `unit.RecordsOfWrites` and a
`TransactionListener` of its `Session`).

A record is read with a query or two per kind of individual it is made of (the record, its predicate individuals,
its observations), whatever its size. A plan whose triples are not written yet (`journal`) is read from its journal
row, which is looked up first: a row turns into triples in one transaction, so one or the other is found. A predicate individual that belongs to its object (a static fact, an
orientation of a joint) is known by its name (`names.atom_fragment`, the names every write gives them); an action's
own predicates are read. Every method is called with the store's lock held.
"""
from __future__ import annotations

from typing import Any, Sequence

from planhrc.model import ArticulatedObject, Atom, Formulation, natural_key

from ..cache import RecordCache, object_info
from ..checks import ObjectInfo
from ..errors import DamagedStoreError
from ..journal import JournalEntry, decode
from ..names import ABOX_IRI, ACTION_CLASSES, PREDICATE_OF_CLASS, PREDICATES, STATE_CLASSES, TBOX_IRI
from ..records import ActionSpec, CondEffect, StoredAction, StoredPlan, StoredProblem, StoredState
from .rows import Individual, individuals
from .schema import RDF_TYPE
from .session import Session

# Records cached past this many are dropped after a commit (read again on demand): the memory stays flat.
CACHE_LIMIT = 5_000
_ACTION_PARTS = ("pre", "effNeg", "effPos")
_COND_PARTS = ("when", "effNeg_a", "effPos_a")


class PgRecords:
    """The records of one PostgreSQL ABox, cached."""

    def __init__(self, session: Session) -> None:
        self.session = session
        self.objects: dict[str, ObjectInfo] = {}
        self._atom_of: dict[str, dict[str, Atom]] = {}  # object id -> name of its own predicate -> atom
        # a journalled plan's records are read from its row, in any process
        self.states = RecordCache("state", StoredState, self._load_state)
        self.problems = RecordCache("problem", StoredProblem, self._load_problem)
        self.plans = RecordCache("plan", StoredPlan, self._load_plan)
        self.actions = RecordCache("action", StoredAction, self._load_action)

    def clear(self) -> None:
        self.objects.clear()
        self._atom_of.clear()
        for cache in (self.states, self.problems, self.plans, self.actions):
            cache.clear()

    def committed(self) -> None:
        if len(self.states) + len(self.actions) > CACHE_LIMIT:
            self.clear()

    def rolled_back(self) -> None:
        self.clear()  # records cached during a rolled-back transaction were never stored

    def put_entry(self, entry: JournalEntry) -> StoredPlan:
        """Cache a journalled plan's records (its actions and expected states); the plan's."""
        return entry.cache(self.plans, self.actions, self.states)

    def _journalled(self, sql: str, params: tuple[Any, ...]) -> JournalEntry | None:
        row = self.session.execute("SELECT payload FROM planhrc_plan_journal WHERE " + sql, params).fetchone()
        if row is None:
            return None
        entry = decode(bytes(row[0]))
        self.put_entry(entry)
        return entry

    # -- rows ---------------------------------------------------------------------------------------------
    def describe(self, names: Sequence[str]) -> dict[str, Individual]:
        """The individuals `names` (those stored), each with every row it is the subject of."""
        if not names:
            return {}
        rows = self.session.execute("SELECT s, p, o, lit, dt FROM planhrc_triple WHERE s = ANY(%s)",
                                    ([ABOX_IRI + n for n in dict.fromkeys(names)],))
        return individuals(rows)

    def _get(self, name: str, cls: str) -> Individual | None:
        ind = self.describe([name]).get(name)
        return ind if ind is not None and cls in ind.types else None

    # -- objects --------------------------------------------------------------------------------------------
    def info(self, object_id: str, field: str | None = None) -> ObjectInfo:
        """The object's info; unknown -> ValidationError naming `field` (writes) or NotFoundError (reads)."""
        return object_info(self.objects, self._load_object, object_id, field)

    def object_ids(self) -> list[str]:
        rows = self.session.execute("SELECT s FROM planhrc_triple WHERE o = %s AND p = %s",
                                    (TBOX_IRI + "ArticulatedObject", RDF_TYPE))
        return sorted((s[len(ABOX_IRI):] for (s,) in rows), key=natural_key)

    def _load_object(self, ident: str) -> ArticulatedObject | None:
        obj = self._get(ident, "ArticulatedObject")
        if obj is None:
            return None
        lengths = {int(link.value("chainIndex")): float(link.value("lengthM"))
                   for link in self.describe(obj.rels.get("hasLink", [])).values() if not link.value("isVirtual")}
        return ArticulatedObject(
            ident=ident, formulation=Formulation(obj.value("formulation")),
            link_lengths_m=tuple(lengths[k] for k in sorted(lengths)),
            orientations=len(obj.rels.get("allowedOrientation", [])), name=obj.data.get("objectName") or "",
        )

    # -- predicate individuals ------------------------------------------------------------------------------
    def atoms(self, object_id: str, names: Sequence[str]) -> dict[str, Atom]:
        """The atoms of predicate individuals of an object: its own by name, the rest read."""
        known = self._atom_of.get(object_id)
        if known is None:
            info = self.info(object_id)
            known = self._atom_of[object_id] = {
                **{name: atom for atom, name in info.static_fragment.items()},
                **{name: atom for atom, name in info.shared_atom_name.items()}}
        out = {name: known[name] for name in names if name in known}
        for name, ind in self.describe([n for n in names if n not in out]).items():
            pddl = next((PREDICATE_OF_CLASS[c] for c in ind.types if c in PREDICATE_OF_CLASS), None)
            if pddl is None:
                raise DamagedStoreError(f"store: predicate individual {name} has no predicate class")
            out[name] = (pddl,) + tuple(ind.one(prop) for prop in PREDICATES[pddl][2])
        missing = [n for n in names if n not in out]
        if missing:
            raise DamagedStoreError(f"store: predicate individual {missing[0]} is not stored")
        return out

    # -- loaders of the cached kinds ------------------------------------------------------------------------
    def _load_state(self, state_id: str) -> StoredState | None:
        object_id, _, number = state_id.rpartition("_state_")
        if number.isdigit() and self._journalled("object_id = %s AND first_state <= %s AND last_state >= %s",
                                                 (object_id, int(number), int(number))):
            return self.states.get(state_id)
        state = self.describe([state_id]).get(state_id)
        kind = next((k for k, cls in STATE_CLASSES.items() if state and cls in state.types), None)
        if state is None or kind is None:
            return None
        object_id = state.one("stateOf")
        madeof = state.rels.get("madeof", [])
        atoms = frozenset(self.atoms(object_id, madeof).values())
        if state.data.get("includesStaticFacts"):
            atoms |= self.info(object_id).static
        observed = None
        if state.rels.get("observes"):
            values = {int(p.one("arg1").rsplit("_l", 1)[1]): float(p.value("observedDegrees"))
                      for p in self.describe(state.rels["observes"]).values()}
            observed = tuple(values[k] for k in sorted(values))
        return StoredState(id=state_id, object_id=object_id, kind=kind, atoms=atoms,
                           created_at=float(state.value("createdAt")), link_orientations_deg=observed)

    def _load_problem(self, problem_id: str) -> StoredProblem | None:
        problem = self._get(problem_id, "Problem")
        if problem is None:
            return None
        return StoredProblem(problem_id, problem.one("aboutObject"), problem.one("init"), problem.one("goal"),
                             float(problem.value("createdAt")))

    def _load_action(self, action_id: str) -> StoredAction | None:
        plan_id, _, step = action_id.rpartition("_a")
        if step.isdigit() and self._journalled("plan_id = %s", (plan_id,)):
            return self.actions.get(action_id)
        return self._load_actions([action_id]).get(action_id)

    def _load_actions(self, action_ids: Sequence[str]) -> dict[str, StoredAction]:
        """Actions read together (a plan's): three queries, whatever their number."""
        found = {name: (ind, next((k for k, c in ACTION_CLASSES.items() if c in ind.types), None))
                 for name, ind in self.describe(action_ids).items()}
        actions = {name: (ind, kind) for name, (ind, kind) in found.items() if kind is not None}
        conds = self.describe([c for ind, _ in actions.values() for c in ind.rels.get("condEff", [])])
        out: dict[str, StoredAction] = {}
        for name, (ind, kind) in actions.items():
            ces = sorted((conds[c] for c in ind.rels.get("condEff", [])), key=lambda c: int(c.value("position")))
            parts: list[Any] = [ind.rels.get(p, []) for p in _ACTION_PARTS]
            ce_parts = [[ce.rels.get(p, []) for p in _COND_PARTS] for ce in ces]
            atoms = self.atoms(ind.one("aboutObject"), [n for part in parts for n in part]
                               + [n for ce in ce_parts for part in ce for n in part])

            def fs(names: list[str]) -> frozenset[Atom]:
                return frozenset(atoms[n] for n in names)

            spec = ActionSpec(name=kind or "", params=tuple(str(ind.data.get("paramList") or "").split()),
                              pre=fs(parts[0]), eff_neg=fs(parts[1]), eff_pos=fs(parts[2]),
                              cond_eff=tuple(CondEffect(fs(w), fs(n), fs(p)) for w, n, p in ce_parts))
            out[name] = StoredAction(name, int(ind.value("stepIndex")), spec)
        return out

    def _load_plan(self, plan_id: str) -> StoredPlan | None:
        if self._journalled("plan_id = %s", (plan_id,)):
            return self.plans.get(plan_id)
        plan = self._get(plan_id, "Plan")
        if plan is None:
            return None
        action_ids = plan.rels.get("madeof", [])
        loaded = self._load_actions(action_ids)
        for action in loaded.values():
            self.actions.put(action)
        if len(loaded) != len(action_ids):
            raise DamagedStoreError(f"store: plan {plan_id} names an action that is not stored")
        state_ids = plan.rels.get("expectedState", [])
        steps = dict(self.session.execute(
            "SELECT s, lit FROM planhrc_triple WHERE s = ANY(%s) AND p = %s",
            ([ABOX_IRI + s for s in state_ids], TBOX_IRI + "stepIndex")).fetchall())
        return StoredPlan(
            id=plan_id, object_id=plan.one("aboutObject"), problem_id=plan.one("solves"),
            planner=str(plan.value("plannerName")), actions=tuple(sorted(loaded.values(), key=lambda a: a.step)),
            expected_state_ids=tuple(sorted(state_ids, key=lambda s: int(steps[ABOX_IRI + s]))),
            created_at=float(plan.value("createdAt")),
        )

"""The PostgreSQL engine of the store's identity map (`..identity.IdentityMap`): records read back from the ABox's
rows and the journal's (a `unit.RecordsOfWrites` and a `TransactionListener` of its `Session`).

A record is read with a query or two per kind of individual it is made of (the record, its predicate individuals,
its observations), whatever its size. A predicate individual that belongs to its object (a static fact, an
orientation of a joint) is known by its name (`names.atom_fragment`, the names every write gives them); an action's
own predicates are read. Every method is called with the store's lock held.
"""
from __future__ import annotations

from typing import Any, Sequence

from planhrc.model import ArticulatedObject, Atom, Formulation, natural_key

from ..errors import DamagedStoreError
from ..identity import IdentityMap
from ..journal import JournalEntry, decode
from ..names import ABOX_IRI, ACTION_CLASSES, PREDICATE_OF_CLASS, PREDICATES, STATE_CLASSES, TBOX_IRI
from ..records import ActionSpec, CondEffect, StoredAction, StoredPlan, StoredProblem, StoredState
from .rows import Individual, individuals
from .schema import RDF_TYPE
from .session import Session

_ACTION_PARTS = ("pre", "effNeg", "effPos")
_COND_PARTS = ("when", "effNeg_a", "effPos_a")


class PgRecords(IdentityMap):
    """The records of one PostgreSQL ABox, cached; what an object's own predicates are, by name."""

    def __init__(self, session: Session) -> None:
        self.session = session
        self._atom_of: dict[str, dict[str, Atom]] = {}  # object id -> name of its own predicate -> atom
        super().__init__()

    def _cached(self) -> int:
        return len(self.states) + len(self.actions)

    def _forget(self) -> None:
        self._atom_of.clear()

    # -- the journal's rows (a journalled plan's records are read from its row, in any process) ----------------
    def _entry(self, plan_id: str) -> JournalEntry | None:
        return self._journal_row("plan_id = %s", (plan_id,))

    def _entry_of_state(self, object_id: str, number: int) -> JournalEntry | None:
        return self._journal_row("object_id = %s AND first_state <= %s AND last_state >= %s",
                                 (object_id, number, number))

    def _journal_row(self, sql: str, params: tuple[Any, ...]) -> JournalEntry | None:
        row = self.session.execute("SELECT payload FROM planhrc_plan_journal WHERE " + sql, params).fetchone()
        return None if row is None else decode(bytes(row[0]))

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
    def object_ids(self) -> list[str]:
        rows = self.session.execute("SELECT s FROM planhrc_triple WHERE o = %s AND p = %s",
                                    (TBOX_IRI + "ArticulatedObject", RDF_TYPE))
        return sorted((s[len(ABOX_IRI):] for (s,) in rows), key=natural_key)

    def _read_object(self, ident: str) -> ArticulatedObject | None:
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

    # -- the rows of the cached kinds -------------------------------------------------------------------------
    def _read_state(self, state_id: str) -> StoredState | None:
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

    def _read_problem(self, problem_id: str) -> StoredProblem | None:
        problem = self._get(problem_id, "Problem")
        if problem is None:
            return None
        return StoredProblem(problem_id, problem.one("aboutObject"), problem.one("init"), problem.one("goal"),
                             float(problem.value("createdAt")))

    def _read_action(self, action_id: str) -> StoredAction | None:
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

    def _read_plan(self, plan_id: str) -> StoredPlan | None:
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

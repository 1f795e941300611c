"""The SQLite engine of the store's identity map (`identity.IdentityMap`): records read back from the ABox's triples
(`abox.Abox`) and journal rows (`journal.JournalTable`). The map caches them; the engine also caches the names of
the storids it has read (`Abox.sid_name`). Every method is called with the store's lock held.
"""
from __future__ import annotations

from typing import Sequence

from planhrc.model import ArticulatedObject, Atom, Formulation, natural_key

from .abox import Abox
from .errors import DamagedStoreError
from .identity import IdentityMap
from .journal import JournalEntry, JournalTable
from .names import ACTION_CLASSES, PREDICATE_OF_CLASS, PREDICATES, STATE_CLASSES
from .owl import RDF_TYPE
from .records import ActionSpec, CondEffect, StoredAction, StoredPlan, StoredProblem, StoredState


class SqliteRecords(IdentityMap):
    """The records of one SQLite ABox, cached; a `TransactionListener` of its `Abox`."""

    def __init__(self, abox: Abox, journal: JournalTable) -> None:
        self.abox = abox
        self.journal = journal
        super().__init__()

    def _cached(self) -> int:
        return len(self.abox.sid_name) + len(self.states)

    def _forget(self) -> None:
        self.abox.forget_names()

    def _entry(self, plan_id: str) -> JournalEntry | None:
        return self.journal.entry(plan_id)

    def _entry_of_state(self, object_id: str, number: int) -> JournalEntry | None:
        return self.journal.entry_of_state(object_id, number)

    # -- objects --------------------------------------------------------------------------------------------
    def object_ids(self) -> list[str]:
        sids = self.abox.q.subjects(RDF_TYPE, self.abox.t["ArticulatedObject"], self.abox.c)
        self.abox.names(sids)
        return sorted((self.abox.sid_name[s] for s in sids), key=natural_key)

    def _read_object(self, ident: str) -> ArticulatedObject | None:
        abox = self.abox
        sid = abox.sid(ident)
        if sid is None or not abox.is_a(sid, "ArticulatedObject"):
            return None
        lengths: dict[int, float] = {}
        for link in abox.objn(sid, "hasLink"):
            if abox.data1(link, "isVirtual"):
                continue
            lengths[int(abox.data1(link, "chainIndex"))] = float(abox.data1(link, "lengthM"))
        return ArticulatedObject(
            ident=ident,
            formulation=Formulation(abox.data1(sid, "formulation")),
            link_lengths_m=tuple(lengths[k] for k in sorted(lengths)),
            orientations=len(abox.objn(sid, "allowedOrientation")),
            name=abox.data1(sid, "objectName") or "",
        )

    # -- the triples of the cached kinds ----------------------------------------------------------------------
    def _predicate_atoms(self, pred_sids: Sequence[int]) -> dict[int, Atom]:
        """Atoms of reified predicate individuals, read with a few queries."""
        out: dict[int, Atom] = {}
        if not pred_sids:
            return out
        abox = self.abox
        class_of = {abox.t[cls]: pddl for cls, pddl in PREDICATE_OF_CLASS.items()}
        props = {abox.t["arg1"]: "arg1", abox.t["arg2"]: "arg2", abox.t["arg3"]: "arg3"}
        kinds: dict[int, str] = {}
        args: dict[int, dict[str, int]] = {}
        sids = list(dict.fromkeys(pred_sids))
        for s, p, o in abox.q.triples_of(sids, [RDF_TYPE, *props]):
            if p == RDF_TYPE:
                if o in class_of:
                    kinds[s] = class_of[o]
            else:
                args.setdefault(s, {})[props[p]] = o
        abox.names(o for d in args.values() for o in d.values())
        for s in sids:
            pddl = kinds.get(s)
            if pddl is None:
                raise DamagedStoreError(f"store: predicate individual {s} has no predicate class")
            _, _, order, _ = PREDICATES[pddl]
            out[s] = (pddl,) + tuple(abox.sid_name[args[s][prop]] for prop in order)
        return out

    def _typed(self, name: str, classes: dict[str, str]) -> tuple[int, str] | None:
        """The storid of an ABox individual and which of `classes` (key -> OWL class) it is, or None."""
        sid = self.abox.sid(name)
        if sid is None:
            return None
        types = self.abox.types(sid)
        key = next((k for k, cls in classes.items() if self.abox.t[cls] in types), None)
        return None if key is None else (sid, key)

    def _read_state(self, state_id: str) -> StoredState | None:
        if (typed := self._typed(state_id, STATE_CLASSES)) is None:
            return None
        abox = self.abox
        sid, kind = typed
        obj_sid = abox.ref(sid, "stateOf")
        abox.names([obj_sid])
        atoms = frozenset(self._predicate_atoms(abox.objn(sid, "madeof")).values())
        if abox.data1(sid, "includesStaticFacts"):
            atoms |= self.info(abox.sid_name[obj_sid]).static
        observed = None
        lo = abox.objn(sid, "observes")
        if lo:
            values: dict[int, float] = {}
            for p in lo:
                link = abox.ref(p, "arg1")
                values[int(abox.data1(link, "chainIndex"))] = float(abox.data1(p, "observedDegrees"))
            observed = tuple(values[k] for k in sorted(values))
        return StoredState(
            id=state_id, object_id=abox.sid_name[obj_sid], kind=kind, atoms=atoms,
            created_at=float(abox.data1(sid, "createdAt")), link_orientations_deg=observed,
        )

    def _read_problem(self, problem_id: str) -> StoredProblem | None:
        abox = self.abox
        sid = abox.sid(problem_id)
        if sid is None or not abox.is_a(sid, "Problem"):
            return None
        refs = [abox.ref(sid, p) for p in ("aboutObject", "init", "goal")]
        abox.names(refs)
        o, i, g = (abox.sid_name[r] for r in refs)
        return StoredProblem(problem_id, o, i, g, float(abox.data1(sid, "createdAt")))

    def _read_action(self, action_id: str) -> StoredAction | None:
        if (typed := self._typed(action_id, ACTION_CLASSES)) is None:
            return None
        abox = self.abox
        sid, name = typed
        parts: dict[str, list[int]] = {p: abox.objn(sid, p) for p in ("pre", "effNeg", "effPos")}
        ces = sorted(abox.objn(sid, "condEff"), key=lambda c: int(abox.data1(c, "position")))
        ce_parts = [{p: abox.objn(c, p) for p in ("when", "effNeg_a", "effPos_a")} for c in ces]
        every = [s for lst in parts.values() for s in lst] + [s for d in ce_parts for lst in d.values() for s in lst]
        atoms = self._predicate_atoms(every)

        def fs(sids: list[int]) -> frozenset[Atom]:
            return frozenset(atoms[s] for s in sids)

        spec = ActionSpec(
            name=name,
            params=tuple((abox.data1(sid, "paramList") or "").split()),
            pre=fs(parts["pre"]), eff_neg=fs(parts["effNeg"]), eff_pos=fs(parts["effPos"]),
            cond_eff=tuple(CondEffect(fs(d["when"]), fs(d["effNeg_a"]), fs(d["effPos_a"])) for d in ce_parts),
        )
        return StoredAction(action_id, int(abox.data1(sid, "stepIndex")), spec)

    def _read_plan(self, plan_id: str) -> StoredPlan | None:
        abox = self.abox
        sid = abox.sid(plan_id)
        if sid is None or not abox.is_a(sid, "Plan"):
            return None
        refs = [abox.ref(sid, "aboutObject"), abox.ref(sid, "solves")]
        action_sids = abox.objn(sid, "madeof")
        state_sids = abox.objn(sid, "expectedState")
        abox.names(refs + action_sids + state_sids)
        actions = sorted((self.actions.get(abox.sid_name[a]) for a in action_sids), key=lambda a: a.step)
        states = sorted(state_sids, key=lambda s: int(abox.data1(s, "stepIndex")))
        return StoredPlan(
            id=plan_id, object_id=abox.sid_name[refs[0]], problem_id=abox.sid_name[refs[1]],
            planner=str(abox.data1(sid, "plannerName")), actions=tuple(actions),
            expected_state_ids=tuple(abox.sid_name[s] for s in states),
            created_at=float(abox.data1(sid, "createdAt")),
        )

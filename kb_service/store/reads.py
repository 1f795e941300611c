"""Records read back from the SQLite ABox's triples, through one cache per kind (`cache.RecordCache`).

`Records` is the store's identity map: the objects (with the lookups the checks need), the states, problems, plans
and actions read or written so far. A plan whose triples are not written yet (`backlog`) is read from its journal
row, which is looked up first: a row turns into triples in one transaction, so one or the other is found. Every
method is called with the store's lock held.
"""
from __future__ import annotations

from typing import Sequence

from planhrc.model import ArticulatedObject, Atom, Formulation, natural_key

from .abox import Abox
from .cache import RecordCache, object_info
from .checks import ObjectInfo
from .errors import DamagedStoreError, NotFoundError, ValidationError
from .journal import JournalEntry, JournalTable
from .names import ACTION_CLASSES, PREDICATE_OF_CLASS, PREDICATES, STATE_CLASSES
from .owl import RDF_TYPE
from .records import ActionSpec, CondEffect, StoredAction, StoredPlan, StoredProblem, StoredState

# Storids and records cached past this many entries are dropped after a commit (they are read again on demand),
# so the service's memory stays flat as the history grows.
CACHE_LIMIT = 5_000


class Records:
    """The records of one SQLite ABox, cached; a `TransactionListener` of its `Abox`."""

    def __init__(self, abox: Abox, journal: JournalTable) -> None:
        self.abox = abox
        self.journal = journal
        self.objects: dict[str, ObjectInfo] = {}
        self.states = RecordCache("state", StoredState, self._load_state)
        self.problems = RecordCache("problem", StoredProblem, self._load_problem)
        self.plans = RecordCache("plan", StoredPlan, self._load_plan)
        self.actions = RecordCache("action", StoredAction, self._load_action)

    # -- the identity map's life --------------------------------------------------------------------------
    def clear(self) -> None:
        """Forget every cached record and storid."""
        self.abox.forget_names()
        self.objects.clear()
        for cache in (self.states, self.problems, self.plans, self.actions):
            cache.clear()

    def committed(self) -> None:
        if len(self.abox.sid_name) + len(self.states) > CACHE_LIMIT:
            self.clear()

    def rolled_back(self) -> None:
        # Records cached during a rolled-back transaction were never stored.
        self.clear()

    def put_entry(self, entry: JournalEntry) -> StoredPlan:
        """Cache a journalled plan's records (its actions and expected states); the plan's."""
        return entry.cache(self.plans, self.actions, self.states)

    # -- objects --------------------------------------------------------------------------------------------
    def info(self, object_id: str, field: str | None = None) -> ObjectInfo:
        """The object's info; unknown -> ValidationError naming `field` (writes) or NotFoundError (reads)."""
        return object_info(self.objects, self._load_object, object_id, field)

    def object_ids(self) -> list[str]:
        sids = self.abox.q.subjects(RDF_TYPE, self.abox.t["ArticulatedObject"], self.abox.c)
        self.abox.names(sids)
        return sorted((self.abox.sid_name[s] for s in sids), key=natural_key)

    def _load_object(self, ident: str) -> ArticulatedObject | None:
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

    # -- loaders of the cached kinds ------------------------------------------------------------------------
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

    def _load_state(self, state_id: str) -> StoredState | None:
        object_id, _, number = state_id.rpartition("_state_")
        if number.isdigit():
            entry = self.journal.entry_of_state(object_id, int(number))
            if entry is not None:
                self.put_entry(entry)
                return self.states.get(state_id)
        abox = self.abox
        typed = self._typed(state_id, STATE_CLASSES)
        if typed is None:
            return None
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

    def _load_problem(self, problem_id: str) -> StoredProblem | None:
        abox = self.abox
        sid = abox.sid(problem_id)
        if sid is None or not abox.is_a(sid, "Problem"):
            return None
        refs = [abox.ref(sid, p) for p in ("aboutObject", "init", "goal")]
        abox.names(refs)
        o, i, g = (abox.sid_name[r] for r in refs)
        return StoredProblem(problem_id, o, i, g, float(abox.data1(sid, "createdAt")))

    def _load_action(self, action_id: str) -> StoredAction | None:
        plan_id, _, step = action_id.rpartition("_a")
        if step.isdigit():
            entry = self.journal.entry(plan_id)
            if entry is not None:
                self.put_entry(entry)
                return self.actions.get(action_id)
        abox = self.abox
        typed = self._typed(action_id, ACTION_CLASSES)
        if typed is None:
            return None
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

    def _load_plan(self, plan_id: str) -> StoredPlan | None:
        entry = self.journal.entry(plan_id)
        if entry is not None:
            return self.put_entry(entry)
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

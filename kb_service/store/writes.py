"""The ABox's writes: new object ids, objects, states, perceptions, problems and plans.

Each write checks its whole input first (`checks`), then adds its triples in one transaction (`Abox.write`; inside
`transaction()` it joins the open one), then caches the record it hands back. A plan is journalled by the backend's
`unit.PlanAdopter`, not written as triples (they are written when a reader of the triples needs them). Every method
is called with the store's lock held. Nothing here names a backend: each gives its `unit.AboxWriter`.
"""
from __future__ import annotations

import time
from typing import Any, Sequence

from planhrc.model import ArticulatedObject, Atom, Perception
from planhrc.transition import frozen_states

from .checks import (ObjectInfo, check_kind, check_observation, check_perception, check_plan, check_state_atoms,
                     is_checked)
from .errors import ConflictError, NotFoundError, ValidationError
from .journal import JournalEntry
from .names import ABOX_IRI, COMPLETE_KINDS, counter_name, record_name
from .records import ActionSpec, CheckedPlan, StoredPlan, StoredProblem, StoredState
from .triples import object_triples, state_triples
from .unit import AboxWriter, PlanAdopter, RecordsOfWrites


class RecordWriter:
    """The writes of one ABox, whatever its backend: what the `interface.Writes` of every store hands on."""

    def __init__(self, abox: AboxWriter[Any], records: RecordsOfWrites, backlog: PlanAdopter) -> None:
        self._abox = abox
        self._records = records
        self._backlog = backlog

    def new_object_id(self) -> str:
        """A fresh object id `objN`; N is never handed out twice, even across restarts."""
        abox = self._abox

        def fill() -> str:
            while True:
                ident = f"obj{abox.next_counter('object')}"
                if not abox.existing([ident]):
                    return ident

        return abox.write(fill)

    def create_object(self, obj: ArticulatedObject) -> None:
        abox = self._abox
        if not isinstance(obj, ArticulatedObject):
            raise ValidationError(f"object: expected an ArticulatedObject, got {type(obj).__name__}")
        clashes = abox.existing((obj.ident,) + obj.all_links + obj.joints)
        if clashes:
            raise ConflictError(f"object.ident: {obj.ident!r} already exists (IRI {ABOX_IRI}{clashes[0]})")
        info = ObjectInfo(obj)

        def fill() -> None:
            b = abox.batch()
            object_triples(abox, b, info)
            abox.flush(b)
            abox.note_object()

        abox.write(fill)
        self._records.objects[obj.ident] = info

    def add_state(self, object_id: str, kind: str, atoms: frozenset[Atom],
                  link_orientations_deg: Sequence[float] | None = None) -> StoredState:
        info = self._records.info(object_id, "object_id")
        kind = check_kind(kind)
        by_joint = check_state_atoms(info, kind, atoms, "atoms")
        observation = check_observation(info, kind, by_joint, link_orientations_deg)
        atoms = frozenset(atoms)
        state_id, created = self._write_state(info, kind, atoms, observation)
        record = StoredState(id=state_id, object_id=info.obj.ident, kind=kind, atoms=atoms, created_at=created,
                             link_orientations_deg=observation.raw_deg if observation else None)
        self._records.states.put(record)
        return record

    def add_perception(self, perception: Perception) -> StoredState:
        """Store a perceived state from a perception validated and snapped where it entered (`model.perceive`)."""
        if not isinstance(perception, Perception):
            raise ValidationError(f"perception: expected a Perception, got {type(perception).__name__}")
        info = self._records.info(perception.object_id, "perception.object_id")
        check_perception(info, perception)
        state_id, created = self._write_state(info, "perceived", perception.atoms, perception)
        record = StoredState(id=state_id, object_id=info.obj.ident, kind="perceived", atoms=perception.atoms,
                             created_at=created, link_orientations_deg=perception.raw_deg)
        self._records.states.put(record)
        return record

    def _write_state(self, info: ObjectInfo, kind: str, atoms: frozenset[Atom],
                     observation: Perception | None) -> tuple[str, float]:
        """A checked state's triples; its name and time."""
        abox = self._abox
        created = time.time()

        def fill() -> str:
            b = abox.batch()
            state_id = state_triples(abox, b, info, kind, atoms, observation, None, created)
            abox.flush(b)
            return state_id

        return abox.write(fill), created

    def add_problem(self, object_id: str, init_state_id: str, goal_state_id: str) -> StoredProblem:
        abox = self._abox
        info = self._records.info(object_id, "object_id")
        states = {}
        for field, sid in (("init_state_id", init_state_id), ("goal_state_id", goal_state_id)):
            try:
                st = self._records.states.get(sid)
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
        ident = info.obj.ident

        def fill() -> str:
            b = abox.batch()
            pid = record_name(ident, "problem", abox.next_counter(counter_name(ident, "problem")))
            b.individual(pid, "Problem")
            b.rel(pid, "aboutObject", ident)
            b.rel(pid, "init", init_state_id)
            b.rel(pid, "goal", goal_state_id)
            b.data(pid, "createdAt", created)
            abox.flush(b)
            return pid

        pid = abox.write(fill)
        record = StoredProblem(pid, ident, init_state_id, goal_state_id, created)
        self._records.problems.put(record)
        return record

    def add_plan(self, problem_id: str, planner: str, actions: Sequence[ActionSpec],
                 expected_states: Sequence[frozenset[Atom]], checked: CheckedPlan | None = None) -> StoredPlan:
        abox = self._abox
        try:
            problem = self._records.problems.get(problem_id)
        except NotFoundError:
            raise ValidationError(f"problem_id: no problem {problem_id!r}") from None
        info = self._records.info(problem.object_id, "problem_id")
        if not isinstance(planner, str) or not planner:
            raise ValidationError("planner: must be a non-empty string")
        actions = tuple(actions)
        expected_states = frozen_states(expected_states)
        ident = info.obj.ident
        body = None
        if is_checked(checked, ident, actions, expected_states):
            assert checked is not None
            body = checked.journal_body
        else:
            check_plan(info, actions, expected_states)
        created = time.time()

        def fill() -> StoredPlan:
            plan_id = record_name(ident, "plan", abox.next_counter(counter_name(ident, "plan")))
            first_state = abox.reserve_counter(counter_name(ident, "state"), len(expected_states))
            return self._backlog.adopt(JournalEntry(plan_id, ident, problem_id, planner, created, first_state,
                                                    actions, expected_states), body)

        return abox.write(fill)

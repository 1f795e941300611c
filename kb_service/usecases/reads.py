"""Reads: the stored records as the service shows them (objects, plans, states, problems, the event log, the
ontology, the PDDL the planner saw, the store's counts). A read changes nothing."""
from __future__ import annotations

from typing import Iterator

from planhrc.model import HAS_ORIENTATION, ArticulatedObject, Atom, Formulation, format_atom
from planhrc.pipeline import action_motion, problem_name
from planhrc.translator import PddlTask, domain_text, read_domain_model, translate

from ..store import NotFoundError, StoredEvent, StoredPlan, StoredProblem, StoredState
from ..store import MAX_EVENTS_PAGE
from .context import Context
from .log import EventRead, event_read
from .values import Health, LinkRead, ObjectRead, PlanRead, PlanStepRead, StateRead


def read_object(context: Context, object_id: str) -> ObjectRead:
    """One object with its goal and execution state."""
    store = context.store
    obj = store.get_object(object_id)
    with context.locks.hold(obj.ident):
        execution = store.get_execution(obj.ident)
        memo = context.memory.of(store, obj.ident)
    return ObjectRead(id=obj.ident, name=obj.name, formulation=obj.formulation.value, orientations=obj.orientations,
                      step_deg=obj.step, goal_state_id=memo.goal_state_id, base_point_xy=memo.base_point_xy,
                      links=tuple(LinkRead(name, length) for name, length in zip(obj.links, obj.link_lengths_m)),
                      joints=tuple(obj.joints), execution=execution)


def list_objects(context: Context) -> list[ObjectRead]:
    return [read_object(context, obj.ident) for obj in context.store.list_objects()]


def read_current_plan(context: Context, object_id: str) -> PlanRead:
    """The plan being followed (or, when none is, the latest one), with its expected states."""
    store = context.store
    store.get_object(object_id)
    execution = store.get_execution(object_id)
    plan = store.get_plan(execution.plan_id) if execution.plan_id else store.latest_plan(object_id)
    if plan is None:
        raise NotFoundError(f"plan: object {object_id} has no plan yet")
    return _plan_read(context, plan)


def read_plan(context: Context, plan_id: str) -> PlanRead:
    return _plan_read(context, context.store.get_plan(plan_id))


def read_state(context: Context, state_id: str) -> StateRead:
    return state_read(context.store.get_state(state_id))


def read_problem(context: Context, problem_id: str) -> StoredProblem:
    """A problem as stored (its record is the read: ids and time only)."""
    return context.store.get_problem(problem_id)


def list_events(context: Context, object_id: str, after_seq: int = 0, limit: int | None = None) -> list[EventRead]:
    """A page of the object's log, oldest first: at most `limit` events after `after_seq`."""
    return [event_read(e) for e in context.store.list_events(object_id, after_seq=after_seq, limit=limit)]


def events_after(context: Context, object_id: str, after_seq: int = 0,
                 limit: int = MAX_EVENTS_PAGE) -> tuple[StoredEvent, ...]:
    """One page of events after `after_seq` (a stream reads the next page at its next poll)."""
    return context.store.list_events(object_id, after_seq=after_seq, limit=limit)


def export_ontology(context: Context, fmt: str, history: str = "current",
                    object_id: str | None = None) -> Iterator[str]:
    """TBox and ABox (the current ABox, or the whole `history`) as RDF/XML (`xml`), Turtle (`turtle`) or
    N-Triples (`nt`), in pieces written as the store's lines are read: a reader that stops stops the export."""
    return context.store.export_stream(fmt, history, None if object_id is None else [object_id])


def read_health(context: Context) -> Health:
    """Counts kept by the store's commits: no scan and no lock, so /health answers while anything runs."""
    store = context.store
    return Health(store.object_count(), store.triple_count(), store.plans_to_write())


def read_pddl(context: Context, object_id: str, with_problem: bool = False) -> PddlTask:
    """The PDDL of the object's latest Problem as the planner saw it (`with_problem`), or only its domain."""
    store = context.store
    obj = store.get_object(object_id)
    model = read_domain_model(context.planning.tbox_path, obj.formulation.value)
    if not with_problem:
        return PddlTask(domain_text(model, False, obj.formulation is Formulation.ABSOLUTE), "", "")
    problem = store.latest_problem(object_id)
    if problem is None:
        raise NotFoundError(f"problem: object {object_id} has no problem yet (set a goal and send a perception)")
    init, goal = store.get_state(problem.init_state_id), store.get_state(problem.goal_state_id)
    return translate(obj, init.atoms, goal.atoms, model, problem_name(obj))


# -- records as reads ------------------------------------------------------------------------------------------
def atoms_read(atoms: frozenset[Atom]) -> tuple[str, ...]:
    return tuple(format_atom(a) for a in sorted(atoms))


def state_read(state: StoredState) -> StateRead:
    joints = {a[2]: int(a[1].split("_", 1)[1]) for a in state.atoms if a[0] == HAS_ORIENTATION and len(a) == 3}
    return StateRead(id=state.id, object_id=state.object_id, kind=state.kind, atoms=atoms_read(state.atoms),
                     joint_values_deg=dict(sorted(joints.items())),
                     link_orientations_deg=tuple(state.link_orientations_deg) if state.link_orientations_deg else None,
                     created_at=state.created_at)


def _plan_read(context: Context, plan: StoredPlan) -> PlanRead:
    store = context.store
    obj = store.get_object(plan.object_id)
    expected = tuple(state_read(store.get_state(sid)) for sid in plan.expected_state_ids)
    return PlanRead(id=plan.id, object_id=plan.object_id, problem_id=plan.problem_id, planner=plan.planner,
                    steps=_steps(obj, plan), expected_state_ids=tuple(plan.expected_state_ids),
                    expected_states=expected, created_at=plan.created_at)


def _steps(obj: ArticulatedObject, plan: StoredPlan) -> tuple[PlanStepRead, ...]:
    steps = []
    for a in sorted(plan.actions, key=lambda a: a.step):
        motion = action_motion(obj, a)
        spec = a.spec
        steps.append(PlanStepRead(
            id=a.id, step=a.step, name=spec.name, params=tuple(spec.params), pre=atoms_read(spec.pre),
            eff_neg=atoms_read(spec.eff_neg), eff_pos=atoms_read(spec.eff_pos),
            cond_eff=tuple({"when": atoms_read(c.when), "eff_neg": atoms_read(c.eff_neg),
                            "eff_pos": atoms_read(c.eff_pos)} for c in spec.cond_eff),
            joint_index=motion["joint_index"], turned_link_index=motion["turned_link_index"],
            held_link_index=motion["held_link_index"], delta_deg=motion["delta_deg"]))
    return tuple(steps)

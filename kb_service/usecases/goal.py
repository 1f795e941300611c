"""Set a goal: stored at once, with a Problem from the latest perceived state when one exists. Planning happens
at the next perception (the paper: setting a goal triggers a perception), so a goal set before any perception
waits for the first one. The old plan was made for another goal: the execution goes idle."""
from __future__ import annotations

from dataclasses import dataclass

from planhrc.event_log import EventKind, GoalSetData
from planhrc.geometry import PLANNING, Cell, ObjectGeometry, configuration_feasible
from planhrc.model import ArticulatedObject, Formulation, State, snap_angle
from planhrc.motion_search import room_for_goal
from planhrc.pipeline import deadline_from, warm_up_job
from planhrc.vocabulary import ExecutionStatus

from ..store import Execution, ValidationError
from .context import Context
from .inputs import allowed, check_count, check_finite
from .log import log_event
from .memory import ObjectMemo
from .unit_of_work import object_write, read_mark, serialized
from .values import GoalSet


@dataclass(frozen=True)
class GoalRequest:
    """A goal: every link's orientation, or one angle per joint (None: that joint is free)."""

    object_id: str
    link_orientations_deg: tuple[float, ...] | None = None
    joint_angles_deg: tuple[float | None, ...] | None = None
    allow_infeasible: bool = False


def set_goal(context: Context, request: GoalRequest) -> GoalSet:
    """Store a goal. For a placed object a complete goal configuration is checked first: one off the table,
    inside the robot or folded onto itself is refused naming the links (unless `allow_infeasible`); links
    beyond the robot's reach are accepted with a warning (the robot will ask the human for them)."""
    return serialized(context, request.object_id, lambda: _set_goal(context, request))


def _set_goal(context: Context, request: GoalRequest) -> GoalSet:
    store, object_id = context.store, request.object_id
    with context.locks.hold(object_id):
        obj = store.get_object(object_id)
        atoms = goal_atoms(obj, request.link_orientations_deg, request.joint_angles_deg)
        mark = read_mark(context, object_id)
        memo = context.memory.of(store, object_id)
        warnings = _warnings(context, obj, memo, atoms, request)
        with object_write(context, object_id, mark):
            goal = store.add_state(object_id, "goal", atoms)
            problem = None
            if memo.perceived_state_id is not None:
                problem = store.add_problem(object_id, memo.perceived_state_id, goal.id)
            store.set_execution(object_id, Execution(None, None, ExecutionStatus.IDLE, None))
            context.validator.stop(object_id)
            said = f" ({'; '.join(warnings)})" if warnings else ""
            log_event(store, object_id, EventKind.GOAL_SET, f"goal set; the next perception plans towards it{said}",
                      GoalSetData(goal_state_id=goal.id, problem_id=problem.id if problem else None,
                                  warnings=tuple(warnings)))
        _warm(context, obj, atoms)
        return GoalSet(goal.id, problem.id if problem else None, tuple(warnings))


def _warm(context: Context, obj: ArticulatedObject, goal: State) -> None:
    """A large object's planning warmed up for its new goal, off this request's path (`LargeTaskPlanning.warm`):
    the perception that plans next finds the object's task grounded."""
    pool = context.pool
    if pool is not None and pool.takes(obj):
        pool.warm(warm_up_job(obj, goal, context.planning, deadline_from(context.planning)))


def goal_atoms(obj: ArticulatedObject, link_orientations_deg: tuple[float, ...] | None,
               joint_angles_deg: tuple[float | None, ...] | None) -> State:
    if (link_orientations_deg is None) == (joint_angles_deg is None):
        raise ValidationError("link_orientations_deg, joint_angles_deg: give exactly one of them")
    if link_orientations_deg is not None:
        field = "link_orientations_deg"
        check_count(obj, link_orientations_deg, field)
        check_finite(link_orientations_deg, field)
        if any(v is None for v in link_orientations_deg):
            raise ValidationError(f"{field}: every link needs an orientation")
        values = obj.joint_values_from_links([v for v in allowed(obj, link_orientations_deg, field) if v is not None])
        return obj.configuration_atoms(values)
    assert joint_angles_deg is not None
    return obj.partial_configuration_atoms(joint_angles_deg, field="joint_angles_deg")


def _warnings(context: Context, obj: ArticulatedObject, memo: ObjectMemo, atoms: State,
              request: GoalRequest) -> list[str]:
    """The geometric check of a goal (placed objects, complete goals): raises ValidationError for an infeasible
    one unless allowed; the warnings to answer with."""
    base = memo.where
    if base is None:
        return []
    links = _goal_links(context, obj, memo, atoms, request.link_orientations_deg)
    if links is None:
        return []
    result = configuration_feasible(ObjectGeometry.of(obj, base), links)
    blocking = [r for r in result.reasons if r.code != "out_of_reach"]
    warnings = [f"goal: {r.message}" for r in result.reasons if r.code == "out_of_reach"]
    if blocking and not request.allow_infeasible:
        raise ValidationError("goal: " + "; ".join(r.message for r in blocking)
                              + " (send allow_infeasible: true to set it anyway)")
    if blocking:
        return [f"goal accepted although infeasible: {r.message}" for r in blocking] + warnings
    return _margin(obj, base, links, request.allow_infeasible) + warnings


def _margin(obj: ArticulatedObject, base: tuple[float, float], links: tuple[int, ...], allow: bool) -> list[str]:
    """A goal keeps the clearance every configuration of a plan comes to rest with (`geometry.PLANNING`: a
    physical turn ends a degree or two off): one drawn closer to the table's edges is reached where the robot can
    slide the object to make room (a warning says so), and refused when no such place exists (unless `allow`)."""
    geometry = ObjectGeometry.of(obj, base)
    tight = configuration_feasible(geometry, links, tolerance=PLANNING, reach_links=())
    if tight.ok:
        return []
    room = room_for_goal(geometry, links, Cell())
    why = "; ".join(r.message for r in tight.reasons)
    if room is not None:
        return [f"goal: {why} where the object lies; with its base point at ({room[0]:.2f}, {room[1]:.2f}) it keeps "
                f"{PLANNING.clearance_m * 100:.1f} cm from the table's edges: the robot makes room first where it can"]
    if not allow:
        raise ValidationError(f"goal: {why}; a goal keeps {PLANNING.clearance_m * 100:.1f} cm from the table's edges "
                              "(a physical turn ends a degree or two off) and no place the robot can slide the object "
                              "to gives it that (send allow_infeasible: true to set it anyway)")
    return [f"goal accepted although it does not keep {PLANNING.clearance_m * 100:.1f} cm from the table's edges: "
            f"{why}"]


def _goal_links(context: Context, obj: ArticulatedObject, memo: ObjectMemo, atoms: State,
                link_orientations_deg: tuple[float, ...] | None) -> tuple[int, ...] | None:
    """Every link's absolute orientation in a complete goal. Absolute formulation: as given. Relative: the goal
    holds only the angles between links and the robot turns downstream links, so l1 stays where it was last
    perceived (where it is given, before the first perception); None when the goal leaves a joint free or l1
    is not known."""
    values = obj.joint_values_of(atoms)
    if len(values) != obj.n_joints:
        return None
    if obj.formulation is Formulation.ABSOLUTE:
        return tuple(values[k] for k in obj.joint_indices)
    store = context.store
    perceived = store.get_state(memo.perceived_state_id) if memo.perceived_state_id is not None else None
    if perceived is not None and perceived.link_orientations_deg:
        first = snap_angle(perceived.link_orientations_deg[0], obj.orientations)
    elif link_orientations_deg is not None:
        first = int(float(link_orientations_deg[0])) % 360
    else:
        return None
    return obj.link_orientations_of(atoms, first)

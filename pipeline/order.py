"""An order of a plan's steps that keeps every configuration of an object placed in the cell on the table: the
planner's steps in another order or one joint the other way round (`planhrc.ordering`), else a longer plan through
intermediate configurations (`planhrc.detour.find_detour`); when none fits where the object lies, the place nearer
the table's middle where one does, for the robot to slide the object to first (`planhrc.detour.find_room`)."""
from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Sequence

from planhrc.detour import Room, find_detour, find_room
from planhrc.model import HAS_ORIENTATION, ArticulatedObject, DomainModelSpec, Formulation, State, orientation_name
from planhrc.ordering import CLOCKWISE, HelpItem, Move, Placement, feasible_alternative, first_obstacle, help_for
from planhrc.transition import StateIndex, apply, ground_action

from .motion import move_of

# How long the search for a detour may take, in step checks and as a share of the planning time left, then the
# search for room (a detour where the object cannot be turned at all would take every check it may: room gets the
# rest), and what they leave of the planning deadline for grounding, replaying and validating the plan they find.
# Shares rather than seconds: on a loaded machine a check takes longer, and a longer deadline gives the searches
# what they need to come to the same answer. Without a deadline each search gets UNBOUNDED_SEARCH_S.
DETOUR_CHECKS = 2000
DETOUR_SHARE = 0.5
ROOM_SHARE = 1.0
VAL_RESERVE_S = 2.0
UNBOUNDED_SEARCH_S = 2.5


@dataclass(frozen=True)
class Ordered:
    """The plan's steps in a feasible order, and what the ordering did in words."""

    steps: tuple[str, ...]
    sentence: str


@dataclass(frozen=True)
class Refusal:
    """No feasible order: why, and what to ask the human."""

    message: str
    help: tuple[HelpItem, ...]
    room: Room | None = None  # where the plan would fit: the robot may slide the object there first


def order_steps(obj: ArticulatedObject, model: DomainModelSpec, init: State, steps: Sequence[str],
                placement: Placement, deadline_at: float | None = None) -> Ordered | Refusal:
    """The planner's steps in an order whose every configuration is feasible (`ordering.feasible_alternative`:
    the same steps, else a longer plan turning one joint the other way round; else `detour.find_detour`: single
    steps through intermediate configurations), grounded again in that order (in the absolute formulation an
    action's from/to orientations depend on the turns before it). When nothing fits where the object lies, the
    refusal names the place where it would (`detour.find_room`). A bimanual plan is not reordered (its turns happen
    between a grasp and a release at their joint): its own order is checked."""
    moves = [move_of(obj, step) for step in steps]
    if obj.formulation is Formulation.BIMANUAL:
        step, problem = first_obstacle(placement, moves)
        if problem is None:
            return Ordered(tuple(steps), f"the planner's order of {len(moves)} actions stays on the table")
        return Refusal(f"the plan's action {step} would not stay on the table or within reach: {problem.sentence()}",
                       help_for(placement, moves, problem))
    answer, added = feasible_alternative(placement, moves, obj.orientations)
    if answer.moves is None:
        alphabet = alphabet_of(obj)
        detour = find_detour(placement, moves, alphabet, obj.orientations, budget=DETOUR_CHECKS,
                             deadline_at=search_deadline(deadline_at, DETOUR_SHARE))
        if detour.moves is not None:
            longer = len(detour.moves) - len(moves)
            obstacle = answer.problem.sentence() if answer.problem is not None else "no order found"
            why = (f"{longer} steps longer than the planner's {len(moves)}: no order of its steps, nor a joint "
                   f"turned the other way round, stays on the table ({obstacle}), so the plan goes through "
                   "intermediate configurations")
            return Ordered(steps_of(obj, model, init, detour.moves), why)
        room = find_room(placement, moves, alphabet, obj.orientations,
                         deadline_at=search_deadline(deadline_at, ROOM_SHARE))
        return Refusal(answer.sentence(), answer.help, room)
    clearance = f" ({answer.clearance_m * 100:.1f} cm from its edges at rest)"
    if list(answer.moves) == moves:
        return Ordered(tuple(steps), f"the planner's order of {len(moves)} actions stays on the table{clearance}")
    what = (f"{added} steps longer: one joint turns the other way round" if added
            else f"reordered {len(moves)} actions")
    return Ordered(steps_of(obj, model, init, answer.moves),
                   f"{what} so that every configuration stays on the table{clearance}")


def steps_of(obj: ArticulatedObject, model: DomainModelSpec, init: State, moves: Sequence[Move]) -> tuple[str, ...]:
    """PDDL steps for `moves` in this order from `init`: each from the joint's orientation at that point."""
    state, steps = frozenset(init), []
    index = StateIndex(state)
    for move in moves:
        joint = obj.joint(move.joint)
        now = next(int(a[1].split("_", 1)[1]) for a in state if a[0] == HAS_ORIENTATION and a[2] == joint)
        after = (now + (obj.step if move.name == "rotateclockwise" else -obj.step)) % 360
        step = (f"({move.name} {obj.link(move.turned)} {obj.link(move.held)} {joint} {orientation_name(now)} "
                f"{orientation_name(after)})")
        state = apply(state, ground_action(model, step, state, index))
        index.moved(state)
        steps.append(step)
    return tuple(steps)


def search_deadline(deadline_at: float | None, share: float) -> float:
    """When a search for a longer plan or for room stops: after `share` of the time left until `VAL_RESERVE_S`
    before the planning deadline (the plan found is still grounded, replayed and checked by VAL within it)."""
    now = time.monotonic()
    if deadline_at is None:
        return now + UNBOUNDED_SEARCH_S
    return now + max(0.0, deadline_at - VAL_RESERVE_S - now) * share


def alphabet_of(obj: ArticulatedObject) -> tuple[Move, ...]:
    """One clockwise step of every joint the robot turns in a detour: the downstream link, the one before held
    (absolute: link K about joint K, link 1 against the table; relative: link K+1 about joint K)."""
    if obj.formulation is Formulation.ABSOLUTE:
        return tuple(Move(CLOCKWISE, k, k - 1, k, obj.step) for k in range(1, obj.n_links + 1))
    return tuple(Move(CLOCKWISE, k + 1, k, k, obj.step) for k in range(1, obj.n_links))

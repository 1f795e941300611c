"""An order of a plan's steps that keeps every configuration of an object placed in the cell on the table."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

from planhrc.model import HAS_ORIENTATION, ArticulatedObject, DomainModelSpec, Formulation, State, orientation_name
from planhrc.ordering import HelpItem, Move, Placement, feasible_alternative, first_obstacle, help_for
from planhrc.transition import StateIndex, apply, ground_action

from .motion import move_of


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


def order_steps(obj: ArticulatedObject, model: DomainModelSpec, init: State, steps: Sequence[str],
                placement: Placement) -> Ordered | Refusal:
    """The planner's steps in an order whose every configuration is feasible (`ordering.feasible_alternative`:
    the same steps, else a longer plan turning one joint the other way round), grounded again in that order (in
    the absolute formulation an action's from/to orientations depend on the turns before it). A bimanual plan is
    not reordered (its turns happen between a grasp and a release at their joint): its own order is checked."""
    moves = [move_of(obj, step) for step in steps]
    if obj.formulation is Formulation.BIMANUAL:
        step, problem = first_obstacle(placement, moves)
        if problem is None:
            return Ordered(tuple(steps), f"the planner's order of {len(moves)} actions stays on the table")
        return Refusal(f"the plan's action {step} would not stay on the table or within reach: {problem.sentence()}",
                       help_for(placement, moves, problem))
    answer, added = feasible_alternative(placement, moves, obj.orientations)
    if answer.moves is None:
        return Refusal(answer.sentence(), answer.help)
    room = f" ({answer.clearance_m * 100:.1f} cm from its edges at rest)"
    if list(answer.moves) == moves:
        return Ordered(tuple(steps), f"the planner's order of {len(moves)} actions stays on the table{room}")
    what = (f"{added} steps longer: one joint turns the other way round" if added
            else f"reordered {len(moves)} actions")
    return Ordered(steps_of(obj, model, init, answer.moves),
                   f"{what} so that every configuration stays on the table{room}")


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

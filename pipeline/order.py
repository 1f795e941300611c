"""The robot's plan for an object placed in the cell: the planner says where the object must end (the state of the
domain its plan reaches); the robot's turns and slides that get it there in the least robot time, every
configuration on the table, come from one search (`planhrc.motion_search.plan_work`), and are grounded again as
steps of the domain for VAL and the replay. When no such plan exists, the refusal says why and what to ask the
human."""
from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Sequence

from planhrc.model import (HAS_ORIENTATION, HOLDING, IN_CENTRE, KEEPER, ArticulatedObject, DomainModelSpec,
                           Formulation, State, orientation_name)
from planhrc.motion_search import Hands, NoWork, Slide, Work, alphabet_of, plan_work, target_offsets
from planhrc.ordering import ANTICLOCKWISE, CLOCKWISE, HelpItem, Move, Placement, first_obstacle, help_for
from planhrc.transition import StateIndex, apply, ground_action

from .config import LaterSlide
from .motion import move_of

# What share of the planning time left the search takes (after VAL_RESERVE_S kept for grounding, replaying and
# validating the plan it finds); shares rather than seconds: on a loaded machine a longer deadline gives the search
# what it needs to come to the same answer. Without a deadline the search gets UNBOUNDED_SEARCH_S.
SEARCH_SHARE = 0.8
VAL_RESERVE_S = 2.0
UNBOUNDED_SEARCH_S = 8.0
# Of the search's time, what the search with a slide before the first turn at most takes; when it finds no plan, the
# search with slides between turns too has the rest (`order_steps`).
FIRST_SLIDE_SHARE = 0.6


@dataclass(frozen=True)
class Ordered:
    """The plan's steps as the robot will do them, what the search found in words, the slide that comes first
    (None: the robot turns where the object lies) and those between its turns (relative and absolute objects:
    a bimanual robot's hands make room before the first turn only)."""

    steps: tuple[str, ...]
    sentence: str
    slide: Slide | None = None
    later_slides: tuple[LaterSlide, ...] = ()


@dataclass(frozen=True)
class Refusal:
    """No plan the robot can carry out on this table: why, and what to ask the human."""

    message: str
    help: tuple[HelpItem, ...]


def order_steps(obj: ArticulatedObject, model: DomainModelSpec, init: State, steps: Sequence[str],
                placement: Placement, deadline_at: float | None = None) -> Ordered | Refusal:
    """The robot's plan reaching the end of the planner's `steps` (the same state of the domain) in the least robot
    time the table allows, or within the bound the search states (`planhrc.motion_search`), grounded from `init`:
    with a slide before the first turn at most; only when there is no such plan (or none was found in its share of
    the time), with slides between turns too (not a bimanual robot's). A slide half-way is a physical motion from a
    configuration the robot has not just planned from, so it is the fallback, not the first choice."""
    moves = [m for m in (move_of(obj, step) for step in steps) if m.delta_deg]
    alphabet = alphabet_of(obj)
    target = target_offsets(alphabet, moves, obj.orientations, obj.step)
    if target is None:
        return Refusal("the plan turns a joint the robot does not turn", ())
    hands = hands_of(obj, init)
    end = search_deadline(deadline_at, SEARCH_SHARE)
    between = placement.slides and not hands.bimanual
    first_end = time.monotonic() + FIRST_SLIDE_SHARE * max(0.0, end - time.monotonic()) if between else end
    work = plan_work(placement, alphabet, target, obj.orientations, hands=hands, slides=placement.slides,
                     deadline_at=first_end)
    if isinstance(work, NoWork) and between:  # no plan that makes room first only: room made between turns too
        work = plan_work(placement, alphabet, target, obj.orientations, hands=hands, between=True, deadline_at=end)
    if isinstance(work, NoWork):
        step, problem = first_obstacle(placement, moves)
        return Refusal(f"no plan of the robot's turns{' and slides' if placement.slides else ''} stays on the table "
                       f"and within reach: {work.reason}", help_for(placement, moves, problem))
    grounded = (bimanual_steps(obj, model, init, work.turns) if obj.formulation is Formulation.BIMANUAL
                else steps_of(obj, model, init, work.turns))
    slide = work.motions[0] if work.motions and isinstance(work.motions[0], Slide) else None
    later = later_slides(work)
    return Ordered(grounded, _sentence(work, slide, later, len(grounded)), slide, later)


def later_slides(work: Work) -> tuple[LaterSlide, ...]:
    """The slides of `work` that come after its first turn, each with the step it comes before (one step per
    turn: a relative or absolute object's plan)."""
    out: list[LaterSlide] = []
    turns = 0
    for motion in work.motions:
        if isinstance(motion, Slide):
            if turns:
                out.append(LaterSlide(turns + 1, motion))
        else:
            turns += 1
    return tuple(out)


def _sentence(work: Work, slide: Slide | None, later: Sequence[LaterSlide], steps: int) -> str:
    """What the search found, for the decision's reason: the slides and where they come, its length beside the
    planner's and the unconstrained shortest, the robot's time and the proof."""
    first = f"{slide.sentence()} first, then " if slide is not None else ""
    between = "".join(f"; before step {s.before_step}, {s.slide.sentence()}" for s in later)
    return (f"{first}{steps} steps that keep every configuration on the table and within reach{between} "
            f"({work.sentence()})")


def hands_of(obj: ArticulatedObject, init: State) -> Hands:
    """What the robot's hands do when the plan starts: a bimanual robot's centred joint and whether it holds the
    links there; nothing for the other formulations (each turn grasps anew)."""
    if obj.formulation is not Formulation.BIMANUAL:
        return Hands()
    centre = next((obj.joint_indices[obj.joints.index(a[1])] for a in init if a[0] == IN_CENTRE), 1)
    up, down = obj.joint_links(centre)
    held = {a[2] for a in init if a[0] == HOLDING}
    return Hands(bimanual=True, centre=centre, grasped={up, down} <= held)


def steps_of(obj: ArticulatedObject, model: DomainModelSpec, init: State, moves: Sequence[Move]) -> tuple[str, ...]:
    """PDDL steps for `moves` in this order from `init`: each from the joint's orientation at that point."""
    state, steps = frozenset(init), []
    index = StateIndex(state)
    for move in moves:
        joint = obj.joint(move.joint)
        now = _orientation(state, joint)
        after = (now + (obj.step if move.name == CLOCKWISE else -obj.step)) % 360
        step = (f"({move.name} {obj.link(move.turned)} {obj.link(move.held)} {joint} {orientation_name(now)} "
                f"{orientation_name(after)})")
        state = apply(state, ground_action(model, step, state, index))
        index.moved(state)
        steps.append(step)
    return tuple(steps)


def bimanual_steps(obj: ArticulatedObject, model: DomainModelSpec, init: State, moves: Sequence[Move]
                   ) -> tuple[str, ...]:
    """The bimanual robot's steps for single-step `moves` (each the downstream link of its joint, the link before
    held) from `init`: for each run of turns at one joint, the hands let go of the joint they hold, centre on it
    and grasp (as needed), then turn, consecutive steps one way merged into 45-degree turns where the domain has
    them; the hands keep the last grasp."""
    keeper = next(a[1] for a in init if a[0] == KEEPER)
    turner = next(g for g in obj.grippers if g != keeper)
    state = frozenset(init)
    index = StateIndex(state)
    out: list[str] = []

    def do(step: str) -> None:
        nonlocal state
        state = apply(state, ground_action(model, step, state, index))
        index.moved(state)
        out.append(step)

    hands = hands_of(obj, init)
    centre, grasped = hands.centre, hands.grasped
    macro = obj.has_macros and 45 // obj.step
    i = 0
    while i < len(moves):
        k = moves[i].joint
        up, down = obj.joint_links(k)
        if centre != k:
            if grasped:
                was_up, was_down = obj.joint_links(centre)
                do(f"(releaselinks {was_down} {was_up} {obj.joint(centre)} {turner} {keeper})")
            do(f"(movetocentre {down} {up} {obj.joint(k)} {obj.joint(centre)} {turner} {keeper})")
            centre, grasped = k, False
        if not grasped:
            do(f"(grasplinks {down} {up} {obj.joint(k)} {turner} {keeper})")
            grasped = True
        run = i
        while run < len(moves) and moves[run].joint == k:
            run += 1
        j = i
        while j < run:
            name = moves[j].name
            same = 1
            while j + same < run and moves[j + same].name == name:
                same += 1
            whole, single = (divmod(same, macro) if macro else (0, same))
            for _ in range(whole):
                now = _orientation(state, obj.joint(k))
                after = (now + (45 if name == CLOCKWISE else -45)) % 360
                do(f"({name}45 {down} {up} {obj.joint(k)} {orientation_name(now)} {orientation_name(after)} "
                   f"{turner} {keeper})")
            for _ in range(single):
                now = _orientation(state, obj.joint(k))
                after = (now + (obj.step if name == CLOCKWISE else -obj.step)) % 360
                do(f"({name} {down} {up} {obj.joint(k)} {orientation_name(now)} {orientation_name(after)} "
                   f"{turner} {keeper})")
            j += same
        i = run
    return tuple(out)


def _orientation(state: State, joint: str) -> int:
    return next(int(a[1].split("_", 1)[1]) for a in state if a[0] == HAS_ORIENTATION and a[2] == joint)


def search_deadline(deadline_at: float | None, share: float) -> float:
    """When the search stops: after `share` of the time left until `VAL_RESERVE_S` before the planning deadline
    (the plan found is still grounded, replayed and checked by VAL within it)."""
    now = time.monotonic()
    if deadline_at is None:
        return now + UNBOUNDED_SEARCH_S
    return now + max(0.0, deadline_at - VAL_RESERVE_S - now) * share

"""The robot's plan for an object placed in the cell: the planner says where the object must end (the state of the
domain its plan reaches); the robot's turns and slides that get it there in the least robot time, every
configuration on the table, come from one search (`planhrc.motion_search.plan_work`), and are grounded again as
steps of the domain for VAL and the replay. When no such plan exists, the refusal says why and what to ask the
human."""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace
from typing import Iterator, Sequence

from planhrc.model import (HAS_ORIENTATION, HOLDING, IN_CENTRE, KEEPER, ArticulatedObject, DomainModelSpec,
                           Formulation, State, orientation_name, snap_angle)
from planhrc.geometry import PLANNING, rotated
from planhrc.judge import Baseline, judge_turn
from planhrc.motion_search import (Hands, NoWork, Slide, Work, alphabet_of, grip_links, places_about, plan_work,
                                   slide_feasible, target_offsets)
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
# A joint at least this far off the orientation grid (a turn dragged the object) is turned back onto it when no plan
# fits where the links lie (`straightening`); the perception's ordinary error is a degree or two.
STRAIGHTEN_MIN_DEG = 6.0


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
class Straighten:
    """No plan fits where the links lie, one fits once links dragged off the orientation grid are turned back onto
    it: the turns (turned link, held link, degrees, in order) and what the search found from there, in words."""

    turns: tuple[tuple[int, int, float], ...]
    sentence: str
    slide: Slide | None = None  # where the robot slides the object first, for room to straighten it


@dataclass(frozen=True)
class Fix:
    """Links turned back onto the orientation grid (`turns`), where the object lies or after `slide`, and where
    they then lie."""

    turns: tuple[tuple[int, int, float], ...]
    slide: Slide | None
    placement: Placement


@dataclass(frozen=True)
class Refusal:
    """No plan the robot can carry out on this table: why, and what to ask the human."""

    message: str
    help: tuple[HelpItem, ...]


def order_steps(obj: ArticulatedObject, model: DomainModelSpec, init: State, steps: Sequence[str],
                placement: Placement, deadline_at: float | None = None) -> Ordered | Straighten | Refusal:
    """The robot's plan reaching the end of the planner's `steps` (the same state of the domain) in the least robot
    time the table allows, or within the bound the search states (`planhrc.motion_search`), grounded from `init`:
    with a slide before the first turn at most; only when there is no such plan (or none was found in its share of
    the time), with slides between turns too (not a bimanual robot's). A slide half-way is a physical motion from a
    configuration the robot has not just planned from, so it is the fallback, not the first choice. When neither
    finds a plan and a turn dragged links off the orientation grid, the links turned back onto it
    (`straightening`) are searched from: a plan there is answered with the straightening (`Straighten`)."""
    moves = [m for m in (move_of(obj, step) for step in steps) if m.delta_deg]
    alphabet = alphabet_of(obj)
    target = target_offsets(alphabet, moves, obj.orientations, obj.step)
    if target is None:
        return Refusal("the plan turns a joint the robot does not turn", ())
    hands = hands_of(obj, init)
    end = search_deadline(deadline_at, SEARCH_SHARE)
    work = _search(obj, placement, alphabet, target, hands, end)
    if isinstance(work, NoWork) and placement.straightens and not hands.bimanual:
        for fix in straightenings(obj, placement):
            again = _search(obj, fix.placement, alphabet, target, hands, end)
            if isinstance(again, Work):
                done = ", ".join(f"link {t} by {d:+.1f}°" for t, _, d in fix.turns)
                first = f"{fix.slide.sentence()}, then " if fix.slide is not None else ""
                return Straighten(fix.turns, f"{first}links off the orientation grid turned back onto it ({done}), "
                                  f"then {_sentence(again, None, later_slides(again), len(again.turns))}", fix.slide)
            if time.monotonic() > end:
                break
    if isinstance(work, NoWork):
        step, problem = first_obstacle(placement, moves)
        return Refusal(f"no plan of the robot's turns{' and slides' if placement.slides else ''} stays on the table "
                       f"and within reach: {work.reason}", help_for(placement, moves, problem))
    grounded = (bimanual_steps(obj, model, init, work.turns) if obj.formulation is Formulation.BIMANUAL
                else steps_of(obj, model, init, work.turns))
    slide = work.motions[0] if work.motions and isinstance(work.motions[0], Slide) else None
    later = later_slides(work)
    return Ordered(grounded, _sentence(work, slide, later, len(grounded)), slide, later)


def _search(obj: ArticulatedObject, placement: Placement, alphabet: Sequence[Move], target: Sequence[int],
            hands: Hands, end: float) -> Work | NoWork:
    """The search with a slide first at most, then (relative, absolute) with slides between turns too, by `end`."""
    between = placement.slides and not hands.bimanual
    first_end = time.monotonic() + FIRST_SLIDE_SHARE * max(0.0, end - time.monotonic()) if between else end
    work = plan_work(placement, alphabet, target, obj.orientations, hands=hands, slides=placement.slides,
                     deadline_at=first_end)
    if isinstance(work, NoWork) and between:  # no plan that makes room first only: room made between turns too
        work = plan_work(placement, alphabet, target, obj.orientations, hands=hands, between=True, deadline_at=end)
    return work


def straightenings(obj: ArticulatedObject, placement: Placement) -> Iterator[Fix]:
    """The turns that bring every joint at least `STRAIGHTEN_MIN_DEG` off the orientation grid back onto it (in
    joint order, each turn the joint's downstream link, the link before it held; absolute: link 1 against the
    table), made where the object lies, else after a slide to a place of the search's grid nearest first (with
    `placement.slides`), wherever the one judge accepts each from where the ones before leave the object (resting
    with the planning clearance); none when no joint is that far off."""
    cell = placement.cell
    angles = tuple(float(a) for a in placement.link_deg)
    # each link's angle less the nearest orientation of the object's grid (as a perception snaps it)
    off = [((a - snap_angle(a, obj.orientations)) + 180.0) % 360.0 - 180.0 for a in angles]
    if obj.formulation is Formulation.ABSOLUTE:
        joints = [(k, k - 1, off[k - 1] - (off[k - 2] if k > 1 else 0.0)) for k in range(1, obj.n_links + 1)]
    else:
        joints = [(k + 1, k, off[k] - off[k - 1]) for k in range(1, obj.n_links)]
    turns = tuple((turned, held, round(-d, 2)) for turned, held, d in joints if abs(d) >= STRAIGHTEN_MIN_DEG)
    if not turns:
        return
    origin = placement.geometry.base_point_xy
    for to in places_about(placement, placement.slides):
        slide = None
        if to != tuple(float(v) for v in origin):
            links = grip_links(placement, to)
            if links is None or not slide_feasible(placement, to, links).ok:
                continue
            slide = Slide(to_xy=to, links=links, distance_m=math.dist(origin, to))
        geometry = placement.geometry.placed(to)
        baseline, here = Baseline.of(geometry, angles, cell), angles
        for turned, held, delta in turns:
            if not judge_turn(geometry, here, turned, held, delta, cell, baseline, rest=PLANNING).ok:
                break
            geometry, here = rotated(geometry, here, turned, held, delta)
        else:
            yield Fix(turns, slide, replace(placement, geometry=geometry, link_deg=here))


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

"""Plans that fit the table when no order of the planner's steps does: a detour through intermediate
configurations, or room made by sliding the whole object towards the table's middle.

`find_detour` searches the configurations reachable by single steps of every joint (each joint's downstream link
turned one orientation step either way, the link before it held), weighted A* from where the object lies to the
planner's end (the same joint angles, so the same state of the domain), every step checked by the one judge
(`planhrc.judge.judge_turn`, through `ordering._Search`: the same rests, the same refused motions). Each step
changes exactly one joint's angle by one step, so the sum over joints of the shortest way round to the end's angle
is a lower bound of the steps left (the heuristic), and the optimal plan's length: a detour found is as long as
the optimal plan plus the steps it adds, and says so.

`find_room` looks for a place nearer the table's middle where the plan (or an order, the other way round, a detour)
fits, and that the robot can slide the object to with both arms: the links it grasps within reach before and after,
every configuration along the slide on the table and clear of the robot.
"""
from __future__ import annotations

import heapq
import itertools
import math
import time
from dataclasses import dataclass, replace
from typing import Sequence

import numpy as np

from planhrc.geometry import (STRICT, Feasibility, ObjectGeometry, configuration_feasible, joint_points, link_centres,
                              reach_shortfall)
from planhrc.judge import Baseline
from planhrc.ordering import (ANTICLOCKWISE, CLOCKWISE, DEFAULT_BUDGET, Move, Ordering, Placement, _OutOfBudget,
                              _Search, feasible_alternative, final_configuration)

# Step checks a detour search may make: about as many as the ordering's own search.
DETOUR_BUDGET = DEFAULT_BUDGET
# Weight of the heuristic (weighted A*): a detour a few steps longer than the shortest one, found with far fewer
# checks; the shortest detours are the usual ones (a link turned out of the way and back).
DETOUR_WEIGHT = 1.5
SLIDE_INCREMENT_M = 0.02  # how finely a slide is checked
MAX_SLIDE_M = 0.30  # how far the robot slides an object in one go (both grippers stay within reach)


@dataclass(frozen=True)
class Room:
    """Where to slide the object (its base point to `to_xy`, grasping links `links`) so that the plan fits there,
    the plan found there, and a sentence."""

    to_xy: tuple[float, float]
    links: tuple[int, int]
    moves: tuple[Move, ...]
    sentence: str


def find_detour(placement: Placement, moves: Sequence[Move], alphabet: Sequence[Move], orientations: int,
                budget: int = DETOUR_BUDGET, deadline_at: float | None = None) -> Ordering:
    """A sequence of single steps from where the object lies to the end of `moves` (the same joint angles), every
    step feasible: weighted A* over the joints' angles (see the module's note). `alphabet` is one clockwise step
    of every joint the robot may turn (the downstream link, held by the one before). Not found: the answer says
    whether the search was exhausted or stopped at its budget or deadline."""
    joints = {m.joint: i for i, m in enumerate(alphabet)}
    step = 360 // orientations
    target = [0] * len(alphabet)
    for move in moves:
        if move.joint not in joints:
            return Ordering(None, 0)
        i = joints[move.joint]
        same_side = move.turned == alphabet[i].turned
        target[i] = (target[i] + (1 if (move.delta_deg > 0) == same_side else -1)) % orientations
    goal = tuple(target)
    search = _Search(placement, budget, baseline=Baseline.of(placement.geometry, placement.link_deg, placement.cell))
    start = tuple([0] * len(alphabet))
    base = tuple(float(a) for a in placement.link_deg)

    def angles(node: tuple[int, ...]) -> tuple[float, ...]:
        turn = [0.0] * len(base)
        for i, offset in enumerate(node):
            for k in range(alphabet[i].turned - 1, len(base)):
                turn[k] += offset * step
        return tuple((a + t) % 360.0 for a, t in zip(base, turn))

    def h(node: tuple[int, ...]) -> int:
        return sum(min((g - n) % orientations, (n - g) % orientations) for n, g in zip(node, goal))

    tie = itertools.count()
    frontier = [(DETOUR_WEIGHT * h(start), next(tie), 0, start)]
    parent: dict[tuple[int, ...], tuple[tuple[int, ...], Move] | None] = {start: None}
    cost = {start: 0}
    closed: set[tuple[int, ...]] = set()
    try:
        while frontier:
            if deadline_at is not None and time.monotonic() > deadline_at:
                return Ordering(None, search.checks, exhausted=False)
            _, _, g, node = heapq.heappop(frontier)
            if node == goal:
                path: list[Move] = []
                at: tuple[int, ...] = node
                while (link := parent[at]) is not None:
                    at, move = link
                    path.append(move)
                return Ordering(tuple(reversed(path)), search.checks)
            if node in closed:
                continue
            closed.add(node)
            here = angles(node)
            for i, forward in enumerate(alphabet):
                for sign in (1, -1):
                    nxt = tuple((v + sign) % orientations if j == i else v for j, v in enumerate(node))
                    if nxt in closed or cost.get(nxt, math.inf) <= g + 1:
                        continue
                    move = replace(forward, name=CLOCKWISE if sign > 0 else ANTICLOCKWISE, delta_deg=sign * step)
                    if not search.step(placement.geometry, here, move, last=nxt == goal).ok:
                        continue
                    cost[nxt] = g + 1
                    parent[nxt] = (node, move)
                    heapq.heappush(frontier, (g + 1 + DETOUR_WEIGHT * h(nxt), next(tie), g + 1, nxt))
    except _OutOfBudget:
        return Ordering(None, search.checks, exhausted=False)
    return Ordering(None, search.checks)


def slide_feasible(placement: Placement, to_xy: Sequence[float], links: tuple[int, int]) -> Feasibility:
    """Whether the robot can slide the object from where it lies to base point `to_xy` holding `links`: both within
    reach before and after, and every configuration on the way (every 2 cm) on the table, clear of the robot and
    unfolded as drawn (problems the object has where it lies, no worse, excused)."""
    geometry, angles, cell = placement.geometry, placement.link_deg, placement.cell
    baseline = Baseline.of(geometry, angles, cell)
    start = np.asarray(geometry.base_point_xy)
    shift = np.asarray(to_xy, dtype=float) - start
    n = max(1, int(math.ceil(float(np.linalg.norm(shift)) / SLIDE_INCREMENT_M)))
    for i in (n, *range(1, n)):
        placed = geometry.placed(start + shift * i / n)
        result = configuration_feasible(placed, angles, cell, reach_links=links if i == n else (),
                                        tolerance=STRICT)
        new = tuple(r for r in result.reasons if not baseline.excused(r))
        if new:
            return Feasibility(False, new)
    return Feasibility(True)


def grip_links(placement: Placement, to_xy: Sequence[float]) -> tuple[int, int] | None:
    """Two links the arms can slide the object by (reachable where it lies and at `to_xy`), as far apart along
    the chain as can be; None when fewer than two are."""
    geometry, angles, robot = placement.geometry, placement.link_deg, placement.cell.robot
    there = geometry.placed(to_xy)
    ok = [k for k, (a, b) in enumerate(zip(link_centres(geometry, angles), link_centres(there, angles)), start=1)
          if reach_shortfall(a, robot) <= 1e-9 and reach_shortfall(b, robot) <= 1e-9]
    if len(ok) < 2:
        return None
    return ok[0], ok[-1]


def find_room(placement: Placement, moves: Sequence[Move], alphabet: Sequence[Move], orientations: int,
              budget: int = DETOUR_BUDGET, deadline_at: float | None = None) -> Room | None:
    """A place nearer the table's middle where the plan fits and that the robot can slide the object to (see the
    module's note), or None. Candidates: the object's middle (where it lies and where the plan ends) moved all or
    half the way to the table's middle, and along one axis only; at most `MAX_SLIDE_M` each."""
    geometry = placement.geometry
    end_geometry, end = final_configuration(placement, moves)
    points = np.vstack([_points(geometry, placement.link_deg), _points(end_geometry, end)])
    middle = (points.min(axis=0) + points.max(axis=0)) / 2.0
    centre = np.asarray(placement.cell.table.center_xy)
    base = np.asarray(geometry.base_point_xy)
    shifts: list[np.ndarray] = []
    for fraction in (1.0, 0.5):
        for mask in ((1.0, 1.0), (1.0, 0.0), (0.0, 1.0)):
            shift = (centre - middle) * fraction * np.asarray(mask)
            length = float(np.linalg.norm(shift))
            if length < SLIDE_INCREMENT_M:
                continue
            if length > MAX_SLIDE_M:
                shift *= MAX_SLIDE_M / length
            if not any(np.allclose(shift, s, atol=0.01) for s in shifts):
                shifts.append(shift)
    share = max(1, budget // max(1, len(shifts)))
    for shift in shifts:
        if deadline_at is not None and time.monotonic() > deadline_at:
            return None
        to = base + shift
        to_xy = (round(float(to[0]), 3), round(float(to[1]), 3))
        links = grip_links(placement, to_xy)
        if links is None or not slide_feasible(placement, to_xy, links).ok:
            continue
        there = replace(placement, geometry=geometry.placed(to_xy))
        answer, _ = feasible_alternative(there, moves, orientations, budget=share)
        if not answer.found:
            answer = find_detour(there, moves, alphabet, orientations, budget=share, deadline_at=deadline_at)
        if answer.moves is not None:
            return Room(to_xy, links, answer.moves,
                        f"slide the object {float(np.linalg.norm(shift)) * 100:.0f} cm towards the table's middle "
                        f"(base point to ({to_xy[0]:.2f}, {to_xy[1]:.2f}), holding links {links[0]} and {links[1]}): "
                        f"there the plan's {len(answer.moves)} actions stay on the table")
    return None


def _points(geometry: ObjectGeometry, angles: Sequence[float]) -> np.ndarray:
    return np.asarray(joint_points(geometry, angles))

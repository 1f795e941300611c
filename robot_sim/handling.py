"""How a human brings the object from one configuration to another safely: pure functions on values.

A human turns a link about its joint with the link before it (l1 about its end on the table), carrying the
links beyond (assumption A1). Such turns change one joint angle each, so they commute: the end depends only on
how much each joint turns. The order still matters on a table: a long chain swung the wrong way sweeps past
the table's edge or through the robot. A human lifts the link it turns over the others, but the links beyond
slide along on the table and nobody reaches through the robot, so a sweep must keep the object on the table
and clear of the robot's body (`SWEEP_HAZARDS`, judged with `planhrc.geometry.EXECUTION`'s tolerance);
problems the object has before the first turn do not count.

* `turn_order`: the joint turns in an order and a way round (delta or 360 - delta) whose every sweep is safe;
* `turn_path`: when no such order exists, a path through intermediate configurations, one joint at a time by at
  most `step_deg`, found by a weighted A* (few moves, quickly), within a budget of sweep checks.
"""
from __future__ import annotations

import heapq
import itertools
import math
from typing import Mapping, Sequence

from planhrc.geometry import Cell, ObjectGeometry, rotated
from planhrc.robot_sim.scene import sweep_hazard
from planhrc.vocabulary import Infeasible

SWEEP_HAZARDS = (Infeasible.OFF_TABLE, Infeasible.INSIDE_ROBOT)
PATH_BUDGET = 6000  # sweep checks of one search: bounds the time the human spends looking for a way (then: None)
GREED = 2.0  # weighted A*: the estimate counts twice, so the search goes for the goal first (not always the fewest moves)


def shorter(delta_deg: float) -> float:
    """The same turn in (-180, 180]."""
    return (delta_deg + 180.0) % 360.0 - 180.0


def joint_angles(theta: Sequence[float]) -> tuple[float, ...]:
    """Each link's orientation relative to the link before it (l1's to the table), degrees in [0, 360)."""
    return tuple((t - (theta[k - 1] if k else 0.0)) % 360.0 for k, t in enumerate(theta))


def orientations(joints: Sequence[float]) -> tuple[float, ...]:
    """The links' orientations from their joint angles (the inverse of `joint_angles`)."""
    return tuple(v % 360.0 for v in itertools.accumulate(joints))


def turn_order(geometry: ObjectGeometry, theta: Sequence[float], cell: Cell, turns: Mapping[int, float],
               baseline: frozenset[tuple[Infeasible, int]]) -> list[tuple[int, float]] | None:
    """An order, and a way round, in which to make the joint turns `turns` (link -> degrees relative to the link
    before it) so that every sweep is safe: [(link, degrees)], or None. A depth-first search over the turns still
    to make, upstream first, remembering the sets of turns from which no order works."""
    links = sorted(k for k, d in turns.items() if abs(d) > 1e-9)
    dead: set[frozenset[int]] = set()

    def visit(done: frozenset[int], angles: tuple[float, ...]) -> list[tuple[int, float]] | None:
        if len(done) == len(links):
            return []
        if done in dead:
            return None
        for k in links:
            if k in done:
                continue
            d = turns[k]
            for way in (d, d - math.copysign(360.0, d)):
                if sweep_hazard(geometry, angles, cell, k, k - 1, way, baseline, SWEEP_HAZARDS) is None:
                    rest = visit(done | {k}, rotated(geometry, angles, k, k - 1, way)[1])
                    if rest is not None:
                        return [(k, way)] + rest
                    break  # the same configuration either way round: a dead end both ways
        dead.add(done)
        return None

    return visit(frozenset(), tuple(float(v) for v in theta))


def turn_path(geometry: ObjectGeometry, theta: Sequence[float], cell: Cell, wanted_joints: Sequence[float],
              baseline: frozenset[tuple[Infeasible, int]], step_deg: float = 45.0, budget: int = PATH_BUDGET
              ) -> list[tuple[int, float]] | None:
    """Moves of one joint by at most `step_deg` each, every sweep safe, that bring the joint angles
    from those of `theta` to `wanted_joints`: [(link, degrees)] with consecutive moves of a joint merged, or None
    when the search finds none within `budget` sweep checks. A weighted A* over the joints' values: a move costs
    one, the estimate of what is left (each joint's steps to its wanted value) counts `GREED` times.

    Each joint takes the values `wanted + m * step_deg` (m = 0 .. 360/step_deg - 1), or keeps the value it has at
    the start until it first moves (to the nearest of those values either way round)."""
    n = len(theta)
    now = joint_angles(theta)
    grid = max(1, round(360.0 / step_deg))
    step = 360.0 / grid

    def value(k: int, m: int | None) -> float:
        return now[k] if m is None else (wanted_joints[k] + m * step) % 360.0

    def moves_left(k: int, m: int | None) -> int:
        if m is None:
            return math.ceil((abs(shorter(wanted_joints[k] - now[k])) - 1e-6) / step)
        return min(m, grid - m)

    start = tuple(0 if abs(shorter(wanted_joints[k] - now[k])) < 1e-6 else None for k in range(n))
    goal = (0,) * n
    checks = 0
    counter = itertools.count()
    # (estimate, tie-break, moves so far, state, path of (link, degrees) turns)
    frontier: list[tuple[float, int, int, tuple[int | None, ...], tuple[tuple[int, float], ...]]] = [
        (float(sum(moves_left(k, m) for k, m in enumerate(start))), next(counter), 0, start, ())]
    closed: set[tuple[int | None, ...]] = set()
    while frontier:
        _, _, cost, state, path = heapq.heappop(frontier)
        if state == goal:
            return _merged(path)
        if state in closed:
            continue
        closed.add(state)
        angles = orientations([value(k, m) for k, m in enumerate(state)])
        for k, m in enumerate(state):
            if m is None:
                options = []
                for sign in (1.0, -1.0):
                    ahead = [(((value(k, j) - now[k]) * sign) % 360.0, j) for j in range(grid)]
                    d, j = min((d, j) for d, j in ahead if d > 1e-6)
                    options.append((sign * d, j))
            else:
                options = [(step, (m + 1) % grid), (-step, (m - 1) % grid)]
            for delta, j in options:
                after = state[:k] + (j,) + state[k + 1:]
                if after in closed:
                    continue
                checks += 1
                if checks > budget:
                    return None
                if sweep_hazard(geometry, angles, cell, k + 1, k, delta, baseline, SWEEP_HAZARDS) is not None:
                    continue
                estimate = cost + 1 + GREED * sum(moves_left(i, v) for i, v in enumerate(after))
                heapq.heappush(frontier, (estimate, next(counter), cost + 1, after, path + ((k + 1, delta),)))
    return None


def _merged(path: Sequence[tuple[int, float]]) -> list[tuple[int, float]]:
    """Consecutive moves of the same joint the same way as one move."""
    out: list[tuple[int, float]] = []
    for link, delta in path:
        if out and out[-1][0] == link and out[-1][1] * delta > 0:
            out[-1] = (link, out[-1][1] + delta)
        else:
            out.append((link, delta))
    return out

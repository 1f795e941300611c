"""The one judge of a robot's turn: whether turning a link about its joint may be done from a pose, and if not, the
geometric fact that forbids it (which link, against which edge or body, how far).

The service (ordering a plan's steps, checking the rest of a plan before it dispatches the next motion) and the
worker (before it moves) call `judge_turn` with the same pose and the same tolerances, so that what one accepts
the other accepts: the pose is the measured one (the link orientations the camera saw and the base point it
measured, not the snapped orientations of the state) and the tolerances are `planhrc.geometry`'s:

* the grasped links (the turned one and the held one) are within reach before the turn and wherever it goes, the
  held one of one arm and the turned one of the other where the turn starts and where it ends;
* every configuration the turn sweeps through (every 5°) lies on the table, out of the robot's body and unfolded,
  as drawn (`STRICT`);
* the configuration it comes to rest in keeps `rest`'s clearance from the table's edges (`PLANNING`'s 1.5 cm on
  the way to the goal: a physical turn ends a degree or two off; `STRICT` for the plan's last motion, whose end is
  the goal as drawn).

A problem the pose already has (a link the human left past the edge) is not held against the turn as long as the
turn does not make it worse (`Baseline`): only problems a turn adds or worsens count. Reach is the exception: a
grasped link out of reach cannot be grasped, however it came to lie there.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Mapping, Sequence

import numpy as np

from planhrc.geometry import (PLANNING, ROOMY, STRICT, Cell, Feasibility, Infeasibility, ObjectGeometry, Tolerance,
                              arm_shortfalls, configuration_feasible, link_centres, reach_shortfall, rotated)
from planhrc.vocabulary import Infeasible

SWEEP_INCREMENT_DEG = 5.0  # how finely a turn's sweep is checked


@dataclass(frozen=True)
class Baseline:
    """The problems a pose already has, and how far off each: (tolerance, code, link) -> distance (0 when not a
    distance), for each tolerance a judgement may use."""

    problems: Mapping[tuple[Tolerance, str, int], float]

    @classmethod
    def of(cls, geometry: ObjectGeometry, angles: Sequence[float], cell: Cell) -> "Baseline":
        return cls({(tolerance, r.code, r.link): r.distance_m for tolerance in (STRICT, PLANNING, ROOMY)
                    for r in configuration_feasible(geometry, angles, cell, tolerance=tolerance).reasons})

    def excused(self, reason: Infeasibility, tolerance: Tolerance = STRICT) -> bool:
        """Whether `reason` (found with `tolerance`) is a problem of the pose, no worse than there."""
        start = self.problems.get((tolerance, reason.code, reason.link))
        return start is not None and reason.distance_m <= start + 1e-3


def judge_turn(geometry: ObjectGeometry, angles: Sequence[float], turned: int, held: int, delta_deg: float,
               cell: Cell, baseline: Baseline, rest: Tolerance = PLANNING) -> Feasibility:
    """Whether turning link `turned` about its joint with `held` (0 = the table) by `delta_deg` may be done from
    the pose (`geometry`'s base point, link orientations `angles`): feasible, or the first problem it adds (see
    the module's note). The reasons carry the fact: code, link, distance and what it runs against."""
    grasped = [k for k in (turned, held) if k >= 1]
    # a link out of reach is not grasped, however it came to lie there; two grasped links take one arm each
    unreachable = two_arms(geometry, angles, turned, held, cell)
    if unreachable is not None:
        return Feasibility(False, (unreachable,))
    n = max(1, int(math.ceil(abs(delta_deg) / SWEEP_INCREMENT_DEG)))
    for i in (n, *range(1, n)):  # where it comes to rest first: most refused turns are refused there
        placed, values = rotated(geometry, angles, turned, held, delta_deg * i / n)
        tolerance = rest if i == n else STRICT
        result = configuration_feasible(placed, values, cell, reach_links=grasped, tolerance=tolerance)
        new = tuple(r for r in result.reasons
                    if r.code is Infeasible.OUT_OF_REACH or not baseline.excused(r, tolerance))
        if new:
            return Feasibility(False, new)
        if i == n and (unreachable := two_arms(placed, values, turned, held, cell)) is not None:
            return Feasibility(False, (unreachable,))
    return Feasibility(True)


def judge_motion(geometry: ObjectGeometry, angles: Sequence[float], turned: int, held: int, delta_deg: float,
                 cell: Cell, final: bool) -> Feasibility:
    """`judge_turn` from a pose, its own problems excused: the check before one dispatched motion (a macro step
    judged as one turn), resting as the plan's last motion (`final`: as drawn) or on the way (`PLANNING`)."""
    return judge_turn(geometry, angles, turned, held, delta_deg, cell, Baseline.of(geometry, angles, cell),
                      rest=STRICT if final else PLANNING)


def two_arms(geometry: ObjectGeometry, angles: Sequence[float], turned: int, held: int, cell: Cell
             ) -> Infeasibility | None:
    """Why the arms cannot hold `held` and turn `turned` in this configuration (None when they can): each grasped
    link within reach of an arm, and two grasped links of two different arms (the holding arm and the turning
    one). The reason names the link that misses, by how much."""
    links = [k for k in (turned, held) if k >= 1]
    centres = link_centres(geometry, angles)
    short = arm_shortfalls(np.asarray([centres[k - 1] for k in links]), cell.robot)
    if len(links) == 1:
        miss = float(short[0].min())
        worst = links[0]
    else:
        pairing = [max(short[0, a], short[1, 1 - a]) for a in (0, 1)]  # turned by arm a, held by the other
        a = int(np.argmin(pairing))
        miss = float(pairing[a])
        worst = links[0] if short[0, a] >= short[1, 1 - a] else links[1]
    if miss <= 1e-9:
        return None
    alone = float(reach_shortfall(centres[worst - 1], cell.robot))
    what = "" if alone > 1e-9 else " by the arm left free by the other grasp"
    return Infeasibility(Infeasible.OUT_OF_REACH, worst, f"link {worst} unreachable{what}: {miss:.2f} m beyond reach",
                         miss, "the arms' reach")

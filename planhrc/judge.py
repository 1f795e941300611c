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
                              Measures, arm_shortfalls, configuration_feasible, link_centres, measure_configurations,
                              reach_shortfall, rotated)
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


class TurnJudge:
    """`judge_turn`'s verdict (feasible or not) on many downstream turns from many poses at once, from one baseline:
    what a search over configurations asks thousands of times. The configurations every turn sweeps through are
    measured in one batch (`geometry.measure_configurations`, the same computation `configuration_feasible` reads
    its reasons from) and judged as `judge_turn` judges them: the grasped links within reach of two arms where the
    turn starts and where it ends, every swept configuration on the table, out of the robot and unfolded as drawn,
    the last one with `rest`'s clearance, problems the baseline has (no worse) excused, reach never. A test holds
    the two to the same answers. Each verdict comes with a second one: whether the turn also rests with `roomy`'s
    clearance (what a search prefers where it can)."""

    def __init__(self, geometry: ObjectGeometry, cell: Cell, baseline: Baseline, rest: Tolerance = PLANNING,
                 roomy: Tolerance = ROOMY) -> None:
        self.geometry, self.cell, self.rest, self.roomy = geometry, cell, rest, roomy
        n = geometry.n_links
        self._tolerances = (STRICT, rest, roomy)
        self._off_base = np.full((3, n), -np.inf)  # per tolerance: the start's distance past the edge (-inf: none)
        self._inside_base = np.zeros((3, n), dtype=bool)
        self._overlap_base = np.zeros((3, n), dtype=bool)  # folds and overlaps share the code: by the later link
        for t, tolerance in enumerate(self._tolerances):
            for (tol, code, link), distance in baseline.problems.items():
                if tol != tolerance or not 1 <= link <= n:
                    continue
                if code is Infeasible.OFF_TABLE:
                    self._off_base[t, link - 1] = distance
                elif code is Infeasible.INSIDE_ROBOT:
                    self._inside_base[t, link - 1] = True
                elif code is Infeasible.OVERLAP:
                    self._overlap_base[t, link - 1] = True

    def excused(self, tolerance: Tolerance) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The start's problems this judge excuses under `tolerance` (STRICT, its rest or its roomy one): how far each
        link lay past the table's edge (-inf: it did not), which lay inside the robot, which folded onto or
        overlapped another."""
        t = self._tolerances.index(tolerance)
        return self._off_base[t], self._inside_base[t], self._overlap_base[t]

    def turns_ok(self, base_point_xy: Sequence[float], angles: Sequence[float],
                 turns: Sequence[tuple[int, int, float]]) -> np.ndarray:
        """For each downstream turn (turned, held = turned - 1, delta_deg) from the pose (the base point, link
        orientations `angles`): whether `judge_turn` would find it feasible (a bool array)."""
        ok, _ = self.judge_many([base_point_xy], [angles], turns)
        return np.asarray(ok[0])

    def judge_many(self, base_points: Sequence[Sequence[float]], poses: Sequence[Sequence[float]],
                   turns: Sequence[tuple[int, int, float]]) -> tuple[np.ndarray, np.ndarray]:
        """`turns_ok` for every pose (base point, link orientations) at once: (P, T) arrays of the verdicts, and of
        whether each turn also rests with the roomy clearance. Where each turn comes to rest is judged first (most
        refused turns are refused there), the configurations it sweeps through only for the turns that rest."""
        n = self.geometry.n_links
        start = np.asarray(poses, dtype=float).reshape(-1, n)
        bases = np.asarray(base_points, dtype=float).reshape(-1, 2)
        p = len(start)
        spec = np.asarray(turns, dtype=float).reshape(-1, 3)
        if np.any(spec[:, 0] != spec[:, 1] + 1):
            raise ValueError("turns: only downstream turns (turned = held + 1) are judged in a batch")
        t_count = len(spec)
        counts = np.maximum(1, np.ceil(np.abs(spec[:, 2]) / SWEEP_INCREMENT_DEG)).astype(int)
        turned, held = spec[:, 0].astype(int) - 1, spec[:, 1].astype(int) - 1  # 0-based; -1: the table
        moved = np.arange(n)[None, :] >= turned[:, None]  # (T, N): the links each turn moves

        # where each turn comes to rest, and the start (for the arms there): one batch
        rests = np.where(moved[None], (start[:, None, :] + spec[None, :, 2, None] * counts[None, :, None]
                                       / counts[None, :, None]) % 360.0, start[:, None, :])
        values = np.concatenate((start[:, None, :], rests), axis=1).reshape(p * (t_count + 1), n)
        m = measure_configurations(self.geometry, values, self.cell, self._tolerances[1:],
                                   base_points=np.repeat(bases, t_count + 1, axis=0))
        bad = self._problems(m, 1).reshape(p, t_count + 1)[:, 1:]
        tight = self._problems(m, 2).reshape(p, t_count + 1)[:, 1:]
        reach = m.reach.reshape(p, t_count + 1, n)[:, 1:]
        t = np.arange(t_count)
        bad |= (reach[:, t, turned] > 1e-9) | ((held >= 0)[None, :] & (reach[:, t, np.maximum(held, 0)] > 1e-9))
        short = m.short.reshape(p, t_count + 1, n, 2)
        ok = ~bad & _arms_hold(short[:, [0] * t_count], turned, held) & _arms_hold(short[:, 1:], turned, held)

        # the configurations swept through on the way, for the turns that rest: one more batch
        pose_i, turn_i = np.nonzero(ok & (counts > 1)[None, :])
        if len(pose_i):
            inner = counts[turn_i] - 1
            owner = np.repeat(np.arange(len(pose_i)), inner)
            firsts = np.concatenate(([0], np.cumsum(inner)[:-1]))
            within = np.arange(len(owner)) - firsts[owner] + 1  # 1 .. count - 1 within its turn
            which = turn_i[owner]
            share = spec[which, 2] * within / counts[which]  # each row's share of its turn, in degrees
            swept = np.where(moved[which], (start[pose_i[owner]] + share[:, None]) % 360.0, start[pose_i[owner]])
            ms = measure_configurations(self.geometry, swept, self.cell, self._tolerances[:1],
                                        base_points=bases[pose_i[owner]])
            rows = np.arange(len(owner))
            row_bad = self._problems(ms, 0)
            row_bad |= (ms.reach[rows, turned[which]] > 1e-9) | (
                (held[which] >= 0) & (ms.reach[rows, np.maximum(held[which], 0)] > 1e-9))
            ok[pose_i, turn_i] &= ~np.logical_or.reduceat(row_bad, firsts)
        return ok, ok & ~tight

    def _problems(self, m: Measures, t: int) -> np.ndarray:
        """Per measured configuration: whether it has a problem the baseline does not excuse under tolerance `t`
        (reach aside)."""
        tolerance = self._tolerances[t]
        off = m.off[tolerance.clearance_m]
        added = (off > tolerance.overhang_m + 1e-9) & ~(off <= self._off_base[t] + 1e-3)
        added |= m.inside & ~self._inside_base[t]
        bad = added.any(axis=1)
        overlap_base = self._overlap_base[t]
        if m.folds.shape[1]:
            bad |= (m.folds & ~overlap_base[1:]).any(axis=1)
        i, j = m.pairs
        if len(i):
            bad |= (m.close[tolerance.overlap_m] & ~overlap_base[j]).any(axis=1)
        return np.asarray(bad)


def _arms_hold(short: np.ndarray, turned: np.ndarray, held: np.ndarray) -> np.ndarray:
    """`two_arms` finds nothing, for each pose and turn (0-based `turned`, `held`; -1: the table), from the
    shortfalls (P, T, N, 2) of the configuration each turn is judged in."""
    t = np.arange(len(turned))
    alone = short[:, t, turned].min(axis=2)
    h = np.maximum(held, 0)
    paired = np.minimum(np.maximum(short[:, t, turned, 0], short[:, t, h, 1]),
                        np.maximum(short[:, t, turned, 1], short[:, t, h, 0]))
    return np.asarray(np.where(held[None, :] >= 0, paired, alone) <= 1e-9)

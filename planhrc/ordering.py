"""An order of a plan's actions whose every configuration stays on the table: a pure function on values.

The actions of this domain commute: a plan's final configuration depends only on how many steps each joint turns
each way, not on their order. The order does matter on a table, though: turning link 2 before link 4 may swing
links 4-5 past the table's edge or through the robot, the other order not. `order_moves` looks for an order of
the given moves in which every step is geometrically feasible (see `planhrc.geometry`):

* every configuration the step sweeps through (every 5°) keeps the links on the table, out of the robot's body
  and clear of each other, and the configuration it comes to rest in keeps the clearance `planhrc.geometry.PLANNING`
  from the table's edges (1.5 cm: a physical turn ends a degree or two off; the plan's end, the goal, as drawn),
  and
* the links the step grasps (the turned and the held one) are within reach before and after it.

Among the feasible orders, one whose resting configurations keep `planhrc.geometry.ROOMY`'s clearance (5 cm) is
preferred: a turn that drags several links along the table flexes the joints beyond it by a few degrees, and the
chain's end lands centimetres from where it was drawn. That search gets eight step checks per move (a few steps
of the plan's own order moved past each other); when it finds nothing, the 1.5 cm clearance decides.

A problem the plan's start configuration already has (a link the human left off the table) is not held against
the plan, as long as the plan does not make it worse (that link no further past the edge, or out of reach, than
at the start): only problems a step adds or worsens count.

The search is a depth-first search over the multiset of remaining moves, trying the moves in the plan's own order
first (so a feasible plan keeps its order) and remembering the configurations from which no order works. It is
bounded by a number of step checks; when no order of the same moves works, `feasible_alternative` tries longer
plans in which one joint turns the other way round (360° - delta), shortest first.

When nothing works, the result names the obstacle (the first infeasible step of the plan's own order) and what the
human could do instead: `HelpItem`s "turn link 4 to 135°".
"""
from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass, field, replace
from typing import Sequence

from planhrc.geometry import (PLANNING, ROOMY, STRICT, Cell, Feasibility, Infeasibility, ObjectGeometry, Tolerance,
                              configuration_feasible, rotated)
from planhrc.judge import Baseline, judge_turn
from planhrc.vocabulary import Infeasible

# Step checks per search: bounds the time the ordering adds to a re-plan; a plan it cannot order within it goes to
# the human (`python -m planhrc.bench.ordering` measures the checks a search takes).
DEFAULT_BUDGET = 4000
# The search for an order keeping ROOMY's clearance may try this many step checks per move: enough to move a few
# steps of the plan's own order past each other, not enough to double the search when no such order exists.
ROOMY_CHECKS_PER_MOVE = 8
CLOCKWISE, ANTICLOCKWISE = "rotateclockwise", "rotateanticlockwise"


@dataclass(frozen=True)
class Move:
    """One planned step as a motion: the action's name, the link that turns, the link held (0 = the table), the
    joint turned about and the turned link's signed rotation (+ clockwise seen from above)."""

    name: str
    turned: int
    held: int
    joint: int
    delta_deg: int

    def other_way(self) -> "Move":
        """The same joint and links, turned in the other direction."""
        return Move(ANTICLOCKWISE if self.name == CLOCKWISE else CLOCKWISE, self.turned, self.held, self.joint,
                    -self.delta_deg)


@dataclass(frozen=True)
class Placement:
    """Where the object lies when the plan starts: its geometry (link lengths, base point) and the absolute
    orientation of every link."""

    geometry: ObjectGeometry
    link_deg: tuple[float, ...]
    cell: Cell = field(default_factory=Cell)
    # The step (degrees) by which a human may turn the whole object about its base point without changing its
    # state: the relative formulation, whose states fix the links' angles to each other, not where l1 points
    # (a human turned it, say); 0: never (the absolute formulation's goals fix every link's orientation).
    whole_turn_deg: int = 0
    # motions the robot refused from a state before: never proposed again from that state
    refused: frozenset["RefusedMotion"] = frozenset()
    grid_deg: int = 1  # the orientation step: what a help request's orientations are rounded to (`link_deg` is measured)
    slides: bool = True  # whether the robot may slide the object first to make room (`planhrc.motion_search`)
    straightens: bool = True  # whether the robot may turn links dragged off the grid back first (`pipeline.order`)


@dataclass(frozen=True)
class RefusedMotion:
    """A turn the robot refused before it moved (its judge, from the pose it measured, found a problem): from the
    state with link orientations `state_deg` (snapped, each a multiple of `step_deg`) and the base point near
    `base_point_xy`, turning `turned` (holding `held`) in `direction` (+1 clockwise, -1 anticlockwise); `fact` is
    what the robot said (which link, against what, how far)."""

    state_deg: tuple[int, ...]
    base_point_xy: tuple[float, float]
    turned: int
    held: int
    direction: int
    step_deg: int
    code: Infeasible
    link: int
    fact: str

    def forbids(self, geometry: ObjectGeometry, angles: Sequence[float], move: "Move", near_m: float = 0.02) -> bool:
        """Whether `move` from the pose (`geometry`, `angles`) is this refused motion from the same state."""
        if (move.turned, move.held) != (self.turned, self.held) or (move.delta_deg > 0) != (self.direction > 0):
            return False
        if math.dist(geometry.base_point_xy, self.base_point_xy) > near_m:
            return False
        return tuple(int(round(a / self.step_deg)) * self.step_deg % 360 for a in angles) == self.state_deg


@dataclass(frozen=True)
class HelpItem:
    """What the robot asks the human: bring link `link` to the absolute orientation `to_deg`."""

    link: int
    to_deg: int
    sentence: str


@dataclass(frozen=True)
class Ordering:
    """The answer of a search: a feasible order of moves (None when none was found), and otherwise the obstacle
    the plan's own order meets (`step`, 1-based, and its `problem`) and the help to ask for."""

    moves: tuple[Move, ...] | None
    checks: int
    exhausted: bool = True  # False: the search stopped at its budget, an order may still exist
    step: int | None = None
    problem: Feasibility | None = None
    help: tuple[HelpItem, ...] = ()
    clearance_m: float = PLANNING.clearance_m  # what the order's resting configurations keep from the edges

    @property
    def found(self) -> bool:
        return self.moves is not None

    def sentence(self) -> str:
        if self.moves is not None:
            return f"a feasible order of {len(self.moves)} actions"
        why = self.problem.sentence() if self.problem is not None else "no order found"
        where = f"at action {self.step}: " if self.step is not None else "at the plan's end: "
        bound = "" if self.exhausted else f" (search stopped after {self.checks} checks)"
        return f"no order of the plan's actions stays on the table and within reach{bound}; {where}{why}"


class _OutOfBudget(Exception):
    pass


@dataclass
class _Search:
    placement: Placement
    budget: int
    checks: int = 0
    baseline: Baseline = field(default_factory=lambda: Baseline({}))
    rest: Tolerance = PLANNING  # what a configuration a step comes to rest in keeps (the plan's end: STRICT)

    def excused(self, reason: Infeasibility, tolerance: Tolerance = STRICT) -> bool:
        """Whether `reason` (found with `tolerance`) is a problem of the start, no worse than there."""
        return self.baseline.excused(reason, tolerance)

    def step(self, geometry: ObjectGeometry, angles: tuple[float, ...], move: Move, last: bool = False
             ) -> Feasibility:
        """Whether `move` is feasible from this configuration: the one judge (`planhrc.judge.judge_turn`, problems
        of the start configuration excepted), resting with `PLANNING`'s clearance (`rest`) unless the move ends
        the plan (`last`: the goal, as drawn); and not a motion the robot refused from the same state before."""
        self.checks += 1
        if self.checks > self.budget:
            raise _OutOfBudget
        for refusal in self.placement.refused:
            if refusal.forbids(geometry, angles, move):
                return Feasibility(False, (Infeasibility(refusal.code, refusal.link,
                                                         f"the robot refused this turn from here: {refusal.fact}"),))
        return judge_turn(geometry, angles, move.turned, move.held, move.delta_deg, self.placement.cell,
                          self.baseline, rest=STRICT if last else self.rest)


def order_moves(placement: Placement, moves: Sequence[Move], budget: int = DEFAULT_BUDGET) -> Ordering:
    """A feasible order of `moves` (the plan's own order when it is feasible), or the obstacle and the help to
    ask for when the search finds none within `budget` step checks."""
    moves = tuple(moves)
    baseline = _baseline(placement)
    roomy = _Search(placement, min(budget // 4, ROOMY_CHECKS_PER_MOVE * len(moves)), baseline=baseline, rest=ROOMY)
    found, _ = _dfs(roomy, moves)
    if found is not None:
        return Ordering(found, roomy.checks, clearance_m=ROOMY.clearance_m)
    search = _Search(placement, budget, baseline=baseline)
    found, exhausted = _dfs(search, moves)
    if found is not None:
        return Ordering(found, roomy.checks + search.checks)
    step, problem = first_obstacle(placement, moves, search)
    unreachable = final_out_of_reach(placement, moves)
    if unreachable is not None:  # the plan's end itself is beyond the robot's reach: say that
        step, problem = None, unreachable
    return Ordering(None, roomy.checks + search.checks, exhausted, step, problem,
                    help_for(placement, moves, problem))


def final_out_of_reach(placement: Placement, moves: Sequence[Move]) -> Feasibility | None:
    """The links the moves turn whose grasp points lie beyond the robot's reach at the end (None when none do)."""
    geometry, final = final_configuration(placement, moves)
    turned = {m.turned for m in moves}
    result = configuration_feasible(geometry, final, placement.cell, reach_links=turned)
    reasons = tuple(r for r in result.reasons if r.code is Infeasible.OUT_OF_REACH)
    return Feasibility(False, reasons) if reasons else None


def feasible_alternative(placement: Placement, moves: Sequence[Move], orientations: int,
                         budget: int = DEFAULT_BUDGET, max_alternatives: int = 8) -> tuple[Ordering, int]:
    """`order_moves` on the plan, then, if no order works, on longer plans where the steps of one joint turn the
    other way round (360° - delta), shortest first: the first feasible one, and how many steps it adds. When none
    is, the plan's own answer (with its obstacle and help) and 0."""
    moves = tuple(moves)
    first = order_moves(placement, moves, budget)
    if first.found:
        return first, 0
    groups = Counter(moves)
    flips = []
    for move, count in groups.items():
        if move.other_way() in groups:
            continue
        added = orientations - 2 * count
        flips.append((added, moves.index(move), move, count))
    for added, _, move, count in sorted(flips)[:max_alternatives]:
        alternative = [m for m in moves if m != move] + [move.other_way()] * (orientations - count)
        answer = order_moves(placement, alternative, budget)
        if answer.found:
            return answer, added
    return first, 0


def first_obstacle(placement: Placement, moves: Sequence[Move],
                   search: _Search | None = None) -> tuple[int | None, Feasibility | None]:
    """The first step of `moves`, in their order, that is not feasible, and why (None, None when all are)."""
    search = search or _Search(placement, math.inf, baseline=_baseline(placement))  # type: ignore[arg-type]
    search.budget = math.inf  # type: ignore[assignment]
    geometry, angles = placement.geometry, tuple(float(a) for a in placement.link_deg)
    for i, move in enumerate(moves, start=1):
        result = search.step(geometry, angles, move, last=i == len(moves))
        if not result.ok:
            return i, result
        geometry, angles = rotated(geometry, angles, move.turned, move.held, move.delta_deg)
    return None, None


def leaves_the_table(placement: Placement, moves: Sequence[Move], increment_deg: float = 5.0
                     ) -> tuple[int | None, Infeasibility | None]:
    """The first of `moves`, in their order, whose sweep puts a link past the table's edge or inside the robot as
    drawn (`STRICT`; problems the start already has, no worse than there, excepted), and the problem; (None,
    None) when none does. Reach and the planning clearance are not judged: this is the check of a plan made for
    the object elsewhere against where the object lies now."""
    search = _Search(placement, math.inf, baseline=_baseline(placement))  # type: ignore[arg-type]
    geometry, angles = placement.geometry, tuple(float(a) for a in placement.link_deg)
    for i, move in enumerate(moves, start=1):
        n = max(1, int(math.ceil(abs(move.delta_deg) / increment_deg)))
        for j in range(1, n + 1):
            placed, values = rotated(geometry, angles, move.turned, move.held, move.delta_deg * j / n)
            result = configuration_feasible(placed, values, placement.cell, reach_links=())
            for reason in result.reasons:
                if reason.code in (Infeasible.OFF_TABLE, Infeasible.INSIDE_ROBOT) and not search.excused(reason):
                    return i, reason
        geometry, angles = rotated(geometry, angles, move.turned, move.held, move.delta_deg)
    return None, None


def final_configuration(placement: Placement, moves: Sequence[Move]) -> tuple[ObjectGeometry, tuple[float, ...]]:
    geometry, angles = placement.geometry, tuple(float(a) for a in placement.link_deg)
    for move in moves:
        geometry, angles = rotated(geometry, angles, move.turned, move.held, move.delta_deg)
    return geometry, angles


def help_for(placement: Placement, moves: Sequence[Move], problem: Feasibility | None,
             why: str | None = None) -> tuple[HelpItem, ...]:
    """What to ask the human when the robot cannot carry the moves out: the links the plan turns and the
    obstacle names (else the links the plan turns), each to its orientation at the plan's end. A human turns a
    link about its joint with the link before it, carrying the links beyond (assumption A1), upstream first;
    when the named turns would leave the object folded or off the table, every link from the first one the plan
    changes to the last is asked for, so that, done in that order, they bring the object to the plan's end,
    which is feasible. `why` (else the obstacle) is said in each sentence."""
    if not moves:
        return ()
    end, final = final_configuration(placement, moves)
    turn = _whole_turn(placement, end, final)
    if turn:  # the plan's end does not lie on the table where the object points now: turn it as a whole first
        turned_start = rotated(placement.geometry, placement.link_deg, 1, 0, turn)[1]
        to = int(round(turned_start[0] / placement.grid_deg)) * placement.grid_deg % 360
        problem_there = configuration_feasible(end, final, placement.cell, reach_links=()).reasons[0].message
        first = HelpItem(1, to, f"turn link 1 to {to}° and the whole object with it, about its base point (pointing "
                                f"as it does now, the plan's end would not lie on the table: {problem_there})")
        rest = help_for(replace(placement, link_deg=turned_start, whole_turn_deg=0), moves, problem, why)
        return (first,) + tuple(item for item in rest if item.link != 1)
    start = tuple(float(a) % 360.0 for a in placement.link_deg)
    grid = placement.grid_deg
    changed = [k for k in range(1, len(final) + 1)
               if round(final[k - 1] / grid) * grid % 360 != round(start[k - 1] / grid) * grid % 360]
    named = [k for k in (problem.links if problem is not None else ()) if k in changed]
    links = named or [m.turned for m in dict.fromkeys(moves) if m.turned in changed] or changed
    if changed and not _safe_for_a_human(placement, final, links):
        links = list(range(min(changed), len(final) + 1))
    why = f" ({why})" if why else f" ({problem.sentence()})" if problem is not None else ""
    items = []
    for k in dict.fromkeys(links):
        to = int(round(final[k - 1] / placement.grid_deg)) * placement.grid_deg % 360
        items.append(HelpItem(k, to, f"turn link {k} to {to}°{why}"))
    return tuple(items)


def _whole_turn(placement: Placement, end: ObjectGeometry, final: Sequence[float]) -> float:
    """For an object a human may turn as a whole (`Placement.whole_turn_deg`) whose plan ends off the table, in
    the robot or folded (as drawn): the smallest turn of it, in whole steps, after which the plan's end is feasible
    for a human (reach aside) and the object, turned where it lies now, has no problem it does not have now, or has
    it no worse (`_Search.excused`); 0 when the end is feasible, or no turn makes it so."""
    step = placement.whole_turn_deg
    if step <= 0 or configuration_feasible(end, final, placement.cell, reach_links=()).ok:
        return 0.0
    now = _Search(placement, 0, baseline=_baseline(placement))
    for k in range(1, 360 // step // 2 + 1):
        for turn in (k * step, -k * step):
            if not configuration_feasible(*rotated(end, final, 1, 0, turn), placement.cell, reach_links=()).ok:
                continue
            turned = configuration_feasible(*rotated(placement.geometry, placement.link_deg, 1, 0, turn),
                                            placement.cell, reach_links=())
            if all(now.excused(r) for r in turned.reasons):
                return float(turn)
    return 0.0


def _safe_for_a_human(placement: Placement, final: Sequence[float], links: Sequence[int]) -> bool:
    """Whether the object lies on the table, clear of the robot and unfolded once a human has turned each of
    `links`, upstream first, to its orientation in `final`, carrying the links beyond (a human is not bound by
    the robot's reach)."""
    geometry, angles = placement.geometry, tuple(float(a) for a in placement.link_deg)
    for k in sorted(set(links)):
        delta = (final[k - 1] - angles[k - 1] + 180.0) % 360.0 - 180.0
        geometry, angles = rotated(geometry, angles, k, k - 1, delta)
    return configuration_feasible(geometry, angles, placement.cell, reach_links=()).ok


def _baseline(placement: Placement) -> Baseline:
    """The start's problems, as drawn and with the clearance a plan keeps (`planhrc.judge.Baseline`)."""
    return Baseline.of(placement.geometry, placement.link_deg, placement.cell)


def _dfs(search: _Search, moves: tuple[Move, ...]) -> tuple[tuple[Move, ...] | None, bool]:
    """Depth-first search over the multiset of remaining moves; (order, exhausted)."""
    groups = list(dict.fromkeys(moves))
    index = {m: i for i, m in enumerate(groups)}
    sequence = [index[m] for m in moves]
    positions: list[list[int]] = [[] for _ in groups]  # where each group's steps sit in the plan's own order
    for pos, g in enumerate(sequence):
        positions[g].append(pos)
    remaining = [len(p) for p in positions]
    dead: set[tuple[object, ...]] = set()
    path: list[int] = []

    def key(geometry: ObjectGeometry) -> tuple[object, ...]:
        return (tuple(remaining), round(geometry.base_point_xy[0], 6), round(geometry.base_point_xy[1], 6))

    def visit(geometry: ObjectGeometry, angles: tuple[float, ...]) -> bool:
        if not any(remaining):
            return True
        here = key(geometry)
        if here in dead:
            return False
        done = [len(positions[g]) - remaining[g] for g in range(len(groups))]
        candidates = sorted((positions[g][done[g]], g) for g in range(len(groups)) if remaining[g])
        for _, g in candidates:
            move = groups[g]
            if not search.step(geometry, angles, move, last=sum(remaining) == 1).ok:
                continue
            after = rotated(geometry, angles, move.turned, move.held, move.delta_deg)
            remaining[g] -= 1
            path.append(g)
            if visit(*after):
                return True
            path.pop()
            remaining[g] += 1
        dead.add(here)
        return False

    start = (search.placement.geometry, tuple(float(a) for a in search.placement.link_deg))
    try:
        if visit(*start):
            return tuple(groups[g] for g in path), True
        return None, True
    except _OutOfBudget:
        return None, False

"""The robot's work on a placed object, planned as one search: turns and slides, every state one the one judge
accepts, the least robot time first (`plan_work`).

A placed object's configuration is where its base point lies and how far each joint has turned from where it lies
now: the *offsets* of the joints the robot turns (each joint's downstream link turned, the link before it held; the
first link against the table in the absolute formulation), one orientation step at a time, modulo K. Turning joint
k changes offset k alone, so the state of the domain the plan ends in fixes the offsets to reach (`target_offsets`),
and the sum over joints of the shorter way round to them is the length of the shortest plan with no table around
it (`unconstrained_steps`).

The search runs A* over (offsets, place, hands):

* **a turn** of one joint by one step either way, judged by the one judge from the configuration it starts in
  (`planhrc.judge.TurnJudge`: the same verdicts as `judge_turn`, every successor of a configuration measured in one
  batch), resting with `PLANNING`'s clearance from the table's edges, the last one too (the goal keeps the clearance
  a physical turn needs), problems the start already has excused as long as no turn makes them worse; never a turn
  the robot refused from that state before;
* **a slide** of the whole object to another place (`slide_feasible`: two links held by the two
  arms, every 2 cm of the way on the table and clear of the robot, the way measured in one batch), among the places
  of a grid of `SLIDE_GRID_M` around where it lies, at most `MAX_SLIDE_M` at a time, where the configuration rests
  (all the places from one configuration measured in one batch); before the first turn, and with `between`
  between any two too (not for a bimanual robot: its hands would let go of the links its plan's steps hold); a
  slide changes where the object lies, not the state of the domain;
* **the hands** (`Hands`): a turn that goes on with the motion under way (the same joint, the same direction) is
  merged with it into one motion, as the worker executes it; a bimanual robot centres its hands on a joint, grasps,
  turns and releases, each a cost of its own.

Each skill costs the robot's time (`SkillCosts`, measured in the simulator by `planhrc sim-bench --skills`), in
whole milliseconds so that equal times tie exactly; among plans of equal time the one with fewer resting
configurations closer than `ROOMY`'s 5 cm to the table's edges wins (a turn dragging links along the table flexes
the joints beyond it by a few degrees). The heuristic, the time of each joint's shorter way round and of one motion
per joint still to turn (plus the slide to the nearest place where the goal fits, where it does not fit here), never
overestimates: a plan found by the exhaustive search is the least robot time the table allows (`Work.exact`). A
node is not expanded when another node of the same configuration (the same offsets and place, other hands) was
reached sooner by at least what the hands can add to the next motion (`_Astar._dominated`): every plan on from it is
matched from the other at no more time, so neither the least time nor whether a plan exists changes. When
the search does not finish within its budget, a weighted search (`f = g + w h`) finds a plan whose time is at most
`Work.bound` times the least possible, the bound taken from the exhaustive search's open list when it stopped.
"""
from __future__ import annotations

import heapq
import itertools
import math
import time
from dataclasses import dataclass, replace
from typing import NamedTuple, Sequence

import numpy as np

from planhrc.geometry import (PLANNING, ROOMY, STRICT, Cell, Feasibility, ObjectGeometry, Tolerance, link_centres,
                              measure_configurations, reach_shortfall, reasons_of)
from planhrc.judge import Baseline, TurnJudge
from planhrc.model import ArticulatedObject, Formulation
from planhrc.ordering import ANTICLOCKWISE, CLOCKWISE, Move, Placement

SLIDE_INCREMENT_M = 0.02  # how finely a slide is checked
MAX_SLIDE_M = 0.30  # how far the robot slides an object in one go (both grippers stay within reach)
SLIDE_GRID_M = 0.10  # the places a slide may take the object to: a grid this fine about where it lies
EXPANSIONS = 20_000  # configurations the exhaustive search may expand (one batch of judged turns each)
WEIGHTS = (2.0, 5.0)  # the weighted searches tried, in turn, when the exhaustive one stops short
EXACT_SHARE = 0.6  # of the search's time, what the exhaustive search may take before the weighted ones
ROOMY_CHECK = ROOMY  # the clearance a resting configuration keeps where it can (a tie-break, not a constraint)
# Open-list entries expanded together, their turns judged in one batch: up to BATCH of them whose f lies within
# BATCH_SLACK_MS of the least. A goal is taken only when it is the least entry, so the plan stays the least time one.
BATCH = 64
BATCH_SLACK_MS = 600


@dataclass(frozen=True, kw_only=True)
class SkillCosts:
    """The robot's time for each skill, in seconds of the simulated cell's physics clock (`planhrc sim-bench
    --skills` measures them; docs/results.md has the figures): a turn's fixed part (both grippers to their links,
    closing, letting go, the arms home) and its time per degree of arc; a slide's fixed part and its time per
    metre; a bimanual robot's centring, grasp and release, and the fixed part of a turn of the links its hands
    already hold."""

    turn_s: float = 1.84
    turn_s_per_deg: float = 0.0145
    slide_s: float = 1.67
    slide_s_per_m: float = 6.04
    centre_s: float = 0.64
    grasp_s: float = 0.30
    release_s: float = 0.89
    held_turn_s: float = 0.07


SKILL_COSTS = SkillCosts()


@dataclass(frozen=True, kw_only=True)
class Hands:
    """What the robot's hands are doing when the plan starts. `bimanual`: hands that work on one joint at a time
    (centre, grasp, turn, release); `centre` is the joint at the centre (1-based) and `grasped` whether both hands
    hold its links. Otherwise each turn is a motion of its own (grasp, turn, release), merged with the one before
    when it goes on with it."""

    bimanual: bool = False
    centre: int = 0
    grasped: bool = False


@dataclass(frozen=True, kw_only=True)
class Slide:
    """A slide of the whole object: its base point to `to_xy`, holding `links` (one per arm)."""

    to_xy: tuple[float, float]
    links: tuple[int, int]
    distance_m: float

    def sentence(self) -> str:
        return (f"slide the object {self.distance_m * 100:.0f} cm (base point to ({self.to_xy[0]:.2f}, "
                f"{self.to_xy[1]:.2f}), holding links {self.links[0]} and {self.links[1]})")


Motion = Move | Slide


@dataclass(frozen=True, kw_only=True)
class Work:
    """The robot's plan: turns (one orientation step each, in order) and slides, the robot's time for it, a
    proved lower bound of the least time the table allows (equal to it when `exact`), and what was searched."""

    motions: tuple[Motion, ...]
    cost_s: float
    lower_bound_s: float
    exact: bool
    unconstrained_steps: int
    expansions: int
    tight_rests: int = 0  # resting configurations closer than ROOMY's clearance to the table's edges
    room: str = ""  # the plans searched among, in words: "" (slides between turns too), or what they were limited to

    @property
    def turns(self) -> tuple[Move, ...]:
        return tuple(m for m in self.motions if isinstance(m, Move))

    @property
    def slides(self) -> tuple[Slide, ...]:
        return tuple(m for m in self.motions if isinstance(m, Slide))

    @property
    def bound(self) -> float:
        """How many times the least robot time the plan may take at most (1.0 when exact)."""
        if self.exact or self.cost_s <= 0:
            return 1.0
        return self.cost_s / max(self.lower_bound_s, 1e-9)

    def sentence(self) -> str:
        turns, slides = len(self.turns), len(self.slides)
        what = f"{turns} turn step{'s' if turns != 1 else ''}"
        if slides:
            what += f" and {slides} slide{'s' if slides != 1 else ''}"
        among = f", {self.room}" if self.room else ""
        proof = (f"the least robot time the table allows{among} (exhaustive search)" if self.exact else
                 f"at most {self.bound:.2f}x the least robot time the table allows{among}")
        return (f"{what}, {self.cost_s:.1f} s of robot time, {proof}; the shortest plan with no table around it has "
                f"{self.unconstrained_steps} steps")


@dataclass(frozen=True, kw_only=True)
class NoWork:
    """No plan: why, whether every plan was ruled out (`exhausted`) or the search stopped at its budget."""

    reason: str
    exhausted: bool
    expansions: int


def slide_feasible(placement: Placement, to_xy: Sequence[float], links: tuple[int, int]) -> Feasibility:
    """Whether the robot can slide the object from where it lies to base point `to_xy` holding `links`: both within
    reach before and after, and every configuration on the way (every 2 cm) on the table, clear of the robot and
    unfolded as drawn (problems the object has where it lies, no worse, excused). Every configuration of the way,
    and where it starts (for what is excused), is measured in one batch; the first one with a new problem is named
    (where it ends first, then from the start on)."""
    geometry, angles, cell = placement.geometry, placement.link_deg, placement.cell
    start = np.asarray(geometry.base_point_xy, dtype=float)
    shift = np.asarray(to_xy, dtype=float) - start
    n = max(1, int(math.ceil(float(np.linalg.norm(shift)) / SLIDE_INCREMENT_M)))
    values = np.asarray([tuple(float(a) for a in angles)] * (n + 1), dtype=float)
    bases = start[None, :] + shift[None, :] * (np.arange(n + 1, dtype=float)[:, None] / n)
    m = measure_configurations(geometry, values, cell, (STRICT,), base_points=bases)
    # a slide moves every link alike: it neither folds nor overlaps links the start does not; what it can add is a
    # link past the table's edge (STRICT) or in the robot's body on the way, or a held link out of reach at its end
    off = m.off[STRICT.clearance_m]
    off_start = np.where(off[0] > STRICT.overhang_m + 1e-9, off[0] + 1e-3, STRICT.overhang_m + 1e-9)
    bad = (off[1:] > off_start[None, :]).any(axis=1) | (m.inside[1:] & ~m.inside[0][None, :]).any(axis=1)
    held = [k - 1 for k in links if 1 <= k <= geometry.n_links]
    short = m.reach
    short_start = np.where(short[0] > 1e-9, short[0] + 1e-3, 1e-9)
    bad[-1] |= bool((short[-1, held] > short_start[held]).any())
    if not bad.any():
        return Feasibility(True)
    baseline = Baseline({(STRICT, r.code, r.link): r.distance_m
                         for r in reasons_of(m, 0, geometry, cell, None, STRICT)})
    for i in (n, *range(1, n)):
        reasons = reasons_of(m, i, geometry, cell, links if i == n else (), STRICT)
        new = tuple(r for r in reasons if not baseline.excused(r))
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


def target_offsets(alphabet: Sequence[Move], moves: Sequence[Move], orientations: int, step_deg: int
                   ) -> tuple[int, ...] | None:
    """How many steps (mod K) each joint of `alphabet` turns in `moves` (a plan's turns, either side of a joint,
    a step or a 45-degree turn each): the offsets the plan ends at; None when a move turns a joint the alphabet does
    not."""
    joints = {m.joint: i for i, m in enumerate(alphabet)}
    target = [0] * len(alphabet)
    for move in moves:
        if move.joint not in joints:
            return None
        i = joints[move.joint]
        steps = int(round(move.delta_deg / step_deg))
        target[i] = (target[i] + (steps if move.turned == alphabet[i].turned else -steps)) % orientations
    return tuple(target)


def alphabet_of(obj: ArticulatedObject) -> tuple[Move, ...]:
    """One clockwise step of every joint the robot turns: the downstream link, the one before held (absolute: link
    K about joint K, link 1 against the table; relative and bimanual: link K+1 about joint K)."""
    if obj.formulation is Formulation.ABSOLUTE:
        return tuple(Move(CLOCKWISE, k, k - 1, k, obj.step) for k in range(1, obj.n_links + 1))
    return tuple(Move(CLOCKWISE, k + 1, k, k, obj.step) for k in range(1, obj.n_links))


def offsets_between(obj: ArticulatedObject, start_deg: Sequence[float], goal_deg: Sequence[float]) -> tuple[int, ...]:
    """The offsets of `alphabet_of(obj)`'s joints that bring the links from `start_deg` to `goal_deg` (each
    snapped to the orientation set); l1's own change is ignored where the robot does not turn it."""
    k, step = obj.orientations, obj.step
    d = [int(round((float(b) - float(a)) / step)) % k for a, b in zip(start_deg, goal_deg)]
    if obj.formulation is Formulation.ABSOLUTE:
        return tuple((d[i] - (d[i - 1] if i else 0)) % k for i in range(len(d)))
    return tuple((d[i] - d[i - 1]) % k for i in range(1, len(d)))


def reachable_in_plane(placement: Placement, obj: ArticulatedObject, goal_deg: Sequence[float],
                       expansions: int = EXPANSIONS) -> bool | None:
    """Whether anyone turning the links in the plane (no reach limit: a person's hands; the table, the robot's body
    and the links themselves still in the way) can bring the object from where it lies to `goal_deg`: a goal
    beyond every such path is no task for anybody. None when the search did not decide within `expansions`."""
    hands_free = replace(placement.cell, robot=replace(placement.cell.robot, reach_m=math.inf, near_x_m=-math.inf))
    target = offsets_between(obj, placement.link_deg, goal_deg)
    work = plan_work(replace(placement, cell=hands_free, refused=frozenset()), alphabet_of(obj), target,
                     obj.orientations, slides=False, expansions=expansions)
    if isinstance(work, Work):
        return True
    return False if work.exhausted else None


def unconstrained_steps(target: Sequence[int], orientations: int) -> int:
    """The length of the shortest plan reaching `target` from offsets 0 with no table around it."""
    return sum(min(t % orientations, -t % orientations) for t in target)


@dataclass(kw_only=True)
class _Space:
    """What the search knows of the object: its joints, the places it may lie, the costs, the judge."""

    placement: Placement
    alphabet: tuple[Move, ...]
    orientations: int
    target: tuple[int, ...]
    costs: SkillCosts
    judge: TurnJudge
    places: tuple[tuple[float, float], ...]  # place 0: where the object lies
    step_deg: int
    base: tuple[float, ...]  # the link orientations where the object lies (offsets 0)
    goal_extra_ms: tuple[int, ...] = ()  # per place: the least slide time to where the goal fits (0: it fits here)
    between: bool = False  # slides between turns too, not only before the first

    def angles(self, offsets: Sequence[int]) -> tuple[float, ...]:
        turn = [0.0] * len(self.base)
        for i, offset in enumerate(offsets):
            for k in range(self.alphabet[i].turned - 1, len(self.base)):
                turn[k] += offset * self.step_deg
        return tuple((a + t) % 360.0 for a, t in zip(self.base, turn))


def _ms(seconds: float) -> int:
    return int(round(seconds * 1000))


def plan_work(placement: Placement, alphabet: Sequence[Move], target: Sequence[int], orientations: int, *,
              hands: Hands = Hands(), costs: SkillCosts = SKILL_COSTS, slides: bool = True, between: bool = False,
              rest: Tolerance = PLANNING, expansions: int = EXPANSIONS,
              deadline_at: float | None = None) -> Work | NoWork:
    """The least robot time plan from where the object lies (offsets 0, `placement`) to `target` (see the module's
    note), with a slide before the first turn (`slides`) and, with `between` (not for a bimanual robot), between any
    two: exact when the exhaustive search finishes within `expansions` and `deadline_at` (`time.monotonic()`), else
    bounded (`Work.bound`); `NoWork` when no plan exists or none was found in time."""
    between = between and slides and not hands.bimanual
    alphabet, target = tuple(alphabet), tuple(t % orientations for t in target)
    step = 360 // orientations
    baseline = Baseline.of(placement.geometry, placement.link_deg, placement.cell)
    places = places_about(placement, slides)
    space = _Space(placement=placement, alphabet=alphabet, orientations=orientations, target=target, costs=costs,
                   judge=TurnJudge(placement.geometry, placement.cell, baseline, rest, ROOMY_CHECK), places=places,
                   step_deg=step, base=tuple(float(a) for a in placement.link_deg), between=between)
    space.goal_extra_ms = _goal_extra(space, rest)
    free = unconstrained_steps(target, orientations)
    if all(extra < 0 for extra in space.goal_extra_ms):
        where = ("anywhere the robot could slide the object to" if slides else
                 "where the object lies (no slide is asked for now)")
        return NoWork(reason=f"the goal does not fit on the table with {rest.clearance_m * 100:.1f} cm to spare from "
                      f"its edges, clear of the robot and unfolded, {where}", exhausted=True, expansions=0)
    exhaustive = _Astar(space, hands, 1.0)
    now = time.monotonic()
    found = exhaustive.run(expansions, None if deadline_at is None else now + EXACT_SHARE * (deadline_at - now))
    if found is not None:
        return _work(space, found, exact=True, lower_ms=found.g_ms, free=free, expansions=exhaustive.expansions)
    if exhaustive.exhausted:
        slid = "turns and slides" if between else ("turns, after a slide," if slides else "turns")
        return NoWork(reason=f"no sequence of the robot's {slid} reaches the goal with every configuration on "
                      "the table, out of the robot's body, within reach and unfolded", exhausted=True,
                      expansions=exhaustive.expansions)
    lower = exhaustive.lower_bound_ms()
    spent = exhaustive.expansions
    for weight in WEIGHTS:
        if deadline_at is not None and time.monotonic() > deadline_at:
            break
        greedy = _Astar(space, hands, weight)
        found = greedy.run(expansions, deadline_at)
        spent += greedy.expansions
        if found is not None:
            return _work(space, found, exact=False, lower_ms=lower, free=free, expansions=spent)
        if greedy.exhausted:
            break
    return NoWork(reason=f"the search for a plan that fits the table stopped after {spent} configurations",
                  exhausted=False, expansions=spent)


def places_about(placement: Placement, slides: bool) -> tuple[tuple[float, float], ...]:
    """Where the object may lie: where it lies, then (with slides) a grid about it within one slide's reach,
    nearest first."""
    x0, y0 = (float(v) for v in placement.geometry.base_point_xy)
    places = [(x0, y0)]
    if slides:
        steps = int(MAX_SLIDE_M // SLIDE_GRID_M)
        grid = [(dx * SLIDE_GRID_M, dy * SLIDE_GRID_M) for dx in range(-steps, steps + 1)
                for dy in range(-steps, steps + 1) if (dx or dy) and math.hypot(dx, dy) * SLIDE_GRID_M <= MAX_SLIDE_M + 1e-9]
        grid.sort(key=lambda d: (math.hypot(*d), d))
        places += [(round(x0 + dx, 4), round(y0 + dy, 4)) for dx, dy in grid]
    return tuple(places)


def _slide_ms(costs: SkillCosts, a: Sequence[float], b: Sequence[float]) -> int:
    return _ms(costs.slide_s + costs.slide_s_per_m * math.dist(a, b))


def resting_places(geometry: ObjectGeometry, angles: Sequence[float], cell: Cell,
                   places: Sequence[Sequence[float]], rest: Tolerance = PLANNING,
                   excused: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """For each place (a base point), whether the configuration `angles` rests there as a plan's configurations
    rest: `rest`'s clearance from the table's edges, clear of the robot's body, unfolded (reach aside), problems of
    `excused` (a `TurnJudge.excused` triple: the start's) no worse."""
    n = geometry.n_links
    off_base, inside_base, overlap_base = excused if excused is not None else (
        np.full(n, -np.inf), np.zeros(n, dtype=bool), np.zeros(n, dtype=bool))
    m = measure_configurations(geometry, np.asarray([tuple(angles)] * len(places), dtype=float), cell, (rest,),
                               base_points=np.asarray(places, dtype=float))
    off = m.off[rest.clearance_m]
    bad = ((off > rest.overhang_m + 1e-9) & ~(off <= off_base[None, :] + 1e-3)).any(axis=1)
    bad |= (m.inside & ~inside_base[None, :]).any(axis=1)
    if m.folds.shape[1]:
        bad |= (m.folds & ~overlap_base[None, 1:]).any(axis=1)
    i, j = m.pairs
    if len(i):
        bad |= (m.close[rest.overlap_m] & ~overlap_base[None, j]).any(axis=1)
    return np.asarray(~bad)


def room_for_goal(geometry: ObjectGeometry, angles: Sequence[float], cell: Cell, slides: bool = True,
                  rest: Tolerance = PLANNING) -> tuple[float, float] | None:
    """Where a goal configuration `angles` rests with `rest`'s clearance: the object's base point when it does
    there, else the nearest place the robot can slide it to where it does (None: nowhere)."""
    places = places_about(Placement(geometry, tuple(float(a) for a in angles), cell), slides)
    fits = resting_places(geometry, angles, cell, places, rest)
    return next((p for p, ok in zip(places, fits) if ok), None)


def _goal_extra(space: _Space, rest: Tolerance) -> tuple[int, ...]:
    """Per place, the least time of the slides to a place where the goal configuration fits (0 where it fits
    there; -1 where it fits nowhere): part of the heuristic, and the first check that the goal can be reached."""
    fits = resting_places(space.placement.geometry, space.angles(space.target), space.placement.cell, space.places,
                          rest, space.judge.excused(rest))
    where = [p for p, ok in zip(space.places, fits) if ok]
    if not where:
        return tuple(-1 for _ in space.places)
    return tuple(0 if ok else min(_slide_ms(space.costs, p, q) for q in where) for p, ok in zip(space.places, fits))


_SLIDES = "slides"  # an open-list entry standing for every slide from its node, not yet listed


class _Node(NamedTuple):
    """A state of the search: the joints' offsets, the place (an index into `_Space.places`), and the hands: the
    joint (alphabet index) and direction of the motion under way (-1, 0: none); bimanual: the joint at the centre
    (alphabet index) and whether both hands hold its links."""

    offsets: tuple[int, ...]
    place: int
    joint: int
    direction: int
    grasped: bool


@dataclass
class _Found:
    node: _Node
    g_ms: int
    tight: int
    path: list[Motion]


class _Astar:
    """One A* run (weight 1: exhaustive and optimal; more: greedier, bounded by the weight)."""

    def __init__(self, space: _Space, hands: Hands, weight: float) -> None:
        self.space, self.hands, self.weight = space, hands, weight
        self.expansions = 0
        self.exhausted = False
        # (f, tight rests, -g, tie, node, entry): entry None for a node reached, _SLIDES for the slides from the
        # node still to put on the list, or the node a slide to `node` starts from (judged when popped)
        self._open: list[tuple[int, int, int, int, _Node, object]] = []
        self._best: dict[_Node, tuple[int, int]] = {}
        self._parent: dict[_Node, tuple[_Node, Motion] | None] = {}
        self._tie = itertools.count()
        self.slide_checks = 0
        step = space.step_deg
        k = space.orientations
        # per joint and offset: the steps still to turn, the shorter way round
        self._distance = [[min((want - now) % k, (now - want) % k) for now in range(k)] for want in space.target]
        self._step_s = step * space.costs.turn_s_per_deg
        self._new_motion_s = (space.costs.centre_s + space.costs.grasp_s + space.costs.held_turn_s
                              if hands.bimanual else space.costs.turn_s)
        self._turns = [(m.turned, m.held, float(sign * step)) for m in space.alphabet for sign in (1, -1)]
        # per configuration (offsets, place): the least (g, tight) of any of its nodes, and how much more the first
        # motion from one node of a configuration can cost than from another (the hands differ, nothing else does):
        # a node costing at least that much more than its configuration's best is dominated (`_dominated`)
        self._config_best: dict[tuple[tuple[int, ...], int], tuple[int, int]] = {}
        self._hands_slack_ms = _ms(space.costs.release_s + space.costs.centre_s + space.costs.grasp_s +
                                   space.costs.held_turn_s if hands.bimanual else space.costs.turn_s) + 1

    # -- the heuristic -----------------------------------------------------------------------------------------
    def h_ms(self, node: _Node) -> int:
        space, costs = self.space, self.space.costs
        distance = self._distance
        total = 0.0
        others = False  # another joint than the one the hands hold must turn (bimanual: they let go first)
        for i, now in enumerate(node.offsets):
            d = distance[i][now]
            if not d:
                continue
            total += d * self._step_s
            if i != node.joint:
                total += self._new_motion_s
                others = True
            elif self.hands.bimanual and not node.grasped:
                total += costs.grasp_s + costs.held_turn_s
        if others and self.hands.bimanual and node.joint >= 0 and node.grasped:
            total += costs.release_s
        return _ms(total) + space.goal_extra_ms[node.place]

    # -- the search --------------------------------------------------------------------------------------------
    def start(self) -> _Node:
        hands = self.hands
        zero = tuple(0 for _ in self.space.alphabet)
        if hands.bimanual:
            return _Node(zero, 0, hands.centre - 1, 0, hands.grasped)
        return _Node(zero, 0, -1, 0, False)

    def _dominated(self, node: _Node, g: int, tight: int) -> bool:
        """Whether another node of the same configuration is reached at least `_hands_slack_ms` sooner, and with
        no more tight rests: every plan on from `node` is then matched from it at no more time (the same motions;
        only the first can cost more, by the hands' slack at most; which turns and slides the judge accepts does
        not depend on the hands), so `node` need not be expanded, and whether a plan exists is unchanged."""
        best = self._config_best.get((node.offsets, node.place))
        return best is not None and (best[0] + self._hands_slack_ms, best[1]) <= (g, tight) and best[1] <= tight

    def _push(self, node: _Node, g: int, tight: int, parent: tuple[_Node, Motion] | None) -> None:
        best = self._best.get(node)
        if best is not None and best <= (g, tight):
            return
        if self._dominated(node, g, tight):
            return
        config = (node.offsets, node.place)
        if (g, tight) < self._config_best.get(config, (math.inf, math.inf)):
            self._config_best[config] = (g, tight)
        self._best[node] = (g, tight)
        self._parent[node] = parent
        f = g + int(math.ceil(self.weight * self.h_ms(node)))
        heapq.heappush(self._open, (f, tight, -g, next(self._tie), node, None))

    def lower_bound_ms(self) -> int:
        """A lower bound of the least time, for an exhaustive run stopped short: the least f = g + h on its open
        list (h never overestimates, so every plan passes through an entry whose f is at most its time)."""
        return self._open[0][0] if self._open else 0

    def run(self, budget: int, deadline_at: float | None) -> _Found | None:
        space = self.space
        start = self.start()
        self._push(start, 0, 0, None)
        while self._open:
            if self.expansions >= budget or (deadline_at is not None and time.monotonic() > deadline_at):
                return None
            batch: list[tuple[_Node, int, int]] = []
            first_f = self._open[0][0]
            while self._open and len(batch) < BATCH:
                entry = self._open[0]
                if batch and entry[0] > first_f + BATCH_SLACK_MS:
                    break
                _, tight, neg_g, _, node, kind = heapq.heappop(self._open)
                g = -neg_g
                if kind is _SLIDES:
                    self._expand_slides(node, g, tight)
                    continue
                if isinstance(kind, _Node):  # a slide not judged yet: judged now, among the cheapest ways on
                    self._judge_slide(node, g, tight, kind)
                    continue
                if self._best.get(node) != (g, tight) or self._dominated(node, g, tight):
                    continue  # reached again at less time since, or dominated since: that entry counts
                if node.offsets == space.target:
                    if not batch:
                        return _Found(node, g, tight, self._path(node))
                    heapq.heappush(self._open, (entry[0], tight, neg_g, next(self._tie), node, None))
                    break
                batch.append((node, g, tight))
            if batch:
                self.expansions += len(batch)
                self._expand_turns(batch)
                if len(space.places) > 1:  # room is made before any turn, or (`between`) between any two
                    for node, _, _ in batch:
                        if node == start or space.between:
                            self._list_slides(node)
        self.exhausted = True
        return None

    def _list_slides(self, node: _Node) -> None:
        """One open-list entry for every slide from `node`, at the least time any of them could lead to the goal."""
        space = self.space
        g, tight = self._best[node]
        cheapest = _ms(space.costs.slide_s + space.costs.slide_s_per_m * SLIDE_GRID_M)
        extra = _ms(space.costs.release_s) if self.hands.bimanual and node.grasped else 0
        h = self.h_ms(node) - space.goal_extra_ms[node.place]
        heapq.heappush(self._open, (g + cheapest + extra + int(math.ceil(self.weight * h)), tight, -g,
                                    next(self._tie), node, _SLIDES))

    def _turn_ms(self, node: _Node, i: int, sign: int) -> tuple[int, _Node]:
        """The time of one step of joint `i` in direction `sign` from `node`, and the node it leads to."""
        costs = self.space.costs
        seconds = self._step_s
        if self.hands.bimanual:
            if node.joint != i:
                seconds += (costs.release_s if node.grasped else 0.0) + costs.centre_s + costs.grasp_s + \
                    costs.held_turn_s
            elif not node.grasped:
                seconds += costs.grasp_s + costs.held_turn_s
            elif node.direction != sign:
                seconds += costs.held_turn_s
        elif node.joint != i or node.direction != sign:
            seconds += costs.turn_s
        offsets = list(node.offsets)
        offsets[i] = (offsets[i] + sign) % self.space.orientations
        return _ms(seconds), _Node(tuple(offsets), node.place, i, sign, self.hands.bimanual)

    def _expand_turns(self, batch: Sequence[tuple[_Node, int, int]]) -> None:
        """Every turn from each node of `batch`, judged in one go (`TurnJudge.judge_many`)."""
        space = self.space
        poses = [space.angles(node.offsets) for node, _, _ in batch]
        wheres = [space.places[node.place] for node, _, _ in batch]
        ok, roomy = space.judge.judge_many(wheres, poses, self._turns)
        for b, (node, g, tight) in enumerate(batch):
            here = poses[b]
            geometry = space.placement.geometry.placed(wheres[b]) if space.placement.refused else None
            for index in np.flatnonzero(ok[b]):
                turned, held, delta = self._turns[index]
                i, sign = int(index) // 2, (1 if delta > 0 else -1)
                move = Move(CLOCKWISE if sign > 0 else ANTICLOCKWISE, turned, held, space.alphabet[i].joint,
                            int(delta))
                if geometry is not None and any(r.forbids(geometry, here, move) for r in space.placement.refused):
                    continue
                cost, after = self._turn_ms(node, i, sign)
                self._push(after, g + cost, tight + (0 if roomy[b, index] else 1), (node, move))

    def _expand_slides(self, node: _Node, g: int, tight: int) -> None:
        """Every slide from `node` onto the open list, each judged only once it is the cheapest way on."""
        space = self.space
        origin = space.places[node.place]
        extra = _ms(space.costs.release_s) if self.hands.bimanual and node.grasped else 0
        near = [p for p, to in enumerate(space.places)
                if p != node.place and math.dist(origin, to) <= MAX_SLIDE_M + 1e-9]
        if not near:
            return
        judge = space.judge
        rests = resting_places(space.placement.geometry, space.angles(node.offsets), space.placement.cell,
                               [space.places[p] for p in near], judge.rest, judge.excused(judge.rest))
        for p, ok in zip(near, rests):
            if not ok:  # the object may not rest there: no slide there from this configuration
                continue
            to = space.places[p]
            after = _Node(node.offsets, p, -1 if not self.hands.bimanual else node.joint, 0, False)
            cost = g + extra + _slide_ms(space.costs, origin, to)
            best = self._best.get(after)
            if best is not None and best <= (cost, tight):
                continue
            f = cost + int(math.ceil(self.weight * self.h_ms(after)))
            heapq.heappush(self._open, (f, tight, -cost, next(self._tie), after, node))

    def _judge_slide(self, after: _Node, cost: int, tight: int, before: _Node) -> None:
        """The slide from `before` to `after`'s place: onto the open list as a way to `after` when the robot can
        make it (`slide_feasible`) and the object may rest there."""
        best = self._best.get(after)
        if best is not None and best <= (cost, tight):
            return
        space = self.space
        here = space.angles(before.offsets)
        origin, to = space.places[before.place], space.places[after.place]
        from_here = Placement(space.placement.geometry.placed(origin), here, space.placement.cell)
        self.slide_checks += 1
        links = grip_links(from_here, to)
        if links is None or not slide_feasible(from_here, to, links).ok:  # where it rests: `_expand_slides`
            return
        self._push(after, cost, tight, (before, Slide(to_xy=to, links=links, distance_m=math.dist(origin, to))))

    def _path(self, node: _Node) -> list[Motion]:
        path: list[Motion] = []
        at: _Node | None = node
        while at is not None and (link := self._parent.get(at)) is not None:
            at, motion = link
            path.append(motion)
        return list(reversed(path))


def _work(space: _Space, found: _Found, *, exact: bool, lower_ms: int, free: int, expansions: int) -> Work:
    room = ("" if space.between else "with no slide" if len(space.places) == 1 else
            "room made before the first turn only")
    return Work(motions=tuple(found.path), cost_s=found.g_ms / 1000.0, lower_bound_s=lower_ms / 1000.0, exact=exact,
                unconstrained_steps=free, expansions=expansions, tight_rests=found.tight, room=room)

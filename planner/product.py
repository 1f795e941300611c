"""Planning for a cyclic part times a small finite control: two grippers, a working position, grasp and release.

A recognised task (`planner.recognise`) whose changing predicates are not all cyclic variables has a *control
part*: ground facts such as ``(free left)``, ``(in-centre j2)``, ``(grasp left l3)``. Its actions are of two kinds:

* control moves change control facts only (grasp, release, bring a joint to the centre);
* turns add a fixed vector mod K to the cyclic variables and change no control fact; their control
  preconditions say in which control states they apply (the joint at the centre, both links in hand).

The control states reachable from the initial one are few (the centre's position times what the hands hold), so
they are enumerated (`ControlGraph`). Under a transform of the goal variables (identity, downstream or upstream
differences, as in `planner.cyclic`) where every turn moves a single coordinate, by any multiple of one step,
the turns of different coordinates are independent: coordinate i needs `need_i` (mod K) and a control state
offers some steps on it (+-1, a 45-degree macro's +-3, ...). A plan is then a walk through control states that
stops, for each coordinate that must change, at a state offering its steps and turns it there with the fewest
turns that add up to `need_i` (breadth-first search over Z_K). A* over (control state, coordinates done), with
the sum of each remaining coordinate's cheapest turning as heuristic, finds a shortest such plan.

It is a shortest plan of the task when the step sets offered for each coordinate are ordered by inclusion (the
same everywhere, or a locked hinge that only turns one way): then a plan that turns a coordinate in several
visits could turn it all at the visited state offering the most steps, in no more turns (the distance over Z_K
is a metric), and every plan must visit, for each coordinate, some state that offers it. Otherwise
the plan is still correct but not proven shortest (`optimal=False`), as is the greedy walk used when the search
would expand more than `NODE_LIMIT` nodes. Unsolvable is claimed only where it is proved: a coordinate whose
change no combination of its steps anywhere gives, or a goal no reachable state offers.
"""
from __future__ import annotations

import heapq
import logging
from dataclasses import dataclass
from typing import Callable, Mapping, Sequence

from planhrc.model import Atom

from .deadline import check as check_deadline
from .recognise import Axis
from .result import PlanStatus

log = logging.getLogger(__name__)

Outcome = tuple[PlanStatus, tuple[str, ...], str, "bool | None"]
Transform = Callable[[tuple[int, ...], tuple[bool, ...]], tuple[int, ...]]

CONTROL_STATE_LIMIT = 20000  # beyond this many reachable control states the control is not "small"
NODE_LIMIT = 50000  # A* nodes expanded before the greedy walk takes over


@dataclass(frozen=True)
class ControlGraph:
    """The control states reachable from `states[0]`; per state, its control moves (with the state each leads
    to) and the turns that apply there."""

    states: tuple[frozenset[Atom], ...]
    moves: tuple[tuple[tuple[Axis, int], ...], ...]
    turns: tuple[tuple[Axis, ...], ...]


def _applies(axis: Axis, state: frozenset[Atom]) -> bool:
    return all((lit.atom in state) != lit.negated for lit in axis.control_pre)


def _move_order(axis: Axis) -> tuple[str, tuple[tuple[str, str], ...]]:
    return axis.action, axis.binding


def explore(axes: Sequence[Axis], start: frozenset[Atom]) -> ControlGraph | str:
    """Every control state reachable from `start` by control moves; a reason (str) when there are too many."""
    moves = [a for a in axes if a.moves_control]
    turns = [a for a in axes if not a.moves_control]
    by_fact: dict[Atom | None, list[Axis]] = {}  # each move under one of its positive preconditions
    for axis in moves:
        positive = sorted(lit.atom for lit in axis.control_pre if not lit.negated)
        by_fact.setdefault(positive[0] if positive else None, []).append(axis)
    index = {start: 0}
    states = [start]
    edges: list[tuple[tuple[Axis, int], ...]] = []
    here: list[tuple[Axis, ...]] = []
    i = 0
    while i < len(states):
        check_deadline("exploring the control states")
        state = states[i]
        out: dict[int, Axis] = {}  # one move per next state (the first by name and arguments): the same walk
        candidates = [a for fact in sorted(state) for a in by_fact.get(fact, ())] + by_fact.get(None, [])
        for axis in sorted(candidates, key=_move_order):
            if not _applies(axis, state):
                continue
            nxt = (state - frozenset(axis.control_del)) | frozenset(axis.control_add)
            if nxt not in index:
                if len(states) >= CONTROL_STATE_LIMIT:
                    return f"more than {CONTROL_STATE_LIMIT} control states are reachable: the control is not small"
                index[nxt] = len(states)
                states.append(nxt)
            out.setdefault(index[nxt], axis)
        edges.append(tuple((axis, nxt) for nxt, axis in out.items() if nxt != i))
        here.append(tuple(a for a in turns if _applies(a, state)))
        i += 1
    return ControlGraph(tuple(states), tuple(edges), tuple(here))


@dataclass(frozen=True)
class Stations:
    """Under one transform: per control state, coordinate -> {step mod K: the preferred turn giving it}."""

    transform: str
    offers: tuple[Mapping[int, Mapping[int, Axis]], ...]
    nested: bool  # the step sets offered for each coordinate are ordered by inclusion
    to_offer: Mapping[int, tuple[int, ...]]  # coordinate -> per state, the fewest control moves to a state offering it
    between: Mapping[int, Mapping[int, int]]  # j -> i -> the fewest moves from a state offering j to one offering i


def stations(graph: ControlGraph, chain: Sequence[int], same: tuple[bool, ...], k: int,
             transforms: Mapping[str, Transform], prefer: Callable[[Axis, int], tuple[object, ...]]
             ) -> Stations | None:
    """The first transform under which every turn moves one goal coordinate (None: no transform does)."""
    turns = {axis for here in graph.turns for axis in here}
    for name, transform in transforms.items():
        images: dict[Axis, tuple[int, int] | None] = {}  # coordinate and step; None: moves no goal coordinate
        fits = True
        for axis in turns:
            effect = dict(axis.effect)
            image = transform(tuple(effect.get(v, 0) for v in chain), same)
            moved = [(i, x % k) for i, x in enumerate(image) if x % k]
            if len(moved) > 1:
                fits = False
                break
            images[axis] = moved[0] if moved else None
        if not fits:
            continue
        offers = []
        seen: dict[int, set[frozenset[int]]] = {}
        for here in graph.turns:
            table: dict[int, dict[int, Axis]] = {}
            for axis in here:
                image_of = images[axis]
                if image_of is None:
                    continue
                i, step = image_of
                best = table.setdefault(i, {}).get(step)
                if best is None or prefer(axis, chain[i]) < prefer(best, chain[i]):
                    table[i][step] = axis
            for i, steps in table.items():
                seen.setdefault(i, set()).add(frozenset(steps))
            # in a fixed order: the turns here came in the grounding's order, which follows hashing
            offers.append({i: dict(sorted(table[i].items())) for i in sorted(table)})
        nested = all(a <= b or b <= a for sets in seen.values() for a in sets for b in sets)
        to_offer = {i: _distances_to(graph, [s for s, table in enumerate(offers) if i in table]) for i in seen}
        between = {j: {i: min(to_offer[i][s] for s, table in enumerate(offers) if j in table) for i in seen}
                   for j in seen}
        return Stations(name, tuple(offers), nested, to_offer, between)
    return None


UNREACHABLE = 1 << 30


def _distances_to(graph: ControlGraph, targets: Sequence[int]) -> tuple[int, ...]:
    """Per control state, the fewest control moves to one of `targets` (breadth-first over reversed moves)."""
    back: list[list[int]] = [[] for _ in graph.states]
    for s, moves in enumerate(graph.moves):
        for _, t in moves:
            back[t].append(s)
    dist = [UNREACHABLE] * len(graph.states)
    for t in targets:
        dist[t] = 0
    frontier = list(targets)
    while frontier:
        nxt = []
        for t in frontier:
            for s in back[t]:
                if dist[s] == UNREACHABLE:
                    dist[s] = dist[t] + 1
                    nxt.append(s)
        frontier = nxt
    return tuple(dist)


class _Distances:
    """Fewest turns from 0 to each value of Z_K with a set of steps, memoised per set; among those, the least
    motion (a change of -2 as -1, -1 rather than +1, -3)."""

    def __init__(self, k: int) -> None:
        self.k = k
        self._tables: dict[frozenset[int], dict[int, tuple[int, int, int]]] = {}

    def table(self, steps: frozenset[int]) -> dict[int, tuple[int, int, int]]:
        """value -> (turns, motion in steps, last step)."""
        table = self._tables.get(steps)
        if table is None:
            table = {0: (0, 0, 0)}
            heap = [(0, 0, 0)]
            while heap:
                turns, motion, value = heapq.heappop(heap)
                if table[value][:2] != (turns, motion):
                    continue
                for step in sorted(steps):
                    reached = (value + step) % self.k
                    cost = (turns + 1, motion + min(step, self.k - step))
                    if reached not in table or cost < table[reached][:2]:
                        table[reached] = (*cost, step)
                        heapq.heappush(heap, (*cost, reached))
            self._tables[steps] = table
        return table

    def cost(self, steps: frozenset[int], target: int) -> int | None:
        found = self.table(steps).get(target % self.k)
        return None if found is None else found[0]

    def path(self, steps: frozenset[int], target: int) -> list[int]:
        table, value, out = self.table(steps), target % self.k, []
        while value:
            step = table[value][2]
            out.append(step)
            value = (value - step) % self.k
        return out[::-1]


# A step of the walk: a control move (the axis, the state it leads to) or the turning of a coordinate at a state.
_Step = tuple[str, object, int]


def plan_product(graph: ControlGraph, where: Stations, need: Sequence[int], goal: frozenset[Atom],
                 distances: _Distances) -> tuple[PlanStatus, list[_Step], str, bool | None]:
    """The walk (control moves and turnings) that reaches the goal: A* when it fits in NODE_LIMIT nodes, else a
    greedy walk. Steps are ("move", axis, next state) and ("turn", coordinate, state)."""
    k = distances.k
    required = [i for i, t in enumerate(need) if t % k]
    bit = {i: 1 << n for n, i in enumerate(required)}
    full = (1 << len(required)) - 1
    cheapest: dict[int, int] = {}
    for i in required:
        union = frozenset(step for table in where.offers for step in table.get(i, {}))
        if distances.cost(union, need[i]) is None:
            return PlanStatus.UNSOLVABLE, [], f"no combination of the turns offered reaches coordinate {i}'s goal", None
        costs = [c for table in where.offers if i in table
                 for c in [distances.cost(frozenset(table[i]), need[i])] if c is not None]
        if not costs:
            return PlanStatus.ERROR, [], f"coordinate {i}: its goal needs turns from several control states", None
        cheapest[i] = min(costs)
    goal_states = [s for s, state in enumerate(graph.states) if goal <= state]
    if not goal_states:
        return PlanStatus.UNSOLVABLE, [], "no reachable control state meets the goal's control facts", None

    def h(state: int, mask: int) -> int:
        """Each remaining coordinate's cheapest turning, and the control moves into a state offering it: from
        this state or from a state offering another remaining coordinate (the walk's stretches between its
        turnings are disjoint, and each ends at a state offering the coordinate turned there)."""
        left = [i for i in required if not mask & bit[i]]
        total = 0
        for i in left:
            entry = where.to_offer[i][state]
            for j in left:
                if j != i and where.between[j][i] < entry:
                    entry = where.between[j][i]
            total += cheapest[i] + entry
        return total

    start = (0, 0)
    best_g = {start: 0}
    parent: dict[tuple[int, int], tuple[tuple[int, int], _Step]] = {}
    heap = [(h(0, 0), 0, 0, start)]  # (f, -g, order, node): among equal f the deeper node first
    counter = 0
    while heap:
        f, minus_g, _, node = heapq.heappop(heap)
        g = -minus_g
        if g != best_g[node]:
            continue
        state, mask = node
        if mask == full and goal <= graph.states[state]:
            return PlanStatus.SOLVED, _walk(parent, node), "", where.nested
        counter += 1
        if counter > NODE_LIMIT:
            log.info("product search: more than %d nodes; greedy walk", NODE_LIMIT)
            walk = _greedy(graph, where, need, required, goal, distances)
            if walk is None:
                return PlanStatus.ERROR, [], f"the search passed {NODE_LIMIT} nodes and the greedy walk is stuck", None
            return PlanStatus.SOLVED, walk, f"greedy walk after {NODE_LIMIT} nodes of search", False
        if counter % 1024 == 0:
            check_deadline("planning over the control states")
        successors: list[tuple[tuple[int, int], int, _Step]] = [
            ((nxt, mask), 1, ("move", axis, nxt)) for axis, nxt in graph.moves[state]]
        for i, steps in where.offers[state].items():
            if i in bit and not mask & bit[i]:
                cost = distances.cost(frozenset(steps), need[i])
                if cost is not None:
                    successors.append(((state, mask | bit[i]), cost, ("turn", i, state)))
        for child, cost, step in successors:
            if g + cost < best_g.get(child, g + cost + 1):
                best_g[child] = g + cost
                parent[child] = (node, step)
                heapq.heappush(heap, (g + cost + h(*child), -(g + cost), counter, child))
    if where.nested:
        return PlanStatus.UNSOLVABLE, [], "no walk through the control states turns every coordinate it must", None
    return PlanStatus.ERROR, [], "no walk turns each coordinate at one control state; not proven unsolvable", None


def _walk(parent: Mapping[tuple[int, int], tuple[tuple[int, int], _Step]], node: tuple[int, int]) -> list[_Step]:
    steps = []
    while node in parent:
        node, step = parent[node]
        steps.append(step)
    return steps[::-1]


def _greedy(graph: ControlGraph, where: Stations, need: Sequence[int], required: Sequence[int],
            goal: frozenset[Atom], distances: _Distances) -> list[_Step] | None:
    """Go to the nearest control state that turns a remaining coordinate (control moves plus its turns), turn
    it, repeat; then to the nearest goal state. None when it gets stuck."""
    todo = set(required)
    state, out = 0, []
    while True:
        check_deadline("planning over the control states (greedy)")
        reach = _breadth_first(graph, state)
        options = []
        for s, (d, _) in reach.items():
            for i, steps in where.offers[s].items():
                if i in todo:
                    cost = distances.cost(frozenset(steps), need[i])
                    if cost is not None:
                        options.append((d + cost, s, i))
        if not todo:
            break
        if not options:
            return None
        _, s, i = min(options)
        out += _moves_to(reach, s) + [("turn", i, s)]
        todo.discard(i)
        state = s
    reach = _breadth_first(graph, state)
    ends = [(d, s) for s, (d, _) in reach.items() if goal <= graph.states[s]]
    return out + _moves_to(reach, min(ends)[1]) if ends else None


def _breadth_first(graph: ControlGraph, start: int) -> dict[int, tuple[int, tuple[Axis, int] | None]]:
    """state -> (control moves from `start`, the last move and the state it came from)."""
    reach: dict[int, tuple[int, tuple[Axis, int] | None]] = {start: (0, None)}
    frontier = [start]
    while frontier:
        nxt = []
        for s in frontier:
            for axis, t in graph.moves[s]:
                if t not in reach:
                    reach[t] = (reach[s][0] + 1, (axis, s))
                    nxt.append(t)
        frontier = nxt
    return reach


def _moves_to(reach: Mapping[int, tuple[int, tuple[Axis, int] | None]], target: int) -> list[_Step]:
    out: list[_Step] = []
    while reach[target][1] is not None:
        axis, previous = reach[target][1]  # type: ignore[misc]
        out.append(("move", axis, target))
        target = previous
    return out[::-1]


def emit(walk: Sequence[_Step], where: Stations, need: Sequence[int], distances: _Distances, cycle: Sequence[str],
         values: list[int], control: frozenset[Atom]) -> tuple[list[str], list[int], frozenset[Atom]]:
    """The plan's steps for a walk, replaying the cyclic values (for the actions' value arguments) and the
    control facts; returns the steps and the final values and control state (for the caller's check)."""
    k = distances.k
    plan: list[str] = []
    for kind, what, state in walk:
        if isinstance(what, Axis):
            plan.append(what.format(values, cycle))
            control = (control - frozenset(what.control_del)) | frozenset(what.control_add)
            continue
        assert kind == "turn" and isinstance(what, int)
        table = where.offers[state][what]
        for step in distances.path(frozenset(table), need[what]):
            axis = table[step]
            plan.append(axis.format(values, cycle))
            for var, delta in axis.effect:
                values[var] = (values[var] + delta) % k
    return plan, values, control


def solve_with_control(axes: Sequence[Axis], k: int, cycle: Sequence[str], transforms: Mapping[str, Transform],
                       prefer: Callable[[Axis, int], tuple[object, ...]], memo: dict[object, object],
                       chain: Sequence[int], same: tuple[bool, ...], current: Mapping[int, int],
                       wanted: Mapping[int, int], control: frozenset[Atom], control_goal: frozenset[Atom],
                       n_variables: int) -> Outcome:
    """Plan from the cyclic values `current` and control facts `control` to `wanted` and `control_goal`. The
    control graph and the stations depend on the initial control state and the goal variables only: kept in
    `memo` (the task's), so re-plans of an object pay for the search alone."""
    if len(memo) > MEMO_LIMIT:
        memo.clear()
    graph = memo.get(("graph", control))
    if graph is None:
        graph = memo[("graph", control)] = explore(axes, control)
    if isinstance(graph, str):
        return PlanStatus.ERROR, (), graph, None
    assert isinstance(graph, ControlGraph)
    key = ("stations", control, tuple(chain), same)
    where = memo.get(key)
    if where is None:
        where = memo[key] = stations(graph, chain, same, k, transforms, prefer) or "none"
    if not isinstance(where, Stations):
        return (PlanStatus.ERROR, (), "with the control part, no transform (identity, downstream, upstream "
                "differences) leaves each turn on one goal coordinate; refusing to guess a plan", None)
    transform = transforms[where.transform]
    need = [(a - b) % k for a, b in zip(transform(tuple(wanted[v] for v in chain), same),
                                        transform(tuple(current[v] for v in chain), same))]
    distances = memo.get("distances")
    if not isinstance(distances, _Distances):
        distances = memo["distances"] = _Distances(k)
    status, walk, message, optimal = plan_product(graph, where, need, control_goal, distances)
    if status is not PlanStatus.SOLVED:
        return status, (), message, None
    values = [current.get(v, 0) for v in range(n_variables)]
    plan, values, reached = emit(walk, where, need, distances, cycle, values, control)
    wrong = [str(v) for v, value in wanted.items() if values[v] != value]
    if wrong or not control_goal <= reached:
        log.error("internal check failed: replayed plan misses variables %s or control %s", wrong, control_goal)
        return PlanStatus.ERROR, (), "internal check failed: the replayed plan misses the goal", None
    proof = ("the turns offered for each coordinate are nested: shortest" if optimal else "not proven shortest")
    return (PlanStatus.SOLVED, tuple(plan),
            f"{where.transform} transform leaves each turn on one coordinate; search over {len(graph.states)} "
            f"control states{' (' + message + ')' if message else ''}: {proof}", optimal)


MEMO_LIMIT = 64  # control graphs and station tables a task keeps

"""Solving a recognised task: planning as algebra over Z_K per variable.

Every axis (`planner.recognise.Axis`) applies in every state and adds a fixed vector modulo K, so the
configurations form an abelian group and a plan is a multiset of axes. With the goal variables S in chain
order, try the transforms T = identity, downstream differences (x_i - x_(i-1)) and upstream differences
(x_i - x_(i+1)). When every axis, restricted to S and mapped by T, is 0 or +-e_i, the task decomposes:
coordinate i needs change t_i (mod K), realised by min(t_i, K - t_i) uses of one axis; each action changes
at most one transformed coordinate by one, so the length is optimal. When the distinct effects form a basis
of Z_K^m, each action moves one basis coordinate and the same argument holds in that basis. When under one
transform every axis touches one coordinate or two neighbouring ones (the paper's absolute schema, whose
unguarded actions turn l(k-1) about jk and move jk alone: after downstream differences e_i - e_(i+1)), an
exact dynamic programme along the chain finds a shortest plan; when every two-coordinate axis shares one hub
coordinate (the benchmark style's upstream turns: e_1 - e_(k+1)), an exact dynamic programme over the
spokes does (both ``optimal=True``). Failing that, if some transform still offers a +-e_i axis for every coordinate that must change, that plan is
returned with ``optimal=False``. Otherwise the status is error: never a wrong plan. Every plan is replayed
and checked against the goal before it is returned.

The chain order comes from the axes: variables moved together by some action form one chain, ordered by how
many distinct action supports contain them (a joint near the free end moves with more turns than one near
the table), ties broken by name with trailing numbers compared as numbers.
"""
from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any, Callable, Generic, Iterable, Mapping, TypeVar, cast

from planhrc.model import Atom, natural_key

from .deadline import check as check_deadline
from .pddl import format_sexpr
from .product import solve_with_control
from .recognise import Axis, CyclicTask
from .zk import (BASIS_LIMIT, TRANSFORMS, Transform, breadth_first, cover_of, path_to, solve_mod,
                 unit_of)
from .result import PlanResult, PlanStatus

log = logging.getLogger(__name__)

NAME = "inproc"

Outcome = tuple[PlanStatus, tuple[str, ...], str, "bool | None"]

VIEW_MEMO_LIMIT = 64  # sets of goal variables whose transformed coordinates a task keeps


@dataclass(frozen=True)
class _View:
    """The goal variables under one transform: each axis's image; when every image is 0 or +-e_i (the task
    decomposes), `cover` (coordinate -> [(sign, axis)]) and `best` ((coordinate, sign) -> the preferred axis),
    else cover None."""

    name: str
    transform: Transform
    images: list[tuple[Axis, tuple[int, ...]]]
    cover: dict[int, list[tuple[int, Axis]]] | None
    best: Mapping[tuple[int, int], Axis]


_R = TypeVar("_R")


class _Shared(Generic[_R]):
    """A property of a `GroundTask` computed once and kept in its `memo`, which every task made from it with
    `for_problem` shares: what depends only on the recognised task (chains, positions, the transforms' views) is
    worked out once per object, not once per problem text, so a re-plan pays only for what its new initial state
    changes."""

    def __init__(self, compute: Callable[[GroundTask], _R]) -> None:
        self.compute = compute
        self.name = compute.__name__

    def __get__(self, task: GroundTask | None, owner: type | None = None) -> _R:
        if task is None:
            raise AttributeError(self.name)
        memo = task.memo
        try:
            return cast(_R, memo[self.name])
        except KeyError:
            value = memo[self.name] = self.compute(task)
            return value


@dataclass(frozen=True)
class GroundTask:
    """A recognised task: re-plan with `solve(init, goal)` without parsing, grounding or recognising again."""

    task: CyclicTask
    init: frozenset[Atom]
    goal: frozenset[Atom]
    memo: dict[str, Any] = field(default_factory=dict, compare=False, repr=False)

    def for_problem(self, init: frozenset[Atom], goal: frozenset[Atom]) -> GroundTask:
        """The same recognised task with another problem's initial state and goal, sharing what was worked out."""
        return GroundTask(self.task, init, goal, self.memo)

    @property
    def domain_name(self) -> str:
        return self.task.domain_name

    @property
    def problem_name(self) -> str:
        return self.task.problem_name

    @property
    def cycle(self) -> tuple[str, ...]:
        return self.task.cycle

    @property
    def k(self) -> int:
        return len(self.task.cycle)

    @property
    def axes(self) -> tuple[Axis, ...]:
        return self.task.axes

    @property
    def static_atoms(self) -> frozenset[Atom]:
        return self.task.static_facts

    @_Shared
    def names(self) -> tuple[str, ...]:
        """Each variable's display name (by recognition index): its owner, or predicate and owner."""
        several = len(self.task.state_predicates) > 1
        return tuple((f"{pred}:" if several else "") + " ".join(owner) for pred, owner in self.task.variables)

    @_Shared
    def order(self) -> tuple[int, ...]:
        """Variable indices in chain order, chain after chain."""
        return self._chains[0]

    @_Shared
    def component(self) -> Mapping[int, int]:
        return self._chains[1]

    @property
    def joints(self) -> tuple[str, ...]:
        """Variable names in chain order (for the rotation domains: the joints)."""
        return tuple(self.names[v] for v in self.order)

    @_Shared
    def _chains(self) -> tuple[tuple[int, ...], Mapping[int, int]]:
        n = len(self.task.variables)
        parent = list(range(n))

        def find(v: int) -> int:
            while parent[v] != v:
                parent[v] = parent[parent[v]]
                v = parent[v]
            return v

        supports = {tuple(v for v, _ in axis.effect) for axis in self.axes}
        count = [0] * n
        for support in supports:
            for v in support:
                count[v] += 1
            for v in support[1:]:
                parent[find(v)] = find(support[0])
        groups: dict[int, list[int]] = {}
        for v in range(n):
            groups.setdefault(find(v), []).append(v)
        chains = sorted((sorted(members, key=lambda v: (count[v], natural_key(self.names[v])))
                         for members in groups.values()), key=lambda c: min(natural_key(self.names[v]) for v in c))
        order, component = [], {}
        for i, chain in enumerate(chains):
            for v in chain:
                order.append(v)
                component[v] = i
        return tuple(order), MappingProxyType(component)

    @_Shared
    def _position(self) -> Mapping[int, int]:
        return MappingProxyType({v: i for i, v in enumerate(self.order)})

    @_Shared
    def _rank(self) -> Mapping[str, int]:
        objects = {obj for axis in self.axes for _, obj in axis.binding}
        return MappingProxyType({o: i for i, o in enumerate(sorted(objects, key=natural_key))})

    @_Shared
    def _effects(self) -> tuple[tuple[Axis, Mapping[int, int]], ...]:
        return tuple((axis, MappingProxyType(dict(axis.effect))) for axis in self.axes)

    @_Shared
    def _lookup(self) -> Mapping[str, tuple[int, Mapping[tuple[str, ...], int]]]:
        """Predicate -> (value position, owner -> variable index)."""
        out: dict[str, tuple[int, dict[tuple[str, ...], int]]] = {}
        for p in self.task.state_predicates:
            out[p.name] = (p.value_position, {})
        for i, (pred, owner) in enumerate(self.task.variables):
            out[pred][1][owner] = i
        return MappingProxyType(out)

    def _primary(self, axis: Axis) -> int:
        if axis.pinned:
            return axis.pinned[0]
        return min((v for v, _ in axis.effect), key=lambda v: self._position[v])

    def solve_problem(self) -> PlanResult:
        """Plan for the problem's own initial state and goal."""
        return self.solve(self.init, self.goal)

    def solve(self, init_atoms: Iterable[Atom], goal_atoms: Iterable[Atom]) -> PlanResult:
        """Plan from `init_atoms` (their state-variable atoms; static atoms, if given, must equal the grounded
        ones) to the conjunction `goal_atoms`."""
        start = time.perf_counter()
        status, plan, message, optimal = self._plan(frozenset(init_atoms), frozenset(goal_atoms))
        return PlanResult(status, plan, time.perf_counter() - start, NAME, message, optimal)

    def _read(self, atom: Atom) -> tuple[int, str] | None:
        """(variable, value name) for a state-variable atom of a known variable, else None."""
        entry = self._lookup.get(atom[0])
        if entry is None or len(atom) < 2:
            return None
        pos, owners = entry
        args = atom[1:]
        if pos >= len(args):
            return None
        var = owners.get(args[:pos] + args[pos + 1:])
        return None if var is None else (var, args[pos])

    def _plan(self, init: frozenset[Atom], goal: frozenset[Atom]) -> Outcome:
        statics = self.task.static_predicates
        given = frozenset(a for a in init if a[0] in statics)
        if given and given != self.static_atoms:
            return PlanStatus.ERROR, (), "init: static facts differ from the grounded task; ground again", None
        index = {o: i for i, o in enumerate(self.cycle)}
        current: dict[int, int] = {}
        for atom in init:
            if atom[0] not in self._lookup:
                continue
            read = self._read(atom)
            if read is None or read[1] not in index:
                return PlanStatus.ERROR, (), f"init: {format_sexpr(atom)} is not a value of a known variable", None
            var, value = read
            if var in current:
                return PlanStatus.ERROR, (), f"init: {self.names[var]} has more than one value", None
            current[var] = index[value]
        missing = [self.names[v] for v in self.order if v not in current]
        if missing:
            return PlanStatus.ERROR, (), f"init: variable(s) without a value: {', '.join(missing)}", None
        control = self.task.control_predicates
        control_goal = frozenset(a for a in goal if a[0] in control)
        wanted: dict[int, int] = {}
        for atom in sorted(goal - control_goal):
            if atom[0] in statics:
                if atom not in self.static_atoms:
                    return PlanStatus.UNSOLVABLE, (), f"goal: static fact {format_sexpr(atom)} is false", None
                continue
            read = self._read(atom)
            if read is None:
                return PlanStatus.ERROR, (), f"goal: {format_sexpr(atom)} is not a value of a known variable", None
            var, value = read
            if value not in index:
                return PlanStatus.UNSOLVABLE, (), f"goal: {value} is not on the cycle of values", None
            if wanted.get(var, index[value]) != index[value]:
                return PlanStatus.UNSOLVABLE, (), f"goal: {self.names[var]} must take two values", None
            wanted[var] = index[value]
        chain = [v for v in self.order if v in wanted]
        same = tuple(self.component[a] == self.component[b] for a, b in zip(chain, chain[1:]))
        if control:  # grippers, a working position...: a cyclic part times a small control (planner.product)
            return solve_with_control(self.axes, self.k, self.cycle, TRANSFORMS, self._preference, self._control_memo,
                                      chain, same, current, wanted, frozenset(a for a in init if a[0] in control),
                                      control_goal, len(self.task.variables))
        if all(current[v] == wanted[v] for v in chain):
            return PlanStatus.SOLVED, (), "goal already holds", True
        attempts = []
        for view in self._views(tuple(chain), same):
            transform = view.transform
            need = [(a - b) % self.k for a, b in zip(transform(tuple(wanted[v] for v in chain), same),
                                                      transform(tuple(current[v] for v in chain), same))]
            attempts.append((view.name, view.images, need))
            if view.cover is not None:
                uncovered = [self.names[chain[i]] for i, t in enumerate(need) if t and i not in view.cover]
                if uncovered:
                    return (PlanStatus.UNSOLVABLE, (), f"no action changes coordinate(s) {', '.join(uncovered)} "
                            f"under the {view.name} transform", None)
                uses = self._choose_units(chain, need, view.cover, view.best)
                if uses is None:
                    return PlanStatus.UNSOLVABLE, (), "a required direction of change has no action", None
                return self._finish(uses, current, wanted, f"{view.name} transform decomposes the task", True)
        uses_or_none = self._basis_uses(chain, attempts[0][1], attempts[0][2])
        if uses_or_none is not None:
            return self._finish(uses_or_none, current, wanted, "the actions' effects form a basis: each action moves "
                                "one coordinate in that basis", True)
        for tname, images, need in attempts:
            verdict, uses = self._chain_dp(chain, images, need)
            if verdict == "unsolvable":
                return PlanStatus.UNSOLVABLE, (), f"no combination of actions reaches the goal ({tname} chain)", None
            if verdict == "solved" and uses is not None:
                return self._finish(uses, current, wanted,
                                    f"{tname} transform leaves a chain of neighbouring coordinates: exact chain DP", True)
        for tname, images, need in attempts:
            verdict, uses = self._star_dp(chain, images, need)
            if verdict == "unsolvable":
                return PlanStatus.UNSOLVABLE, (), f"no combination of actions reaches the goal ({tname} star)", None
            if verdict == "solved" and uses is not None:
                return self._finish(uses, current, wanted,
                                    f"{tname} transform leaves moves around one hub coordinate: exact star DP", True)
        best: tuple[str, list[tuple[Axis, int]]] | None = None
        for tname, images, need in attempts:
            cover = cover_of(images, self.k)
            if all(i in cover for i, t in enumerate(need) if t):
                uses = self._choose_units(chain, need, cover)
                if uses is not None and (best is None or sum(n for _, n in uses) < sum(n for _, n in best[1])):
                    best = (tname, uses)
        if best is not None:
            return self._finish(best[1], current, wanted, f"{best[0]} transform covers the goal but does not "
                                "decompose every action: not proven optimal", False)
        return (PlanStatus.ERROR, (),
                "no transform (identity, downstream, upstream differences) decomposes this task; "
                "refusing to guess a plan", None)

    def _preference(self, axis: Axis, target: int) -> tuple[Any, ...]:
        """Prefer the axis pinning the target itself, then the nearest, then (among equal effects) the binding
        with the later-numbered objects: with links numbered from the table outwards that turns the downstream
        link and holds the upstream one."""
        primary = self._primary(axis)
        return (primary != target, abs(self._position[primary] - self._position[target]),
                tuple(-self._rank[obj] for _, obj in axis.binding), axis.action)

    def _views(self, chain: tuple[int, ...], same: tuple[bool, ...]) -> tuple[_View, ...]:
        """The goal variables' coordinates under each transform (`_View`): they depend on which variables the goal
        names, not on the values, so an object's re-plans (always the same goal variables) share them."""
        key = (chain, same)
        views = self._view_memo.get(key)
        if views is None:
            views = tuple(self._view(name, transform, chain, same) for name, transform in TRANSFORMS.items())
            if len(self._view_memo) >= VIEW_MEMO_LIMIT:
                self._view_memo.clear()
            self._view_memo[key] = views
        return views

    def _view(self, name: str, transform: Transform, chain: tuple[int, ...], same: tuple[bool, ...]) -> _View:
        images = [(axis, transform(tuple(effect.get(v, 0) for v in chain), same)) for axis, effect in self._effects]
        if not all(not any(x % self.k for x in img) or unit_of(img, self.k) is not None for _, img in images):
            return _View(name, transform, images, None, {})
        cover = cover_of(images, self.k)
        best = {(i, sign): min(axes, key=lambda a: self._preference(a, chain[i]))
                for i in cover for sign in (1, -1)
                for axes in [[axis for s, axis in cover[i] if s == sign]] if axes}
        return _View(name, transform, images, cover, best)

    @_Shared
    def _control_memo(self) -> dict[object, object]:
        return {}

    @_Shared
    def _view_memo(self) -> dict[tuple[tuple[int, ...], tuple[bool, ...]], tuple[_View, ...]]:
        return {}

    def _choose_units(self, chain: list[int], need: list[int], cover: dict[int, list[tuple[int, Axis]]],
                      best: Mapping[tuple[int, int], Axis] | None = None) -> list[tuple[Axis, int]] | None:
        """For each coordinate, the cheaper direction: t uses of a +e_i axis or K - t uses of a -e_i axis (`best`:
        the preferred axis of each coordinate and sign, when known)."""
        uses: list[tuple[Axis, int]] = []
        for i, t in enumerate(need):
            if not t:
                continue
            options = []
            for sign, steps in ((1, t), (-1, self.k - t)):
                if best is not None:
                    chosen = best.get((i, sign))
                    if chosen is not None:
                        options.append((steps, sign != 1, chosen))
                    continue
                axes = [axis for s, axis in cover[i] if s == sign]
                if axes:
                    options.append((steps, sign != 1, min(axes, key=lambda a: self._preference(a, chain[i]))))
            if not options:
                return None
            steps, _, axis = min(options, key=lambda o: (o[0], o[1]))
            uses.append((axis, steps))
        return uses

    def _basis_uses(self, chain: list[int], images: list[tuple[Axis, tuple[int, ...]]], need: list[int]
                    ) -> list[tuple[Axis, int]] | None:
        """When the distinct effects (up to sign) are exactly m vectors forming a basis of Z_K^m, every action
        moves one basis coordinate by one step: solve B c = need (mod K) and take min(c_i, K - c_i) steps of
        each. None when the effects do not form such a basis (or m exceeds BASIS_LIMIT)."""
        k, m = self.k, len(chain)
        if m > BASIS_LIMIT:
            return None
        vectors: dict[tuple[int, ...], list[tuple[int, Axis]]] = {}
        for axis, img in images:
            v = tuple(x % k for x in img)
            if not any(v):
                continue
            neg = tuple((-x) % k for x in v)
            key, sign = (v, 1) if v <= neg else (neg, -1)
            vectors.setdefault(key, []).append((sign, axis))
        if len(vectors) != m:
            return None
        basis = sorted(vectors)
        coefficients = solve_mod([list(col) for col in zip(*basis)], need, k)
        if coefficients is None:
            return None
        uses: list[tuple[Axis, int]] = []
        for vector, c in zip(basis, coefficients):
            if not c:
                continue
            options = []
            for sign, steps in ((1, c), (-1, k - c)):
                axes = [axis for s, axis in vectors[vector] if s == sign]
                if axes:
                    target = chain[next(i for i, x in enumerate(vector) if x)]
                    options.append((steps, sign != 1, min(axes, key=lambda a: self._preference(a, target))))
            steps, _, axis = min(options, key=lambda o: (o[0], o[1]))
            uses.append((axis, steps))
        return uses

    def _chain_dp(self, chain: list[int], images: list[tuple[Axis, tuple[int, ...]]], need: list[int]
                  ) -> tuple[str, list[tuple[Axis, int]] | None]:
        """Exact minimum when every transformed axis touches one coordinate or two neighbouring ones.

        Moves on coordinate i alone and moves on (i, i+1) are tabulated by breadth-first search over Z_K and
        Z_K x Z_K; a dynamic programme along the chain carries the pair moves' share into the next coordinate.
        Returns ("unfit", None) when some axis spans more, ("unsolvable", None) or ("solved", uses).
        """
        move: tuple[int, ...]
        k, m = self.k, len(need)
        singles: list[dict[tuple[int, ...], Axis]] = [{} for _ in range(m)]
        pairs: list[dict[tuple[int, ...], Axis]] = [{} for _ in range(m)]
        for axis, img in images:
            nz = [i for i, x in enumerate(img) if x % k]
            if not nz:
                continue
            if len(nz) == 1:
                table, move = singles[nz[0]], (img[nz[0]] % k,)
            elif len(nz) == 2 and nz[1] == nz[0] + 1:
                table, move = pairs[nz[0]], (img[nz[0]] % k, img[nz[1]] % k)
            else:
                return "unfit", None
            target = chain[nz[0]]
            if move not in table or self._preference(axis, target) < self._preference(table[move], target):
                table[move] = axis
        if not any(pairs):
            return "unfit", None
        searches: dict[tuple[Any, ...], tuple[dict[Any, Any], dict[Any, Any]]] = {}

        def search(moves: tuple[tuple[int, ...], ...], dims: int) -> tuple[dict[Any, Any], dict[Any, Any]]:
            key = (dims, moves)
            if key not in searches:
                searches[key] = breadth_first(moves, k, dims)
            return searches[key]

        zero_pair = ({(0, 0): 0}, {(0, 0): None})
        dp: dict[int, int] = {0: 0}
        back: list[dict[int, tuple[int, tuple[int, int], int]]] = []
        for i in range(m):
            check_deadline("planning (chain dynamic programme)")
            pair_dist, _ = search(tuple(sorted(pairs[i])), 2) if pairs[i] else zero_pair
            single_dist, _ = search(tuple(sorted(singles[i])), 1)
            new: dict[int, int] = {}
            step_back: dict[int, tuple[int, tuple[int, int], int]] = {}
            for carry, cost in dp.items():
                for (x, y), pair_cost in pair_dist.items():
                    u = (need[i] - carry - x) % k
                    single_cost = single_dist.get((u,))
                    if single_cost is None:
                        continue
                    total = cost + pair_cost + single_cost
                    if total < new.get(y, total + 1):
                        new[y] = total
                        step_back[y] = (carry, (x, y), u)
            dp = new
            back.append(step_back)
        if 0 not in dp:
            return "unsolvable", None
        counts: dict[Axis, int] = {}
        y = 0
        for i in range(m - 1, -1, -1):
            carry, pair_state, u = back[i][y]
            if pairs[i]:
                for move in path_to(search(tuple(sorted(pairs[i])), 2)[1], pair_state):
                    counts[pairs[i][move]] = counts.get(pairs[i][move], 0) + 1
            for move in path_to(search(tuple(sorted(singles[i])), 1)[1], (u,)):
                counts[singles[i][move]] = counts.get(singles[i][move], 0) + 1
            y = carry
        return "solved", list(counts.items())

    def _star_dp(self, chain: list[int], images: list[tuple[Axis, tuple[int, ...]]], need: list[int]
                 ) -> tuple[str, list[tuple[Axis, int]] | None]:
        """Exact minimum when every transformed axis touches one coordinate, or two of which one is the same
        hub for all (the benchmark style's upstream turns after downstream differences: e_1 - e_(k+1)).

        Per spoke i, moves on (hub, i) and on i alone are tabulated by breadth-first search; a dynamic
        programme over the spokes carries the hub's accumulated share, and the hub's own moves close it.
        Returns ("unfit", None), ("unsolvable", None) or ("solved", uses) like `_chain_dp`.
        """
        move: tuple[int, ...]
        k, m = self.k, len(need)
        supports = []
        for axis, img in images:
            nz = tuple(i for i, x in enumerate(img) if x % k)
            if len(nz) > 2:
                return "unfit", None
            supports.append(nz)
        common = None
        for nz in supports:
            if len(nz) == 2:
                common = set(nz) if common is None else common & set(nz)
        if not common:
            return "unfit", None
        hub = min(common)
        singles: list[dict[tuple[int, ...], Axis]] = [{} for _ in range(m)]
        spokes: list[dict[tuple[int, ...], Axis]] = [{} for _ in range(m)]
        for (axis, img), nz in zip(images, supports):
            if not nz:
                continue
            if len(nz) == 1:
                table, move, target = singles[nz[0]], (img[nz[0]] % k,), chain[nz[0]]
            else:
                spoke = nz[0] if nz[1] == hub else nz[1]
                table, move, target = spokes[spoke], (img[hub] % k, img[spoke] % k), chain[spoke]
            if move not in table or self._preference(axis, target) < self._preference(table[move], target):
                table[move] = axis
        searches: dict[tuple[Any, ...], tuple[dict[Any, Any], dict[Any, Any]]] = {}

        def search(moves: tuple[tuple[int, ...], ...], dims: int) -> tuple[dict[Any, Any], dict[Any, Any]]:
            key = (dims, moves)
            if key not in searches:
                searches[key] = breadth_first(moves, k, dims)
            return searches[key]

        dp: dict[int, int] = {0: 0}
        back: list[tuple[int, dict[int, tuple[int, tuple[int, int], int]]]] = []
        for i in range(m):
            if i == hub:
                continue
            pair_dist = search(tuple(sorted(spokes[i])), 2)[0] if spokes[i] else {(0, 0): 0}
            single_dist = search(tuple(sorted(singles[i])), 1)[0]
            best: dict[int, tuple[int, tuple[int, int], int]] = {}  # hub share -> (cost, pair state, single)
            for (a, b), pair_cost in pair_dist.items():
                u = (need[i] - b) % k
                single_cost = single_dist.get((u,))
                if single_cost is not None and pair_cost + single_cost < best.get(a, (pair_cost + single_cost + 1,))[0]:
                    best[a] = (pair_cost + single_cost, (a, b), u)
            new: dict[int, int] = {}
            step_back: dict[int, tuple[int, tuple[int, int], int]] = {}
            for carry, cost in dp.items():
                for a, (c, pair_state, u) in best.items():
                    y = (carry + a) % k
                    if cost + c < new.get(y, cost + c + 1):
                        new[y] = cost + c
                        step_back[y] = (carry, pair_state, u)
            dp = new
            back.append((i, step_back))
        hub_dist = search(tuple(sorted(singles[hub])), 1)[0]
        finals = [(cost + hub_dist[((need[hub] - carry) % k,)], carry) for carry, cost in dp.items()
                  if ((need[hub] - carry) % k,) in hub_dist]
        if not finals:
            return "unsolvable", None
        _, y = min(finals)
        counts: dict[Axis, int] = {}
        for move in path_to(search(tuple(sorted(singles[hub])), 1)[1], ((need[hub] - y) % k,)):
            counts[singles[hub][move]] = counts.get(singles[hub][move], 0) + 1
        for i, step_back in reversed(back):
            carry, pair_state, u = step_back[y]
            if spokes[i]:
                for move in path_to(search(tuple(sorted(spokes[i])), 2)[1], pair_state):
                    counts[spokes[i][move]] = counts.get(spokes[i][move], 0) + 1
            for move in path_to(search(tuple(sorted(singles[i])), 1)[1], (u,)):
                counts[singles[i][move]] = counts.get(singles[i][move], 0) + 1
            y = carry
        return "solved", list(counts.items())

    def _finish(self, uses: list[tuple[Axis, int]], current: dict[int, int], wanted: dict[int, int],
                message: str, optimal: bool) -> Outcome:
        """Emit the uses in chain order, replaying the state for the value arguments, and check that the
        replayed state meets the goal (a safety net: a failed check is an error, never a plan)."""
        k = self.k
        state = [current.get(v, 0) for v in range(len(self.task.variables))]
        plan: list[str] = []
        for axis, count in sorted(uses, key=lambda u: (self._position[self._primary(u[0])], u[0].action)):
            for _ in range(count):
                plan.append(axis.format(state, self.cycle))
                for v, step in axis.effect:
                    state[v] = (state[v] + step) % k
        wrong = [self.names[v] for v, value in wanted.items() if state[v] != value]
        if wrong:
            log.error("internal check failed: replayed plan misses %s", wrong)
            return PlanStatus.ERROR, (), f"internal check failed: the plan would miss {', '.join(wrong)}", None
        return PlanStatus.SOLVED, tuple(plan), message, optimal

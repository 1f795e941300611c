"""The in-process planner for the rotation domain family: planning as algebra over Z_K per joint.

`ground_task(domain, problem)` parses and grounds once. It accepts a domain only when every action has
exactly the shape of the golden domains (tests/data/domain-*.pddl), up to variable names and parameter
order:

    parameters  ?l1 ?l2 - link, ?j1 - joint, ?o1 ?o2 - orientation
    precondition (connected ?j1 ?l1) (connected ?j1 ?l2) (hasorientation ?o1 ?j1)
                 (orientationord ?o1 ?o2) [clockwise, +1]  or  (orientationord ?o2 ?o1) [anticlockwise, -1]
                 optional (not (= ?l1 ?l2)), optional guard (affected ?j1 ?l1 ?j1)
    effect      (not (hasorientation ?o1 ?j1)) (hasorientation ?o2 ?j1)
                 optional (forall (?j2 ?o3 ?o4) (when (and (affected ?j2 ?l1 ?j1) (not (= ?j2 ?j1))
                          (hasorientation ?o3 ?j2) (orientationord ?o3 ?o4) | (orientationord ?o4 ?o3))
                          (and (not (hasorientation ?o3 ?j2)) (hasorientation ?o4 ?j2))))

`?l1` is the link named by `affected` (the link that turns); in the relative formulation, which has no
`affected`, it is the first link parameter. Grounding yields one *axis* per applicable (action, ?l1, ?l2,
?j1): its effect is a vector over joints with entries in {-1, 0, +1} (one orientation step), which does not
depend on the state as long as every joint has exactly one orientation and `orientationord` is one cycle.

The group of joint configurations is abelian (Z_K per joint), so a plan is a multiset of axes. With the
goal joints S in chain order, try the transforms T = identity, downstream differences (x_i - x_{i-1}) and
upstream differences (x_i - x_{i+1}). When every axis, restricted to S and mapped by T, is 0 or +-e_i, the
task decomposes: coordinate i needs change t_i (mod K), realised by min(t_i, K - t_i) uses of one axis;
each action changes at most one transformed coordinate by one, so the length is optimal.
When no transform decomposes every axis but under one of them every axis touches one coordinate or two
neighbouring ones (the paper's absolute schema: its unguarded actions turn l(k-1) about jk and move jk
alone, which after downstream differences is e_i - e_(i+1)), an exact dynamic programme along the chain
finds a shortest plan (``optimal=True``). Failing that, if some transform still offers a +-e_i axis for
every coordinate that must change, that plan is returned with ``optimal=False``. Otherwise the status is
error: never a wrong plan. Every plan is replayed and checked against the goal before it is returned.
"""
from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from functools import cached_property
from itertools import permutations
from types import MappingProxyType
from typing import Callable, Iterable, Mapping

from .errors import PlannerError
from .pddl import ActionSchema, Atom, Domain, Problem, SExpr, format_sexpr, parse_domain, parse_problem
from .result import PlanResult, PlanStatus

log = logging.getLogger(__name__)

NAME = "inproc"
CONNECTED = "connected"
HAS_ORIENTATION = "hasorientation"
ORIENTATION_ORD = "orientationord"
AFFECTED = "affected"
STATIC_PREDICATES = frozenset({CONNECTED, ORIENTATION_ORD, AFFECTED})


class OutsideFamilyError(PlannerError):
    """The domain or problem is not a member of the rotation family this planner understands."""


# -- recognising the action schemas ------------------------------------------------------------------------
@dataclass(frozen=True)
class RotationSchema:
    """One recognised action schema. `roles[i]` names parameter i: 'l1', 'l2', 'j', 'o1' or 'o2'."""

    action: str
    roles: tuple[str, ...]
    link_type: str
    joint_type: str
    orientation_type: str
    direction: int  # +1 when o2 follows o1 in orientationord (clockwise), -1 otherwise
    distinct_links: bool
    guarded: bool  # precondition (affected ?j1 ?l1 ?j1)
    cascade: int  # 0: no conditional effect; else the step of every other affected joint


def _conjuncts(expr: SExpr) -> list[SExpr]:
    if isinstance(expr, tuple) and expr and expr[0] == "and":
        return list(expr[1:])
    return [expr]


def _is_atom(expr: SExpr) -> bool:
    return isinstance(expr, tuple) and len(expr) >= 1 and all(isinstance(e, str) for e in expr) and expr[0] not in (
        "not", "and", "or", "forall", "when", "exists", "imply")


def recognise_schema(schema: ActionSchema) -> RotationSchema:
    """Check that `schema` has exactly the shape of the family; raise OutsideFamilyError saying why not."""
    where = f"action {schema.name}"

    def fail(why: str) -> OutsideFamilyError:
        return OutsideFamilyError(f"{where}: {why}; the in-process planner only handles the rotation family")

    params = dict(schema.parameters)
    if len(schema.parameters) != 5:
        raise fail(f"expected 5 parameters (2 links, 1 joint, 2 orientations), got {len(schema.parameters)}")
    pre = _conjuncts(schema.precondition)
    positives = [p for p in pre if _is_atom(p)]
    has = [p for p in positives if p[0] == HAS_ORIENTATION]
    if len(has) != 1 or len(has[0]) != 3:
        raise fail("expected exactly one (hasorientation ?o1 ?j1) precondition")
    o1, j = has[0][1], has[0][2]
    ords = [p for p in positives if p[0] == ORIENTATION_ORD and len(p) == 3 and o1 in p[1:]]
    if len(ords) != 1:
        raise fail("expected exactly one (orientationord ...) precondition on ?o1")
    direction = 1 if ords[0][1] == o1 else -1
    o2 = ords[0][2] if direction == 1 else ords[0][1]
    conns = [p for p in positives if p[0] == CONNECTED and len(p) == 3 and p[1] == j]
    link_vars = [p[2] for p in conns]
    if len(conns) != 2 or len(set(link_vars)) != 2:
        raise fail("expected exactly two (connected ?j1 ?l) preconditions on two different links")
    guards = [p for p in positives if p[0] == AFFECTED and len(p) == 4 and p[1] == j and p[3] == j]
    cascade, cascade_link = _recognise_effect(schema, j, o1, o2, fail)
    turned_candidates = {g[2] for g in guards} | ({cascade_link} if cascade_link else set())
    if len(turned_candidates) > 1:
        raise fail("guard and conditional effect name different links")
    turned = turned_candidates.pop() if turned_candidates else link_vars[0]
    if turned not in link_vars:
        raise fail(f"`affected` names {turned}, which is not a connected link")
    other = link_vars[1] if turned == link_vars[0] else link_vars[0]
    roles_by_var = {turned: "l1", other: "l2", j: "j", o1: "o1", o2: "o2"}
    if len(roles_by_var) != 5 or set(roles_by_var) != set(params):
        raise fail("parameters are not exactly ?l1 ?l2 ?j1 ?o1 ?o2")
    expected: set[SExpr] = {("connected", j, turned), ("connected", j, other), (HAS_ORIENTATION, o1, j), ords[0]}
    expected |= set(guards)
    distinct = {("not", ("=", turned, other)), ("not", ("=", other, turned))} & set(pre)
    expected |= distinct
    if len(pre) != len(expected) or set(pre) != expected:
        extra = [format_sexpr(p) for p in pre if p not in expected]
        raise fail(f"unexpected precondition(s) {', '.join(extra) or '(duplicates)'}")
    if len(guards) > 1 or len(distinct) > 1:
        raise fail("duplicated precondition")
    types = {role: params[var] for var, role in roles_by_var.items()}
    if types["l1"] != types["l2"] or types["o1"] != types["o2"]:
        raise fail("the two links (or the two orientations) have different types")
    return RotationSchema(
        action=schema.name,
        roles=tuple(roles_by_var[var] for var, _ in schema.parameters),
        link_type=types["l1"],
        joint_type=types["j"],
        orientation_type=types["o1"],
        direction=direction,
        distinct_links=bool(distinct),
        guarded=bool(guards),
        cascade=cascade,
    )


def _recognise_effect(schema: ActionSchema, j: str, o1: str, o2: str,
                      fail: Callable[[str], OutsideFamilyError]) -> tuple[int, str | None]:
    """Return (cascade step, link variable named by the conditional effect's `affected`)."""
    effects = _conjuncts(schema.effect)
    direct = {("not", (HAS_ORIENTATION, o1, j)), (HAS_ORIENTATION, o2, j)}
    rest = [e for e in effects if e not in direct]
    if len(effects) - len(rest) != 2 or len(set(effects)) != len(effects):
        raise fail("effect must delete (hasorientation ?o1 ?j1) and add (hasorientation ?o2 ?j1)")
    if not rest:
        return 0, None
    if len(rest) != 1:
        raise fail(f"unexpected effect(s) {', '.join(format_sexpr(e) for e in rest)}")
    fa = rest[0]
    if not (isinstance(fa, tuple) and len(fa) == 3 and fa[0] == "forall" and isinstance(fa[1], tuple)
            and isinstance(fa[2], tuple) and len(fa[2]) == 3 and fa[2][0] == "when"):
        raise fail(f"unexpected effect {format_sexpr(fa)}")
    qvars = [tok for tok in fa[1] if isinstance(tok, str) and tok.startswith("?")]
    cond, eff = _conjuncts(fa[2][1]), _conjuncts(fa[2][2])
    aff = [c for c in cond if _is_atom(c) and c[0] == AFFECTED and len(c) == 4 and c[3] == j]
    has = [c for c in cond if _is_atom(c) and c[0] == HAS_ORIENTATION and len(c) == 3]
    if len(aff) != 1 or len(has) != 1:
        raise fail("conditional effect must test (affected ?j2 ?l1 ?j1) and (hasorientation ?o3 ?j2)")
    j2, link = aff[0][1], aff[0][2]
    o3 = has[0][1]
    if has[0][2] != j2:
        raise fail("conditional effect must test the orientation of the affected joint")
    ords = [c for c in cond if _is_atom(c) and c[0] == ORIENTATION_ORD and len(c) == 3 and o3 in c[1:]]
    if len(ords) != 1:
        raise fail("conditional effect must test one (orientationord ...) on ?o3")
    step = 1 if ords[0][1] == o3 else -1
    o4 = ords[0][2] if step == 1 else ords[0][1]
    expected_cond = {aff[0], has[0], ords[0], ("not", ("=", j2, j))}
    alt_cond = {aff[0], has[0], ords[0], ("not", ("=", j, j2))}
    if set(cond) not in (expected_cond, alt_cond) or len(cond) != 4:
        raise fail("conditional effect must be guarded by exactly (affected ?j2 ?l1 ?j1) (not (= ?j2 ?j1)) "
                   "(hasorientation ?o3 ?j2) (orientationord ...)")
    if set(eff) != {("not", (HAS_ORIENTATION, o3, j2)), (HAS_ORIENTATION, o4, j2)} or len(eff) != 2:
        raise fail("conditional effect must move ?j2 from ?o3 to ?o4")
    if sorted(qvars) != sorted({j2, o3, o4}):
        raise fail("forall must quantify exactly ?j2 ?o3 ?o4")
    return step, link


# -- grounding ---------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Axis:
    """One ground action up to its orientation arguments, with its effect vector over joints."""

    schema: RotationSchema
    l1: str
    l2: str
    joint: str
    effect: tuple[tuple[str, int], ...]  # (joint, step), sorted by chain order

    def format(self, o1: str, o2: str) -> str:
        binding = {"l1": self.l1, "l2": self.l2, "j": self.joint, "o1": o1, "o2": o2}
        return "(" + " ".join([self.schema.action] + [binding[r] for r in self.schema.roles]) + ")"


# A transform maps a vector over the goal joints (chain order) to new coordinates; `same[i]` tells whether
# goal joint i and goal joint i+1 lie on the same chain (differences never cross two objects).
Transform = Callable[[tuple[int, ...], tuple[bool, ...]], tuple[int, ...]]


def _identity(v: tuple[int, ...], same: tuple[bool, ...]) -> tuple[int, ...]:
    return v


def _downstream(v: tuple[int, ...], same: tuple[bool, ...]) -> tuple[int, ...]:
    return tuple(v[i] - (v[i - 1] if i and same[i - 1] else 0) for i in range(len(v)))


def _upstream(v: tuple[int, ...], same: tuple[bool, ...]) -> tuple[int, ...]:
    n = len(v)
    return tuple(v[i] - (v[i + 1] if i + 1 < n and same[i] else 0) for i in range(n))


TRANSFORMS: dict[str, Transform] = {"identity": _identity, "downstream": _downstream, "upstream": _upstream}


def natural_key(name: str) -> tuple:
    """obj1_j10 sorts after obj1_j9: split trailing digits off each name."""
    stem = name.rstrip("0123456789")
    digits = name[len(stem):]
    return (stem, int(digits) if digits else -1, name)


@dataclass(frozen=True)
class GroundTask:
    """A grounded task of the family: re-plan with `solve(init, goal)` without parsing or grounding again."""

    domain_name: str
    problem_name: str
    joints: tuple[str, ...]  # chain order, object after object
    component: Mapping[str, int]  # joint -> index of its chain (connected component of links and joints)
    cycle: tuple[str, ...]  # orientations in orientationord order
    axes: tuple[Axis, ...]
    static_atoms: frozenset[Atom]
    init: frozenset[Atom]
    goal: frozenset[Atom]
    link_rank: Mapping[str, int]

    @property
    def k(self) -> int:
        return len(self.cycle)

    @cached_property
    def _effects(self) -> tuple[tuple[Axis, Mapping[str, int]], ...]:
        """Each axis with its effect as a read-only joint -> step map (built once, on first use)."""
        return tuple((axis, MappingProxyType(dict(axis.effect))) for axis in self.axes)

    def solve_problem(self) -> PlanResult:
        """Plan for the problem's own initial state and goal."""
        return self.solve(self.init, self.goal)

    def solve(self, init_atoms: Iterable[Atom], goal_atoms: Iterable[Atom]) -> PlanResult:
        """Plan from `init_atoms` (their hasorientation atoms; static atoms, if given, must equal the grounded
        ones) to the conjunction `goal_atoms`."""
        start = time.perf_counter()
        status, plan, message, optimal = self._plan(frozenset(init_atoms), frozenset(goal_atoms))
        return PlanResult(status, plan, time.perf_counter() - start, NAME, message, optimal)

    # The four-tuple keeps `solve` the only place that measures time.
    def _plan(self, init: frozenset[Atom], goal: frozenset[Atom]
              ) -> tuple[PlanStatus, tuple[str, ...], str, bool | None]:
        statics = frozenset(a for a in init if a[0] in STATIC_PREDICATES)
        if statics and statics != self.static_atoms:
            return PlanStatus.ERROR, (), "init: static facts differ from the grounded task; ground again", None
        index = {o: i for i, o in enumerate(self.cycle)}
        joint_set = set(self.joints)
        current: dict[str, int] = {}
        for atom in init:
            if atom[0] != HAS_ORIENTATION:
                continue
            if len(atom) != 3 or atom[2] not in joint_set or atom[1] not in index:
                return PlanStatus.ERROR, (), f"init: {format_sexpr(atom)} is not an orientation of a joint", None
            if atom[2] in current:
                return PlanStatus.ERROR, (), f"init: joint {atom[2]} has more than one orientation", None
            current[atom[2]] = index[atom[1]]
        missing = [j for j in self.joints if j not in current]
        if missing:
            return PlanStatus.ERROR, (), f"init: joint(s) without an orientation: {', '.join(missing)}", None
        wanted: dict[str, int] = {}
        for atom in sorted(goal):
            if atom[0] in STATIC_PREDICATES:
                if atom not in self.static_atoms:
                    return PlanStatus.UNSOLVABLE, (), f"goal: static fact {format_sexpr(atom)} is false", None
                continue
            if atom[0] != HAS_ORIENTATION or len(atom) != 3 or atom[2] not in joint_set:
                return PlanStatus.ERROR, (), f"goal: {format_sexpr(atom)} is not an orientation of a joint", None
            if atom[1] not in index:
                return PlanStatus.UNSOLVABLE, (), f"goal: {atom[1]} is not on the orientation cycle", None
            if wanted.get(atom[2], index[atom[1]]) != index[atom[1]]:
                return PlanStatus.UNSOLVABLE, (), f"goal: joint {atom[2]} must take two orientations", None
            wanted[atom[2]] = index[atom[1]]
        chain = [j for j in self.joints if j in wanted]
        if all(current[j] == wanted[j] for j in chain):
            return PlanStatus.SOLVED, (), "goal already holds", True
        same = tuple(self.component[a] == self.component[b] for a, b in zip(chain, chain[1:]))
        restricted = [(axis, tuple(effect.get(j, 0) for j in chain)) for axis, effect in self._effects]
        attempts = []
        for tname, transform in TRANSFORMS.items():
            images = [(axis, transform(vec, same)) for axis, vec in restricted]
            need = [(a - b) % self.k for a, b in zip(transform(tuple(wanted[j] for j in chain), same),
                                                      transform(tuple(current[j] for j in chain), same))]
            attempts.append((tname, images, need))
            if all(not any(img) or _unit(img) is not None for _, img in images):
                cover = _cover(images)
                uncovered = [chain[i] for i, t in enumerate(need) if t and i not in cover]
                if uncovered:
                    return (PlanStatus.UNSOLVABLE, (),
                            f"no action changes coordinate(s) {', '.join(uncovered)} under the {tname} transform", None)
                uses = self._choose_units(chain, need, cover)
                if uses is None:
                    return PlanStatus.UNSOLVABLE, (), "a required direction of rotation has no action", None
                return self._finish(uses, current, wanted, f"{tname} transform decomposes the task", True)
        for tname, images, need in attempts:
            verdict, uses = self._chain_dp(chain, images, need)
            if verdict == "unsolvable":
                return PlanStatus.UNSOLVABLE, (), f"no combination of actions reaches the goal ({tname} chain)", None
            if verdict == "solved" and uses is not None:
                return self._finish(uses, current, wanted,
                                    f"{tname} transform leaves a chain of neighbouring coordinates: exact chain DP", True)
        best: tuple[str, list[tuple[Axis, int]]] | None = None
        for tname, images, need in attempts:
            cover = _cover(images)
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

    def _preference(self, axis: Axis, target: str) -> tuple:
        """Prefer the axis about the target joint itself, then the nearest, then the downstream link as ?l1."""
        position = self._position
        return (axis.joint != target, abs(position[axis.joint] - position[target]), -self.link_rank[axis.l1],
                -self.link_rank[axis.l2], axis.schema.action)

    @cached_property
    def _position(self) -> Mapping[str, int]:
        return MappingProxyType({j: i for i, j in enumerate(self.joints)})

    def _choose_units(self, chain: list[str], need: list[int], cover: dict[int, list[tuple[int, Axis]]]
                      ) -> list[tuple[Axis, int]] | None:
        """For each coordinate, the cheaper direction: t uses of a +e_i axis or K - t uses of a -e_i axis."""
        uses: list[tuple[Axis, int]] = []
        for i, t in enumerate(need):
            if not t:
                continue
            options = []
            for sign, steps in ((1, t), (-1, self.k - t)):
                axes = [axis for s, axis in cover[i] if s == sign]
                if axes:
                    options.append((steps, sign != 1, min(axes, key=lambda a: self._preference(a, chain[i]))))
            if not options:
                return None
            steps, _, axis = min(options, key=lambda o: (o[0], o[1]))
            uses.append((axis, steps))
        return uses

    def _chain_dp(self, chain: list[str], images: list[tuple[Axis, tuple[int, ...]]], need: list[int]
                  ) -> tuple[str, list[tuple[Axis, int]] | None]:
        """Exact minimum when every transformed axis touches one coordinate or two neighbouring ones.

        Moves on coordinate i alone and moves on (i, i+1) are tabulated by breadth-first search over Z_K and
        Z_K x Z_K; a dynamic programme along the chain carries the pair moves' share into the next coordinate.
        Returns ("unfit", None) when some axis spans more, ("unsolvable", None) or ("solved", uses).
        """
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
        searches: dict[tuple, tuple[dict, dict]] = {}

        def search(moves: tuple[tuple[int, ...], ...], dims: int) -> tuple[dict, dict]:
            key = (dims, moves)
            if key not in searches:
                searches[key] = _breadth_first(moves, k, dims)
            return searches[key]

        zero_pair = ({(0, 0): 0}, {(0, 0): None})
        dp: dict[int, int] = {0: 0}
        back: list[dict[int, tuple[int, tuple[int, int], int]]] = []
        for i in range(m):
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
                for move in _path(search(tuple(sorted(pairs[i])), 2)[1], pair_state):
                    counts[pairs[i][move]] = counts.get(pairs[i][move], 0) + 1
            for move in _path(search(tuple(sorted(singles[i])), 1)[1], (u,)):
                counts[singles[i][move]] = counts.get(singles[i][move], 0) + 1
            y = carry
        return "solved", list(counts.items())

    def _finish(self, uses: list[tuple[Axis, int]], current: dict[str, int], wanted: dict[str, int],
                message: str, optimal: bool) -> tuple[PlanStatus, tuple[str, ...], str, bool | None]:
        """Emit the uses in chain order, replaying the state for the orientation arguments, and check that
        the replayed state meets the goal (a safety net: a failed check is an error, never a plan)."""
        k = self.k
        state = dict(current)
        plan: list[str] = []
        for axis, count in sorted(uses, key=lambda u: (self._position[u[0].joint], u[0].schema.action)):
            for _ in range(count):
                here = state[axis.joint]
                plan.append(axis.format(self.cycle[here], self.cycle[(here + axis.schema.direction) % k]))
                for j, step in axis.effect:
                    state[j] = (state[j] + step) % k
        wrong = [j for j, v in wanted.items() if state[j] != v]
        if wrong:
            log.error("internal check failed: replayed plan misses %s", wrong)
            return PlanStatus.ERROR, (), f"internal check failed: the plan would miss {', '.join(wrong)}", None
        return PlanStatus.SOLVED, tuple(plan), message, optimal


def _cover(images: list[tuple[Axis, tuple[int, ...]]]) -> dict[int, list[tuple[int, Axis]]]:
    """Coordinate -> [(sign, axis)] for every axis whose image is +-e_coordinate."""
    cover: dict[int, list[tuple[int, Axis]]] = {}
    for axis, img in images:
        unit = _unit(img)
        if unit is not None:
            cover.setdefault(unit[0], []).append((unit[1], axis))
    return cover


def _breadth_first(moves: tuple[tuple[int, ...], ...], k: int, dims: int) -> tuple[dict, dict]:
    """Fewest moves from 0 to every reachable vector of Z_K^dims, with parent links."""
    start = (0,) * dims
    dist = {start: 0}
    parent: dict[tuple[int, ...], tuple[tuple[int, ...], tuple[int, ...]] | None] = {start: None}
    frontier = [start]
    while frontier:
        nxt = []
        for s in frontier:
            for mv in moves:
                t = tuple((a + b) % k for a, b in zip(s, mv))
                if t not in dist:
                    dist[t] = dist[s] + 1
                    parent[t] = (s, mv)
                    nxt.append(t)
        frontier = nxt
    return dist, parent


def _path(parent: Mapping, target: tuple[int, ...]) -> list[tuple[int, ...]]:
    moves = []
    while parent[target] is not None:
        target, mv = parent[target]
        moves.append(mv)
    return moves


def _unit(v: tuple[int, ...]) -> tuple[int, int] | None:
    """(index, sign) when v is +-e_index, else None."""
    nonzero = [(i, x) for i, x in enumerate(v) if x]
    if len(nonzero) == 1 and nonzero[0][1] in (1, -1):
        return nonzero[0]
    return None


def ground_task(domain: str, problem: str) -> GroundTask:
    """Parse and ground once; raises PlannerError (OutsideFamilyError) when the task is not of the family."""
    return ground_parsed(parse_domain(domain), parse_problem(problem))


def ground_parsed(dom: Domain, prob: Problem) -> GroundTask:
    schemas = [recognise_schema(a) for a in dom.actions]
    if prob.domain_name != dom.name:
        log.debug("problem %s is for domain %s, not %s", prob.name, prob.domain_name, dom.name)
    statics = frozenset(a for a in prob.init if a[0] in STATIC_PREDICATES)
    for atom in prob.init:
        if atom[0] not in STATIC_PREDICATES and atom[0] != HAS_ORIENTATION:
            raise OutsideFamilyError(f"init: unknown predicate in {format_sexpr(atom)}")
    joint_types = {s.joint_type for s in schemas}
    link_types = {s.link_type for s in schemas}
    orientation_types = {s.orientation_type for s in schemas}
    if len(joint_types) != 1 or len(link_types) != 1 or len(orientation_types) != 1:
        raise OutsideFamilyError("actions disagree on the types of links, joints or orientations")
    joints = sorted(prob.objects_of(dom.subtypes(joint_types.pop())), key=natural_key)
    links = sorted(prob.objects_of(dom.subtypes(link_types.pop())), key=natural_key)
    orientations = set(prob.objects_of(dom.subtypes(orientation_types.pop())))
    cycle = _orientation_cycle(statics, orientations)
    link_set, joint_set = set(links), set(joints)
    links_of: dict[str, list[str]] = {j: [] for j in joints}
    for atom in statics:
        if atom[0] == CONNECTED and len(atom) == 3 and atom[1] in joint_set and atom[2] in link_set:
            links_of[atom[1]].append(atom[2])
    joints, component = chain_order(joints, links_of)
    position = {j: i for i, j in enumerate(joints)}
    axes: list[Axis] = []
    for schema in schemas:
        for j in joints:
            ls = sorted(links_of[j], key=natural_key)
            pairs = list(permutations(ls, 2)) + ([] if schema.distinct_links else [(x, x) for x in ls])
            for l1, l2 in pairs:
                if schema.guarded and (AFFECTED, j, l1, j) not in statics:
                    continue
                effect = {j: schema.direction}
                if schema.cascade:
                    for j2 in joints:
                        if j2 != j and (AFFECTED, j2, l1, j) in statics:
                            effect[j2] = schema.cascade
                ordered = tuple(sorted(effect.items(), key=lambda kv: position[kv[0]]))
                axes.append(Axis(schema, l1, l2, j, ordered))
    log.debug("grounded %s/%s: %d joints, %d orientations, %d axes", dom.name, prob.name, len(joints),
              len(cycle), len(axes))
    return GroundTask(dom.name, prob.name, tuple(joints), MappingProxyType(component), cycle, tuple(axes), statics, prob.init, prob.goal,
                      {name: i for i, name in enumerate(links)})


def chain_order(joints: list[str], links_of: Mapping[str, list[str]]) -> tuple[list[str], dict[str, int]]:
    """Joints in chain order, chain after chain, and each joint's chain index.

    A chain is a connected component of the joint-link graph. When it is a simple path, its joints are listed
    walking from the end link with the smaller name (either direction is fine: the transforms try
    differences both ways); otherwise (branching, cycles) by name with trailing numbers compared as numbers.
    """
    joints_of: dict[str, list[str]] = {}
    for j in joints:
        for link in links_of[j]:
            joints_of.setdefault(link, []).append(j)
    seen: set[str] = set()
    order: list[str] = []
    component: dict[str, int] = {}
    for first in joints:  # natural-key order: chains come out in the order of their first joint
        if first in seen:
            continue
        members, stack = [], [first]
        seen.add(first)
        while stack:
            j = stack.pop()
            members.append(j)
            for link in links_of[j]:
                for other in joints_of[link]:
                    if other not in seen:
                        seen.add(other)
                        stack.append(other)
        index = len({*component.values()})
        walked = _walk_path(members, links_of, joints_of)
        for j in walked if walked is not None else sorted(members, key=natural_key):
            order.append(j)
            component[j] = index
    return order, component


def _walk_path(members: list[str], links_of: Mapping[str, list[str]],
               joints_of: Mapping[str, list[str]]) -> list[str] | None:
    if any(len(set(links_of[j])) != 2 for j in members):
        return None
    links = {link for j in members for link in links_of[j]}
    if any(len(joints_of[link]) > 2 for link in links):
        return None
    ends = sorted((link for link in links if len(joints_of[link]) == 1), key=natural_key)
    if len(ends) != 2:
        return None
    walked: list[str] = []
    link, previous = ends[0], None
    while True:
        nxt = [j for j in joints_of[link] if j != previous]
        if not nxt:
            break
        previous = nxt[0]
        walked.append(previous)
        link = next(x for x in links_of[previous] if x != link)
    return walked if len(walked) == len(members) else None


def _orientation_cycle(statics: frozenset[Atom], orientations: set[str]) -> tuple[str, ...]:
    succ: dict[str, str] = {}
    for atom in sorted(a for a in statics if a[0] == ORIENTATION_ORD):
        if len(atom) != 3 or atom[1] not in orientations or atom[2] not in orientations:
            raise OutsideFamilyError(f"init: {format_sexpr(atom)} does not relate two orientations")
        if atom[1] in succ:
            raise OutsideFamilyError(f"orientationord: {atom[1]} has two successors")
        succ[atom[1]] = atom[2]
    if not succ:
        raise OutsideFamilyError("orientationord: no orientation order in init")
    if len(set(succ.values())) != len(succ) or set(succ.values()) != set(succ):
        raise OutsideFamilyError("orientationord: must be a single cycle over the orientations (it does not wrap)")
    start = min(succ, key=natural_key)
    cycle = [start]
    while succ[cycle[-1]] != start:
        cycle.append(succ[cycle[-1]])
    if len(cycle) != len(succ):
        raise OutsideFamilyError("orientationord: forms several cycles, expected one")
    return tuple(cycle)


class InprocPlanner:
    """Planner protocol wrapper: ground + solve. Bad PDDL and out-of-family tasks give status error."""

    name = NAME

    def solve(self, domain: str, problem: str, timeout_s: float) -> PlanResult:
        start = time.perf_counter()
        try:
            task = ground_task(domain, problem)
        except PlannerError as exc:
            return PlanResult(PlanStatus.ERROR, (), time.perf_counter() - start, NAME, str(exc))
        result = task.solve_problem()
        elapsed = time.perf_counter() - start
        if elapsed > timeout_s:
            return PlanResult(PlanStatus.TIMEOUT, (), elapsed, NAME, f"took {elapsed:.3f} s > {timeout_s} s")
        return PlanResult(result.status, result.plan, elapsed, NAME, result.message, result.optimal)

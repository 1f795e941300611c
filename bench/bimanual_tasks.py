"""Random tasks of the bimanual formulation's family, written in the style of the field's files.

A chain of links l1 .. lN joined by joints j1 .. j(N-1) lies on a table; each joint has an absolute angle, one of K
on a cycle. Two hands work on one joint at a time: the joint must be at the working position (the centre), both
hands grasp the two links it joins, and turning the downstream link moves that joint and every joint after it
(a conditional effect over the joints `carries` lists, as the absolute formulation's `affected`). Then the hands
let go before they grasp elsewhere. Two variants, as in the field:

* ``basic``: `centre` (bring another joint to the centre, hands free), `grasp`, `turn-up` / `turn-down` (one
  step), `release`;
* ``macros``: no separate centring; `centre-and-grasp` brings a joint to the centre and grasps in one action,
  and `turn-up-3` / `turn-down-3` turn three steps at once (45 degrees with K = 24).

The text uses what those files use: typed lists whose dash touches the type (``?j -joint``), `:adl`,
`:equality`, `:conditional-effects`, `forall` / `when` and negative preconditions; the problems list, beside the
`carries` facts turns use, the upstream ones no turn can use (as the field's problems do).

`optimal_length` gives the length of a shortest plan by a formula, independently of any planner: in downstream
differences (d_k = angle of j_k minus that of j_(k-1)) a turn of j_k changes d_k alone, so each joint that must
change costs its own turning steps (the fewest steps of +-1, or +-1 and +-3, that add up to the change mod K),
and the hands cost one grasp per such joint and one release between two of them; ``basic`` adds one centring
per such joint, except the one at the centre at the start when it must change (it is done first).
"""
from __future__ import annotations

import random
from dataclasses import dataclass
from typing import Iterable

from planhrc.bench.errors import BenchError

VARIANTS = ("basic", "macros")
HANDS = ("left", "right")


@dataclass(frozen=True)
class BimanualInstance:
    links: int
    orientations: int
    index: int
    variant: str
    init: tuple[int, ...]  # step index (0 .. K-1) of each joint's angle, j1 first
    goal: tuple[int, ...]
    centre: int  # the joint at the centre at the start (1-based)

    @property
    def joints(self) -> int:
        return self.links - 1

    @property
    def label(self) -> str:
        return f"{self.links}-{self.orientations}"

    @property
    def name(self) -> str:
        return f"bimanual-{self.variant}-{self.links}-{self.orientations}-{self.index}"


def make_instances(links: Iterable[int], orientations: Iterable[int], per_cell: int, variant: str = "macros"
                   ) -> tuple[BimanualInstance, ...]:
    """`per_cell` random instances per (links, orientations), the same for the same arguments (seeded by cell)."""
    if variant not in VARIANTS:
        raise BenchError(f"variant: expected one of {', '.join(VARIANTS)}, got {variant!r}")
    out = []
    for n in links:
        for k in orientations:
            for i in range(per_cell):
                rng = random.Random(f"planhrc-bimanual-{variant}-{n}-{k}-{i}")
                init = tuple(rng.randrange(k) for _ in range(n - 1))
                goal = tuple(rng.randrange(k) for _ in range(n - 1))
                out.append(BimanualInstance(n, k, i, variant, init, goal, rng.randrange(1, n)))
    return tuple(out)


def angle_name(step: int, orientations: int) -> str:
    return f"a{step * 360 // orientations}"


def domain_text(variant: str = "macros") -> str:
    actions = ([_CENTRE] if variant == "basic" else []) + [_GRASP, _turn("up", 1), _turn("down", 1), _RELEASE]
    if variant == "macros":
        actions += [_CENTRE_AND_GRASP, _turn("up", 3), _turn("down", 3)]
    return _HEAD + "".join(actions) + ")\n"


def problem_text(inst: BimanualInstance) -> str:
    k, n = inst.orientations, inst.links
    angles = " ".join(angle_name(s, k) for s in range(k))
    init = [f"(precedes l{i} l{i + 1})" for i in range(1, n)]
    init += [f"(joins j{i} l{i}) (joins j{i} l{i + 1})" for i in range(1, n)]
    for i in range(1, n):  # turning j_i by its downstream link l_(i+1) carries every later joint
        init += [f"(carries j{m} l{i + 1} j{i})" for m in range(i + 1, n)]
        if i + 1 < n:  # the upstream facts of the field's files: l_(i+1) is upstream of j_(i+1), so no turn uses them
            init += [f"(carries j{m} l{i + 1} j{i + 1})" for m in range(1, i + 1)]
    init += [f"(next {angle_name(s, k)} {angle_name((s + 1) % k, k)})" for s in range(k)]
    init += [f"(at-angle {angle_name(v, k)} j{i})" for i, v in enumerate(inst.init, 1)]
    init += [f"(centred j{inst.centre})"] + [f"(empty {h})" for h in HANDS]
    goal = [f"(at-angle {angle_name(v, k)} j{i})" for i, v in enumerate(inst.goal, 1)]
    return (f"(define (problem {inst.name})\n(:domain two-hands)\n(:objects\n    {' '.join(HANDS)} - hand\n"
            f"    {' '.join(f'l{i}' for i in range(1, n + 1))} - link\n"
            f"    {' '.join(f'j{i}' for i in range(1, n))} - joint\n    {angles} - angle)\n"
            "(:init\n    " + "\n    ".join(init) + ")\n(:goal (and\n    " + "\n    ".join(goal) + ")))\n")


def turning_steps(change: int, orientations: int, macros: bool) -> int:
    """The fewest turns (+-1, and +-3 with macros) that change an angle by `change` steps mod K."""
    k = orientations
    moves = (1, k - 1, 3 % k, (k - 3) % k) if macros else (1, k - 1)
    dist = {0: 0}
    frontier = [0]
    while frontier:
        nxt = []
        for s in frontier:
            for m in moves:
                t = (s + m) % k
                if t not in dist:
                    dist[t] = dist[s] + 1
                    nxt.append(t)
        frontier = nxt
    return dist[change % k]


def optimal_length(inst: BimanualInstance) -> int:
    k = inst.orientations
    changes = [((g - (inst.goal[i - 1] if i else 0)) - (s - (inst.init[i - 1] if i else 0))) % k
               for i, (s, g) in enumerate(zip(inst.init, inst.goal))]
    needed = [i + 1 for i, c in enumerate(changes) if c]
    if not needed:
        return 0
    turns = sum(turning_steps(c, k, inst.variant == "macros") for c in changes)
    hands = 2 * len(needed) - 1  # a grasp per joint, a release between two
    if inst.variant == "basic":
        hands += len(needed) - (1 if inst.centre in needed else 0)  # a centring per joint but the one in place
    return turns + hands


_HEAD = """; Two hands turn a chain of links on a table, one joint at a time at the centre (planhrc's own test family).
(define (domain two-hands)
(:requirements :strips :typing :equality :negative-preconditions :conditional-effects :adl)
(:types link joint angle hand)
(:predicates
    (joins ?j -joint ?l -link)
    (next ?a -angle ?b -angle)
    (at-angle ?a -angle ?j -joint)
    (precedes ?l -link ?m -link)
    (holding ?h -hand ?l -link)
    (held ?l -link)
    (centred ?j -joint)
    (empty ?h -hand)
    (carries ?k -joint ?l -link ?j -joint))  ; turning ?j by its link ?l moves ?k too
"""

_CENTRE = """
(:action centre
 :parameters (?l -link ?from ?to -joint ?h -hand)
 :precondition (and (centred ?from) (joins ?to ?l) (empty ?h) (not (held ?l)))
 :effect (and (not (centred ?from)) (centred ?to)))
"""

_GRASP = """
(:action grasp
 :parameters (?turned ?kept -link ?j -joint ?ht ?hk -hand)
 :precondition (and (centred ?j) (empty ?ht) (empty ?hk) (not (= ?ht ?hk)) (not (= ?turned ?kept))
                    (not (held ?turned)) (not (held ?kept)) (joins ?j ?turned) (joins ?j ?kept))
 :effect (and (not (empty ?ht)) (not (empty ?hk)) (held ?turned) (held ?kept)
              (holding ?ht ?turned) (holding ?hk ?kept)))
"""

_RELEASE = """
(:action release
 :parameters (?turned ?kept -link ?j -joint ?ht ?hk -hand)
 :precondition (and (holding ?ht ?turned) (holding ?hk ?kept) (held ?turned) (held ?kept)
                    (joins ?j ?turned) (joins ?j ?kept) (not (= ?turned ?kept)))
 :effect (and (empty ?ht) (empty ?hk) (not (held ?turned)) (not (held ?kept))
              (not (holding ?ht ?turned)) (not (holding ?hk ?kept))))
"""

_CENTRE_AND_GRASP = """
(:action centre-and-grasp
 :parameters (?turned ?kept -link ?from ?to -joint ?ht ?hk -hand)
 :precondition (and (centred ?from) (joins ?to ?turned) (joins ?to ?kept) (not (= ?turned ?kept))
                    (empty ?ht) (empty ?hk) (not (= ?ht ?hk)) (not (held ?turned)) (not (held ?kept)))
 :effect (and (not (centred ?from)) (centred ?to) (not (empty ?ht)) (not (empty ?hk))
              (held ?turned) (held ?kept) (holding ?ht ?turned) (holding ?hk ?kept)))
"""


def _turn(direction: str, steps: int) -> str:
    """A turn of the centred joint by its downstream link, `steps` steps up or down the cycle, carrying the
    joints after it along."""
    name = f"turn-{direction}" + (f"-{steps}" if steps > 1 else "")
    chain = [f"?a{i}" for i in range(steps + 1)]
    carried = [f"?c{i}" for i in range(steps + 1)]

    def path(values: list[str]) -> str:
        pairs = zip(values, values[1:]) if direction == "up" else zip(values[1:], values)
        return " ".join(f"(next {a} {b})" for a, b in pairs)

    return f"""
(:action {name}
 :parameters (?turned ?kept -link ?j -joint {' '.join(chain)} -angle ?ht ?hk -hand)
 :precondition (and (precedes ?kept ?turned) (centred ?j) (holding ?hk ?kept) (holding ?ht ?turned)
                    (held ?turned) (held ?kept) (joins ?j ?turned) (joins ?j ?kept) (not (= ?turned ?kept))
                    (at-angle {chain[0]} ?j) {path(chain)})
 :effect (and (not (at-angle {chain[0]} ?j)) (at-angle {chain[-1]} ?j)
              (forall (?k -joint {' '.join(carried)} -angle)
                  (when (and (carries ?k ?turned ?j) (not (= ?k ?j)) (at-angle {carried[0]} ?k) {path(carried)})
                        (and (not (at-angle {carried[0]} ?k)) (at-angle {carried[-1]} ?k))))))
"""

"""Arithmetic over Z_K for the cyclic planner (`cyclic`): the transforms of a vector over the goal variables,
elimination modulo K, which axes cover which coordinates, and breadth-first search over small products of Z_K."""
from __future__ import annotations

from math import gcd
from typing import Any, Callable, Mapping

from .deadline import check as check_deadline
from .recognise import Axis

# A transform maps a vector over the goal variables (chain order) to new coordinates; `same[i]` tells whether
# goal variable i and i+1 lie on the same chain (differences never cross two objects).
Transform = Callable[[tuple[int, ...], tuple[bool, ...]], tuple[int, ...]]


def identity(v: tuple[int, ...], same: tuple[bool, ...]) -> tuple[int, ...]:
    return v


def downstream(v: tuple[int, ...], same: tuple[bool, ...]) -> tuple[int, ...]:
    return tuple(v[i] - (v[i - 1] if i and same[i - 1] else 0) for i in range(len(v)))


def upstream(v: tuple[int, ...], same: tuple[bool, ...]) -> tuple[int, ...]:
    n = len(v)
    return tuple(v[i] - (v[i + 1] if i + 1 < n and same[i] else 0) for i in range(n))


TRANSFORMS: dict[str, Transform] = {"identity": identity, "downstream": downstream, "upstream": upstream}


BASIS_LIMIT = 60  # Gaussian elimination in pure Python: O(m^3) for m goal variables


def solve_mod(matrix: list[list[int]], rhs: list[int], k: int) -> list[int] | None:
    """x with matrix @ x = rhs (mod k) by elimination with unit pivots; None when some column has no unit
    pivot (then the vectors are not a basis this method can use)."""
    m = len(matrix)
    rows = [row[:] + [rhs[i] % k] for i, row in enumerate(matrix)]
    for col in range(m):
        pivot = next((r for r in range(col, m) if gcd(rows[r][col] % k, k) == 1), None)
        if pivot is None:
            return None
        rows[col], rows[pivot] = rows[pivot], rows[col]
        inv = pow(rows[col][col] % k, -1, k)
        rows[col] = [(x * inv) % k for x in rows[col]]
        for r in range(m):
            if r != col and rows[r][col] % k:
                f = rows[r][col]
                rows[r] = [(a - f * b) % k for a, b in zip(rows[r], rows[col])]
    return [rows[i][m] for i in range(m)]


def cover_of(images: list[tuple[Axis, tuple[int, ...]]], k: int) -> dict[int, list[tuple[int, Axis]]]:
    """Coordinate -> [(sign, axis)] for every axis whose image is +-e_coordinate."""
    cover: dict[int, list[tuple[int, Axis]]] = {}
    for axis, img in images:
        unit = unit_of(img, k)
        if unit is not None:
            cover.setdefault(unit[0], []).append((unit[1], axis))
    return cover


def unit_of(v: tuple[int, ...], k: int) -> tuple[int, int] | None:
    """(index, sign) when v is +-e_index modulo K, else None."""
    nonzero = [(i, x % k) for i, x in enumerate(v) if x % k]
    if len(nonzero) == 1 and nonzero[0][1] in (1, k - 1):
        return (nonzero[0][0], 1 if nonzero[0][1] == 1 else -1)
    return None


def breadth_first(moves: tuple[tuple[int, ...], ...], k: int, dims: int) -> tuple[dict[Any, Any], dict[Any, Any]]:
    """Fewest moves from 0 to every reachable vector of Z_K^dims, with parent links."""
    start = (0,) * dims
    dist = {start: 0}
    parent: dict[tuple[int, ...], tuple[tuple[int, ...], tuple[int, ...]] | None] = {start: None}
    frontier = [start]
    while frontier:
        check_deadline("planning (breadth-first search over Z_K)")
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


def path_to(parent: Mapping[Any, Any], target: tuple[int, ...]) -> list[tuple[int, ...]]:
    moves = []
    while parent[target] is not None:
        target, mv = parent[target]
        moves.append(mv)
    return moves

"""How long `ordering.order_moves` takes on long chains: `python -m planhrc.bench.ordering [--links 20]`.

Each episode draws a random goal on the table (every link turned by -30°, 0 or +30° from its predecessor's
direction, kept only when feasible), makes the plan of downstream steps that reaches it from the straight start and
shuffles it (the harshest order a planner could give), then times the search for a feasible order. Prints one JSON
object: the medians and maxima of time, plan length and step checks, and how many plans were ordered.
"""
from __future__ import annotations

import argparse
import json
import random
import statistics
import time
from typing import Any, Sequence

from planhrc.geometry import ObjectGeometry, configuration_feasible
from planhrc.ordering import Move, Placement, feasible_alternative


def run(links: int = 20, episodes: int = 50, orientations: int = 12, link_m: float = 0.05,
        seed: int = 7) -> dict[str, Any]:
    step = 360 // orientations
    geometry = ObjectGeometry((link_m,) * links, (0.5, 0.55))
    start = (90.0,) * links
    rng = random.Random(seed)
    times: list[float] = []
    lengths: list[int] = []
    checks: list[int] = []
    found = 0
    while len(times) < episodes:
        goal = [90.0]
        for _ in range(links - 1):
            goal.append((goal[-1] + rng.choice([-step, 0, 0, step])) % 360)
        if not configuration_feasible(geometry, goal).ok:
            continue
        moves = _moves(goal, start, step)
        rng.shuffle(moves)
        t = time.perf_counter()
        answer, _ = feasible_alternative(Placement(geometry, start), moves, orientations)
        times.append(time.perf_counter() - t)
        lengths.append(len(moves))
        checks.append(answer.checks)
        found += answer.found
    return {"links": links, "episodes": episodes, "orientations": orientations, "ordered": found,
            "ms_median": round(statistics.median(times) * 1000, 1), "ms_max": round(max(times) * 1000, 1),
            "actions_median": statistics.median(lengths), "actions_max": max(lengths),
            "checks_median": statistics.median(checks), "checks_max": max(checks)}


def _moves(goal: Sequence[float], start: Sequence[float], step: int) -> list[Move]:
    moves: list[Move] = []
    for k in range(2, len(goal) + 1):
        turn = ((goal[k - 1] - goal[k - 2]) - (start[k - 1] - start[k - 2]) + 180) % 360 - 180
        name = "rotateclockwise" if turn > 0 else "rotateanticlockwise"
        moves += [Move(name, k, k - 1, k - 1, step if turn > 0 else -step)] * int(abs(turn) // step)
    return moves


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m planhrc.bench.ordering", description=__doc__.splitlines()[0])
    parser.add_argument("--links", type=int, default=20)
    parser.add_argument("--episodes", type=int, default=50)
    parser.add_argument("--seed", type=int, default=7)
    args = parser.parse_args(argv)
    print(json.dumps(run(args.links, args.episodes, seed=args.seed)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

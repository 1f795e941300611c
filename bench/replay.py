"""How long grounding takes, on both of its paths: `python -m planhrc.bench.replay [--links 20] [--orientations 12]`.

* `replay` (the transition equations, the hot path of every re-plan): the expected states of one plan of a random
  task, per formulation, timed cold (the domain's `Grounder` emptied first: every step ground from the TBox's
  schemas) and warm (the same plan again: the steps as the `Grounder` remembers them);
* `ground_task` (the in-process planner's grounding of parsed PDDL, with recognition), timed on the same tasks.

Prints one JSON object: per formulation, the plan's length and the median time of each, in milliseconds.
"""
from __future__ import annotations

import argparse
import json
import random
import statistics
import timeit
from typing import Any, Callable, Sequence

from planhrc.model import Formulation, make_object
from planhrc.paths import default_tbox_path
from planhrc.planner.inproc import InprocPlanner, ground_task
from planhrc.transition import grounder, replay
from planhrc.translator.domain import get_domain, read_domain_model
from planhrc.translator.problem import get_problem


def run(links: int = 20, orientations: int = 12, repeat: int = 15, seed: int = 7) -> dict[str, Any]:
    out: dict[str, Any] = {"links": links, "orientations": orientations, "repeat": repeat}
    for formulation in Formulation:
        obj = make_object("obj1", formulation, links, orientations)
        rng = random.Random(seed)
        init = obj.state([rng.choice(obj.orientation_degrees) for _ in obj.joint_indices])
        goal = obj.configuration_atoms([rng.choice(obj.orientation_degrees) for _ in obj.joint_indices])
        domain_text = get_domain(default_tbox_path(), formulation.value)
        problem_text = get_problem(obj, init, goal, "bench")
        plan = InprocPlanner().solve(domain_text, problem_text, 60.0).plan
        model = read_domain_model(default_tbox_path(), formulation.value)

        def cold() -> None:
            grounder.cache_clear()
            replay(model, init, plan)

        def warm() -> None:
            replay(model, init, plan)

        out[formulation.value] = {
            "plan_length": len(plan),
            "replay_cold_ms": _median_ms(cold, repeat),
            "replay_warm_ms": _median_ms(warm, repeat),
            "ground_task_ms": _median_ms(lambda: ground_task(domain_text, problem_text), repeat),
        }
    return out


def _median_ms(call: Callable[[], object], repeat: int) -> float:
    call()  # the first call pays for imports and caches outside what is measured
    return round(statistics.median(timeit.repeat(call, number=1, repeat=repeat)) * 1000, 3)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m planhrc.bench.replay", description=__doc__.splitlines()[0])
    parser.add_argument("--links", type=int, default=20)
    parser.add_argument("--orientations", type=int, default=12)
    parser.add_argument("--repeat", type=int, default=15)
    parser.add_argument("--seed", type=int, default=7)
    args = parser.parse_args(argv)
    print(json.dumps(run(args.links, args.orientations, args.repeat, args.seed)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

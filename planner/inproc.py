"""The in-process planner: parse -> ground -> recognise -> solve, each stage its own module.

    planner.pddl       parse PDDL text into frozen domain and problem values
    planner.operators  action schemas in one normal form (literals, flat conditional effect blocks)
    planner.ground     static / relevant / state-variable analyses, then grounding by joins over static facts
    planner.recognise  does every ground action add a fixed vector modulo K to cyclic variables? (or why not)
    planner.cyclic     optimal plans for such tasks by algebra over Z_K

`ground_task(domain, problem)` runs the first four stages and returns a `GroundTask` that re-plans from any
initial state with `solve(init, goal)`. `InprocPlanner.solve(domain, problem, timeout_s)` is the registry's
interface; it memoises the work that does not depend on the initial state (the parsed domain and its
analyses, the grounded and recognised task, keyed on the objects, the static facts and which variables have
a value), so re-planning from a new perceived state only parses the problem and solves.
"""
from __future__ import annotations

import logging
import time
from functools import lru_cache

from planhrc.errors import DeadlineExceeded
from planhrc.model import Atom

from .cyclic import NAME, GroundTask
from .deadline import within
from .errors import PlannerError
from .ground import LiftedTask, OutsideFamilyError, analyse, ground_lifted, owner_values
from .pddl import Domain, Problem, parse_domain, parse_problem
from .recognise import CyclicTask, recognise
from .result import PlanResult, PlanStatus

log = logging.getLogger(__name__)

__all__ = ["GroundTask", "InprocPlanner", "OutsideFamilyError", "forget", "ground_parsed", "ground_task"]

def ground_task(domain: str, problem: str) -> GroundTask:
    """Parse, ground and recognise once; raises PlannerError (OutsideFamilyError says why) when the task is
    not one the in-process planner solves."""
    return ground_parsed(parse_domain(domain), parse_problem(problem))


def ground_parsed(dom: Domain, prob: Problem) -> GroundTask:
    lifted = analyse(dom, frozenset(a[0] for a in prob.goal))
    return GroundTask(_recognised(lifted, prob), prob.init, prob.goal)


def _recognised(lifted: LiftedTask, prob: Problem) -> CyclicTask:
    grounded = ground_lifted(lifted, prob.name, prob.objects, lifted.static_facts(prob.init),
                             owner_values(lifted, prob.init))
    return recognise(grounded, prob.init)


# The work that does not depend on the initial state, memoised: pure functions of their (immutable) arguments,
# bounded, shared by every InprocPlanner the registry builds, so the fallback chain re-plans without
# re-parsing the domain or grounding again.
@lru_cache(maxsize=16)
def parsed_domain(text: str) -> Domain:
    return parse_domain(text)


@lru_cache(maxsize=16)
def _analysed(text: str, goal_predicates: frozenset[str]) -> LiftedTask:
    return analyse(parsed_domain(text), goal_predicates)


@lru_cache(maxsize=16)
def _recognised_cached(lifted: LiftedTask, problem_name: str, objects: tuple[tuple[str, str], ...],
                       statics: frozenset[Atom], owners: frozenset[tuple[str, tuple[str, ...]]]) -> GroundTask:
    """Keyed on the lifted task (by identity: one per domain text and goal predicates), the objects, the static
    facts and which variables have a value; the ground task without a problem, whose `for_problem` tasks share
    what the solver works out."""
    grounded = ground_lifted(lifted, problem_name, objects, statics, owners)
    return GroundTask(recognise(grounded, frozenset()), frozenset(), frozenset())


def forget() -> None:
    """Empty the memoised stages, so that the next call parses, grounds and recognises from scratch (a benchmark
    that compares the in-process planner with planners that start afresh for every task)."""
    parsed_domain.cache_clear()
    _analysed.cache_clear()
    _recognised_cached.cache_clear()


def cached_ground_task(domain: str, problem: str) -> GroundTask:
    """`ground_task` that reuses the parsed domain and the grounded task when only the init values changed."""
    prob = parse_problem(problem)
    lifted = _analysed(domain, frozenset(a[0] for a in prob.goal))
    task = _recognised_cached(lifted, "", prob.objects, lifted.static_facts(prob.init), owner_values(lifted, prob.init))
    return task.for_problem(prob.init, prob.goal)


class InprocPlanner:
    """Planner protocol wrapper. Bad PDDL and tasks outside the family give status error with the reason."""

    name = NAME

    def solve(self, domain: str, problem: str, timeout_s: float) -> PlanResult:
        start = time.perf_counter()
        try:
            with within(timeout_s):  # grounding and solving check the clock (planner.deadline)
                task = cached_ground_task(domain, problem)
                result = task.solve_problem()
        except DeadlineExceeded as exc:
            elapsed = time.perf_counter() - start
            return PlanResult(PlanStatus.TIMEOUT, (), elapsed, NAME, f"{exc} ({elapsed:.3f} s > {timeout_s} s)")
        except PlannerError as exc:
            return PlanResult(PlanStatus.ERROR, (), time.perf_counter() - start, NAME, str(exc))
        elapsed = time.perf_counter() - start
        if elapsed > timeout_s:
            return PlanResult(PlanStatus.TIMEOUT, (), elapsed, NAME, f"took {elapsed:.3f} s > {timeout_s} s")
        return PlanResult(result.status, result.plan, elapsed, NAME, result.message, result.optimal)

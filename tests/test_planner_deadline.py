"""The in-process planner keeps to its time limit on tasks too large for it, and the limit is per call."""
import random
import threading
import time

from planhrc.errors import DeadlineExceeded
from planhrc.model import make_object
from planhrc.paths import default_tbox_path
from planhrc.planner import deadline
from planhrc.planner.inproc import InprocPlanner
from planhrc.planner.result import PlanStatus
from planhrc.translator import get_domain, get_problem


def _task(formulation, links, k, seed=3):
    obj = make_object("obj1", formulation, links, k)
    rng = random.Random(seed)
    init = [rng.choice(obj.orientation_degrees) for _ in obj.joint_indices]
    goal = [rng.choice(obj.orientation_degrees) for _ in obj.joint_indices]
    return (get_domain(default_tbox_path(), formulation),
            get_problem(obj, obj.configuration_atoms(init), obj.configuration_atoms(goal), f"big{links}"))


def test_a_200_link_absolute_task_times_out_at_its_limit_not_minutes_later():
    domain, problem = _task("absolute", 200, 12)
    t = time.perf_counter()
    result = InprocPlanner().solve(domain, problem, 0.5)
    elapsed = time.perf_counter() - t
    assert result.status is PlanStatus.TIMEOUT and "time limit" in result.message
    assert elapsed < 5.0, elapsed  # parsing the 200-link text comes first; grounding stops at the limit


def test_a_small_task_is_unaffected_and_a_timeout_is_not_memoised():
    domain, problem = _task("relative", 6, 4)
    assert InprocPlanner().solve(domain, problem, 30.0).status is PlanStatus.SOLVED
    big_domain, big_problem = _task("absolute", 120, 12, seed=4)
    assert InprocPlanner().solve(big_domain, big_problem, 0.2).status is PlanStatus.TIMEOUT
    assert InprocPlanner().solve(domain, problem, 30.0).status is PlanStatus.SOLVED


def test_limits_nest_and_belong_to_their_thread():
    seen = {}

    def other():
        deadline.check("another thread")  # no limit here: the main thread's limit is its own
        seen["ok"] = True

    with deadline.within(10.0):
        with deadline.within(0.0):
            time.sleep(0.01)
            try:
                deadline.check("inner")
            except DeadlineExceeded as exc:
                seen["inner"] = str(exc)
        deadline.check("outer")  # the outer limit is untouched by the inner one
        t = threading.Thread(target=other)
        t.start()
        t.join()
    assert seen == {"inner": "time limit reached while inner", "ok": True}

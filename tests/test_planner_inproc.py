"""The in-process planner: recognition of the family, optimal lengths, VAL-checked plans, re-planning."""
import random
from pathlib import Path

import pytest

from planhrc.model import Formulation, make_object
from planhrc.planner import PlanStatus, ground_task, validate_plan
from planhrc.planner.errors import PlannerError
from planhrc.planner.inproc import InprocPlanner, OutsideFamilyError
from planhrc.translator.problem import get_problem

DATA = Path(__file__).parent / "data"
DOMAINS = {
    "relative": (DATA / "domain-relative.pddl").read_text(),
    "absolute": (DATA / "domain-absolute.pddl").read_text(),
    "absolute-paper": (DATA / "domain-absolute-paper.pddl").read_text(),
}
# Plans are checked against the paper's schemas: relative is the paper's own; absolute-paper has no guard.
PAPER = {"relative": DOMAINS["relative"], "absolute": DOMAINS["absolute-paper"]}


def make_case(formulation: str, n_links: int, k: int, seed: int, goal_fraction: float = 1.0):
    """A random instance: (object, init values, goal values {joint index: deg}, problem text)."""
    rng = random.Random(seed)
    obj = make_object("obj1", formulation, n_links, k)
    degs = obj.orientation_degrees
    init = [rng.choice(degs) for _ in obj.joint_indices]
    chosen = [j for j in obj.joint_indices if rng.random() < goal_fraction] or [obj.joint_indices[-1]]
    goal = {j: rng.choice(degs) for j in chosen}
    goal_atoms = {("hasorientation", f"deg_{v}", obj.joint(j)) for j, v in goal.items()}
    text = get_problem(obj, obj.configuration_atoms(init), goal_atoms, f"case-{seed}")
    return obj, init, goal, text


def cyclic(delta_deg: int, step: int, k: int) -> int:
    t = (delta_deg // step) % k
    return min(t, k - t)


def optimal_length(obj, init, goal) -> int:
    """Relative: sum of cyclic distances; absolute: sum over consecutive goal joints of the change of their
    difference (the first goal joint is measured against the fixed table link l0)."""
    values = dict(zip(obj.joint_indices, init))
    step, k = obj.step, obj.orientations
    if obj.formulation is Formulation.RELATIVE:
        return sum(cyclic(g - values[j], step, k) for j, g in goal.items())
    total, prev_goal, prev_init = 0, 0, 0
    for j in sorted(goal):
        total += cyclic((goal[j] - prev_goal) - (values[j] - prev_init), step, k)
        prev_goal, prev_init = goal[j], values[j]
    return total


@pytest.mark.parametrize("formulation", ["relative", "absolute"])
def test_golden_fixture_is_solved_optimally_and_validates(formulation):
    problem = (DATA / f"problem-{formulation}-3x4.pddl").read_text()
    result = InprocPlanner().solve(DOMAINS[formulation], problem, 5.0)
    assert result.status is PlanStatus.SOLVED, result.message
    assert result.optimal is True
    assert len(result.plan) == {"relative": 1, "absolute": 4}[formulation]
    assert validate_plan(PAPER[formulation], problem, result.plan).valid


def test_relative_plan_turns_the_downstream_link():
    problem = (DATA / "problem-relative-3x4.pddl").read_text()
    result = InprocPlanner().solve(DOMAINS["relative"], problem, 5.0)
    assert result.plan == ("(rotateanticlockwise obj1_l2 obj1_l1 obj1_j1 deg_0 deg_270)",)


@pytest.mark.parametrize("formulation", ["relative", "absolute"])
@pytest.mark.parametrize("seed", range(6))
def test_random_instances_are_optimal_and_valid(formulation, seed):
    rng = random.Random(1000 + seed)
    n_links = rng.randint(3, 12)
    k = rng.choice([4, 6, 8, 10, 12])
    obj, init, goal, problem = make_case(formulation, n_links, k, seed, goal_fraction=rng.choice([0.3, 0.6, 1.0]))
    result = InprocPlanner().solve(DOMAINS[formulation], problem, 5.0)
    assert result.status is PlanStatus.SOLVED, result.message
    assert result.optimal is True
    assert len(result.plan) == optimal_length(obj, init, goal)
    check = validate_plan(PAPER[formulation], problem, result.plan)
    assert check.valid, check.reason


@pytest.mark.slow
@pytest.mark.parametrize("formulation", ["relative", "absolute"])
@pytest.mark.parametrize("seed", range(30))
def test_random_instance_sweep_up_to_20_links(formulation, seed):
    rng = random.Random(5000 + seed)
    n_links = rng.randint(3, 20)
    k = rng.choice([4, 6, 8, 10, 12])
    obj, init, goal, problem = make_case(formulation, n_links, k, seed, goal_fraction=rng.random())
    result = InprocPlanner().solve(DOMAINS[formulation], problem, 5.0)
    assert result.status is PlanStatus.SOLVED, result.message
    assert len(result.plan) == optimal_length(obj, init, goal)
    check = validate_plan(PAPER[formulation], problem, result.plan)
    assert check.valid, check.reason


@pytest.mark.parametrize("seed", range(4))
def test_paper_domain_is_solved_exactly_by_the_chain_dp(seed):
    """Without the guard, turning l(k-1) about jk moves jk alone: after downstream differences those actions
    touch two neighbouring coordinates, and the chain DP still finds a shortest plan (never longer than with
    the guard)."""
    rng = random.Random(300 + seed)
    obj, init, goal, problem = make_case("absolute", rng.randint(3, 12), rng.choice([4, 6, 8, 12]), seed,
                                         goal_fraction=rng.choice([0.4, 1.0]))
    result = InprocPlanner().solve(DOMAINS["absolute-paper"], problem, 5.0)
    assert result.status is PlanStatus.SOLVED, result.message
    assert result.optimal is True
    assert len(result.plan) <= optimal_length(obj, init, goal)
    check = validate_plan(DOMAINS["absolute-paper"], problem, result.plan)
    assert check.valid, check.reason


@pytest.mark.parametrize("formulation", ["relative", "absolute"])
def test_replanning_reuses_the_ground_task(formulation):
    obj, init, goal, problem = make_case(formulation, 20, 12, seed=7)
    task = ground_task(DOMAINS[formulation], problem)
    rng = random.Random(11)
    for _ in range(20):
        new_init = [rng.choice(obj.orientation_degrees) for _ in obj.joint_indices]
        result = task.solve(obj.configuration_atoms(new_init), task.goal)
        assert result.status is PlanStatus.SOLVED
        assert len(result.plan) == optimal_length(obj, new_init, goal)
    # the last one also validates as a whole problem
    text = get_problem(obj, obj.configuration_atoms(new_init), task.goal, "replan")
    assert validate_plan(PAPER[formulation], text, result.plan).valid


def test_goal_already_satisfied_gives_empty_plan():
    obj, init, goal, problem = make_case("absolute", 4, 4, seed=1)
    task = ground_task(DOMAINS["absolute"], problem)
    result = task.solve(task.init, obj.configuration_atoms(init))
    assert result.status is PlanStatus.SOLVED and result.plan == ()


def test_contradictory_goal_is_unsolvable():
    obj, init, goal, problem = make_case("relative", 4, 4, seed=1)
    task = ground_task(DOMAINS["relative"], problem)
    result = task.solve(task.init, {("hasorientation", "deg_0", "obj1_j1"), ("hasorientation", "deg_90", "obj1_j1")})
    assert result.status is PlanStatus.UNSOLVABLE


def test_joint_without_links_cannot_move():
    obj, init, goal, problem = make_case("relative", 3, 4, seed=2)
    problem = problem.replace("(connected obj1_j2 obj1_l3)", "").replace("(connected obj1_j2 obj1_l2)", "")
    task = ground_task(DOMAINS["relative"], problem)
    result = task.solve(task.init, {("hasorientation", "deg_0" if init[1] else "deg_90", "obj1_j2")})
    assert result.status is PlanStatus.UNSOLVABLE
    assert "obj1_j2" in result.message


def test_init_with_two_orientations_for_a_joint_is_an_error():
    obj, init, goal, problem = make_case("relative", 3, 4, seed=2)
    task = ground_task(DOMAINS["relative"], problem)
    bad = set(task.init) | {("hasorientation", f"deg_{(init[0] + 90) % 360}", "obj1_j1")}
    result = task.solve(bad, task.goal)
    assert result.status is PlanStatus.ERROR and "more than one value" in result.message


def test_changed_static_facts_are_refused():
    obj, init, goal, problem = make_case("absolute", 3, 4, seed=2)
    task = ground_task(DOMAINS["absolute"], problem)
    bad = set(task.init) - {("affected", "obj1_j3", "obj1_l1", "obj1_j1")}
    assert task.solve(bad, task.goal).status is PlanStatus.ERROR


def test_domain_outside_the_family_is_an_error_not_a_plan():
    problem = (DATA / "problem-relative-3x4.pddl").read_text()
    odd = DOMAINS["relative"].replace("(orientationord ?o1 ?o2))\n    :effect",
                                      "(orientationord ?o1 ?o2)\n      (connected ?j1 ?l1))\n    :effect", 1)
    odd = odd.replace("(hasorientation ?o2 ?j1)))\n  (:action rotateanticlockwise",
                      "(hasorientation ?o2 ?j1)\n      (not (connected ?j1 ?l1))))\n  (:action rotateanticlockwise", 1)
    assert odd != DOMAINS["relative"]
    with pytest.raises(OutsideFamilyError, match="rotateclockwise"):
        ground_task(odd, problem)
    result = InprocPlanner().solve(odd, problem, 5.0)
    assert result.status is PlanStatus.ERROR and result.plan == ()


def test_unwrapped_orientation_order_is_refused():
    problem = (DATA / "problem-relative-3x4.pddl").read_text().replace("(orientationord deg_270 deg_0)", "")
    with pytest.raises(OutsideFamilyError, match="cycle"):
        ground_task(DOMAINS["relative"], problem)


def test_an_affected_set_that_skips_a_joint_is_solved_through_a_basis():
    """Turning l1 about j1 moves j1, j2 and j4 but not j3: no difference transform separates the actions, but
    their effects form a basis of Z_K^4, so each action moves one basis coordinate and the plan is optimal."""
    obj, init, goal, problem = make_case("absolute", 4, 4, seed=5, goal_fraction=1.0)
    problem = problem.replace("(affected obj1_j3 obj1_l1 obj1_j1)", "")
    problem = problem.replace("(affected obj1_j3 obj1_l2 obj1_j2)", "")
    task = ground_task(DOMAINS["absolute"], problem)
    values = dict(zip(obj.joint_indices, init))
    target = {("hasorientation", f"deg_{(values[j] + (90 if j == 1 else 0)) % 360}", obj.joint(j))
              for j in obj.joint_indices}
    result = task.solve(task.init, target)
    assert result.status is PlanStatus.SOLVED and result.optimal is True and "basis" in result.message
    text = get_problem(obj, obj.configuration_atoms(init), target, "skips").replace(
        "(affected obj1_j3 obj1_l1 obj1_j1)", "").replace("(affected obj1_j3 obj1_l2 obj1_j2)", "")
    assert validate_plan(DOMAINS["absolute"], text, result.plan).valid


TWISTS = """
(define (domain twists)
  (:requirements :strips :typing :negative-preconditions)
  (:types dial notch)
  (:predicates (at ?n - notch ?d - dial) (next ?a ?b - notch) (first ?d - dial) (second ?d - dial) (third ?d - dial))
  (:action twist_same
    :parameters (?x ?y ?z - dial ?x1 ?x2 ?y1 ?y2 ?z1 ?z2 - notch)
    :precondition (and (first ?x) (second ?y) (third ?z) (at ?x1 ?x) (next ?x1 ?x2) (at ?y1 ?y) (next ?y1 ?y2)
                       (at ?z1 ?z) (next ?z1 ?z2))
    :effect (and (not (at ?x1 ?x)) (at ?x2 ?x) (not (at ?y1 ?y)) (at ?y2 ?y) (not (at ?z1 ?z)) (at ?z2 ?z)))
  (:action twist_opposite
    :parameters (?x ?y ?z - dial ?x1 ?x2 ?y1 ?y2 ?z1 ?z2 - notch)
    :precondition (and (first ?x) (second ?y) (third ?z) (at ?x1 ?x) (next ?x1 ?x2) (at ?y1 ?y) (next ?y2 ?y1)
                       (at ?z1 ?z) (next ?z1 ?z2))
    :effect (and (not (at ?x1 ?x)) (at ?x2 ?x) (not (at ?y1 ?y)) (at ?y2 ?y) (not (at ?z1 ?z)) (at ?z2 ?z)))
  (:action turn_third
    :parameters (?z - dial ?z1 ?z2 - notch)
    :precondition (and (third ?z) (at ?z1 ?z) (next ?z1 ?z2))
    :effect (and (not (at ?z1 ?z)) (at ?z2 ?z))))
"""


def test_a_task_no_method_separates_is_refused_not_guessed():
    """Effects (1,1,1), (1,-1,1), (0,0,1) over Z_4: not a basis (determinant -2), no transform separates them.
    The goal (2,0,2) is reachable (twist_same + twist_opposite), but the planner cannot prove a length and
    says so instead of guessing."""
    notches = " ".join(f"n{i}" for i in range(4))
    problem = f"""(define (problem t) (:domain twists)
      (:objects a b c - dial {notches} - notch)
      (:init (first a) (second b) (third c) (at n0 a) (at n0 b) (at n0 c)
             (next n0 n1) (next n1 n2) (next n2 n3) (next n3 n0))
      (:goal (and (at n2 a) (at n0 b) (at n2 c))))"""
    result = InprocPlanner().solve(TWISTS, problem, 5.0)
    assert result.status is PlanStatus.ERROR and result.plan == ()
    assert "refusing to guess" in result.message


@pytest.mark.parametrize("text", ["", "(define (domain x)", "(define (problem x) (:domain y))", "hello"])
def test_unreadable_pddl_raises_planner_error(text):
    with pytest.raises(PlannerError):
        ground_task(text, (DATA / "problem-relative-3x4.pddl").read_text())
    with pytest.raises(PlannerError):
        ground_task(DOMAINS["relative"], text)


def write_problem(objects: dict[str, list[str]], init: set, goal: set, name: str = "multi") -> str:
    """A minimal PDDL writer for hand-made problems (several objects in one problem)."""
    fmt = lambda atom: "(" + " ".join(atom) + ")"  # noqa: E731
    objs = "\n".join(f"    {' '.join(names)} - {t}" for t, names in objects.items())
    return (f"(define (problem {name}) (:domain d)\n  (:objects\n{objs})\n  (:init\n"
            + "\n".join("    " + fmt(a) for a in sorted(init)) + ")\n  (:goal (and\n"
            + "\n".join("    " + fmt(a) for a in sorted(goal)) + ")))\n")


@pytest.mark.parametrize("formulation", ["relative", "absolute"])
def test_two_objects_in_one_problem(formulation):
    """Differences are taken along each chain, never across two objects."""
    rng = random.Random(4)
    a = make_object("obja", formulation, 5, 8)
    b = make_object("objb", formulation, 4, 8)
    init, goal, expected = set(), set(), 0
    objects = {"link": [], "joint": [], "orientation": list(a.orientation_names)}
    for obj in (a, b):
        values = [rng.choice(obj.orientation_degrees) for _ in obj.joint_indices]
        target = {j: rng.choice(obj.orientation_degrees) for j in obj.joint_indices if rng.random() < 0.7}
        init |= obj.state(values)
        goal |= {("hasorientation", f"deg_{v}", obj.joint(j)) for j, v in target.items()}
        objects["link"] += obj.all_links
        objects["joint"] += obj.joints
        expected += optimal_length(obj, values, target)
    problem = write_problem(objects, init, goal)
    result = InprocPlanner().solve(DOMAINS[formulation], problem, 5.0)
    assert result.status is PlanStatus.SOLVED, result.message
    assert result.optimal is True and len(result.plan) == expected
    assert validate_plan(PAPER[formulation], problem, result.plan).valid


def test_chain_order_comes_from_the_links_not_the_names():
    obj, init, goal, problem = make_case("absolute", 4, 6, seed=8)
    renamed = problem
    for old, new in (("obj1_j1", "hinge_c"), ("obj1_j2", "hinge_a"), ("obj1_j3", "hinge_d"), ("obj1_j4", "hinge_b")):
        renamed = renamed.replace(old, new)
    task = ground_task(DOMAINS["absolute"], renamed)
    assert task.joints == ("hinge_c", "hinge_a", "hinge_d", "hinge_b")
    result = task.solve_problem()
    assert result.status is PlanStatus.SOLVED and len(result.plan) == optimal_length(obj, init, goal)
    assert validate_plan(DOMAINS["absolute-paper"], renamed, result.plan).valid


def test_same_task_gives_the_same_plan():
    """Determinism: re-grounding, re-planning and reordering the init text do not change the plan."""
    obj, init, goal, problem = make_case("absolute", 9, 8, seed=21, goal_fraction=0.6)
    first = InprocPlanner().solve(DOMAINS["absolute-paper"], problem, 5.0)
    head, sep, rest = problem.partition("(:init\n")
    body, sep2, tail = rest.partition("  )\n  (:goal")
    shuffled = head + sep + "\n".join(reversed(body.splitlines())) + "\n" + sep2 + tail
    assert shuffled != problem
    again = InprocPlanner().solve(DOMAINS["absolute-paper"], shuffled, 5.0)
    task = ground_task(DOMAINS["absolute-paper"], problem)
    assert first.plan == again.plan == task.solve_problem().plan == task.solve_problem().plan


@pytest.mark.parametrize("formulation", ["relative", "absolute"])
def test_problems_of_one_task_share_what_the_solver_works_out_and_plan_as_a_fresh_task(formulation):
    """`cached_ground_task` hands out tasks that share the recognised task's memo (chains, the transforms' views):
    each plans exactly what a task grounded afresh from the same text plans, partial goals included."""
    from planhrc.planner.inproc import cached_ground_task

    obj, _, goal, _ = make_case(formulation, 12, 8, seed=5)
    rng = random.Random(5)
    memos = []
    for _ in range(15):
        init = [rng.choice(obj.orientation_degrees) for _ in obj.joint_indices]
        atoms = {("hasorientation", f"deg_{v}", obj.joint(j)) for j, v in goal.items()}
        partial = {a for a in atoms if rng.random() < 0.8} or atoms
        text = get_problem(obj, obj.configuration_atoms(init), partial, "p")
        task = cached_ground_task(DOMAINS[formulation], text)
        memos.append(task.memo)
        got, fresh = task.solve_problem(), ground_task(DOMAINS[formulation], text).solve_problem()
        assert (got.status, got.plan, got.message, got.optimal) == (fresh.status, fresh.plan, fresh.message,
                                                                    fresh.optimal)
        assert got.status is PlanStatus.SOLVED
    assert all(m is memos[0] for m in memos)

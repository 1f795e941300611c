"""Domains written other ways than ours: the in-process planner grounds them, recognises the family on the
grounded task (or says why not), and every plan passes VAL against the variant's own domain."""
import json
import random

import pytest

from planhrc.planner import PlanStatus, plan_with_fallback, validate_plan
from planhrc.planner.cli import main as cli_main
from planhrc.planner.inproc import InprocPlanner, OutsideFamilyError, ground_task
from planhrc.planner.registry import get_planner


def write_problem(domain: str, objects: dict[str, list[str]], init: set, goal: set, name: str = "variant") -> str:
    fmt = lambda atom: "(" + " ".join(atom) + ")"  # noqa: E731
    objs = "\n".join(f"    {' '.join(names)} - {t}" for t, names in objects.items() if names)
    return (f"(define (problem {name}) (:domain {domain})\n  (:objects\n{objs})\n  (:init\n"
            + "\n".join("    " + fmt(a) for a in sorted(init)) + ")\n  (:goal (and\n"
            + "\n".join("    " + fmt(a) for a in sorted(goal)) + ")))\n")


def cyclic(t: int, k: int) -> int:
    t %= k
    return min(t, k - t)


# -- renamed predicates, actions, types; reordered arguments and parameters (relative semantics) ----------
RENAMED = """
(define (domain renamed)
  (:requirements :strips :typing :equality :negative-preconditions)
  (:types part hinge angle)
  (:predicates (Joins ?p - part ?h - hinge) (HasAngle ?h - hinge ?a - angle) (AngleOrd ?a ?b - angle))
  (:action increase_angle
    :parameters (?a1 - angle ?h - hinge ?a2 - angle ?held - part ?moving - part)
    :precondition (and (AngleOrd ?a1 ?a2) (Joins ?moving ?h) (HasAngle ?h ?a1) (Joins ?held ?h)
                       (not (= ?moving ?held)))
    :effect (and (HasAngle ?h ?a2) (not (HasAngle ?h ?a1))))
  (:action decrease_angle
    :parameters (?h - hinge ?moving ?held - part ?a1 ?a2 - angle)
    :precondition (and (Joins ?moving ?h) (Joins ?held ?h) (not (= ?held ?moving)) (HasAngle ?h ?a1)
                       (AngleOrd ?a2 ?a1))
    :effect (and (not (HasAngle ?h ?a1)) (HasAngle ?h ?a2))))
"""


def renamed_problem(n: int, k: int, seed: int) -> tuple[str, int]:
    rng = random.Random(seed)
    parts, hinges, angles = [f"p{i}" for i in range(1, n + 1)], [f"h{i}" for i in range(1, n)], [f"a{i}" for i in range(k)]
    init = {("joins", parts[i], hinges[i]) for i in range(n - 1)} | {("joins", parts[i + 1], hinges[i]) for i in range(n - 1)}
    init |= {("angleord", angles[i], angles[(i + 1) % k]) for i in range(k)}
    start = {h: rng.randrange(k) for h in hinges}
    goal = {h: rng.randrange(k) for h in hinges if rng.random() < 0.7}
    init |= {("hasangle", h, angles[v]) for h, v in start.items()}
    text = write_problem("renamed", {"part": parts, "hinge": hinges, "angle": angles}, init,
                         {("hasangle", h, angles[v]) for h, v in goal.items()} or {("hasangle", "h1", "a0")})
    return text, sum(cyclic(goal[h] - start[h], k) for h in goal) if goal else cyclic(-start["h1"], k)


@pytest.mark.parametrize("seed", range(4))
def test_renamed_and_reordered_domain(seed):
    problem, optimal = renamed_problem(3 + seed * 2, [4, 6, 8, 12][seed], seed)
    result = InprocPlanner().solve(RENAMED, problem, 10.0)
    assert result.status is PlanStatus.SOLVED and result.optimal is True, result.message
    assert len(result.plan) == optimal
    assert validate_plan(RENAMED, problem, result.plan).valid


# -- chains in the absolute style: our generator of facts, any vocabulary ---------------------------------
def chain(n: int, k: int, seed: int, *, upstream: bool = False, goal_fraction: float = 1.0):
    """Links l0 (the table) .. ln, joints j1 .. jn, angles a0 .. a(K-1); Affected downstream (turning lk about
    jk moves jk .. jn) and, with `upstream`, the benchmark's upstream facts (turning l(k-1) about jk moves
    j1 .. j(k-1)). Returns (objects, static facts in our vocabulary, init values, goal values)."""
    rng = random.Random(seed)
    links, joints, angles = [f"l{i}" for i in range(n + 1)], [f"j{i}" for i in range(1, n + 1)], [f"a{i}" for i in range(k)]
    facts = {("connected", joints[i], links[i]) for i in range(n)} | {("connected", joints[i], links[i + 1]) for i in range(n)}
    facts |= {("angleord", angles[i], angles[(i + 1) % k]) for i in range(k)}
    facts |= {("affected", joints[m], links[i + 1], joints[i]) for i in range(n) for m in range(i, n)}
    if upstream:
        facts |= {("affected", joints[m], links[i], joints[i]) for i in range(n) for m in range(i)}
    start = {j: rng.randrange(k) for j in joints}
    goal = {j: rng.randrange(k) for j in joints if rng.random() < goal_fraction} or {joints[-1]: (start[joints[-1]] + 1) % k}
    return {"link": links, "joint": joints, "angle": angles}, facts, start, goal


BENCHMARK = """
(define (domain benchmark)
  (:requirements :strips :typing :equality :negative-preconditions :conditional-effects)
  (:types link joint angle)
  (:predicates (Connected ?j - joint ?l - link) (HasAngle ?j - joint ?a - angle) (AngleOrd ?a1 ?a2 - angle)
               (Affected ?j2 - joint ?l - link ?j1 - joint))
  (:action increase_angle
    :parameters (?l1 ?l2 - link ?j1 - joint ?a1 ?a2 - angle)
    :precondition (and (Connected ?j1 ?l1) (Connected ?j1 ?l2) (not (= ?l1 ?l2)) (HasAngle ?j1 ?a1) (AngleOrd ?a1 ?a2))
    :effect (and (not (HasAngle ?j1 ?a1)) (HasAngle ?j1 ?a2)
                 (forall (?j2 - joint ?a3 ?a4 - angle)
                   (when (and (Affected ?j2 ?l1 ?j1) (not (= ?j2 ?j1)) (HasAngle ?j2 ?a3) (AngleOrd ?a3 ?a4))
                         (and (not (HasAngle ?j2 ?a3)) (HasAngle ?j2 ?a4))))))
  (:action decrease_angle
    :parameters (?l1 ?l2 - link ?j1 - joint ?a1 ?a2 - angle)
    :precondition (and (Connected ?j1 ?l1) (Connected ?j1 ?l2) (not (= ?l1 ?l2)) (HasAngle ?j1 ?a1) (AngleOrd ?a2 ?a1))
    :effect (and (not (HasAngle ?j1 ?a1)) (HasAngle ?j1 ?a2)
                 (forall (?j2 - joint ?a3 ?a4 - angle)
                   (when (and (Affected ?j2 ?l1 ?j1) (not (= ?j2 ?j1)) (HasAngle ?j2 ?a3) (AngleOrd ?a4 ?a3))
                         (and (not (HasAngle ?j2 ?a3)) (HasAngle ?j2 ?a4)))))))
"""

# Three parameters, every change in a conditional effect (the turned joint included through Affected).
THREE_PARAMETERS = """
(define (domain three-parameters)
  (:requirements :strips :typing :equality :negative-preconditions :conditional-effects)
  (:types link joint angle)
  (:predicates (Connected ?j - joint ?l - link) (HasAngle ?j - joint ?a - angle) (AngleOrd ?a1 ?a2 - angle)
               (Affected ?j2 - joint ?l - link ?j1 - joint))
  (:action increase_angle
    :parameters (?moving - link ?j - joint ?held - link)
    :precondition (and (Connected ?j ?moving) (Connected ?j ?held) (not (= ?moving ?held)))
    :effect (forall (?j2 - joint ?a1 ?a2 - angle)
              (when (and (Affected ?j2 ?moving ?j) (HasAngle ?j2 ?a1) (AngleOrd ?a1 ?a2))
                    (and (not (HasAngle ?j2 ?a1)) (HasAngle ?j2 ?a2)))))
  (:action decrease_angle
    :parameters (?moving - link ?j - joint ?held - link)
    :precondition (and (Connected ?j ?moving) (Connected ?j ?held) (not (= ?moving ?held)))
    :effect (forall (?j2 - joint ?a1 ?a2 - angle)
              (when (and (Affected ?j2 ?moving ?j) (HasAngle ?j2 ?a1) (AngleOrd ?a2 ?a1))
                    (and (not (HasAngle ?j2 ?a1)) (HasAngle ?j2 ?a2))))))
"""

# The root joint's angle changes together with the turned one; the root also turns alone.
ROOT = """
(define (domain root-moves-too)
  (:requirements :strips :typing :equality :negative-preconditions)
  (:types link joint angle)
  (:predicates (Connected ?j - joint ?l - link) (HasAngle ?j - joint ?a - angle) (AngleOrd ?a1 ?a2 - angle)
               (Root ?j - joint))
  (:action increase_angle
    :parameters (?l1 ?l2 - link ?j ?r - joint ?a1 ?a2 ?b1 ?b2 - angle)
    :precondition (and (Root ?r) (not (= ?j ?r)) (Connected ?j ?l1) (Connected ?j ?l2) (not (= ?l1 ?l2))
                       (HasAngle ?j ?a1) (AngleOrd ?a1 ?a2) (HasAngle ?r ?b1) (AngleOrd ?b1 ?b2))
    :effect (and (not (HasAngle ?j ?a1)) (HasAngle ?j ?a2) (not (HasAngle ?r ?b1)) (HasAngle ?r ?b2)))
  (:action decrease_angle
    :parameters (?l1 ?l2 - link ?j ?r - joint ?a1 ?a2 ?b1 ?b2 - angle)
    :precondition (and (Root ?r) (not (= ?j ?r)) (Connected ?j ?l1) (Connected ?j ?l2) (not (= ?l1 ?l2))
                       (HasAngle ?j ?a1) (AngleOrd ?a2 ?a1) (HasAngle ?r ?b1) (AngleOrd ?b2 ?b1))
    :effect (and (not (HasAngle ?j ?a1)) (HasAngle ?j ?a2) (not (HasAngle ?r ?b1)) (HasAngle ?r ?b2)))
  (:action turn_root
    :parameters (?r - joint ?b1 ?b2 - angle)
    :precondition (and (Root ?r) (HasAngle ?r ?b1) (AngleOrd ?b1 ?b2))
    :effect (and (not (HasAngle ?r ?b1)) (HasAngle ?r ?b2)))
  (:action turn_root_back
    :parameters (?r - joint ?b1 ?b2 - angle)
    :precondition (and (Root ?r) (HasAngle ?r ?b1) (AngleOrd ?b2 ?b1))
    :effect (and (not (HasAngle ?r ?b1)) (HasAngle ?r ?b2))))
"""


def chain_problem(domain: str, n: int, k: int, seed: int, *, upstream: bool = False, root: bool = False,
                  goal_fraction: float = 1.0) -> tuple[str, dict, dict]:
    objects, facts, start, goal = chain(n, k, seed, upstream=upstream, goal_fraction=goal_fraction)
    angles = objects["angle"]
    init = {(p.capitalize(), *rest) for p, *rest in facts}
    if root:
        init = {a for a in init if a[0] != "Affected"} | {("Root", "j1")}
    init |= {("HasAngle", j, angles[v]) for j, v in start.items()}
    text = write_problem(domain, objects, init, {("HasAngle", j, angles[v]) for j, v in goal.items()})
    return text, start, goal


def absolute_optimal(start: dict, goal: dict, k: int) -> int:
    """Downstream-only moves (turning lk about jk adds 1 to jk .. jn): the change of consecutive differences."""
    total, prev_goal, prev_start = 0, 0, 0
    for j in sorted(goal, key=lambda name: int(name[1:])):
        total += cyclic((goal[j] - prev_goal) - (start[j] - prev_start), k)
        prev_goal, prev_start = goal[j], start[j]
    return total


@pytest.mark.parametrize("seed", range(3))
def test_three_parameter_actions_with_conditional_effects(seed):
    n, k = 4 + 3 * seed, [4, 8, 12][seed]
    problem, start, goal = chain_problem("three-parameters", n, k, seed)
    result = InprocPlanner().solve(THREE_PARAMETERS, problem, 10.0)
    assert result.status is PlanStatus.SOLVED and result.optimal is True, result.message
    # turning the upstream link l(k-1) about jk moves nothing here (no Affected fact names it)
    assert len(result.plan) == absolute_optimal(start, goal, k)
    assert validate_plan(THREE_PARAMETERS, problem, result.plan).valid


@pytest.mark.parametrize("seed", range(3))
def test_benchmark_style_with_upstream_and_downstream_affected(seed):
    problem, start, goal = chain_problem("benchmark", 3 + 2 * seed, [4, 6, 8][seed], seed, upstream=True,
                                         goal_fraction=0.7)
    result = InprocPlanner().solve(BENCHMARK, problem, 10.0)
    assert result.status is PlanStatus.SOLVED and result.optimal is True, result.message
    assert "exact" in result.message  # a chain or (upstream turns share the first joint) a star programme
    assert validate_plan(BENCHMARK, problem, result.plan).valid
    assert len(result.plan) <= absolute_optimal(start, goal, [4, 6, 8][seed])


@pytest.mark.parametrize("seed", [11, 12])
def test_benchmark_style_optimality_against_fast_downward(seed):
    """The star programme's claim of optimality agrees with an optimal search (A* with hmax)."""
    problem, _, _ = chain_problem("benchmark", 3, 4, seed=seed, upstream=True)
    ours = InprocPlanner().solve(BENCHMARK, problem, 10.0)
    reference = get_planner("fd-opt").solve(BENCHMARK, problem, 60.0)
    assert ours.optimal is True and reference.solved and reference.optimal is True
    assert len(ours.plan) == len(reference.plan)


@pytest.mark.parametrize("seed", range(3))
def test_root_joint_changing_with_the_turned_one(seed):
    n, k = 3 + seed, [4, 6, 8][seed]
    problem, start, goal = chain_problem("root-moves-too", n, k, seed, root=True)
    result = InprocPlanner().solve(ROOT, problem, 10.0)
    assert result.status is PlanStatus.SOLVED and result.optimal is True, result.message
    assert "basis" in result.message
    assert validate_plan(ROOT, problem, result.plan).valid
    # every joint but the root needs its own change; the root's remaining change comes last
    others = [j for j in goal if j != "j1"]
    lower = sum(1 for j in others if (goal[j] - start[j]) % k)
    assert len(result.plan) >= lower
    if seed == 0:
        reference = get_planner("fd-opt").solve(ROOT, problem, 60.0)
        assert reference.solved and len(reference.plan) == len(result.plan)


# -- extra static preconditions, extra objects and actions ------------------------------------------------
def paper_absolute_with_statics() -> str:
    from pathlib import Path
    text = (Path(__file__).parent / "data" / "domain-absolute-paper.pddl").read_text()
    text = text.replace("(affected ?j2 - joint ?l - link ?j1 - joint))",
                        "(affected ?j2 - joint ?l - link ?j1 - joint)\n    (Fixed ?l - link) (Revolute ?j - joint))")
    return text.replace("(not (= ?l1 ?l2))", "(not (= ?l1 ?l2))\n      (not (Fixed ?l1))\n      (Revolute ?j1)")


def our_absolute_problem(n: int, k: int, seed: int, extra_init: str) -> tuple[str, object, list, dict]:
    from planhrc.model import make_object
    from planhrc.translator.problem import get_problem
    rng = random.Random(seed)
    obj = make_object("obj1", "absolute", n, k)
    init = [rng.choice(obj.orientation_degrees) for _ in obj.joint_indices]
    goal = {j: rng.choice(obj.orientation_degrees) for j in obj.joint_indices}
    text = get_problem(obj, obj.configuration_atoms(init), {("hasorientation", f"deg_{v}", obj.joint(j))
                                                            for j, v in goal.items()}, f"statics-{seed}",
                       "planhrc-absolute-paper")
    return text.replace("(:init", "(:init\n" + extra_init, 1), obj, init, goal


@pytest.mark.parametrize("seed", range(3))
def test_extra_static_preconditions_positive_and_negative(seed):
    """The issue's case: the paper's absolute domain with (not (Fixed ?l1)) and a Fixed fact for the table."""
    domain = paper_absolute_with_statics()
    n, k = 3 + 2 * seed, [4, 6, 12][seed]
    joints = " ".join(f"(Revolute obj1_j{i})" for i in range(1, n + 1))
    problem, obj, init, goal = our_absolute_problem(n, k, seed, f"    (Fixed obj1_l0) {joints}")
    result = InprocPlanner().solve(domain, problem, 10.0)
    assert result.status is PlanStatus.SOLVED and result.optimal is True, result.message
    assert validate_plan(domain, problem, result.plan).valid
    assert not any(step.split()[1] == "obj1_l0" for step in result.plan)  # the fixed link never turns
    if seed == 0:
        reference = get_planner("fd-opt").solve(domain, problem, 60.0)
        assert reference.solved and len(reference.plan) == len(result.plan)


def test_a_missing_positive_static_fact_removes_the_actions():
    domain = paper_absolute_with_statics()
    problem, *_ = our_absolute_problem(3, 4, 1, "    (Fixed obj1_l0) (Revolute obj1_j1) (Revolute obj1_j3)")
    task = ground_task(domain, problem)
    assert all(dict(axis.binding)["?j1"] != "obj1_j2" for axis in task.axes)


EXTRAS = (lambda text: text.replace("(:types link joint orientation)", "(:types link joint orientation sensor)")
          .replace("(orientationord ?o1 - orientation ?o2 - orientation))",
                   "(orientationord ?o1 - orientation ?o2 - orientation)\n"
                   "    (sees ?s - sensor ?l - link) (inspected ?l - link) (weldable ?j - joint))")
          .rstrip()[:-1] + """
  (:action inspect
    :parameters (?s - sensor ?l - link)
    :precondition (sees ?s ?l)
    :effect (inspected ?l))
  (:action weld
    :parameters (?j - joint ?o1 ?o2 ?o3 - orientation)
    :precondition (and (weldable ?j) (hasorientation ?o1 ?j) (orientationord ?o1 ?o2) (orientationord ?o2 ?o3))
    :effect (and (not (hasorientation ?o1 ?j)) (hasorientation ?o3 ?j))))
""")


def test_irrelevant_objects_and_actions():
    from pathlib import Path
    data = Path(__file__).parent / "data"
    domain = EXTRAS((data / "domain-relative.pddl").read_text())
    base = (data / "problem-relative-3x4.pddl").read_text()
    problem = base.replace("deg_0 deg_90 deg_180 deg_270 - orientation",
                           "deg_0 deg_90 deg_180 deg_270 - orientation\n    cam1 cam2 - sensor\n    spare_l - link")
    problem = problem.replace("(:init", "(:init\n    (sees cam1 obj1_l1) (sees cam2 spare_l)", 1)
    assert problem != base
    plain = InprocPlanner().solve((data / "domain-relative.pddl").read_text(), base, 5.0)
    result = InprocPlanner().solve(domain, problem, 5.0)
    assert result.status is PlanStatus.SOLVED and result.optimal is True, result.message
    assert result.plan == plain.plan
    assert validate_plan(domain, problem, result.plan).valid


# -- outside the family -----------------------------------------------------------------------------------
LOCKING = RENAMED.replace("(AngleOrd ?a ?b - angle))", "(AngleOrd ?a ?b - angle) (Unlocked ?h - hinge))").replace(
    "(domain renamed)", "(domain locking)").replace(
    "(:action increase_angle", """(:action lock
    :parameters (?h - hinge)
    :precondition (Unlocked ?h)
    :effect (not (Unlocked ?h)))
  (:action increase_angle""").replace("(HasAngle ?h ?a1) (Joins ?held ?h)", "(HasAngle ?h ?a1) (Unlocked ?h) (Joins ?held ?h)")


def locking_problem(seed: int = 2) -> tuple[str, int]:
    problem, optimal = renamed_problem(3, 4, seed=seed)
    return problem.replace("(:domain renamed)", "(:domain locking)").replace(
        "(:init", "(:init\n    (unlocked h1) (unlocked h2)", 1), optimal


def test_a_control_fact_the_turns_need_is_planned_around():
    """`unlocked` is deleted without an add: not a cyclic variable but a control fact the turns need. The control
    part times the cycle (planner.product) keeps the hinges unlocked and plans as the renamed domain does."""
    problem, optimal = locking_problem()
    result = InprocPlanner().solve(LOCKING, problem, 10.0)
    assert result.status is PlanStatus.SOLVED and result.optimal is True, result.message
    assert len(result.plan) == optimal and not any(step.startswith("(lock") for step in result.plan)
    assert validate_plan(LOCKING, problem, result.plan).valid


# A turn that also locks its hinge changes the cycle and the control at once: outside the family.
TURN_AND_LOCK = LOCKING.replace("(domain locking)", "(domain turn-and-lock)").replace(
    "(:effect (and (HasAngle ?h ?a2) (not (HasAngle ?h ?a1))))".lower(), "").replace(
    ":effect (and (HasAngle ?h ?a2) (not (HasAngle ?h ?a1))))",
    ":effect (and (HasAngle ?h ?a2) (not (HasAngle ?h ?a1)) (not (Unlocked ?h))))")


def test_outside_the_family_says_why_and_the_chain_falls_back(tmp_path):
    problem = locking_problem()[0].replace("(:domain locking)", "(:domain turn-and-lock)")
    assert TURN_AND_LOCK != LOCKING
    with pytest.raises(OutsideFamilyError, match=r"action \(increase_angle .*changes both cyclic values and the control"):
        ground_task(TURN_AND_LOCK, problem)
    result = plan_with_fallback(TURN_AND_LOCK, problem, ["inproc", "fd-lama"], 30.0)
    assert result.solved and result.planner == "fd-lama" and "control" in result.attempts[0].message
    assert result.validated and validate_plan(TURN_AND_LOCK, problem, result.plan).valid
    (tmp_path / "d.pddl").write_text(TURN_AND_LOCK)
    (tmp_path / "p.pddl").write_text(problem)
    assert cli_main(["plan", str(tmp_path / "d.pddl"), str(tmp_path / "p.pddl"), "--json"]) == 0


@pytest.mark.parametrize("name", ["renamed", "three-parameters", "benchmark", "root", "statics"])
def test_planhrc_plan_answers_every_variant(name, tmp_path, capsys):
    domain, problem = {
        "renamed": lambda: (RENAMED, renamed_problem(4, 6, 3)[0]),
        "three-parameters": lambda: (THREE_PARAMETERS, chain_problem("three-parameters", 5, 6, 3)[0]),
        "benchmark": lambda: (BENCHMARK, chain_problem("benchmark", 5, 6, 3, upstream=True)[0]),
        "root": lambda: (ROOT, chain_problem("root-moves-too", 4, 6, 3, root=True)[0]),
        "statics": lambda: (paper_absolute_with_statics(),
                            our_absolute_problem(4, 6, 3, "    (Fixed obj1_l0) " + " ".join(
                                f"(Revolute obj1_j{i})" for i in range(1, 5)))[0]),
    }[name]()
    (tmp_path / "d.pddl").write_text(domain)
    (tmp_path / "p.pddl").write_text(problem)
    assert cli_main(["plan", str(tmp_path / "d.pddl"), str(tmp_path / "p.pddl"), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["planner"] == "inproc" and out["status"] == "solved"
    assert validate_plan(domain, problem, out["plan"]).valid

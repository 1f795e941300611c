"""A VAL problem narrowed to the objects some steps can reach (`planner.scope.narrow_problem`) gets the answer the
whole problem gets from VAL, for right and wrong steps alike, and is smaller only where that is provable."""
import random

import pytest

from planhrc.model import make_object
from planhrc.paths import default_tbox_path
from planhrc.pipeline import piece_of
from planhrc.planner.scope import narrow_problem
from planhrc.planner.validate import validate_plan
from planhrc.transition import replay
from planhrc.translator.domain import read_domain_model
from planhrc.translator.problem import get_problem


def _joints_of(problem):
    return {n for line in problem.splitlines() if line.endswith("- joint") for n in line.split()[:-2]}


def _steps(obj, values, count, rng, joints):
    """`count` random one-step turns from joint values `values` on joints `joints`, and the values after them."""
    values = dict(values)
    steps = []
    for _ in range(count):
        k = rng.choice(joints)
        clockwise = rng.random() < 0.5
        then = (values[k] + (obj.step if clockwise else -obj.step)) % 360
        name = "rotateclockwise" if clockwise else "rotateanticlockwise"
        steps.append(f"({name} {obj.link(k)} {obj.link(k - 1)} {obj.joint(k)} deg_{values[k]} deg_{then})")
        for m in obj.joint_indices:  # the absolute formulation: the turned link and every one beyond it
            if m >= k:
                values[m] = (values[m] + (obj.step if clockwise else -obj.step)) % 360
    return steps, values


def test_narrowed_problems_get_the_whole_problems_answers_on_random_pieces():
    """Random pieces on the later joints of an absolute object, from random states to exact goals (the expected
    state, or one joint wrong: upstream, where the piece cannot reach, or downstream), with now and then a step
    tampered with: VAL answers the narrowed problem as it answers the whole one, and it is narrowed (upstream joints
    left out) exactly when the goal on them holds initially."""
    obj = make_object("o", "absolute", 6, 4)
    domain = _validation_domain()
    rng = random.Random(5)
    answers = {True: 0, False: 0}
    narrowed_count = 0
    for trial in range(24):
        values = {k: rng.choice(obj.orientation_degrees) for k in obj.joint_indices}
        first = rng.choice([3, 4, 5])
        steps, after = _steps(obj, values, rng.randint(1, 4), rng, list(range(first, 7)))
        goal_values = dict(after)
        wrong = trial % 4
        if wrong == 1:  # a joint the steps cannot reach, expected elsewhere
            goal_values[1] = (goal_values[1] + obj.step) % 360
        elif wrong == 2:  # a joint they do reach
            goal_values[6] = (goal_values[6] + obj.step) % 360
        elif wrong == 3:  # a step tampered with: its start orientation is not the joint's
            name, turned, held, joint, start, end = steps[0].strip("()").split()
            steps[0] = f"({name} {turned} {held} {joint} deg_{(int(start[4:]) + 90) % 360} {end})"
        init = obj.state([values[k] for k in obj.joint_indices])
        goal = obj.configuration_atoms([goal_values[k] for k in obj.joint_indices])
        problem = get_problem(obj, init, goal, "t")
        narrowed = narrow_problem(domain, problem, steps)
        whole = validate_plan(domain, problem, steps).valid
        assert validate_plan(domain, narrowed, steps).valid == whole, (trial, steps)
        answers[whole] += 1
        if wrong == 1:  # the goal on an unreachable joint does not hold: every joint kept
            assert _joints_of(narrowed) == _joints_of(problem)
        else:
            assert _joints_of(narrowed) == {obj.joint(k) for k in range(min(
                int(s.split()[3].rsplit("j", 1)[1]) for s in steps), 7)}
            narrowed_count += 1
    assert answers[True] and answers[False] and narrowed_count >= 12


def test_a_later_piece_of_a_plan_leaves_out_the_joints_upstream_of_its_steps_and_is_accepted():
    """`piece_of` with the domain: a piece turning joints 9 .. 11 of 12 is checked on joints 9 .. 12 only (and
    VAL accepts it), a piece turning joint 2 on every joint but the first."""
    obj = make_object("obj1", "absolute", 12, 6)
    domain = _validation_domain()
    rng = random.Random(2)
    values = {k: rng.choice(obj.orientation_degrees) for k in obj.joint_indices}
    early, middle = _steps(obj, values, 6, rng, [2])
    plan = [*early, *_steps(obj, middle, 6, rng, [9, 10, 11])[0]]
    init = obj.state([values[k] for k in obj.joint_indices])
    _, states = replay(read_domain_model(default_tbox_path(), "absolute"), init, plan)
    goal = frozenset(a for a in states[-1] if a[0] == "hasorientation")
    problem = get_problem(obj, init, goal, "obj1-task")
    later = piece_of(obj, problem, plan, states, 7, 12, domain)
    assert _joints_of(later.problem) == {obj.joint(k) for k in range(9, 13)}
    assert validate_plan(domain, later.problem, later.steps).valid
    first = piece_of(obj, problem, plan, states, 1, 6, domain)
    assert _joints_of(first.problem) == set(obj.joints) - {obj.joint(1)}
    assert validate_plan(domain, first.problem, first.steps).valid


def _validation_domain():
    from planhrc.translator.domain import domain_text

    return domain_text(read_domain_model(default_tbox_path(), "absolute"), paper_exact=True, absolute=True)


@pytest.mark.parametrize("domain_kind", ["relative", "unbound"])
def test_a_domain_without_statically_bound_quantifiers_keeps_every_problem_whole(domain_kind):
    """No joint is dropped where the module's argument does not hold: no quantified effect (relative: nothing at
    all is), or a quantified joint bound by no static literal on the action's parameters (orientations no step
    holds may still be: `planner.held`)."""
    from planhrc.translator.domain import domain_text

    obj = make_object("o", "absolute", 6, 4)
    init = obj.state([0, 90, 180, 270, 0, 90])
    problem = get_problem(obj, init, obj.configuration_atoms([0, 90, 180, 270, 0, 180]), "t")
    steps = ["(rotateclockwise o_l6 o_l5 o_j6 deg_90 deg_180)"]
    if domain_kind == "relative":
        domain = domain_text(read_domain_model(default_tbox_path(), "relative"), paper_exact=True, absolute=False)
    else:
        domain = _validation_domain().replace("(affected ?j2 ?l1 ?j1)", "(affected ?j2 ?l2 ?o4)")
    if domain_kind == "relative":
        assert narrow_problem(domain, problem, steps) == problem
    else:
        assert _joints_of(narrow_problem(domain, problem, steps)) == _joints_of(problem)
    # the real absolute domain does narrow this one, to the last joint, and VAL accepts it as the whole one
    narrowed = narrow_problem(_validation_domain(), problem, steps)
    assert _joints_of(narrowed) == {"o_j6"}
    assert validate_plan(_validation_domain(), narrowed, steps).valid
    assert validate_plan(_validation_domain(), problem, steps).valid

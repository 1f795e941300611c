"""A VAL problem without the orientations no relaxed run of the steps holds (`planner.held`, through
`planner.scope.narrow_problem`) gets the answer the whole problem gets from VAL, for right and wrong steps and
goals alike, on the bimanual and the absolute domains, and is smaller only where the argument holds."""
import random
import re

import pytest

from planhrc.model import make_object
from planhrc.pipeline import config_from_settings, piece_of, plan
from planhrc.planner.scope import narrow_problem
from planhrc.planner.validate import validate_plan
from planhrc.settings import make_settings


def _orientations_of(problem):
    return {n for line in problem.splitlines() if line.endswith("- orientation") for n in line.split()[:-2]}


def _solved(formulation, rng, links=6, orientations=24):
    """A random task of `formulation` planned by the in-process planner, VAL not asked."""
    obj = make_object("obj1", formulation, links, orientations)
    config = config_from_settings(make_settings(validate_plans=False))
    while True:
        values = [rng.choice(obj.orientation_degrees) for _ in range(links)]
        target = [rng.choice(obj.orientation_degrees) for _ in range(links)]
        init = obj.state(obj.joint_values_from_links(values))
        goal = obj.configuration_atoms(obj.joint_values_from_links(target))
        outcome = plan(obj, init, goal, config)
        if outcome.solved and len(outcome.steps) >= 4:
            return obj, outcome


def _spoilt(step, kind, rng, degrees):
    """`step` made wrong: its start orientation (kind 1) or its end orientation (kind 2) replaced by another."""
    found = re.findall(r"deg_\d+", step)
    if len(found) < 2:
        return step
    old = found[kind - 1]
    new = f"deg_{rng.choice([d for d in degrees if f'deg_{d}' != old])}"
    parts = step.split(" ")
    at = [i for i, p in enumerate(parts) if p.strip(")") == old][0 if kind == 1 else -1]
    parts[at] = parts[at].replace(old, new)
    return " ".join(parts)


@pytest.mark.parametrize("formulation", ["bimanual", "absolute"])
def test_narrowed_pieces_get_the_whole_problems_answers_right_and_wrong(formulation):
    """Random pieces of random plans (1-4 steps, from an expected state to the exact next one, or the last piece
    to the task's goal), right or made wrong (a step's start or end orientation, or the exact goal's orientation of
    one joint replaced by another): VAL answers the narrowed problem as it answers the whole one; most right pieces
    lose orientations, and every problem keeps the orientations its initial state holds on the joints it keeps."""
    rng = random.Random(11 if formulation == "bimanual" else 12)
    answers = {True: 0, False: 0}
    narrowed_count = 0
    for trial in range(36):
        obj, outcome = _solved(formulation, rng)
        task, steps, states = outcome.task, list(outcome.steps), outcome.expected_states
        first = rng.randrange(1, len(steps) + 1)
        last = min(len(steps), first + rng.randrange(4))
        whole = piece_of(obj, task.problem, steps, states, first, last)
        problem, piece = whole.problem, list(whole.steps)
        wrong = trial % 4
        if wrong in (1, 2):
            at = rng.randrange(len(piece))
            piece[at] = _spoilt(piece[at], wrong, rng, obj.orientation_degrees)
        elif wrong == 3 and "(not (hasorientation" in problem:
            goal_line = rng.choice([line for line in problem.split("(:goal")[1].splitlines()
                                    if line.startswith("    (hasorientation")])
            joint = goal_line.strip("() ").split()[2]
            other = rng.choice([d for d in obj.orientation_degrees if f"deg_{d} " not in goal_line])
            head, goal = problem.split("(:goal")
            problem = head + "(:goal" + goal.replace(goal_line, f"    (hasorientation deg_{other} {joint})").replace(
                f"    (not (hasorientation deg_{other} {joint}))\n", "")
        narrowed = narrow_problem(task.validation_domain, problem, piece)
        answer = validate_plan(task.validation_domain, problem, piece).valid
        assert validate_plan(task.validation_domain, narrowed, piece).valid == answer, (trial, piece)
        answers[answer] += 1
        joints = {n for line in narrowed.splitlines() if line.endswith("- joint") for n in line.split()[:-2]}
        held = {a[1] for a in states[first - 1] if a[0] == "hasorientation" and a[2] in joints}
        assert held <= _orientations_of(narrowed)
        if _orientations_of(narrowed) < _orientations_of(problem):
            narrowed_count += 1
    assert answers[True] >= 9 and answers[False] >= 9 and narrowed_count >= 18


def test_a_one_turn_piece_keeps_what_its_joints_hold_and_are_turned_to():
    """One 45-degree turn of a bimanual plan: the orientations kept are exactly those the piece's start state
    holds and those its joints are turned to (its exact goal's); VAL accepts it on both problems."""
    rng = random.Random(3)
    for _ in range(20):
        obj, outcome = _solved("bimanual", rng)
        turns = [i for i, s in enumerate(outcome.steps, start=1) if s.startswith("(rotate")]
        if turns:
            break
    at = turns[0]
    task, states = outcome.task, outcome.expected_states
    whole = piece_of(obj, task.problem, outcome.steps, states, at, at)
    narrowed = piece_of(obj, task.problem, outcome.steps, states, at, at, task.validation_domain)
    before = {a[1] for a in states[at - 1] if a[0] == "hasorientation" and a[2] in narrowed.problem}
    after = {a[1] for a in states[at] if a[0] == "hasorientation" and a[2] in narrowed.problem}
    assert _orientations_of(narrowed.problem) == before | after
    assert len(before | after) < obj.orientations
    assert validate_plan(task.validation_domain, narrowed.problem, narrowed.steps).valid
    assert validate_plan(task.validation_domain, whole.problem, whole.steps).valid


def test_a_quantified_orientation_in_no_positive_literal_keeps_every_orientation():
    """Where a quantified orientation occurs in no positive literal of its effect's condition the relaxed run
    cannot bound it: no orientation is dropped (joints the steps cannot reach still are, `planner.scope`)."""
    rng = random.Random(4)
    obj, outcome = _solved("bimanual", rng)
    task = outcome.task
    domain = task.validation_domain.replace("(orientationord45 ?o3 ?o4))", "(not (orientationord45 ?o4 ?o3)))")
    assert domain != task.validation_domain
    turns = [i for i, s in enumerate(outcome.steps, start=1) if s.startswith("(rotate")]
    piece = piece_of(obj, task.problem, outcome.steps, outcome.expected_states, turns[0], turns[0])
    assert _orientations_of(narrow_problem(domain, piece.problem, piece.steps)) == set(obj.orientation_names)
    assert _orientations_of(narrow_problem(task.validation_domain, piece.problem, piece.steps)) < set(
        obj.orientation_names)


def test_a_large_objects_piece_is_not_run_when_its_start_holds_every_orientation():
    """The first piece of an absolute 30 x 6 plan, whose start state holds all six orientations on the joints its
    steps reach, keeps them all (the relaxed run stops before its first step) and is still narrowed to those
    joints."""
    obj = make_object("obj1", "absolute", 30, 6)
    config = config_from_settings(make_settings(validate_plans=False))
    values = [(60 * k) % 360 for k in range(30)]
    init = obj.state(obj.joint_values_from_links(values))
    goal = obj.configuration_atoms(obj.joint_values_from_links([0] * 30))
    outcome = plan(obj, init, goal, config)
    assert outcome.solved
    task = outcome.task
    piece = piece_of(obj, task.problem, outcome.steps, outcome.expected_states, 1, 4, task.validation_domain)
    assert _orientations_of(piece.problem) == set(obj.orientation_names)
    lowest = min(int(step.split()[3].rsplit("_j", 1)[1]) for step in piece.steps)
    joints = {n for line in piece.problem.splitlines() if line.endswith("- joint") for n in line.split()[:-2]}
    assert lowest > 1 and joints == {obj.joint(k) for k in range(lowest, 31)}
    assert validate_plan(task.validation_domain, piece.problem, piece.steps).valid

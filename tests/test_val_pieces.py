"""VAL on a plan cut into pieces (each ending in an exact expected state) says what one VAL run says."""
from dataclasses import replace

import pytest

from planhrc import pipeline
from planhrc.model import make_object
from planhrc.pipeline import config_from_settings, plan, validation_pieces
from planhrc.pipeline import pieces as pieces_module
from planhrc.planner.scope import narrow_problem
from planhrc.planner.validate import validate_pieces, validate_plan
from planhrc.settings import make_settings


def _solved(formulation, pieces=3):
    obj = make_object("obj1", formulation, 10, 8)
    config = config_from_settings(make_settings(val_pieces=pieces, validate_plans=False))
    init = obj.state(obj.joint_values_from_links([0, 45, 90, 135, 180, 225, 270, 315, 0, 45]))
    goal = obj.configuration_atoms(obj.joint_values_from_links([180, 0, 180, 0, 180, 0, 180, 0, 180, 0]))
    outcome = plan(obj, init, goal, config)
    assert outcome.solved and len(outcome.steps) >= 3 * pipeline.MIN_PIECE_STEPS
    return obj, replace(config, validate=True), outcome


def _both(obj, outcome, n):
    """(one VAL run on the whole plan, VAL on n pieces) for an outcome's steps and expected states."""
    task = outcome.task
    whole = validate_plan(task.validation_domain, task.problem, outcome.steps)
    pieces = validation_pieces(obj, outcome, n)
    return whole.valid, validate_pieces(task.validation_domain, pieces).valid, pieces


@pytest.mark.parametrize("formulation", ["relative", "absolute"])
def test_pieces_accept_a_valid_plan_and_cover_it_exactly(formulation):
    obj, config, outcome = _solved(formulation)
    whole, pieced, pieces = _both(obj, outcome, 3)
    assert whole and pieced and len(pieces) == 3
    assert sum((p[1] for p in pieces), ()) == outcome.steps  # consecutive, nothing left out or repeated
    def head(text):
        return sorted(text.split("(:goal")[0].splitlines())

    def task_for(steps):  # the task's problem as VAL gets it for these steps (`planner.scope`: the same answers)
        return narrow_problem(outcome.task.validation_domain, outcome.task.problem, steps)

    assert head(pieces[0][0]) == head(task_for(pieces[0][1]))  # the first piece starts from the task's own init
    middle = head(pieces[1][0])
    # the task's static facts, less those naming a joint the piece leaves out (none in the relative formulation)
    dropped = set(obj.joints) - {name for line in middle if line.endswith("- joint") for name in line.split()}
    assert not dropped or formulation == "absolute"
    assert [x for x in middle if "hasorientation" not in x and "- joint" not in x] == [
        x for x in head(outcome.task.problem) if "hasorientation" not in x and "- joint" not in x
        and dropped.isdisjoint(x.strip("() ").split())]
    assert "(not (hasorientation" in pieces[0][0] and "(not (hasorientation" not in pieces[-1][0]
    checked = pipeline.validate(outcome, obj, config)
    assert checked.validated


@pytest.mark.parametrize("formulation", ["relative", "absolute"])
def test_a_wrong_step_inside_a_middle_piece_is_refused_as_by_one_run(formulation):
    obj, config, outcome = _solved(formulation)
    pieces = validation_pieces(obj, outcome, 3)
    k = len(pieces[0][1]) + 1  # the second step of the middle piece
    step = outcome.steps[k]
    name = "rotateclockwise" if "anticlockwise" in step else "rotateanticlockwise"
    words = step.strip("()").split()
    flipped = "(" + " ".join([name] + words[1:-2] + [words[-1], words[-2]]) + ")"  # the opposite turn
    bad = replace(outcome, steps=outcome.steps[:k] + (flipped,) + outcome.steps[k + 1:])
    whole, pieced, _ = _both(obj, bad, 3)
    assert not whole and not pieced
    checked = pipeline.validate(bad, obj, config)  # pieces only where effects are conditional (absolute)
    assert checked.status == "invalid"
    assert ("piece 2 of 3" in checked.message) == (formulation == "absolute"), checked.message


def test_a_piece_that_ends_elsewhere_is_refused_though_one_run_accepts_the_reordered_plan():
    """The pieces are conservative: two steps of different joints swapped across a cut still reach the goal
    (relative steps commute), so one run accepts; but the first piece no longer ends in its expected state, so
    the pieces refuse. They may refuse a plan one run accepts (its expected states are then wrong, so it must
    not be followed anyway), never the other way round."""
    obj, config, outcome = _solved("relative")
    cut = len(validation_pieces(obj, outcome, 3)[0][1])
    before, after = outcome.steps[cut - 1], outcome.steps[cut]
    assert before.split()[3] != after.split()[3], "the steps around the cut should turn different joints"
    moved = outcome.steps[:cut - 1] + (after, before) + outcome.steps[cut + 1:]
    whole, pieced, _ = _both(obj, replace(outcome, steps=moved), 3)
    assert whole and not pieced


def test_a_wrong_expected_state_at_a_cut_is_refused():
    obj, config, outcome = _solved("absolute")
    cut = len(validation_pieces(obj, outcome, 2)[0][1])
    states = list(outcome.expected_states)
    states[cut] = states[cut + 1]  # the state one step later
    bad = replace(outcome, expected_states=tuple(states))
    assert not validate_pieces(outcome.task.validation_domain, validation_pieces(obj, bad, 2)).valid


def test_a_plan_short_of_the_goal_is_refused_in_its_last_piece():
    obj, config, outcome = _solved("relative")
    short = replace(outcome, steps=outcome.steps[:-1], expected_states=outcome.expected_states[:-1])
    whole, pieced, _ = _both(obj, short, 3)
    assert not whole and not pieced


def test_short_plans_and_one_piece_use_one_run():
    obj, config, outcome = _solved("relative")
    assert len(validation_pieces(obj, outcome, 1)) == 1
    few = replace(outcome, steps=outcome.steps[:pipeline.MIN_PIECE_STEPS],
                  expected_states=outcome.expected_states[:pipeline.MIN_PIECE_STEPS + 1])
    assert len(validation_pieces(obj, few, 4)) == 1


@pytest.mark.parametrize("formulation", ["relative", "absolute", "bimanual"])
def test_a_piece_built_from_the_tasks_parts_is_the_problem_written_then_narrowed(formulation):
    """`piece_of` builds a piece's problem from the task's parts, read once, rather than writing the problem's text
    and reading it again to narrow it: the text, byte for byte, of the way it replaces (`_problem_text`, then
    `narrow_problem`), for every piece of a plan, the last piece (the task's goal) and a task text of another
    shape (written and read as before)."""
    obj = make_object("obj1", formulation, 6, 12)
    config = config_from_settings(make_settings(validate_plans=False))
    init = obj.state(obj.joint_values_from_links([0, 90, 180, 270, 0, 90]))
    goal = obj.configuration_atoms(obj.joint_values_from_links([180, 0, 330, 30, 180, 240]))
    outcome = plan(obj, init, goal, config)
    assert outcome.solved and len(outcome.steps) >= 4
    task, steps, states = outcome.task, outcome.steps, outcome.expected_states

    def written(problem, a, b, domain):
        text = pieces_module._problem_text(obj, states[a - 1], None if b == len(steps) else states[b], problem)
        return text if domain is None else narrow_problem(domain, text, steps[a - 1:b])

    spaced = task.problem.replace("  (:goal (and\n", "\n  (:goal (and\n", 1)  # a line before the goal
    compared = 0
    for a in range(2, len(steps) + 1):
        for b in sorted({a, min(a + 2, len(steps)), len(steps)}):
            for problem, domain in ((task.problem, task.validation_domain), (task.problem, None),
                                    (spaced, task.validation_domain)):
                piece = pieces_module.piece_of(obj, problem, steps, states, a, b, domain)
                assert piece.problem == written(problem, a, b, domain)
                assert piece.steps == tuple(steps[a - 1:b])
                compared += 1
    assert compared >= 3 * 2 * (len(steps) - 1)

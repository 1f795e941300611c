"""The cooperation model, one test per branch, on small inline states of a 3-link relative object (K = 4).

The plan used throughout turns j1 from 0 to 180 in two steps, then j2 from 0 to 90:
s^e_1 = (0, 0) -a1-> s^e_2 = (90, 0) -a2-> s^e_3 = (180, 0) -a3-> s^e_4 = (180, 90) = goal.
"""
import pytest

from planhrc.cooperation import Decision, PlanView, decide
from planhrc.model import make_object

OBJ = make_object("o", "relative", 3, 4)


def state(j1: int, j2: int) -> frozenset:
    return OBJ.state([j1, j2])


def pre(j: int, deg: int) -> frozenset:
    """pre(a) of a rotation of joint j starting at `deg`: the static facts it needs and its orientation."""
    return OBJ.connected_atoms() | OBJ.ord_atoms() | {("hasorientation", f"deg_{deg}", f"o_j{j}")}


GOAL = OBJ.configuration_atoms([180, 90])
PLAN = PlanView(
    expected_states=(state(0, 0), state(90, 0), state(180, 0), state(180, 90)),
    preconditions=(pre(1, 0), pre(1, 90), pre(2, 0)),
)


def test_goal_reached_when_perceived_is_subsumed_by_the_goal():
    d = decide(state(180, 90), GOAL, PLAN, next_step=3)
    assert d == Decision("goal_reached", None, None, d.reason)
    assert "goal" in d.reason


def test_partial_goal_is_reached_by_any_state_asserting_its_atoms():
    partial_goal = frozenset({("hasorientation", "deg_90", "o_j2")})
    assert decide(state(270, 90), partial_goal, PLAN, next_step=1).kind == "goal_reached"


def test_no_plan_when_there_is_none():
    d = decide(state(0, 0), GOAL, None, next_step=None)
    assert (d.kind, d.next_step, d.matched_expected_step) == ("no_plan", None, None)


@pytest.mark.parametrize("step", [1, 2, 3])
def test_continue_when_perceived_matches_the_next_expected_state(step):
    d = decide(PLAN.expected_states[step - 1], GOAL, PLAN, next_step=step)
    assert (d.kind, d.next_step, d.matched_expected_step) == ("continue", step, step)


def test_continue_when_perceived_only_satisfies_the_next_precondition():
    # a3 turns j2 from 0; j1 ended at 270 instead of 180 (an unmodelled effect): a3 is still executable.
    d = decide(state(270, 0), GOAL, PLAN, next_step=3, last_outcome="succeeded")
    assert (d.kind, d.next_step, d.matched_expected_step) == ("continue", 3, None)
    assert "pre(a_3)" in d.reason


def test_failed_action_with_unchanged_configuration_is_retried():
    d = decide(state(90, 0), GOAL, PLAN, next_step=2, last_outcome="failed")
    assert (d.kind, d.next_step) == ("continue", 2)
    assert "retry" in d.reason and "failed" in d.reason


def test_resume_ahead_after_a_human_did_part_of_the_work():
    d = decide(state(180, 0), GOAL, PLAN, next_step=1)
    assert (d.kind, d.next_step, d.matched_expected_step) == ("resume", 3, 3)


def test_precondition_alone_is_not_enough_after_a_failed_or_partial_action():
    # (270, 0) satisfies pre(a_3) (j2 at 0) but matches no expected state.
    assert decide(state(270, 0), GOAL, PLAN, next_step=3, last_outcome="succeeded").kind == "continue"
    for outcome in ("failed", "partial"):
        assert decide(state(270, 0), GOAL, PLAN, next_step=3, last_outcome=outcome).kind == "replan"


def test_resume_back_after_a_partial_action_was_undone():
    d = decide(state(0, 0), GOAL, PLAN, next_step=3, last_outcome="partial")
    assert (d.kind, d.next_step, d.matched_expected_step) == ("resume", 1, 1)


def test_resume_picks_the_latest_matching_expected_state():
    looping = PlanView(
        expected_states=(state(0, 0), state(90, 0), state(0, 0), state(0, 90)),
        preconditions=(pre(1, 0), pre(1, 90), pre(2, 0)),
    )
    d = decide(state(0, 0), OBJ.configuration_atoms([0, 90]), looping, next_step=2)
    assert (d.kind, d.next_step, d.matched_expected_step) == ("resume", 3, 3)


def test_resume_when_there_is_no_next_step():
    d = decide(state(90, 0), GOAL, PLAN, next_step=None)
    assert (d.kind, d.next_step) == ("resume", 2)


def test_replan_when_no_expected_state_matches():
    d = decide(state(270, 270), GOAL, PLAN, next_step=2)
    assert (d.kind, d.next_step, d.matched_expected_step) == ("replan", None, None)


def test_replan_when_only_the_final_expected_state_matches_but_not_the_goal():
    stale_goal = OBJ.configuration_atoms([0, 270])
    d = decide(state(180, 90), stale_goal, PLAN, next_step=None)
    assert (d.kind, d.matched_expected_step) == ("replan", 4)


def test_plan_view_checks_the_number_of_expected_states():
    with pytest.raises(ValueError, match="expected_states"):
        PlanView(expected_states=(state(0, 0),), preconditions=(pre(1, 0),))


def test_inputs_are_not_changed():
    perceived = state(90, 0)
    before = (perceived, GOAL, PLAN)
    decide(perceived, GOAL, PLAN, next_step=1)
    assert (perceived, GOAL, PLAN) == before


def test_a_turn_that_would_leave_the_table_is_not_retried_the_same_way():
    from planhrc.cooperation import FailureHistory, escalate
    from planhrc.vocabulary import DecisionKind, FailureReason, Remedy

    retry = Decision(DecisionKind.CONTINUE, 2, 2, "retry a_2")
    history = FailureHistory(joint=1, turned=2, reason=FailureReason.LEFT_TABLE)
    answer = escalate(retry, history, (1, 2))
    assert answer.kind is DecisionKind.REPLAN and answer.remedy is Remedy.OTHER_WAY
    tried = FailureHistory(joint=1, turned=2, reason=FailureReason.LEFT_TABLE, failures=3,
                           tried=(Remedy.OTHER_WAY, Remedy.REPLAN))
    assert escalate(retry, tried, (1, 2)).kind is DecisionKind.HUMAN_HELP_REQUESTED


def test_a_plan_whose_states_are_kept_as_changes_decides_as_one_of_whole_states():
    """A plan view holding the replay's `ExpectedStates` (each state made only when read; which states subsume the
    perceived one is worked out from the changes) decides exactly as the same view with every state whole, on
    perceived states along the plan, off it, and at every next step."""
    import random

    from planhrc.paths import default_tbox_path
    from planhrc.transition import replay
    from planhrc.translator.domain import read_domain_model

    obj = make_object("o", "absolute", 6, 8)
    domain = read_domain_model(default_tbox_path(), "absolute")
    plan = [f"(rotateclockwise o_l{k} o_l{k - 1} o_j{k} deg_{45 * i} deg_{45 * (i + 1)})"
            for k in (5, 3) for i in range(3)]
    actions, states = replay(domain, obj.state([0] * 6), plan)
    goal = obj.configuration_atoms(obj.link_orientations_of(states[-1]))
    lazy = PlanView(expected_states=states, preconditions=tuple(a.pre for a in actions))
    whole = PlanView(expected_states=tuple(states), preconditions=lazy.preconditions)
    rng = random.Random(2)
    perceived = list(states) + [obj.state([rng.choice(obj.orientation_degrees) for _ in range(6)]) for _ in range(8)]
    for seen in perceived:
        for next_step in (None, 1, 3, len(plan)):
            assert decide(seen, goal, lazy, next_step) == decide(seen, goal, whole, next_step)
    assert decide(states[3], goal, lazy, 1).kind == "resume"

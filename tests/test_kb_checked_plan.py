"""A plan checked ahead (`check_plan`, outside the store's lock) is written exactly as one checked in `add_plan`."""
from __future__ import annotations

import pytest

from planhrc.kb_service.store.errors import ValidationError
from planhrc.model import make_object
from tests.store_backends import Place, kb, place  # noqa: F401 (fixtures)
from tests.test_kb_scenarios import plan_for


def _write(place: Place, checked_ahead: bool):
    with place.open() as kb:
        obj = make_object("obj1", "absolute", 4, 4)
        kb.create_object(obj)
        init = kb.add_state("obj1", "perceived", obj.state([0, 90, 180, 270]))
        actions, states = plan_for(obj, init.atoms, [(1, True), (3, False), (2, True), (4, True)])
        goal = kb.add_state("obj1", "goal", states[-1])
        problem = kb.add_problem("obj1", init.id, goal.id)
        checked = kb.check_plan("obj1", actions, states) if checked_ahead else None
        plan = kb.add_plan(problem.id, "inproc", actions, states, checked)
    with place.open() as kb:  # read back from the database (the store wrote the plan out when it closed)
        again = kb.get_plan(plan.id)
        return (plan.expected_state_ids, [kb.get_state(s).atoms for s in again.expected_state_ids],
                [a.spec for a in again.actions],
                sorted(t for t in kb.export_lines("all") if "createdAt" not in t))  # times differ


def test_a_plan_checked_ahead_is_stored_as_one_checked_in_the_write(place, tmp_path):
    assert _write(place, False) == _write(place.another(tmp_path / "ahead"), True)


def test_check_plan_refuses_bad_input_and_a_mismatched_check_is_redone(kb):
    a, b = make_object("obj1", "absolute", 3, 4), make_object("obj2", "absolute", 3, 4)
    kb.create_object(a)
    kb.create_object(b)
    init = kb.add_state("obj1", "perceived", a.state([0, 90, 180]))
    actions, states = plan_for(a, init.atoms, [(1, True)])
    with pytest.raises(ValidationError, match="expected_states"):
        kb.check_plan("obj1", actions, states[:1])
    with pytest.raises(ValidationError, match="object_id"):
        kb.check_plan("obj9", actions, states)
    before = kb.triple_count()
    with pytest.raises(ValidationError, match="obj1"):
        kb.check_plan("obj2", actions, states)  # atoms of another object
    assert kb.triple_count() == before  # checking writes nothing
    goal = kb.add_state("obj1", "goal", states[-1])
    problem = kb.add_problem("obj1", init.id, goal.id)
    other = kb.check_plan("obj1", actions, list(states))  # not the objects add_plan is given: checked again
    plan = kb.add_plan(problem.id, "inproc", actions, states, other)
    assert [kb.get_state(s).atoms for s in plan.expected_state_ids] == list(states)


def test_a_plan_check_past_its_deadline_stops_with_a_deadline_error(kb):
    import time

    from planhrc.kb_service.store.errors import DeadlineError
    obj = make_object("obj1", "absolute", 4, 4)
    kb.create_object(obj)
    init = obj.state([0, 90, 180, 270])
    actions, states = plan_for(obj, init, [(1, True), (3, False)])
    with pytest.raises(DeadlineError, match="expected state 1 of 3"):
        kb.check_plan("obj1", actions, states, deadline_at=time.monotonic() - 1.0)
    assert kb.check_plan("obj1", actions, states, deadline_at=time.monotonic() + 60.0).expected_states == tuple(states)


def test_actions_checked_once_are_valid_for_their_object_only(kb):
    """`check_plan` keeps the actions it found valid per object (`ObjectInfo.valid_actions`): the same actions are
    still refused for another object, an action refused is refused again (never kept), and a new object under a
    known name (its lookups built afresh) checks them again."""
    from dataclasses import replace

    from planhrc.kb_service.store.checks import ObjectInfo, check_plan

    a, b = make_object("obj1", "absolute", 3, 4), make_object("obj2", "absolute", 3, 4)
    kb.create_object(a)
    kb.create_object(b)
    init = kb.add_state("obj1", "perceived", a.state([0, 90, 180]))
    actions, states = plan_for(a, init.atoms, [(1, True), (2, False)])
    kb.check_plan("obj1", actions, states)
    kb.check_plan("obj1", actions, states)  # from what was kept
    with pytest.raises(ValidationError, match="obj1"):
        kb.check_plan("obj2", actions, states)  # valid for obj1 is not valid for obj2
    foreign = replace(actions[0], params=("obj9_l1",) + tuple(actions[0].params[1:]))
    for _ in range(2):
        with pytest.raises(ValidationError, match=r"actions\[0\]\.params\[0\]"):
            kb.check_plan("obj1", (foreign,) + tuple(actions[1:]), states)

    info = ObjectInfo(a)
    check_plan(info, actions, states)
    assert set(actions) <= info.valid_actions
    bigger = ObjectInfo(make_object("obj1", "absolute", 2, 4))  # the name again, another object: checked afresh
    assert not bigger.valid_actions
    with pytest.raises(ValidationError):
        check_plan(bigger, actions, states)


def test_a_plan_checked_ahead_has_its_journal_row_made_ahead_too(kb, monkeypatch):
    """The journal row's body is made with the check, outside the store's lock: the write that stores the plan
    does not make it again (a large plan's body takes most of a second, which every other write would wait for)."""
    from planhrc.kb_service.store import journal

    obj = make_object("obj1", "absolute", 4, 4)
    kb.create_object(obj)
    init = kb.add_state("obj1", "perceived", obj.state([0, 90, 180, 270]))
    actions, states = plan_for(obj, init.atoms, [(1, True), (3, False)])
    goal = kb.add_state("obj1", "goal", states[-1])
    problem = kb.add_problem("obj1", init.id, goal.id)
    checked = kb.check_plan("obj1", actions, states)
    assert checked.journal_body == journal.encode_body(checked.actions, checked.expected_states)

    def made_inside(*args):
        raise AssertionError("the journal row's body was made inside the write")

    monkeypatch.setattr(journal, "encode_body", made_inside)
    plan = kb.add_plan(problem.id, "inproc", checked.actions, checked.expected_states, checked)
    assert [kb.get_state(s).atoms for s in plan.expected_state_ids] == list(states)


def test_a_check_of_the_first_steps_leaves_the_later_ones_to_check_steps(kb):
    """`check_plan(..., first_steps=n)` checks the first n actions and the states up to s^e_(n+1), nothing after (a
    state of another object later in the plan passes it); `check_steps` then checks a later range and refuses that
    state, naming its field; a range outside the plan is refused too. The plan so checked is written as given."""
    a, b = make_object("obj1", "absolute", 3, 4), make_object("obj2", "absolute", 3, 4)
    kb.create_object(a)
    kb.create_object(b)
    init = kb.add_state("obj1", "perceived", a.state([0, 90, 180]))
    actions, states = plan_for(a, init.atoms, [(1, True), (2, False), (3, True)])
    foreign = b.state([0, 0, 0])
    bad = (*states[:3], foreign)  # s^e_4 (after a_3) belongs to obj2
    checked = kb.check_plan("obj1", actions, bad, first_steps=2)
    assert checked.checked_steps == 2 and checked.expected_states == bad
    assert kb.check_plan("obj1", actions, states).checked_steps is None  # every step
    kb.check_steps("obj1", actions, bad, 1, 2)
    with pytest.raises(ValidationError, match=r"expected_states\[3\]"):
        kb.check_steps("obj1", actions, bad, 3, 3)
    with pytest.raises(ValidationError, match="steps: a_3..a_4"):
        kb.check_steps("obj1", actions, states, 3, 4)
    with pytest.raises(ValidationError, match=r"expected_states\[3\]"):
        kb.check_plan("obj1", actions, bad)  # a whole check still finds it

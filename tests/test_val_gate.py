"""The early answer: a re-plan on a domain with conditional effects is answered once VAL has accepted the plan's
first piece, and no later step is dispatched before VAL has accepted the piece it lies in (through a restart).

The service's use cases run in process on a real store file, with the real planner and real VAL. Two tests hold the later
pieces' VAL back (a wrapper that waits before calling the real VAL) to see what happens while a verdict is pending;
one hands VAL a plan with a tampered later step (the stored plan is the planner's: only VAL's copy differs).
"""
from __future__ import annotations

import contextlib
import threading
import time
from dataclasses import asdict, replace
from pathlib import Path
from typing import Iterator

import pytest

from planhrc import pipeline
from planhrc.kb_service import usecases
from planhrc.kb_service.planning_pool import PlanningPool
from planhrc.kb_service.store import SqliteStore
from planhrc.kb_service.usecases import (Context, FeedbackRequest, GoalRequest, NewObject, PerceptionRequest,
                                        give_feedback, perceive, take_next_action)
from planhrc.event_log import DecisionData
from planhrc.kb_service.usecases.log import piece_record_of, read_event
from planhrc.pipeline import PieceRecord, Verdict, gate, stages, val_runs
from planhrc.model import make_object
from planhrc.paths import default_tbox_path
from planhrc.settings import make_settings
from tests.test_service_api import move

LINKS, K = 10, 8
START = [0, 45, 90, 135, 180, 225, 270, 315, 0, 45]
GOAL = [180, 0, 180, 0, 180, 0, 180, 0, 180, 0]


@contextlib.contextmanager
def service(db: Path, pool: PlanningPool | None = None, **overrides) -> Iterator[tuple[SqliteStore, Context]]:
    tbox = default_tbox_path()
    with SqliteStore(str(db), tbox) as kb:
        context = usecases.open_context(kb, make_settings(tbox_path=str(tbox), **overrides), pool=pool)
        try:
            yield kb, context
        finally:
            usecases.close_context(context)


def new_object(cell: Context, formulation: str = "absolute") -> str:
    ident = usecases.create_object(cell, NewObject("bar", LINKS, K, formulation)).id
    usecases.set_goal(cell, GoalRequest(ident, tuple(GOAL)))
    return ident


def perceived(cell: Context, oid: str, links: list) -> usecases.Turn:
    return perceive(cell, PerceptionRequest(oid, tuple(links)))


def succeeded(cell: Context, oid: str, action: usecases.NextAction) -> None:
    give_feedback(cell, FeedbackRequest(oid, action.id, "succeeded"))


def kinds(kb: SqliteStore, oid: str, kind: str) -> list:
    return [e for e in kb.list_events(oid) if e.kind == kind]


def adoption(kb: SqliteStore, oid: str, plan_id: str):
    return next(e for e in kb.list_events(oid) if e.kind == "replan" and e.data.get("plan_id") == plan_id)


@pytest.fixture
def held_back(monkeypatch):
    """VAL on the later pieces waits until the test sets the event (then runs the real VAL)."""
    release = threading.Event()
    real = val_runs.check_piece

    def slow(*args, **kwargs):
        release.wait(60)
        return real(*args, **kwargs)

    monkeypatch.setattr(val_runs, "check_piece", slow)
    yield release
    release.set()


def test_the_answer_comes_once_the_first_piece_is_accepted_and_a_later_step_waits_for_its_verdict(tmp_path, held_back):
    with service(tmp_path / "kb.sqlite3") as (kb, cell):
        oid = new_object(cell)
        answer = perceived(cell, oid, START)
        assert answer.decision == "replan" and answer.next_action.step == 1
        event = adoption(kb, oid, answer.plan_id)
        pieces = event.data["val_pieces"]
        accepted = event.data["val_accepted"]
        first = pieces[:len(accepted)]  # the first motion, in pieces checked at once before the answer
        assert accepted == list(range(1, len(accepted) + 1)) and len(pieces) > len(accepted)
        assert first[0][0] == 1 and first[-1][1] == answer.next_action.last_step
        assert all(b + 1 == c for (_, b), (c, _) in zip(pieces, pieces[1:]))  # consecutive, nothing left out
        assert pieces[-1][1] == len(usecases.read_plan(cell, answer.plan_id).steps)
        assert "are checked before they are dispatched" in answer.reason
        assert kinds(kb, oid, "val_verdict") == []  # answered while VAL still holds the later pieces

        action = take_next_action(cell, oid)  # the first motion lies in the accepted piece
        assert action is not None and action.step == 1
        succeeded(cell, oid, action)
        links = move(START, asdict(action))
        result: dict = {}
        perceiving = threading.Thread(target=lambda: result.update(turn=perceived(cell, oid, links)))
        perceiving.start()
        perceiving.join(1.5)
        assert perceiving.is_alive(), "a step of a piece VAL has not decided on must wait for the verdict"
        held_back.set()
        perceiving.join(60)
        turn = result["turn"]
        assert turn.decision == "continue" and turn.next_action.step == pieces[len(accepted)][0]
        verdicts = kinds(kb, oid, "val_verdict")
        decided = next(e for e in reversed(kb.list_events(oid)) if e.kind == "continue")
        assert any(v.data["piece"] == len(accepted) + 1 and v.data["verdict"] == "accepted" and v.seq < decided.seq
                   for v in verdicts)


def _tamper_once(cell: Context, monkeypatch) -> list:
    """VAL's copy of the first plan gets one later step turned the other way (the store keeps the planner's)."""
    real = stages.expect
    tampered: list = []

    def expect(obj, init, goal, found, deadline_at):
        outcome = real(obj, init, goal, found, deadline_at)
        assert not cell.validator.beside(outcome.task)  # absolute: VAL checks the plan in pieces, after the pipeline
        if tampered or not outcome.solved:
            return outcome
        k = len(outcome.steps) - 3  # in the last piece
        words = outcome.steps[k].strip("()").split()
        name = "rotateclockwise" if "anticlockwise" in words[0] else "rotateanticlockwise"
        flipped = "(" + " ".join([name] + words[1:-2] + [words[-1], words[-2]]) + ")"
        tampered.append(k + 1)
        return replace(outcome, steps=outcome.steps[:k] + (flipped,) + outcome.steps[k + 1:])

    monkeypatch.setattr(stages, "expect", expect)
    return tampered


def test_a_later_piece_val_refuses_is_never_dispatched_and_leads_to_a_replan(tmp_path, monkeypatch):
    with service(tmp_path / "kb.sqlite3") as (kb, cell):
        oid = new_object(cell)
        tampered = _tamper_once(cell, monkeypatch)
        answer = perceived(cell, oid, START)
        plan_id = answer.plan_id
        assert answer.decision == "replan" and tampered
        adopted = read_event(adoption(kb, oid, plan_id))
        assert isinstance(adopted, DecisionData)
        record = piece_record_of(adopted)
        assert record is not None
        refused = record.covering(tampered[0], tampered[0])[0]
        first_refused = record.bounds(refused)[0]
        deadline = time.monotonic() + 60
        while not any(e.data["piece"] == refused for e in kinds(kb, oid, "val_verdict")):
            assert time.monotonic() < deadline
            time.sleep(0.05)

        links, withheld = list(START), None
        while True:  # the robot carries out the plan motion after motion, as far as VAL accepted it
            action = take_next_action(cell, oid)
            if action is None:
                withheld = kinds(kb, oid, "dispatch_withheld")
                break
            assert action.last_step < first_refused  # no motion reaching into the refused piece goes out
            succeeded(cell, oid, action)
            links = move(links, asdict(action))
        assert withheld and f"VAL refused piece {refused}" in withheld[-1].reason
        assert kb.get_execution(oid).status == "idle"

        again = perceived(cell, oid, links)
        assert again.decision == "replan" and again.plan_id != plan_id
        assert f"VAL refused piece {refused} of plan {plan_id}" in again.reason
        dispatched = [e.data["step"] for e in kinds(kb, oid, "dispatched") if e.data["plan_id"] == plan_id]
        assert dispatched and max(dispatched) < first_refused
        assert take_next_action(cell, oid).plan_id == again.plan_id


def test_after_a_restart_a_step_whose_verdict_was_not_recorded_is_checked_by_val_before_it_goes_out(
        tmp_path, held_back):
    db = tmp_path / "kb.sqlite3"
    with service(db) as (kb, cell):
        oid = new_object(cell)
        answer = perceived(cell, oid, START)
        plan_id = answer.plan_id
        accepted = len(adoption(kb, oid, plan_id).data["val_accepted"])
        action = take_next_action(cell, oid)
        succeeded(cell, oid, action)
        assert kinds(kb, oid, "val_verdict") == []
    held_back.set()  # the stopped service's VAL runs were cancelled: nothing more is recorded
    links = move(START, asdict(action))

    with service(db) as (kb, cell):  # a restart on the same file
        time.sleep(0.2)
        assert kinds(kb, oid, "val_verdict") == []
        decided = perceived(cell, oid, links)
        assert decided.decision == "continue" and decided.plan_id == plan_id
        step = decided.next_action.step
        verdicts = kinds(kb, oid, "val_verdict")
        assert [(v.data["piece"], v.data["verdict"]) for v in verdicts] == [(accepted + 1, "accepted")]
        assert verdicts[0].data["first_step"] <= step <= verdicts[0].data["last_step"]
        continued = [e for e in kb.list_events(oid) if e.kind == "continue"][-1]
        assert verdicts[0].seq < continued.seq
        taken = take_next_action(cell, oid)
        assert taken.step == step
        assert len(kinds(kb, oid, "val_verdict")) == 1  # recorded once, not asked again


def test_relative_plans_and_the_setting_off_are_validated_whole_before_the_answer(tmp_path):
    with service(tmp_path / "rel.sqlite3") as (kb, cell):
        oid = new_object(cell, "relative")
        answer = perceived(cell, oid, START)
        assert answer.decision == "replan"
        assert "val_pieces" not in adoption(kb, oid, answer.plan_id).data
    with service(tmp_path / "off.sqlite3", val_early_answer=False) as (kb, cell):
        oid = new_object(cell)
        answer = perceived(cell, oid, START)
        assert answer.decision == "replan"
        assert "val_pieces" not in adoption(kb, oid, answer.plan_id).data
        time.sleep(0.3)
        assert kinds(kb, oid, "val_verdict") == []


def test_the_early_answer_on_the_planning_pool_path(tmp_path):
    """A task large enough for the planning pool (here: every task) is planned in a worker; VAL then runs in the
    service, the first piece before the answer and the rest behind it."""
    with PlanningPool(1, min_atoms=1) as pool, service(tmp_path / "kb.sqlite3", pool=pool) as (kb, cell):
        oid = new_object(cell)
        answer = perceived(cell, oid, START)
        assert answer.decision == "replan" and pool.pids()
        event = adoption(kb, oid, answer.plan_id).data
        pieces, accepted = event["val_pieces"], event["val_accepted"]
        assert len(accepted) == 2  # the first motion of this plan has several steps: two pieces at once
        deadline = time.monotonic() + 60
        while len(kinds(kb, oid, "val_verdict")) < len(pieces) - len(accepted):
            assert time.monotonic() < deadline
            time.sleep(0.05)
        assert all(v.data["verdict"] == "accepted" for v in kinds(kb, oid, "val_verdict"))


# -- the parts ---------------------------------------------------------------------------------------------------
def test_piece_bounds_put_the_first_motion_alone_then_cut_the_rest():
    assert pipeline.piece_bounds(40, 2, 3) == [(0, 3), (3, 21), (21, 40)]
    assert pipeline.piece_bounds(40, 2) == [(0, 20), (20, 40)]
    assert pipeline.piece_bounds(10, 2, 3) == [(0, 3), (3, 10)]  # the rest is too short to cut again
    assert pipeline.piece_bounds(3, 2, 3) == [(0, 3)]
    assert pipeline.piece_bounds(40, 2, 5, 2) == [(0, 2), (2, 5), (5, 23), (23, 40)]  # the first motion in two
    assert pipeline.piece_bounds(40, 2, 1, 2) == [(0, 1), (1, 21), (21, 40)]  # one step: one piece


def test_the_first_motion_is_the_first_run_of_merged_steps():
    obj = make_object("o", "absolute", LINKS, K)
    init = obj.state(obj.joint_values_from_links(START))
    goal = obj.configuration_atoms(obj.joint_values_from_links(GOAL))
    outcome = pipeline.plan(obj, init, goal, pipeline.config_from_settings(make_settings(validate_plans=False)))
    first = pipeline.first_motion_steps(obj, outcome.actions, merge=True)
    motions = [pipeline.action_motion(obj, a) for a in outcome.actions]
    assert all(m["joint_index"] == motions[0]["joint_index"] for m in motions[:first])
    assert first == len(outcome.actions) or motions[first]["joint_index"] != motions[0]["joint_index"] or \
        motions[first]["delta_deg"] * motions[0]["delta_deg"] < 0 or abs(sum(m["delta_deg"] for m in motions[:first + 1])) >= 360
    assert pipeline.first_motion_steps(obj, outcome.actions, merge=False) == 1
    assert pipeline.early_answer_first_piece(obj, outcome, merge=True) == first
    relative = make_object("r", "relative", LINKS, K)
    rel = pipeline.plan(relative, relative.state(relative.joint_values_from_links(START)),
                        relative.configuration_atoms(relative.joint_values_from_links(GOAL)),
                        pipeline.config_from_settings(make_settings(validate_plans=False)))
    assert pipeline.early_answer_first_piece(relative, rel, merge=True) is None  # no conditional effects


def test_a_piece_record_names_the_pieces_a_motion_lies_in():
    record = PieceRecord("p", ((1, 3), (4, 20), (21, 40)), {1: Verdict(True, "")})
    assert record.covering(1, 3) == [1]
    assert record.covering(3, 5) == [1, 2]
    assert record.covering(20, 21) == [2, 3]
    assert record.bounds(3) == (21, 40)


def test_the_gate_passes_a_motion_only_when_every_piece_it_lies_in_is_accepted():
    record = PieceRecord("p", ((1, 3), (4, 20), (21, 40)), {1: Verdict(True, ""), 3: Verdict(False, "step 22 fails")})
    assert gate(record, "p", 1, 3).passes
    waiting = gate(record, "p", 3, 5)
    assert waiting.missing == 2 and waiting.refusal is None and not waiting.passes
    refused = gate(record.with_verdict(2, Verdict(True, "")), "p", 20, 21)
    assert refused.refusal == "VAL refused piece 3 of plan p (a_21..a_40): step 22 fails" and not refused.passes
    assert gate(record, "another plan", 21, 40).passes and gate(None, "p", 21, 40).passes  # validated whole
    assert record.verdicts.keys() == {1, 3}  # with_verdict made a new record

"""An absolute re-plan's VAL runs: how many, on what (each step of the plan in exactly one run, the later runs on
problems without the joints upstream of their steps), and a large absolute object answered with a validated first
action within the planning deadline.

The service's use cases run in process on a real store file with the real planner and real VAL; the runs are
counted by wrapping the two functions that start them (the run itself is VAL's)."""
from __future__ import annotations

import random
import time

import pytest

from planhrc.kb_service import usecases
from planhrc.kb_service.usecases import GoalRequest, NewObject
from planhrc.pipeline import MIN_PIECE_STEPS, later, val_runs, validation
from planhrc.model import make_object
from planhrc.settings import make_settings
from tests.servers import TOKEN, serving, token_client
from tests.test_val_gate import adoption, kinds, perceived, service


def _joints_in(problem: str) -> set[str]:
    return {n for line in problem.splitlines() if line.endswith("- joint") for n in line.split()[:-2]}


def _joint_index(step: str) -> int:
    return int(step.split()[3].rsplit("_j", 1)[1])


@pytest.fixture
def val_runs_seen(monkeypatch):
    """Every VAL run a re-plan starts, as (problem, steps, before the answer?), in the order they start."""
    seen: list[tuple[str, tuple[str, ...], bool]] = []
    real_start, real_check = val_runs.start_runs, later.check_piece

    def start_runs(task, pieces, armed=None):
        seen.extend((problem, tuple(steps), True) for problem, steps in pieces)
        return real_start(task, pieces, armed)

    def check_piece(domain, piece, *args, **kwargs):
        seen.append((piece.problem, piece.steps, False))
        return real_check(domain, piece, *args, **kwargs)

    monkeypatch.setattr(val_runs, "start_runs", start_runs)
    monkeypatch.setattr(later, "check_piece", check_piece)
    return seen


def _settled(kb, oid: str, count: int) -> None:
    deadline = time.monotonic() + 60
    while len(kinds(kb, oid, "val_verdict")) < count:
        assert time.monotonic() < deadline, "the later pieces' verdicts did not come"
        time.sleep(0.05)


def test_an_absolute_replan_checks_each_step_once_and_the_later_pieces_without_unreachable_joints(
        tmp_path, val_runs_seen):
    """20 x 12: the first motion in `val_pieces` runs before the answer, the rest in runs of at least 16 steps
    behind it (`validation.LATER_PIECE_STEPS`), one run per piece and nothing else: the steps of the runs, in
    order, are the plan's steps once each, no run is on the whole plan, and every later run's problem holds exactly
    the joints from its first turned joint on (the plan turns the joints in chain order)."""
    links, k = 20, 12
    rng = random.Random(4)
    obj = make_object("probe", "absolute", links, k)
    with service(tmp_path / "kb.sqlite3", val_pieces=2) as (kb, cell):
        oid = usecases.create_object(cell, NewObject("bar", links, k, "absolute")).id
        usecases.set_goal(cell, GoalRequest(oid, tuple(float(rng.choice(obj.orientation_degrees))
                                                       for _ in range(links))))
        answer = perceived(cell, oid, [float(rng.choice(obj.orientation_degrees)) for _ in range(links)])
        assert answer.decision == "replan"
        steps = tuple("(" + " ".join((s.name, *s.params)) + ")" for s in usecases.read_plan(cell, answer.plan_id).steps)
        event = adoption(kb, oid, answer.plan_id).data
        pieces, accepted = event["val_pieces"], event["val_accepted"]
        _settled(kb, oid, len(pieces) - len(accepted))
    before = [run for run in val_runs_seen if run[2]]
    behind = [run for run in val_runs_seen if not run[2]]
    assert len(before) == len(accepted) <= 2 and len(val_runs_seen) == len(pieces)
    rest = len(steps) - pieces[len(accepted) - 1][1]
    assert len(behind) == max(2, rest // (2 * MIN_PIECE_STEPS)) == len(pieces) - len(accepted)
    assert validation.LATER_PIECE_STEPS == 2 * MIN_PIECE_STEPS
    assert sum((run[1] for run in val_runs_seen), ()) == steps  # each step once, in order
    assert all(len(run[1]) < len(steps) for run in val_runs_seen)  # never the whole plan as well
    for problem, run_steps, _ in behind:
        first = min(_joint_index(s) for s in run_steps)
        assert _joints_in(problem) == {f"{oid}_j{j}" for j in range(first, links + 1)}
    assert any(len(_joints_in(problem)) < links for problem, _, _ in behind)


def _large_object_answer(tmp_path, links: int, k: int, seed: int):
    rng = random.Random(seed)
    obj = make_object("probe", "absolute", links, k)
    with service(tmp_path / "kb.sqlite3") as (kb, cell):
        oid = usecases.create_object(cell, NewObject("big", links, k, "absolute")).id
        usecases.set_goal(cell, GoalRequest(oid, tuple(float(rng.choice(obj.orientation_degrees))
                                                       for _ in range(links))))
        t = time.monotonic()
        answer = perceived(cell, oid, [float(rng.choice(obj.orientation_degrees)) for _ in range(links)])
        seconds = time.monotonic() - t
        event = adoption(kb, oid, answer.plan_id).data
        plan = usecases.read_plan(cell, answer.plan_id)
        return answer, event, plan, seconds, make_settings().planning_deadline_s


def test_a_50_by_36_absolute_object_gets_a_validated_first_action(tmp_path):
    """The issue's size, 50 links x 36 orientations: the re-plan is answered within the planning deadline with its
    first motion accepted by VAL and the rest of its hundreds of steps left behind the answer (the replay of those
    steps, not VAL, used to take the whole deadline: a 503)."""
    answer, event, plan, seconds, deadline_s = _large_object_answer(tmp_path, 50, 36, 5)
    assert answer.decision == "replan" and answer.next_action is not None and answer.next_action.step == 1
    accepted = [event["val_pieces"][i - 1] for i in event["val_accepted"]]
    assert accepted and accepted[0][0] == 1 and accepted[-1][1] >= answer.next_action.last_step
    assert len(plan.steps) > 300 and event["val_pieces"][-1][1] == len(plan.steps)
    assert "are checked before they are dispatched" in answer.reason and seconds < deadline_s


@pytest.mark.slow
def test_a_200_by_12_absolute_object_gets_a_validated_first_action_over_http(tmp_path):
    """200 links x 12 orientations on `planhrc serve` (a real process on a loopback port, its planning pool on):
    the perception answers 200 within the planning deadline with the plan's first motion accepted by VAL and the
    rest of its hundreds of steps checked behind the answer (a worker's replay and the service's unpacking of the
    expected states used to take past the deadline: a 503)."""
    links, k = 200, 12
    rng = random.Random(7)
    obj = make_object("probe", "absolute", links, k)
    with serving(tmp_path / "kb.sqlite3", env={"PLANHRC_TOKEN": TOKEN}) as url, token_client(url) as client:
        r = client.post("/objects", json={"name": "big", "links": links, "orientations": k, "formulation": "absolute"})
        assert r.status_code == 201, r.text
        oid = r.json()["id"]
        goal = [float(rng.choice(obj.orientation_degrees)) for _ in range(links)]
        assert client.put(f"/objects/{oid}/goal", json={"link_orientations_deg": goal}).status_code == 200
        perceived_deg = [float(rng.choice(obj.orientation_degrees)) for _ in range(links)]
        t = time.monotonic()
        r = client.post(f"/objects/{oid}/perceptions", json={"link_orientations_deg": perceived_deg})
        seconds = time.monotonic() - t
        assert r.status_code == 200, r.text
        answer = r.json()
        assert answer["decision"] == "replan" and answer["next_action"]["step"] == 1
        assert seconds < make_settings().planning_deadline_s, seconds
        event = next(e for e in client.get(f"/objects/{oid}/events").json()
                     if e["kind"] == "replan" and e["data"].get("plan_id") == answer["plan_id"])["data"]
        accepted = [event["val_pieces"][i - 1] for i in event["val_accepted"]]
        assert accepted and accepted[0][0] == 1 and accepted[-1][1] >= answer["next_action"]["last_step"]
        assert event["val_pieces"][-1][1] > 300  # the plan's hundreds of steps, the later ones behind the answer

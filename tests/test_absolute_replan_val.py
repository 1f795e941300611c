"""An absolute re-plan's VAL runs: how many, on what (each step of the plan in exactly one run, the later runs on
problems without the joints upstream of their steps), and a large absolute object answered with a validated first
action within the planning deadline.

The service's use cases run in process on a real store file with the real planner and real VAL; the runs are
counted by wrapping the two functions that start them (the run itself is VAL's)."""
from __future__ import annotations

import random
import threading
import time

import pytest

from planhrc.kb_service import usecases
from planhrc.kb_service.store import checks
from planhrc.kb_service.usecases import GoalRequest, NewObject
from planhrc.pipeline import MIN_PIECE_STEPS, piece_of, val_runs, validation
from planhrc.model import make_object
from tests.servers import TOKEN, serving, token_client
from tests.test_val_gate import adoption, kinds, perceived, service


# Far above what these tests measure (a few seconds on a quiet 2-core machine): their verdicts count work, never time.
ROOMY_DEADLINE_S = 600.0


def _joints_in(problem: str) -> set[str]:
    return {n for line in problem.splitlines() if line.endswith("- joint") for n in line.split()[:-2]}


def _joint_index(step: str) -> int:
    return int(step.split()[3].rsplit("_j", 1)[1])


@pytest.fixture
def val_runs_seen(monkeypatch):
    """Every VAL run a re-plan starts, as (problem, steps, before the answer?), in the order they start."""
    seen: list[tuple[str, tuple[str, ...], bool]] = []
    real_start, real_check = val_runs.start_runs, val_runs.check_piece

    def start_runs(task, pieces, armed=None):
        pieces = list(pieces)
        seen.extend((problem, tuple(steps), True) for problem, steps in pieces)
        return real_start(task, pieces, armed)

    def check_piece(domain, piece, *args, **kwargs):
        seen.append((piece.problem, piece.steps, False))
        return real_check(domain, piece, *args, **kwargs)

    monkeypatch.setattr(val_runs, "start_runs", start_runs)
    monkeypatch.setattr(val_runs, "check_piece", check_piece)
    return seen


def _settled(kb, oid: str, count: int) -> None:
    deadline = time.monotonic() + ROOMY_DEADLINE_S
    while len(kinds(kb, oid, "val_verdict")) < count:
        assert time.monotonic() < deadline, "the later pieces' verdicts did not come"
        time.sleep(0.05)


def test_an_absolute_replan_checks_each_step_once_and_the_later_pieces_without_unreachable_joints(
        tmp_path, val_runs_seen, expected_states_checked):
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
    # the store's checks likewise: the first motion's states before the answer, every other one behind it, once
    first_motion_end = pieces[len(accepted) - 1][1]
    assert [i for i, answering in expected_states_checked if answering] == list(range(first_motion_end + 1))
    assert sorted(i for i, _ in expected_states_checked) == list(range(len(steps) + 1))


@pytest.fixture
def expected_states_checked(monkeypatch):
    """The store's checks of expected states, as (index checked, on the thread that asked for the answer?), in
    order (perceived states not counted)."""
    seen: list[tuple[int, bool]] = []
    real, answering = checks.check_state_atoms, threading.current_thread()

    def counted(info, kind, atoms, field):
        if kind == "expected":
            seen.append((int(field.split("[")[1].rstrip("]")), threading.current_thread() is answering))
        return real(info, kind, atoms, field)

    monkeypatch.setattr(checks, "check_state_atoms", counted)
    return seen


def test_a_50_by_36_absolute_object_gets_a_validated_first_action(tmp_path, expected_states_checked):
    """The issue's size, 50 links x 36 orientations: the re-plan is answered with its first motion accepted by VAL
    and checked by the store (its actions and the expected states up to the one after it), and nothing more of its
    hundreds of steps: the store checks the later steps behind the answer, each piece's before VAL on it (the
    first later piece's verdict is waited for). The deadline is far above the work (a count, not a time)."""
    links, k = 50, 36
    rng = random.Random(5)
    obj = make_object("probe", "absolute", links, k)
    with service(tmp_path / "kb.sqlite3", planning_deadline_s=ROOMY_DEADLINE_S) as (kb, cell):
        oid = usecases.create_object(cell, NewObject("big", links, k, "absolute")).id
        usecases.set_goal(cell, GoalRequest(oid, tuple(float(rng.choice(obj.orientation_degrees))
                                                       for _ in range(links))))
        answer = perceived(cell, oid, [float(rng.choice(obj.orientation_degrees)) for _ in range(links)])
        event = adoption(kb, oid, answer.plan_id).data
        plan = usecases.read_plan(cell, answer.plan_id)
        pieces, accepted = event["val_pieces"], event["val_accepted"]
        _settled(kb, oid, 1)
        verdict = kinds(kb, oid, "val_verdict")[0].data
    assert answer.decision == "replan" and answer.next_action is not None and answer.next_action.step == 1
    first_motion = [pieces[i - 1] for i in accepted]
    assert first_motion and first_motion[0][0] == 1 and first_motion[-1][1] >= answer.next_action.last_step
    assert len(plan.steps) > 300 and pieces[-1][1] == len(plan.steps)
    before = [i for i, answering in expected_states_checked if answering]
    assert before == list(range(first_motion[-1][1] + 1))  # s^e_1 .. the state after the first motion, no more
    first, last = pieces[len(accepted)]
    assert verdict["first_step"] == first and verdict["verdict"] == "accepted"
    behind = [i for i, answering in expected_states_checked if not answering]
    assert behind[:last - first + 1] == list(range(first, last + 1))  # the states after a_first .. a_last
    assert "are checked before they are dispatched" in answer.reason


def test_a_later_piece_the_store_refuses_is_refused_without_val(tmp_path, val_runs_seen, monkeypatch):
    """A later piece whose steps the store's check refuses gets a refused verdict naming the store's reason, and VAL
    never runs on it; the gate then withholds its motion."""
    from planhrc.kb_service.store import ValidationError

    refused_at: list[int] = []

    def refusing(self, object_id, actions, states, first, last):
        if not refused_at:
            refused_at.append(first)
            raise ValidationError(f"expected_states[{first}]: made up for the test")

    links, k = 20, 12
    rng = random.Random(4)
    obj = make_object("probe", "absolute", links, k)
    with service(tmp_path / "kb.sqlite3", val_pieces=2, planning_deadline_s=ROOMY_DEADLINE_S) as (kb, cell):
        monkeypatch.setattr(type(kb), "check_steps", refusing)
        oid = usecases.create_object(cell, NewObject("bar", links, k, "absolute")).id
        usecases.set_goal(cell, GoalRequest(oid, tuple(float(rng.choice(obj.orientation_degrees))
                                                       for _ in range(links))))
        answer = perceived(cell, oid, [float(rng.choice(obj.orientation_degrees)) for _ in range(links)])
        event = adoption(kb, oid, answer.plan_id).data
        steps = tuple("(" + " ".join((s.name, *s.params)) + ")" for s in usecases.read_plan(cell, answer.plan_id).steps)
        _settled(kb, oid, len(event["val_pieces"]) - len(event["val_accepted"]))
        verdicts = kinds(kb, oid, "val_verdict")
    refused = [v.data for v in verdicts if v.data["verdict"] == "refused"]
    assert len(refused) == 1 and refused[0]["first_step"] == refused_at[0]
    assert "the store's check refused" in refused[0]["reason"] and "made up for the test" in refused[0]["reason"]
    refused_steps = steps[refused_at[0] - 1:refused[0]["last_step"]]
    later_runs = [run_steps for _, run_steps, before in val_runs_seen if not before]
    assert refused_steps not in later_runs  # VAL never saw the piece the store refused
    assert len(later_runs) == len(event["val_pieces"]) - len(event["val_accepted"]) - 1  # all the others


@pytest.mark.slow
def test_a_200_by_12_absolute_object_gets_a_validated_first_action_over_http(tmp_path):
    """200 links x 12 orientations on `planhrc serve` (a real process on a loopback port, its planning pool on):
    the perception answers 200 with the plan's first motion accepted by VAL and the rest of its hundreds of steps
    checked behind the answer (the first later piece's verdict is waited for). The service's planning deadline is set far above the
    work (`ROOMY_DEADLINE_S`): how fast it answers is `python -m planhrc.bench.large`'s to say, not a test's."""
    links, k = 200, 12
    rng = random.Random(7)
    obj = make_object("probe", "absolute", links, k)
    env = {"PLANHRC_TOKEN": TOKEN, "PLANHRC_PLANNING_DEADLINE_S": str(ROOMY_DEADLINE_S)}
    with serving(tmp_path / "kb.sqlite3", env=env) as url, token_client(url, timeout=ROOMY_DEADLINE_S) as client:
        r = client.post("/objects", json={"name": "big", "links": links, "orientations": k, "formulation": "absolute"})
        assert r.status_code == 201, r.text
        oid = r.json()["id"]
        goal = [float(rng.choice(obj.orientation_degrees)) for _ in range(links)]
        assert client.put(f"/objects/{oid}/goal", json={"link_orientations_deg": goal}).status_code == 200
        perceived_deg = [float(rng.choice(obj.orientation_degrees)) for _ in range(links)]
        r = client.post(f"/objects/{oid}/perceptions", json={"link_orientations_deg": perceived_deg})
        assert r.status_code == 200, r.text
        answer = r.json()
        assert answer["decision"] == "replan" and answer["next_action"]["step"] == 1
        event = next(e for e in client.get(f"/objects/{oid}/events").json()
                     if e["kind"] == "replan" and e["data"].get("plan_id") == answer["plan_id"])["data"]
        pieces, accepted = event["val_pieces"], [event["val_pieces"][i - 1] for i in event["val_accepted"]]
        assert accepted and accepted[0][0] == 1 and accepted[-1][1] >= answer["next_action"]["last_step"]
        assert pieces[-1][1] > 300  # the plan's hundreds of steps, the later ones behind the answer
        deadline = time.monotonic() + ROOMY_DEADLINE_S
        while not (verdicts := [e["data"] for e in client.get(f"/objects/{oid}/events").json()
                                if e["kind"] == "val_verdict"]):
            assert time.monotonic() < deadline, "the first later piece's verdict did not come"
            time.sleep(0.2)
        assert verdicts[0]["first_step"] == pieces[len(accepted)][0] and verdicts[0]["verdict"] == "accepted"


def _a_random_task_with_the_early_answer(links: int, k: int, rng: random.Random):
    """A random absolute task of `links` x `k` (object, goal, initial state), the service's planning config and a
    validator with the early answer."""
    from planhrc.pipeline import config_from_settings
    from planhrc.settings import make_settings

    obj = make_object("rod", "absolute", links, k)
    goal = obj.configuration_atoms([rng.choice(obj.orientation_degrees) for _ in range(links)])
    init = obj.state([rng.choice(obj.orientation_degrees) for _ in range(links)])
    config = config_from_settings(make_settings())
    return obj, goal, init, config, validation.Validator(config, early_answer=True, merge_macro_steps=True,
                                                         armed=False)


def test_a_replan_from_a_planning_worker_starts_val_on_its_first_motion_before_the_replay_comes_back(monkeypatch):
    """The worker sends the plan's steps before it replays them: VAL's runs on the first motion start then (before
    the outcome), on exactly the pieces the early answer would cut from the outcome's own expected states, and the
    verdict is the early answer's. Runs started for another plan are not kept: they are stopped and the first
    motion is checked afresh."""
    from planhrc.kb_service.planning_pool import PlanningPool
    from planhrc.pipeline import (PlanningJob, ReplanRequest, early_answer_first_piece,
                                  plan_for_service)
    from planhrc.pipeline import replan

    links, k = 30, 12
    monkeypatch.setattr(replan, "EARLY_VAL_MIN_LINKS", links)  # the gate is the next test's
    rng = random.Random(3)
    obj, goal, init, config, validator = _a_random_task_with_the_early_answer(links, k, rng)
    order: list[tuple[str, tuple[tuple[str, tuple[str, ...]], ...]]] = []
    real_start = val_runs.start_runs

    def start_runs(task, pieces, armed=None):  # each piece recorded as VAL starts on it
        seen: list[tuple[str, tuple[str, ...]]] = []

        def recorded():
            for problem, steps in pieces:
                seen.append((problem, tuple(steps)))
                yield problem, steps

        checks = real_start(task, recorded(), armed)
        order.append(("val", tuple(seen)))
        return checks

    monkeypatch.setattr(val_runs, "start_runs", start_runs)
    try:
        with PlanningPool(1, 1) as pool:
            real_plan = pool.plan

            def plan(job: PlanningJob, steps_known=None):
                outcome = real_plan(job, steps_known)
                order.append(("outcome", ()))
                return outcome

            monkeypatch.setattr(pool, "plan", plan)
            planned = plan_for_service(ReplanRequest(obj, init, goal, time.monotonic() + ROOMY_DEADLINE_S), config,
                                       validator, pool)
            outcome = planned.outcome
            verdict = planned.verdict.outcome()
            assert [what for what, _ in order] == ["val", "outcome"]  # VAL began before the replay came back
            first = early_answer_first_piece(obj, outcome, True)
            assert first is not None and planned.verdict.steps_before_answer == first
            cut = [piece_of(obj, outcome.task.problem, outcome.steps, outcome.expected_states, a + 1, b,
                            outcome.task.validation_domain) for a, b in validator._first_bounds(len(outcome.steps),
                                                                                                  first)]
            assert order[0][1] == tuple((p.problem, p.steps) for p in cut)  # what the early answer checks
            assert verdict is not None and verdict.solved and verdict.validated_steps == first
            planned.verdict.cancel()

            # runs started for another plan of the object: stopped, the first motion checked afresh
            other = obj.state([rng.choice(obj.orientation_degrees) for _ in range(links)])
            elsewhere = plan_for_service(ReplanRequest(obj, other, goal, time.monotonic() + ROOMY_DEADLINE_S),
                                         config, validator, pool)
            stale = validator.start_first(obj, other, elsewhere.outcome.task, elsewhere.outcome.steps,
                                          time.monotonic() + ROOMY_DEADLINE_S)
            elsewhere.verdict.cancel()
            assert stale is not None and not stale.matches(outcome, first)
            before = len(order)
            again = validator.check(obj, outcome, time.monotonic() + ROOMY_DEADLINE_S, first_started=stale)
            assert [what for what, _ in order[before:]] == ["val"]  # started afresh, on the outcome's own pieces
            assert order[-1][1] == order[0][1]
            checked = again.outcome()
            assert checked is not None and checked.solved and checked.validated_steps == first
            again.cancel()
    finally:
        validator.close()


def test_a_worker_plan_of_a_smaller_object_has_val_started_after_the_outcome(monkeypatch):
    """Below `EARLY_VAL_MIN_LINKS` the worker's replay is short: the service does not replay the first motion itself
    to start VAL early; VAL starts on the outcome's own pieces once it is back, and its verdict is the same."""
    from planhrc.kb_service.planning_pool import PlanningPool
    from planhrc.pipeline import ReplanRequest, early_answer_first_piece, plan_for_service
    from planhrc.pipeline import replan

    links, k = 20, 12
    assert links < replan.EARLY_VAL_MIN_LINKS
    rng = random.Random(3)
    obj, goal, init, config, validator = _a_random_task_with_the_early_answer(links, k, rng)
    order: list[str] = []
    real_start = val_runs.start_runs
    monkeypatch.setattr(val_runs, "start_runs", lambda task, pieces, armed=None: (
        order.append("val"), real_start(task, pieces, armed))[1])
    first_calls: list[int] = []
    real_first = validator.start_first
    monkeypatch.setattr(validator, "start_first", lambda *a, **kw: (first_calls.append(1), real_first(*a, **kw))[1])
    try:
        with PlanningPool(1, 1) as pool:
            real_plan = pool.plan

            def plan(job, steps_known=None):
                assert steps_known is None  # the worker is not asked for its steps before the replay
                outcome = real_plan(job, steps_known)
                order.append("outcome")
                return outcome

            monkeypatch.setattr(pool, "plan", plan)
            planned = plan_for_service(ReplanRequest(obj, init, goal, time.monotonic() + ROOMY_DEADLINE_S), config,
                                       validator, pool)
            verdict = planned.verdict.outcome()
            assert order[0] == "outcome" and "val" in order and not first_calls
            first = early_answer_first_piece(obj, planned.outcome, True)
            assert first is not None and planned.verdict.steps_before_answer == first
            assert verdict is not None and verdict.solved and verdict.validated_steps == first
            planned.verdict.cancel()
    finally:
        validator.close()

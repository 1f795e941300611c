"""The planning pool's worker processes: the same outcome as the pipeline in process, and a pool that stays usable
after a worker crashes, after a deadline the worker keeps, and after one it does not."""
from __future__ import annotations

import os
import pickle
import signal
import threading
import time
from dataclasses import replace

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from planhrc import pipeline
from planhrc.kb_service.planning_pool import (ATOMS_PER_FRAME, PlanningJob, PlanningPool, pack_outcome, state_size,
                                              unpack_outcome)
from planhrc.model import make_object
from planhrc.settings import make_settings
from planhrc.vocabulary import PlanningStatus
from tests.processes import alive


@pytest.fixture(scope="module")
def config():
    return pipeline.config_from_settings(make_settings())


def _job(config, obj, start, goal, deadline_s=10.0):
    return PlanningJob(obj, obj.state(start), obj.configuration_atoms(goal), config, None,
                       time.monotonic() + deadline_s)


def test_a_worker_gives_the_outcome_the_pipeline_gives_in_process(config):
    rod = make_object("rod", "absolute", 12, 12)
    start, goal = [30 * (i % 12) for i in range(12)], [(90 + 60 * i) % 360 for i in range(12)]
    here = pipeline.plan(rod, rod.state(start), rod.configuration_atoms(goal), config, defer_validation=True)
    with PlanningPool(1, 1) as pool:
        there = pool.plan(_job(config, rod, start, goal))
    assert there.status is PlanningStatus.SOLVED and here.actions
    assert there.validated and not here.validated  # VAL ran in the worker
    assert (there.actions, there.expected_states, there.steps, there.task) == (
        here.actions, here.expected_states, here.steps, here.task)


def test_states_travel_as_the_first_and_differences_in_small_frames(config):
    rod = make_object("rod", "absolute", 120, 12)  # 7,500 atoms a state, most of them static
    start, goal = [0] * 120, [30 * (i % 12) for i in range(120)]
    outcome = pipeline.plan(rod, rod.state(start), rod.configuration_atoms(goal), config, defer_validation=True)
    frames = list(pack_outcome(outcome))
    back = unpack_outcome(iter(frames))
    assert (back.expected_states, back.actions, back.steps) == (outcome.expected_states, outcome.actions, outcome.steps)
    states_only = list(pack_outcome(replace(outcome, actions=())))
    assert sum(map(len, states_only)) < 0.5 * len(pickle.dumps(tuple(outcome.expected_states)))  # each state whole
    assert len(frames) > 10 and max(map(len, frames)) < 100 * ATOMS_PER_FRAME  # no frame unpickles for long


@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(formulation=st.sampled_from(["relative", "absolute", "bimanual"]), links=st.integers(3, 6),
       k=st.sampled_from([4, 8, 12]), data=st.data())
def test_the_outcome_comes_back_equal_with_its_states_made_on_the_initial_state(config, formulation, links, k,
                                                                                   data):
    """Any small object of each formulation: the unpacked outcome equals the packed one (actions, expected states),
    its first state is the initial state given to `unpack_outcome` (not a copy), and states sent without their
    actions (compared whole) come back equal too."""
    obj = make_object("o", formulation, links, k)
    angles = st.lists(st.sampled_from(obj.orientation_degrees), min_size=obj.n_joints, max_size=obj.n_joints)
    init, goal = obj.state(data.draw(angles)), obj.configuration_atoms(data.draw(angles))
    outcome = pipeline.plan(obj, init, goal, config, defer_validation=True)
    assert outcome.solved, outcome.message
    back = unpack_outcome(pack_outcome(outcome), init)
    assert (back.actions, back.expected_states, back.steps) == (outcome.actions, outcome.expected_states,
                                                              outcome.steps)
    assert not outcome.expected_states or back.expected_states[0] is init
    bare = replace(outcome, actions=())
    assert unpack_outcome(pack_outcome(bare)).expected_states == outcome.expected_states


def test_a_huge_outcome_is_frozen_out_of_the_collectors_full_passes(config, monkeypatch):
    """An outcome whose expected states hold FREEZE_ATOMS atoms or more is frozen once unpacked (`gc.freeze`): the
    collector's full passes, which hold the interpreter, would walk it after every few thousand allocations; a
    smaller one is not."""
    import gc

    import planhrc.kb_service.planning_pool as planning_pool

    rod = make_object("rod", "absolute", 8, 8)
    start, goal = [45 * (i % 8) for i in range(8)], [(90 + 45 * i) % 360 for i in range(8)]
    try:
        with PlanningPool(1, 1) as pool:
            frozen = gc.get_freeze_count()
            assert pool.plan(_job(config, rod, start, goal)).status is PlanningStatus.SOLVED
            assert gc.get_freeze_count() == frozen  # small: left to the collector
            monkeypatch.setattr(planning_pool, "FREEZE_ATOMS", 1)
            outcome = pool.plan(_job(config, rod, start, goal))
            assert outcome.status is PlanningStatus.SOLVED and gc.get_freeze_count() > frozen
            assert gc.isenabled()
    finally:
        gc.unfreeze()


def test_the_pool_survives_a_worker_that_dies_mid_plan(config):
    big = make_object("big", "absolute", 120, 12)
    small = make_object("small", "absolute", 4, 12)
    with PlanningPool(1, 1) as pool:
        assert pool.plan(_job(config, small, [0] * 4, [90, 0, 0, 30])).solved  # the worker is up
        (pid,) = pool.pids()
        killer = threading.Timer(1.0, os.kill, (pid, signal.SIGKILL))
        killer.start()
        t = time.monotonic()
        died = pool.plan(_job(config, big, [0] * 120, [30 * (i % 12) for i in range(120)], deadline_s=30))
        killer.join()
        assert died.status is PlanningStatus.ERROR and "stopped" in died.message, died.message
        assert time.monotonic() - t < 10
        again = pool.plan(_job(config, small, [0] * 4, [0, 90, 0, 30]))
        assert again.solved, again.message
        assert pool.pids() and pool.pids() != (pid,)
    assert not alive(pid)


def test_a_worker_keeps_the_deadline_and_stays(config):
    """The worker's pipeline stops at the job's deadline and answers `timeout`; the same worker takes the next job."""
    big = make_object("big", "absolute", 200, 12)
    small = make_object("small", "absolute", 4, 12)
    with PlanningPool(1, 1, grace_s=5.0) as pool:
        assert pool.plan(_job(config, small, [0] * 4, [90, 0, 0, 30])).solved
        pids = pool.pids()
        t = time.monotonic()
        late = pool.plan(_job(config, big, [0] * 200, [30 * (i % 12) for i in range(200)], deadline_s=1.0))
        assert late.status is PlanningStatus.TIMEOUT, late.message
        assert time.monotonic() - t < 1.0 + 5.0
        assert pool.plan(_job(config, small, [0] * 4, [0, 90, 0, 30])).solved
        assert pool.pids() == pids


def test_a_worker_past_the_deadline_and_its_grace_is_stopped_and_replaced(config):
    """A worker that does not answer (here: stopped with SIGSTOP) is killed once the deadline and the grace have
    passed; the job ends `timeout` and the next job gets a new worker."""
    small = make_object("small", "absolute", 4, 12)
    with PlanningPool(1, 1, grace_s=0.5) as pool:
        assert pool.plan(_job(config, small, [0] * 4, [90, 0, 0, 30])).solved
        (pid,) = pool.pids()
        os.kill(pid, signal.SIGSTOP)
        t = time.monotonic()
        stuck = pool.plan(_job(config, small, [0] * 4, [0, 90, 0, 30], deadline_s=1.0))
        assert stuck.status is PlanningStatus.TIMEOUT and "worker was stopped" in stuck.message, stuck.message
        assert 1.0 <= time.monotonic() - t < 3.0
        assert pool.plan(_job(config, small, [0] * 4, [0, 90, 0, 30])).solved
        assert pool.pids() != (pid,)
        deadline = time.monotonic() + 5
        while alive(pid) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert not alive(pid)


def test_a_closed_pool_has_no_process_left_and_takes_nothing(config):
    small = make_object("small", "absolute", 4, 12)
    pool = PlanningPool(2, 1)
    assert pool.plan(_job(config, small, [0] * 4, [90, 0, 0, 30])).solved
    pids = pool.pids()
    pool.close()
    assert pids and not any(alive(p) for p in pids)
    assert not pool.takes(small)
    assert pool.plan(_job(config, small, [0] * 4, [90, 0, 0, 30])).status is PlanningStatus.ERROR


def test_only_large_tasks_go_to_the_pool():
    pool = PlanningPool(2, make_settings().planning_pool_min_atoms)
    assert state_size(make_object("r", "relative", 20, 12)) == 69
    assert not pool.takes(make_object("r", "relative", 20, 12))
    assert pool.takes(make_object("a", "absolute", 20, 12))
    assert not PlanningPool(0, 1).takes(make_object("a", "absolute", 20, 12))


def test_a_warm_up_grounds_the_objects_task_so_a_replan_from_another_state_grounds_nothing(config):
    from planhrc.planner import inproc

    rod = make_object("rod", "absolute", 30, 12)
    goal = rod.configuration_atoms([30 * (i % 12) for i in range(30)])
    inproc.forget()
    warmed = pipeline.warm_up(pipeline.warm_up_job(rod, goal, config, time.monotonic() + 60))
    assert warmed.solved and not warmed.actions and not warmed.expected_states and warmed.task is None
    grounded = inproc._recognised_cached.cache_info()
    assert grounded.misses == 1
    found = pipeline.find_plan(rod, rod.state([90] * 30), goal, config)
    assert isinstance(found, pipeline.Found) and found.steps
    assert inproc._recognised_cached.cache_info().misses == grounded.misses  # the warm-up's grounding, used
    # a goal the first configuration already holds: warmed from the second one
    zeros = rod.configuration_atoms([0] * 30)
    assert not pipeline.warm_up_job(rod, zeros, config, time.monotonic() + 60).init >= zeros


def test_an_objects_next_job_waits_for_the_worker_warming_up_for_it_and_a_warm_worker_is_not_warmed_again(config):
    rod = make_object("rod", "absolute", 30, 12)
    goal = [30 * (i % 12) for i in range(30)]
    with PlanningPool(2, 1) as pool:
        pool.warm(pipeline.warm_up_job(rod, rod.configuration_atoms(goal), config, time.monotonic() + 60))
        (pid,) = pool.pids()  # started for the warm-up, which is still importing the pipeline
        assert pool.plan(_job(config, rod, [90] * 30, goal, deadline_s=60)).solved
        assert pool.pids() == (pid,)  # the job took the warming worker, not a second, cold one
        pool.warm(pipeline.warm_up_job(rod, rod.configuration_atoms(goal), config, time.monotonic() + 60))
        other = make_object("other", "absolute", 30, 12)
        assert pool.plan(_job(config, other, [0] * 30, goal, deadline_s=60)).solved
        assert pool.pids() == (pid,)  # the worker that planned `rod` was not taken by a second warm-up


def test_a_large_objects_goal_starts_a_worker_warming_up_before_any_perception(tmp_path):
    from fastapi.testclient import TestClient

    from planhrc.kb_service.app import create_app

    settings = make_settings(db_path=str(tmp_path / "kb.sqlite3"), token=None, planning_workers=1)
    with TestClient(create_app(settings)) as client:
        pool = client.app.state.context.pool
        made = []
        for formulation, links in (("relative", 4), ("absolute", 30)):
            r = client.post("/objects", json={"name": formulation, "links": links, "orientations": 12,
                                              "formulation": formulation})
            assert r.status_code == 201, r.text
            made.append(r.json()["id"])
            r = client.put(f"/objects/{made[-1]}/goal", json={"link_orientations_deg": [30.0] * links})
            assert r.status_code == 200, r.text
            assert len(pool.pids()) == (0 if formulation == "relative" else 1)  # a small object's goal: no worker
        (pid,) = pool.pids()
        r = client.post(f"/objects/{made[1]}/perceptions", json={"link_orientations_deg": [0.0] * 30})
        assert r.status_code == 200 and r.json()["decision"] == "replan", r.text
        assert pool.pids() == (pid,)


def test_a_planning_process_collects_after_each_job_and_everything_every_hundred():
    """The collector is off during a job; after it the young generations are collected, and every generation
    after every FULL_COLLECT_JOBS-th job (the grounded tasks a worker keeps are walked only then)."""
    import gc

    from planhrc.kb_service.planning_pool import FULL_COLLECT_JOBS, JobCollector

    collector = JobCollector()
    assert gc.isenabled()
    young, old = gc.get_stats()[1]["collections"], gc.get_stats()[2]["collections"]
    for _ in range(FULL_COLLECT_JOBS - 1):
        with collector.job():
            assert not gc.isenabled()
    assert gc.isenabled()
    assert gc.get_stats()[1]["collections"] - young >= FULL_COLLECT_JOBS - 1
    full_before = gc.get_stats()[2]["collections"]
    with pytest.raises(RuntimeError):
        with collector.job():  # a job that fails is still followed by its collection, the collector back on
            raise RuntimeError("planning failed")
    assert gc.isenabled() and collector.done == FULL_COLLECT_JOBS
    assert gc.get_stats()[2]["collections"] == full_before + 1 and full_before >= old

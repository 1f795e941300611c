"""VAL as a process the caller does not wait on (`planner.validate.ValRun`) and VAL processes armed ahead of need
(`planner.armed`): the same verdicts as a plain run, each with the CPU its run used, nothing left behind, nothing
outliving its owner."""
from __future__ import annotations

import os
import resource
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from planhrc.model import make_object
from planhrc.planner import get_planner
from planhrc.planner.armed import ArmedValidators
from planhrc.planner.errors import PlannerError
from planhrc.planner.validate import keep_off_this_cpu, start_validation, validate_pieces, validate_plan
from planhrc.translator.problem import get_problem
from tests.processes import alive, left_alive, pids_of_a_killed_owner

DATA = Path(__file__).parent / "data"
DOMAIN = (DATA / "domain-relative.pddl").read_text()
PAPER_ABSOLUTE = (DATA / "domain-absolute-paper.pddl").read_text()


def _task(formulation: str = "relative", links: int = 6, k: int = 8) -> tuple[str, list[str]]:
    obj = make_object("obj1", formulation, links, k)
    n = obj.n_joints
    problem = get_problem(obj, obj.configuration_atoms([0] * n),
                          obj.configuration_atoms([(45 * (i + 1)) % 360 for i in range(n)]), "t")
    domain = DOMAIN if formulation == "relative" else PAPER_ABSOLUTE
    plan = list(get_planner("inproc").solve(domain, problem, 10).plan)
    assert plan
    return problem, plan


def _scratch_files() -> set[str]:
    return {p for p in os.listdir("/dev/shm") if p.startswith("planhrc-val")} if os.path.isdir("/dev/shm") else set()


def test_a_run_answers_later_and_as_a_plain_run_does():
    problem, plan = _task()
    run = start_validation(DOMAIN, problem, plan)
    first = run.verdict(0)  # asked at once: VAL has hardly started
    final = run.verdict(None)
    assert final is not None and final.valid
    assert first is None or first.valid
    assert run.verdict(0) is final  # asked again: the same answer
    wrong = start_validation(DOMAIN, problem, plan[:-1]).verdict(None)
    assert wrong is not None and not wrong.valid
    assert wrong.reason == validate_plan(DOMAIN, problem, plan[:-1]).reason
    assert "Goal not satisfied" in wrong.reason


def _children_cpu_s() -> float:
    used = resource.getrusage(resource.RUSAGE_CHILDREN)  # the children this process has waited for
    return used.ru_utime + used.ru_stime


def test_a_verdict_says_the_cpu_its_run_used():
    """A cold run's CPU is all its process used (this process's count of its reaped children grows by as much); an
    armed run's leaves out what VAL spent before it was given the plan (its start-up and the domain)."""
    problem, plan = _task("absolute")
    for steps in (plan, plan[:-1]):  # accepted and refused (the verbose run for the reason is not counted)
        before = _children_cpu_s()
        run = start_validation(PAPER_ABSOLUTE, problem, steps)
        verdict = run.verdict(None)
        assert run._proc.returncode is not None and verdict.valid == (steps == plan)
        if verdict.valid:
            assert abs(verdict.cpu_s - (_children_cpu_s() - before)) < 1e-5, verdict
        else:
            assert 0 < verdict.cpu_s < _children_cpu_s() - before  # the verbose run came after
    armed = ArmedValidators(arm_delay_s=0.0, forking=False)
    try:
        armed.start(PAPER_ABSOLUTE, problem, plan).verdict(None)
        _armed_once(armed, PAPER_ABSOLUTE)
        before = _children_cpu_s()
        verdict = armed.start(PAPER_ABSOLUTE, problem, plan).verdict(None)
        whole = _children_cpu_s() - before
        assert armed.counts["armed"] == 1 and verdict.valid
        assert 0 < verdict.cpu_s < whole, (verdict.cpu_s, whole)  # the process's CPU less its start-up
    finally:
        armed.close()
    before = _children_cpu_s()
    pieces = validate_pieces(PAPER_ABSOLUTE, [(problem, plan), (problem, plan)])  # two runs: their CPU together
    assert pieces.valid and abs(pieces.cpu_s - (_children_cpu_s() - before)) < 2e-5, pieces


def test_a_run_past_its_time_limit_is_killed_and_leaves_no_files():
    before = _scratch_files()
    problem, plan = _task("absolute", 12, 8)
    run = start_validation(PAPER_ABSOLUTE, problem, plan)
    pid = run.pid
    with pytest.raises(PlannerError, match="did not finish within"):
        run.result(0.0005)
    assert not alive(pid)
    # this run's scratch folder is gone (another process on the machine may have its own meanwhile)
    assert run._tmp is not None and os.path.basename(run._tmp) not in before
    assert not os.path.exists(run._tmp) and os.path.basename(run._tmp) not in _scratch_files()


def test_a_started_run_is_kept_off_the_callers_cpu_until_the_caller_waits():
    if len(os.sched_getaffinity(0)) < 2:
        pytest.skip("one CPU: nothing to keep off")
    proc = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(5)"])
    try:
        release = keep_off_this_cpu(proc.pid)
        assert release is not None
        kept = os.sched_getaffinity(proc.pid)
        assert kept and kept < os.sched_getaffinity(0)
        release()
        assert os.sched_getaffinity(proc.pid) == os.sched_getaffinity(0)
    finally:
        proc.kill()
        proc.wait()


def _armed_once(armed: ArmedValidators, domain: str) -> None:
    """Wait until `armed` holds its processes for `domain`, each waiting for its problem."""
    deadline = time.monotonic() + 20
    while armed.armed_count(domain) < armed.per_domain:
        assert time.monotonic() < deadline, "no VAL process was armed"
        time.sleep(0.01)


@pytest.mark.parametrize("formulation", ["relative", "absolute"])
def test_an_armed_process_gives_the_verdict_of_a_cold_run(formulation):
    domain = DOMAIN if formulation == "relative" else PAPER_ABSOLUTE
    problem, plan = _task(formulation)
    armed = ArmedValidators(arm_delay_s=0.0, forking=False)
    try:
        assert armed.start(domain, problem, plan).verdict(None).valid  # cold: nothing armed yet
        assert armed.counts == {"forked": 0, "past": 0, "armed": 0, "cold": 1}
        _armed_once(armed, domain)
        good = armed.start(domain, problem, plan).verdict(None)
        _armed_once(armed, domain)
        bad = armed.start(domain, problem, plan[:-1]).verdict(None)
        assert armed.counts == {"forked": 0, "past": 0, "armed": 2, "cold": 1}
        assert good.valid
        assert not bad.valid and bad.reason == validate_plan(domain, problem, plan[:-1]).reason
    finally:
        armed.close()


def test_closing_ends_every_armed_process_and_removes_its_files():
    before = _scratch_files()
    problem, plan = _task()
    armed = ArmedValidators(arm_delay_s=0.0, forking=False)
    armed.start(DOMAIN, problem, plan).verdict(None)
    _armed_once(armed, DOMAIN)
    pids = [a.proc.pid for runs in armed._armed.values() for a in runs]
    assert len(pids) == armed.per_domain
    assert pids and all(alive(p) for p in pids)
    armed.close()
    assert not any(alive(p) for p in pids)
    assert _scratch_files() == before
    assert armed.start(DOMAIN, problem, plan).verdict(None).valid  # after close: cold runs, nothing armed again
    assert armed.armed_count() == 0


def test_an_armed_process_that_died_is_replaced_by_a_cold_run():
    problem, plan = _task()
    armed = ArmedValidators(arm_delay_s=0.0, forking=False)
    try:
        armed.start(DOMAIN, problem, plan).verdict(None)
        _armed_once(armed, DOMAIN)
        for runs in armed._armed.values():
            for a in runs:
                os.kill(a.proc.pid, signal.SIGKILL)
                a.proc.wait()
        assert armed.start(DOMAIN, problem, plan[:-1]).verdict(None).valid is False
        assert armed.counts["cold"] == 2 and armed.counts["armed"] == 0
    finally:
        armed.close()


def test_an_armed_process_does_not_outlive_its_owner_killed_with_sigkill(tmp_path):
    """The owner holds the FIFO VAL waits on: when the owner dies, VAL reads end-of-file and exits."""
    problem, plan = _task()
    (tmp_path / "p.pddl").write_text(problem)
    script = textwrap.dedent(f"""
        import sys, time
        from pathlib import Path
        from planhrc.planner.armed import ArmedValidators
        domain = Path({str(DATA / "domain-relative.pddl")!r}).read_text()
        problem = Path({str(tmp_path / "p.pddl")!r}).read_text()
        armed = ArmedValidators(arm_delay_s=0.0, forking=False)
        armed.start(domain, problem, {plan!r}).verdict(None)
        while armed.armed_count() < armed.per_domain:
            time.sleep(0.01)
        print(*[a.proc.pid for runs in armed._armed.values() for a in runs], flush=True)
        time.sleep(60)
    """)
    assert not left_alive(pids_of_a_killed_owner(script)), "an armed VAL process outlived its owner"


def test_an_armed_process_does_not_outlive_an_owner_killed_before_it_reached_the_fifo(tmp_path):
    """An owner killed while its VAL still reads the domain: VAL, opening the FIFO afterwards through the owner's
    descriptor, finds it gone and exits (opening the FIFO by its name, it would wait for a writer for ever)."""
    head, _, actions = DOMAIN.partition("  (:action ")
    body = "  (:action " + actions.rstrip()[:-1]  # the actions, without the domain's closing parenthesis
    copies = "".join(body.replace("(:action rotate", f"(:action r{i}-rotate") + "\n" for i in range(3000))
    big = tmp_path / "big-domain.pddl"
    big.write_text(head + copies + ")\n")  # VAL takes a tenth of a second or so to read it
    script = textwrap.dedent(f"""
        import os, signal, tempfile
        from pathlib import Path
        from planhrc.planner.armed import _Armed
        armed = _Armed(Path({str(big)!r}).read_text(), tempfile.mkdtemp(dir={str(tmp_path)!r}), "a")
        print(armed.proc.pid, flush=True)
        os.kill(os.getpid(), signal.SIGKILL)  # before VAL has read the domain
    """)
    owner = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, text=True)
    try:
        pid = int(owner.stdout.readline())
    finally:
        owner.wait()
    assert owner.returncode == -signal.SIGKILL
    deadline = time.monotonic() + 10
    while alive(pid) and time.monotonic() < deadline:
        time.sleep(0.05)
    if alive(pid):
        os.kill(pid, signal.SIGKILL)
        raise AssertionError("an armed VAL process outlived an owner killed before VAL opened the FIFO")


def test_a_val_process_cannot_take_the_hosts_memory():
    """VAL grounds quantified effects instance by instance: its address space is capped, so a check too large for
    the cap ends without a verdict instead of exhausting the machine."""
    from planhrc.planner.validate import VAL_ADDRESS_SPACE_BYTES

    problem, plan = _task()
    run = start_validation(DOMAIN, problem, plan)
    with open(f"/proc/{run.pid}/limits") as f:
        line = next(l for l in f if l.startswith("Max address space"))
    assert line.split()[3] == str(VAL_ADDRESS_SPACE_BYTES)
    assert run.result(30).valid

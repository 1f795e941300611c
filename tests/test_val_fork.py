"""VAL's fork server (`planner.valfork`): its runs write what `Validate` started on its own writes, with the same exit
code, from VAL's start-up or from past a domain; the CPU the server gives after a run's status is what the kernel
counted for the run; a cancelled or killed run leaves the server serving; nothing outlives the owner; without a C
compiler the checks go on as before."""
from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from planhrc.planner.armed import ArmedValidators
from planhrc.planner.errors import PlannerError
from planhrc.planner.validate import (VAL_ADDRESS_SPACE_BYTES, VAL_FILES, ValRun, plan_text, val_env,
                                      validate_binary)
from planhrc.planner.valfork import ForkedProcess, ForkServer, ForkServerError, library
from tests.processes import alive, left_alive, pids_of_a_killed_owner, reaped_cpu_s
from tests.test_val_runs import DOMAIN, PAPER_ABSOLUTE, _task

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux") or shutil.which("cc") is None,
                                reason="the fork server needs Linux (glibc) and a C compiler")


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    forks = ForkServer.start(tmp_path_factory.mktemp("valfork-cache"))  # compiled afresh, as on a new machine
    assert forks is not None, "no fork server although there is a C compiler"
    yield forks
    forks.close()


def _files(folder: Path, domain: str, problem: str, plan: list[str]) -> list[str]:
    folder.mkdir(exist_ok=True)
    files = [str(folder / name) for name in VAL_FILES]
    for path, text in zip(files, (domain, problem, plan_text(plan))):
        Path(path).write_text(text)
    return files


def _forked(server: ForkServer, files: list[str]) -> tuple[bytes, int]:
    output, proc = _forked_run(server, files)
    assert proc.returncode is not None
    return output, proc.returncode


def _forked_run(server: ForkServer, files: list[str]) -> tuple[bytes, ForkedProcess]:
    """A run's own output (its status taken off) and the run, settled."""
    proc = server.run(files)
    output = b""
    while chunk := proc.stdout.read(65536):
        output += chunk
    proc.stdout.close()
    return proc.settle(output), proc


def _cold(files: list[str]) -> tuple[bytes, int]:
    binary = validate_binary()
    done = subprocess.run([str(binary), *files], env=val_env(binary), stdout=subprocess.PIPE,
                          stderr=subprocess.STDOUT, timeout=60)
    return done.stdout, done.returncode


@pytest.mark.parametrize("formulation", ["relative", "absolute"])
def test_a_forked_run_writes_what_validate_on_its_own_writes(server, tmp_path, formulation):
    problem, plan = _task(formulation)
    domain = DOMAIN if formulation == "relative" else PAPER_ABSOLUTE
    swapped = [plan[1], plan[0], *plan[2:]] if len(plan) > 2 else plan[:-1]
    for name, steps in (("whole", plan), ("short", plan[:-1]), ("swapped", swapped)):
        files = _files(tmp_path / name, domain, problem, steps)
        forked, cold = _forked(server, files), _cold(files)
        assert forked == cold, name
    assert _cold(_files(tmp_path / "whole", domain, problem, plan))[1] == 0
    assert b"Plan valid" in _forked(server, [str(tmp_path / "whole" / n) for n in VAL_FILES])[0]


@pytest.fixture(scope="module")
def past_servers(tmp_path_factory):
    """A server past each domain of the tests, its domain's file beside it."""
    folder = tmp_path_factory.mktemp("past")
    servers = {}
    for name, text in (("relative", DOMAIN), ("absolute", PAPER_ABSOLUTE)):
        path = folder / f"{name}-domain.pddl"
        path.write_text(text)
        servers[name] = ForkServer.start(domain=str(path))
        assert servers[name] is not None and servers[name].domain == str(path)
    yield servers
    for past in servers.values():
        past.close()


def _past_files(past: ForkServer, folder: Path, problem: str, plan: list[str]) -> list[str]:
    files = _files(folder, "", problem, plan)
    assert past.domain is not None
    os.unlink(files[0])
    files[0] = past.domain
    return files


@pytest.mark.parametrize("formulation", ["relative", "absolute"])
def test_a_run_past_the_domain_writes_what_validate_on_its_own_writes(past_servers, tmp_path, formulation):
    """Right plans, wrong ones, a plan naming an action the domain lacks, a problem VAL cannot parse, a missing
    plan: byte for byte and exit code for exit code what `Validate DOMAIN PROBLEM PLAN` gives (the plan's path
    included, which VAL prints), one run after another on the same server."""
    past = past_servers[formulation]
    problem, plan = _task(formulation)
    swapped = [plan[1], plan[0], *plan[2:]] if len(plan) > 2 else plan[:-1]
    unknown = ["(fly obj1_l1 obj1_l2)", *plan]
    broken = problem.replace("(:init", "(:init (", 1)
    cases = [("whole", problem, plan), ("short", problem, plan[:-1]), ("swapped", problem, swapped),
             ("unknown", problem, unknown), ("broken", broken, plan), ("whole-again", problem, plan)]
    codes = set()
    for name, text, steps in cases:
        files = _past_files(past, tmp_path / name, text, steps)
        forked, cold = _forked(past, files), _cold(files)
        assert forked == cold, name
        codes.add(cold[1])
    files = _past_files(past, tmp_path / "no-plan", problem, plan)
    files[2] = str(tmp_path / "no-such-plan.txt")
    assert _forked(past, files) == _cold(files)
    assert len(codes) > 1 and b"Plan valid" in _forked(past, _past_files(past, tmp_path / "w", problem, plan))[0]


def test_a_server_past_a_domain_refuses_a_run_on_another(past_servers, tmp_path):
    problem, plan = _task()
    other = _files(tmp_path, DOMAIN, problem, plan)  # the same text, another file: not what the server parsed
    with pytest.raises(ForkServerError, match="refused"):
        past_servers["relative"].run(other)
    assert past_servers["relative"].alive()
    assert _forked(past_servers["relative"], _past_files(past_servers["relative"], tmp_path / "ok", problem,
                                                         plan))[1] == 0


def test_a_forked_run_s_status_carries_the_cpu_the_kernel_counted_for_it(server, tmp_path):
    """Each run's CPU, as the server writes it after the run's status, is what the kernel charged to the run: the
    server's own count of its reaped children's CPU (/proc, in clock ticks) grows by the runs' figures together,
    and no run has more CPU than the time from its request to its end (VAL runs on one thread)."""
    problem, plan = _task("absolute", 12, 8)
    files = _files(tmp_path, PAPER_ABSOLUTE, problem, plan)
    before = reaped_cpu_s(server.pid)
    spent = []
    for _ in range(20):
        t = time.perf_counter()
        output, proc = _forked_run(server, files)
        ran = time.perf_counter() - t
        assert proc.returncode == 0 and b"Plan valid" in output and b"planhrc-valfork" not in output
        assert proc.cpu_s is not None and 0 < proc.cpu_s <= ran, (proc.cpu_s, ran)
        spent.append(proc.cpu_s)
    counted = reaped_cpu_s(server.pid) - before
    tick = 1 / os.sysconf("SC_CLK_TCK")  # each of user and system is counted in whole ticks
    assert abs(counted - sum(spent)) <= 2 * tick + 0.002, (counted, sum(spent))


def test_a_status_without_its_cpu_is_a_killed_run_s():
    """`settle` takes only a whole status line (exit code and CPU): anything else is output of a run that was
    killed before the server wrote its status."""
    read_end, write_end = os.pipe()
    os.close(write_end)
    for tail, code, cpu in ((b"\nplanhrc-valfork-status 0 1500\n", 0, 0.0015),
                            (b"\nplanhrc-valfork-status -9 20\n", -9, 0.00002),
                            (b"\nplanhrc-valfork-status 0\n", -signal.SIGKILL, None),
                            (b"\nplanhrc-valfork-status 0 15", -signal.SIGKILL, None)):
        proc = ForkedProcess(0, os.dup(read_end))
        output = proc.settle(b"Plan valid" + tail)
        proc.stdout.close()
        assert (proc.returncode, proc.cpu_s) == (code, cpu), tail
        assert output == (b"Plan valid" if cpu is not None else b"Plan valid" + tail)
    os.close(read_end)


def test_a_run_on_a_missing_file_fails_as_validate_fails(server, tmp_path):
    problem, plan = _task()
    files = _files(tmp_path, DOMAIN, problem, plan)
    files[1] = str(tmp_path / "no-such-problem.pddl")
    forked, cold = _forked(server, files), _cold(files)
    assert forked == cold and cold[1] != 0


def test_cancelled_and_killed_runs_leave_the_server_serving(server, tmp_path):
    problem, plan = _task("absolute", 12, 8)
    for i in range(5):  # cancelled at once: the server writes a status nobody reads (no SIGPIPE for it)
        files = _files(tmp_path / "x", PAPER_ABSOLUTE, problem, plan)
        run = ValRun(server.run(files), files, None)
        pid = run.pid
        if i % 2:
            with pytest.raises(PlannerError, match="did not finish within"):
                run.result(0.0005)  # past its time: the run's group killed
        else:
            run.cancel()
        deadline = time.monotonic() + 10
        while alive(pid) and time.monotonic() < deadline:
            time.sleep(0.01)
        assert not alive(pid)
        assert not any((tmp_path / "x").iterdir())  # the run's files are gone
        (tmp_path / "x").rmdir()
    assert server.alive()
    files = _files(tmp_path, PAPER_ABSOLUTE, problem, plan)
    verdict = ValRun(server.run(files), files, None).result(60)
    assert verdict.valid


def test_a_forked_run_cannot_take_the_hosts_memory(server, tmp_path):
    fifo = tmp_path / "problem.pddl"
    os.mkfifo(fifo)  # no writer: the run waits there, still running when its limits are read
    problem, plan = _task()
    files = _files(tmp_path / "f", DOMAIN, problem, plan)
    files[1] = str(fifo)
    proc = server.run(files)
    try:
        with open(f"/proc/{proc.pid}/limits") as f:
            line = next(l for l in f if l.startswith("Max address space"))
        assert line.split()[3] == str(VAL_ADDRESS_SPACE_BYTES)
    finally:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.stdout.close()


@pytest.mark.parametrize("past", [False, True], ids=["from-start-up", "past-the-domain"])
def test_the_server_and_its_runs_end_with_their_owner_killed_with_sigkill(tmp_path, past):
    """The owner holds the server's socket: when it dies the server reads end-of-file and exits, and a run still
    going (here waiting on a problem nobody writes) dies with the server."""
    problem, plan = _task()
    files = _files(tmp_path, DOMAIN, problem, plan)
    os.unlink(files[1])
    os.mkfifo(files[1])
    script = textwrap.dedent(f"""
        import time
        from planhrc.planner.valfork import ForkServer
        forks = ForkServer.start(domain={files[0]!r} if {past!r} else None)
        proc = forks.run({files!r})
        print(forks.pid, proc.pid, flush=True)
        time.sleep(60)
    """)
    pids = pids_of_a_killed_owner(script)
    assert len(pids) == 2
    assert not left_alive(pids), "the fork server or its run outlived its owner"


def test_checks_run_on_the_fork_server_and_arm_without_a_c_compiler(monkeypatch):
    problem, plan = _task()
    forking = ArmedValidators(arm_delay_s=0.0)
    try:
        assert forking.start(DOMAIN, problem, plan).verdict(None).valid
        assert not forking.start(DOMAIN, problem, plan[:-1]).verdict(None).valid
        assert forking.counts["forked"] + forking.counts["past"] == 2
        assert forking.counts["armed"] == forking.counts["cold"] == 0
        assert forking.armed_count() == 0  # nothing armed beside the servers
        deadline = time.monotonic() + 30
        while forking.past_count() == 0 and time.monotonic() < deadline:  # started off the checks' thread
            time.sleep(0.01)
        assert forking.past_count() == 1
        before = forking.counts["past"]
        assert not forking.start(DOMAIN, problem, plan[1:]).verdict(None).valid
        assert forking.start(DOMAIN, problem, plan).verdict(None).valid
        assert forking.counts["past"] == before + 2  # once the domain's server is up, its checks run past it
    finally:
        forking.close()
    monkeypatch.setattr("planhrc.planner.valfork.library", lambda folder=None: None)
    armed = ArmedValidators(arm_delay_s=0.0)
    try:
        assert armed.start(DOMAIN, problem, plan).verdict(None).valid
        assert armed.counts == {"forked": 0, "past": 0, "armed": 0, "cold": 1} and not armed.forking
    finally:
        armed.close()


def test_without_a_c_compiler_there_is_no_library(monkeypatch, tmp_path):
    monkeypatch.setattr(shutil, "which", lambda name: None)
    assert library(tmp_path) is None
    assert ForkServer.start(tmp_path) is None
    assert not list(tmp_path.iterdir())


def test_a_library_that_fails_to_compile_is_not_kept(monkeypatch, tmp_path):
    bad = tmp_path / "valfork.c"
    bad.write_text("this is not C\n")
    monkeypatch.setattr("planhrc.planner.valfork.SOURCE", bad)
    folder = tmp_path / "cache"
    folder.mkdir()
    assert library(folder) is None
    assert not list(folder.iterdir())


def test_servers_past_many_domains_stay_bounded(monkeypatch):
    """Weeks of domains: at most `max_domains` servers past a domain run at once (the least recently used stopped,
    its domain's file removed), and the starts remembered per domain stay bounded too."""
    from planhrc.planner import armed as armed_module

    forking = ArmedValidators(arm_delay_s=0.0, max_domains=2)
    try:
        domains = [DOMAIN.replace("(domain ", f"(domain d{i}-", 1) for i in range(3)]
        for domain in domains:
            forking._start_past(domain)
        assert forking.past_count() == 2
        assert sorted(p.domain is not None and os.path.exists(p.domain) for p in forking._past.values()) == [True] * 2
        files = {p.domain for p in forking._past.values()}
        monkeypatch.setattr(armed_module.ForkServer, "start", classmethod(lambda cls, folder=None, domain=None: None))
        for i in range(armed_module.PAST_STARTS_KEPT + 20):  # no server can be had for these: nothing left behind
            forking._start_past(f"(define (domain many-{i}))")
        assert len(forking._past_starts) == armed_module.PAST_STARTS_KEPT
        assert forking.past_count() == 2 and {p.domain for p in forking._past.values()} == files
        assert sorted(os.listdir(os.path.dirname(next(iter(files))))) == sorted(os.path.basename(f) for f in files)
    finally:
        forking.close()


def test_checks_go_on_when_the_fork_servers_are_killed():
    """Both servers killed (SIGKILL): the next check is refused by neither, it runs cold and gives VAL's verdict;
    the checks after it have their servers again."""
    problem, plan = _task()
    forking = ArmedValidators(arm_delay_s=0.0)
    try:
        assert forking.start(DOMAIN, problem, plan).verdict(None).valid
        deadline = time.monotonic() + 30
        while forking.past_count() == 0 and time.monotonic() < deadline:
            time.sleep(0.01)
        servers = [forking._forks, *forking._past.values()]
        assert len(servers) == 2 and all(s is not None for s in servers)
        for killed in servers:
            os.kill(killed.pid, signal.SIGKILL)
            killed._proc.wait()
        before = dict(forking.counts)
        assert not forking.start(DOMAIN, problem, plan[:-1]).verdict(None).valid  # refused by VAL, not by a server
        assert forking.counts["cold"] == before["cold"] + 1 and forking.past_count() == 0
        assert forking.start(DOMAIN, problem, plan).verdict(None).valid
        assert forking.counts["forked"] + forking.counts["past"] == before["forked"] + before["past"] + 1
    finally:
        forking.close()

"""VAL started ahead of need (`ArmedValidators`): a fork server whose runs skip VAL's start-up (`planner.valfork`),
and per domain in use a fork server past that domain, whose runs skip its parse as well; or, where there is no
fork server (no C compiler), VAL processes that have each read their domain and wait for a problem.

A domain's first checks run on the plain fork server while its own server starts off the request's path (the
arming thread); from then on its checks are runs of that server, which reads only their problem and plan (VAL spends
most of a short check's CPU lexing its input; past the domain, one turn of a bimanual 6 x 24 object's narrowed piece
took 0.8 ms of VAL's CPU against 1.3 ms, `tests/test_val_fork.py` comparing the outputs byte for byte).

A cold VAL run spends most of a short check before it reads the problem: starting the process, loading its
libraries and parsing the domain (about half of a relative 20 x 12 check's CPU time, by `perf stat`). A
service re-plans the same few domains all day, so it keeps one VAL process per domain already past that point:
`Validate DOMAIN PROBLEM PLAN` started with the domain a file, the problem a named pipe (FIFO) and the plan a
path that does not exist yet. VAL reads its arguments in order, so it parses the domain, opens the FIFO and
blocks reading it. A check then writes the plan file and the problem into the FIFO, and the process is an
ordinary `ValRun` from there: the same binary, the same three inputs, the same verdict as a cold run.

This process holds the FIFO open for reading and writing from the start, and VAL opens it through that descriptor
(`/proc/<this process>/fd/<n>`), so VAL's `open` does not wait; if this process dies (even by SIGKILL), VAL either
reads end-of-file instead of a problem or, not at the FIFO yet, finds the path gone, and exits: an armed VAL never
outlives its service. After one is used, another is armed for that domain by a background thread `ARM_DELAY_S`
later, off the request's path; a check that finds none armed (back-to-back re-plans, a new domain) starts a
cold run. Linux only (named pipes and /proc); elsewhere every run is cold.
"""
from __future__ import annotations

import logging
import os
import tempfile
import threading
import time
from collections import OrderedDict
from typing import Sequence

from .process import kill_group
from .validate import VAL_FILES, ValRun, plan_text, remove_files, scratch_dir, spawn_val, start_validation, write_file
from .valfork import ForkServer

log = logging.getLogger(__name__)

ARM_DELAY_S = 0.05  # a new process is armed this long after one was used: after the answer, not during the request
MAX_DOMAINS = 4  # domains kept armed at once (the least recently used one is dropped)
READY_WAIT_S = 2.0  # how long the arming thread watches a new process reach its problem
FIRST_LOOK_S = 0.004  # the arming thread's first look at a new process, a little after VAL has read a short domain
FORK_SERVER_STARTS = 3  # a fork server that went away is started again this many times at most, then checks arm
PAST_STARTS_KEPT = 64  # domains whose servers past them were started, remembered (a count each) to stop retrying


class _Armed:
    """One VAL process that has parsed `domain` and waits for its problem on a FIFO; its files are `<prefix>-`
    domain.pddl, problem.pddl and plan.txt in the folder `folder`, which outlives it (removing a folder costs the
    kernel far more than removing its files, on the request's path)."""

    def __init__(self, domain: str, folder: str, prefix: str) -> None:
        self.files = [os.path.join(folder, f"{prefix}-{name}") for name in VAL_FILES]
        self.fifo_fd: int | None = None
        self.confirmed = False  # seen waiting for its problem (`wait_ready`)
        try:
            write_file(self.files[0], domain)
            os.mkfifo(self.files[1], 0o600)
            # read and write: VAL's open does not wait for a writer, and VAL sees end-of-file if this process dies
            self.fifo_fd = os.open(self.files[1], os.O_RDWR)
            # VAL opens the FIFO through this process's descriptor: should this process die before VAL gets there
            # (VAL still reading the domain), the path is gone and VAL stops, where opening the FIFO itself would
            # wait for a writer for ever
            held = f"/proc/{os.getpid()}/fd/{self.fifo_fd}"
            self.proc = spawn_val((self.files[0], held, self.files[2]), folder)
        except BaseException:
            self.discard()
            raise

    def wait_ready(self, timeout_s: float) -> bool:
        """Wait until VAL has the FIFO open, up to `timeout_s`: done by the arming thread, so that a check finds it
        `confirmed` and feeds it without looking again. Each look reads the process's descriptors in /proc, so the
        looks are spaced out more and more (`FIRST_LOOK_S`, doubling): VAL usually gets there before the first."""
        end = time.monotonic() + timeout_s
        pause = FIRST_LOOK_S
        while True:
            time.sleep(min(pause, max(0.0, end - time.monotonic())))
            if self.ready():
                self.confirmed = True
                return True
            if self.proc.poll() is not None or time.monotonic() >= end:
                return False
            pause *= 2

    def ready(self) -> bool:
        """VAL runs and has the FIFO open (it has parsed the domain and waits for the problem)."""
        if self.proc.poll() is not None:
            return False
        if self.confirmed:  # it waits for the problem until it gets it
            return True
        target = os.stat(self.files[1])
        try:
            fds = os.listdir(f"/proc/{self.proc.pid}/fd")
        except OSError:
            return False
        for fd in fds:
            try:
                st = os.stat(f"/proc/{self.proc.pid}/fd/{fd}")
            except OSError:
                continue
            if (st.st_dev, st.st_ino) == (target.st_dev, target.st_ino):
                return True
        return False

    def feed(self, problem: str, plan: Sequence[str], nice: int) -> ValRun:
        """Give VAL its plan and problem: from now on the run is an ordinary `ValRun`, whose CPU leaves out what
        VAL spent before (its start-up and the domain, done ahead of the request)."""
        assert self.fifo_fd is not None
        spent = cpu_so_far(self.proc.pid)  # VAL waits on the FIFO: nothing more until the problem comes
        write_file(self.files[2], plan_text(plan))  # a plain file, complete before VAL opens it (after the problem)
        data = memoryview(problem.encode())
        fd, self.fifo_fd = self.fifo_fd, None
        try:
            while data:  # VAL reads as this writes: a problem larger than the pipe's buffer just takes turns
                data = data[os.write(fd, data):]
        finally:
            os.close(fd)  # the only writer gone: VAL reads end-of-file after the problem
        return ValRun(self.proc, self.files, None, nice=nice, piped_problem=problem, spent_s=spent)

    def discard(self) -> None:
        """Stop the process (if any) and remove the files."""
        if self.fifo_fd is not None:
            os.close(self.fifo_fd)
            self.fifo_fd = None
        proc = getattr(self, "proc", None)
        if proc is not None and proc.poll() is None:
            kill_group(proc.pid)
            proc.wait()
        if proc is not None and proc.stdout is not None:
            proc.stdout.close()
        remove_files(self.files, None)


def cpu_so_far(pid: int) -> float | None:
    """The CPU seconds process `pid` (one thread) has run, to the nanosecond (Linux: /proc/PID/schedstat's first
    field, the count `wait4` later reports in user + system); None when it cannot be read, or reads 0 (a kernel
    without scheduler statistics), for a process that has certainly run."""
    try:
        with open(f"/proc/{pid}/schedstat", "rb") as f:
            ns = int(f.read().split()[0])
    except (OSError, ValueError, IndexError):
        return None
    return ns / 1e9 if ns > 0 else None


class ArmedValidators:
    """VAL started ahead of need for `start` to use: a fork server (`planner.valfork`) when one can be had here,
    its runs past VAL's start-up whatever the domain; else VAL processes armed per domain, `per_domain` of each (a
    plan's first motion may be checked in that many pieces at once). `close()` stops them (the service's
    shutdown).

    Thread-safe: requests of several objects may start checks at once; one background thread arms."""

    def __init__(self, arm_delay_s: float = ARM_DELAY_S, max_domains: int = MAX_DOMAINS, per_domain: int = 2, *,
                 forking: bool = True) -> None:
        self.arm_delay_s = arm_delay_s
        self.max_domains = max_domains
        self.per_domain = max(1, per_domain)
        self.supported = os.name == "posix" and os.path.isdir("/proc/self/fd") and hasattr(os, "mkfifo")
        self._lock = threading.Condition()
        self._armed: OrderedDict[str, list[_Armed]] = OrderedDict()  # domain -> its armed runs, most recent last
        self._closed = False
        self._thread: threading.Thread | None = None
        self._folder: str | None = None  # made with the first armed process, removed by close()
        self._made = 0
        self.counts = {"forked": 0, "past": 0, "armed": 0, "cold": 0}  # checks started by each way
        self.forking = forking and self.supported
        self._forks: ForkServer | None = None
        self._fork_starts = 0
        # fork servers past a domain (`planner.valfork`), most recently used last, and the domains to start one for
        self._past: OrderedDict[str, ForkServer] = OrderedDict()
        self._past_wanted: set[str] = set()
        self._past_starts: OrderedDict[str, int] = OrderedDict()  # the last domains' starts (bounded: weeks of them)

    def start(self, domain: str, problem: str, plan: Sequence[str], *, nice: int = 0) -> ValRun:
        """A VAL run on the plan, on an armed process of `domain` when there is one ready, else started cold;
        either way `domain` is armed again for the next checks."""
        if not self.supported:
            return start_validation(domain, problem, plan, nice=nice)
        forks = self._fork_server()
        if forks is not None:
            past = self._past_server(domain)
            if past is not None:
                run = self._served(past, "past", domain, problem, plan, nice)
                if run is not None:
                    return run
                self._drop_past(domain, past)  # that server went away: the plain one takes the check
            run = self._served(forks, "forked", domain, problem, plan, nice)
            if run is not None:
                return run
            self._drop_fork_server(forks)  # the server went away: started again by the next check
            self._count("cold")
            return start_validation(domain, problem, plan, nice=nice)
        with self._lock:
            if self._closed:
                return start_validation(domain, problem, plan, nice=nice)
            ready = self._armed.pop(domain, [])
            armed = ready.pop(0) if ready else None
            self._armed[domain] = ready  # most recently used; the arming thread fills it up again
            dropped: list[_Armed] = []
            while len(self._armed) > self.max_domains:
                dropped.extend(self._armed.popitem(last=False)[1])
            self._start_thread()
            self._lock.notify_all()
        for old in dropped:
            old.discard()
        if armed is not None:
            if armed.ready():
                try:
                    run = armed.feed(problem, plan, nice)
                    self._count("armed")
                    return run
                except OSError as exc:  # the armed process went away meanwhile: a cold run instead
                    log.warning("an armed VAL process could not take its problem (%s): starting VAL cold", exc)
            armed.discard()
        self._count("cold")
        return start_validation(domain, problem, plan, nice=nice)

    def _fork_server(self) -> ForkServer | None:
        """The fork server, started by the first check that needs it (None: none here, or this is closed)."""
        if not self.forking:
            return None
        with self._lock:
            if self._closed:
                return None
            if self._forks is None and self._fork_starts < FORK_SERVER_STARTS:
                self._fork_starts += 1
                self._forks = ForkServer.start()
                if self._forks is None:  # none can be had here: checks arm processes from now on
                    self.forking = False
            return self._forks

    def _past_server(self, domain: str) -> ForkServer | None:
        """The fork server past `domain`, or None: then one is started for it off the caller's thread, by the
        arming thread (at most `FORK_SERVER_STARTS` times a domain, `max_domains` domains at once)."""
        with self._lock:
            past = self._past.get(domain)
            if past is not None:
                self._past.move_to_end(domain)
                return past
            if not self._closed and self._past_starts.get(domain, 0) < FORK_SERVER_STARTS:
                self._past_wanted.add(domain)
                self._start_thread()
                self._lock.notify_all()
            return None

    def _start_past(self, domain: str) -> None:
        """Start the fork server past `domain` (the arming thread), its domain a file of its own in the runs'
        folder; the least recently used beyond `max_domains` is stopped."""
        with self._lock:
            self._past_wanted.discard(domain)
            if self._closed or domain in self._past:
                return
            self._past_starts[domain] = self._past_starts.get(domain, 0) + 1
            self._past_starts.move_to_end(domain)
            while len(self._past_starts) > PAST_STARTS_KEPT:
                self._past_starts.popitem(last=False)
            path = os.path.join(self._scratch(), f"p{self._made}-domain.pddl")
        try:
            write_file(path, domain)
            past = ForkServer.start(domain=path)
        except Exception as exc:  # no room in the scratch folder...: the plain server takes the checks
            log.warning("could not start VAL's fork server past a domain (%s)", exc)
            past = None
        if past is None:
            remove_files([path], None)
            return
        dropped: list[ForkServer] = []
        with self._lock:
            if self._closed:
                dropped.append(past)
            else:
                self._past[domain] = past
                while len(self._past) > self.max_domains:
                    dropped.append(self._past.popitem(last=False)[1])
        for old in dropped:
            _close_past(old)

    def _drop_past(self, domain: str, past: ForkServer) -> None:
        with self._lock:
            if self._past.get(domain) is past:
                del self._past[domain]
        _close_past(past)

    def _drop_fork_server(self, forks: ForkServer) -> None:
        with self._lock:
            if self._forks is forks:
                self._forks = None
        forks.close()

    def _served(self, forks: ForkServer, kind: str, domain: str, problem: str, plan: Sequence[str], nice: int
                ) -> ValRun | None:
        """A check as a run of `forks`, counted as `kind`; None when that server could not take it."""
        try:
            run = self._forked(forks, domain, problem, plan, nice)
        except OSError as exc:
            log.warning("VAL's fork server (%s) could not take a check (%s)", kind, exc)
            return None
        self._count(kind)
        return run

    def _forked(self, forks: ForkServer, domain: str, problem: str, plan: Sequence[str], nice: int) -> ValRun:
        """A check as a run of the fork server, its files in the folder the armed processes use: all three, or
        the problem and the plan on a server past the domain (whose domain file is the server's)."""
        with self._lock:
            prefix = os.path.join(self._scratch(), f"f{self._made}-")
        shared = () if forks.domain is None else (forks.domain,)  # the server's own domain file: not the run's
        ours = [prefix + name for name in VAL_FILES[len(shared):]]  # written here, removed with the run
        texts = (domain, problem, plan_text(plan))[len(shared):]
        try:
            for path, text in zip(ours, texts):
                write_file(path, text)
            return ValRun(forks.run([*shared, *ours]), [*shared, *ours], None, nice=nice, shared=shared)
        except BaseException:
            remove_files(ours, None)
            raise

    def _scratch(self) -> str:
        """The folder of the runs' files (made by the first run, removed by `close`), one more run counted in
        `_made` for a prefix of its own (with the lock held)."""
        if self._folder is None:
            self._folder = tempfile.mkdtemp(prefix="planhrc-val-armed-", dir=scratch_dir())
        self._made += 1
        return self._folder

    def _count(self, kind: str) -> None:
        with self._lock:
            self.counts[kind] += 1

    def _start_thread(self) -> None:
        if self._thread is None:
            self._thread = threading.Thread(target=self._arm_loop, name="planhrc-val-armer", daemon=True)
            self._thread.start()

    def _missing(self) -> list[str]:
        return [d for d, runs in self._armed.items() for _ in range(self.per_domain - len(runs))]

    def _arm_loop(self) -> None:
        while True:
            with self._lock:
                while not self._closed and not self._missing() and not self._past_wanted:
                    self._lock.wait()
                if self._closed:
                    return
            time.sleep(self.arm_delay_s)  # let the request that used the last one finish first
            with self._lock:
                wanted = self._missing()
                past = list(self._past_wanted)
            for domain in past:
                self._start_past(domain)
            for domain in wanted:
                try:
                    with self._lock:
                        folder, prefix = self._scratch(), f"a{self._made}"
                    armed = _Armed(domain, folder, prefix)
                    armed.wait_ready(READY_WAIT_S)  # not ready by then: the check that takes it looks again
                except Exception as exc:  # no VAL, no room in the scratch folder...: checks start cold
                    log.warning("could not arm a VAL process (%s): checks start VAL cold", exc)
                    with self._lock:
                        self._armed.pop(domain, None)
                    continue
                with self._lock:
                    runs = self._armed.get(domain)
                    keep = not self._closed and runs is not None and len(runs) < self.per_domain
                    if keep and runs is not None:
                        runs.append(armed)
                if not keep:
                    armed.discard()

    def past_count(self) -> int:
        """How many fork servers past a domain run now."""
        with self._lock:
            return len(self._past)

    def armed_count(self, domain: str | None = None) -> int:
        """How many VAL processes are armed now (for `domain`, or for every domain)."""
        with self._lock:
            if domain is not None:
                return len(self._armed.get(domain, ()))
            return sum(len(runs) for runs in self._armed.values())

    def close(self) -> None:
        """Stop arming and end every armed process and the fork server."""
        with self._lock:
            self._closed = True
            armed = [a for runs in self._armed.values() for a in runs]
            self._armed.clear()
            self._lock.notify_all()
            thread = self._thread
            forks, self._forks = self._forks, None
            pasts = list(self._past.values())
            self._past.clear()
            self._past_wanted.clear()
        if forks is not None:
            forks.close()
        for past in pasts:
            _close_past(past)
        if thread is not None:
            thread.join(timeout=10)
        for a in armed:
            a.discard()
        if self._folder is not None:
            remove_files((), self._folder)  # the runs' files went with them; only the folder is left


def _close_past(past: ForkServer) -> None:
    """Stop a fork server past a domain (its runs end with it) and remove its domain's file."""
    past.close()
    if past.domain is not None:
        remove_files([past.domain], None)

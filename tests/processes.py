"""Whether a process still runs, as the tests that kill services and their children look at it, and the CPU of
the children a process has waited for (Linux /proc)."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path


def alive(pid: int) -> bool:
    """The process exists and has not ended (a zombie, Z, or a dead task, X, has)."""
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state not in ("Z", "X")


def reaped_cpu_s(pid: int) -> float:
    """The CPU (user + system) of the children process `pid` has waited for, as the kernel counts it (/proc: in
    whole clock ticks, each of user and system)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[13]) + int(fields[14])) / os.sysconf("SC_CLK_TCK")


def pids_of_a_killed_owner(script: str) -> list[int]:
    """Run `script` in a Python process that prints the pids of processes it started on one line, check they run,
    then kill that owner with SIGKILL; the pids."""
    owner = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, text=True)
    try:
        assert owner.stdout is not None
        pids = [int(p) for p in owner.stdout.readline().split()]
        assert pids and all(alive(p) for p in pids), f"the owner's processes do not run: {pids}"
    finally:
        owner.kill()
        owner.wait()
    return pids


def left_alive(pids: list[int], timeout_s: float = 10.0) -> list[int]:
    """Those of `pids` still running after up to `timeout_s` (killed then, so that no test leaves them behind)."""
    deadline = time.monotonic() + timeout_s
    while any(alive(p) for p in pids) and time.monotonic() < deadline:
        time.sleep(0.05)
    left = [p for p in pids if alive(p)]
    for p in left:
        try:
            os.kill(p, signal.SIGKILL)
        except ProcessLookupError:
            pass
    return left

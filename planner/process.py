"""Run a planner process in its own process group with a wall-clock limit (shared by the external backends)."""
from __future__ import annotations

import importlib.util
import logging
import os
import signal
import subprocess
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from .errors import PlannerError

log = logging.getLogger(__name__)


def installed_file(package: str, relative: str, what: str) -> Path:
    """A file shipped inside an installed Python package (a planner or validator binary, a driver script).

    The package is found, not imported: up_fast_downward's `__init__` imports unified-planning, seconds of work
    that running the driver script does not need."""
    try:
        spec = importlib.util.find_spec(package)
    except (ImportError, ValueError) as exc:  # pragma: no cover - dependency of the project
        raise PlannerError(f"{what}: the {package} package is not installed") from exc
    if spec is None:
        raise PlannerError(f"{what}: the {package} package is not installed")
    if spec.origin is None or not spec.submodule_search_locations:
        raise PlannerError(f"{what}: the {package} package has no files on disk")
    path = Path(spec.origin).resolve().parent / relative
    if not path.is_file():
        raise PlannerError(f"{what}: {relative} not found at {path}")
    return path


@dataclass(frozen=True)
class ProcessOutcome:
    returncode: int | None  # None when killed at the time limit
    stdout: str
    stderr: str

    @property
    def timed_out(self) -> bool:
        return self.returncode is None


def run_limited(cmd: list[str], cwd: str, timeout_s: float, env: dict[str, str] | None = None, *, nice: int = 0,
                on_start: Callable[[int], None] | None = None) -> ProcessOutcome:
    """Run `cmd`; at `timeout_s` kill its whole process group (the planner and everything it started).

    The group is killed too when the caller is interrupted (Ctrl-C, SIGTERM turned into an exception): it runs
    in its own session, so nothing else would stop it. `nice` > 0 lowers the process's priority by that much
    below the caller's (set from here as soon as it exists); `on_start` is given its process group id (to kill
    it from elsewhere)."""
    proc = subprocess.Popen(cmd, cwd=cwd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True)
    try:
        if nice > 0:
            renice(proc.pid, nice)
        if on_start is not None:
            on_start(proc.pid)
        out, err = proc.communicate(timeout=max(timeout_s, 0.001))
        return ProcessOutcome(proc.returncode, out, err)
    except subprocess.TimeoutExpired:
        log.debug("killing process group %d after %.3f s", proc.pid, timeout_s)
        kill_group(proc.pid)
        out, err = proc.communicate()
        return ProcessOutcome(None, out, err)
    except BaseException:
        kill_group(proc.pid)
        proc.wait()
        raise


def renice(pid: int, nice: int) -> None:
    try:
        os.setpriority(os.PRIO_PROCESS, pid, min(19, os.getpriority(os.PRIO_PROCESS, 0) + nice))
    except (ProcessLookupError, PermissionError):  # already gone, or not ours to change: it runs as it is
        pass


def kill_group(pgid: int) -> None:
    try:
        os.killpg(pgid, signal.SIGKILL)
    except ProcessLookupError:
        pass

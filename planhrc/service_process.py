"""`planhrc serve` as a child process on a loopback port: the one way the demo, the benchmarks and the tests start
the service, wait for it to answer and stop it with its whole process group.

It starts the service through its command line only (no import of the service), so the worker's side of the
project (`robot_sim`) can use it too.
"""
from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any, Callable, Iterator, Mapping, Sequence

import httpx

from planhrc.errors import PlanhrcError


class ServiceStartError(PlanhrcError):
    """The child service exited before it answered, or did not answer in time; the message says where its log is."""


class StillWritingError(PlanhrcError):
    """The service still changed its store's counts behind its answers when the wait ended."""


@dataclass(frozen=True)
class RunningService:
    """A started service: its base URL, its process id (the leader of its process group) and its log file."""

    url: str
    pid: int
    log_path: Path | None


def free_port() -> int:
    """A loopback TCP port nobody listens on now."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def serve_command(port: int, db: str | Path, args: Sequence[str] = (), host: str = "127.0.0.1") -> list[str]:
    """The command line of `planhrc serve` on `db` at `host:port`, run by this interpreter."""
    return [sys.executable, "-m", "planhrc.cli", "serve", "--host", host, "--port", str(port), "--db", str(db),
            *args]


def wait_until_serving(proc: subprocess.Popen[bytes], base: str, timeout_s: float = 90,
                       log_path: Path | None = None) -> None:
    """Poll `base`/health until the service answers 200; ServiceStartError (with its log, if given) when the
    process exits first or `timeout_s` passes."""
    deadline = time.monotonic() + timeout_s
    while True:
        if proc.poll() is not None:
            shown = f":\n{log_path.read_text(errors='replace')[-4000:]}" if log_path and log_path.exists() else ""
            raise ServiceStartError(f"planhrc serve exited with {proc.returncode}{shown}")
        try:
            if httpx.get(f"{base}/health", timeout=2).status_code == 200:
                return
        except httpx.TransportError:
            pass
        if time.monotonic() > deadline:
            where = f"; see {log_path}" if log_path else ""
            raise ServiceStartError(f"planhrc serve did not answer /health within {timeout_s:g} s{where}")
        time.sleep(0.05)


_PR_SET_PDEATHSIG = 1


def _bound_prctl() -> Callable[..., int] | None:
    """libc's `prctl`, looked up once in this process (Linux), so that a child between fork and exec only calls it."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        import ctypes

        prctl: Callable[..., int] = ctypes.CDLL(None, use_errno=True).prctl
        return prctl
    except (OSError, AttributeError):
        return None


_PRCTL = _bound_prctl()


def die_with_parent() -> None:
    """`preexec_fn` of a child that must not outlive this process (Linux): it receives SIGTERM when the thread that
    started it ends, which for a child started by a call that waits for it (`subprocess.run`) means when this process
    dies, SIGKILL included. Elsewhere nothing."""
    if _PRCTL is not None:
        _PRCTL(_PR_SET_PDEATHSIG, signal.SIGTERM)


def stop_process_group(proc: subprocess.Popen[bytes], grace_s: float = 15.0) -> None:
    """SIGTERM to the child's process group, SIGKILL after `grace_s`; returns once the child is reaped."""
    for sig, wait_s in ((signal.SIGTERM, grace_s), (signal.SIGKILL, None)):
        try:
            os.killpg(proc.pid, sig)
        except ProcessLookupError:
            break
        try:
            proc.wait(timeout=wait_s)
            break
        except subprocess.TimeoutExpired:
            continue
    proc.wait()


@contextmanager
def running_service(db: str | Path, *, port: int | None = None, args: Sequence[str] = (),
                    env: Mapping[str, str] | None = None, clean_env: bool = False, log_path: Path | None = None,
                    cwd: Path | None = None, startup_timeout_s: float = 90.0) -> Iterator[RunningService]:
    """`planhrc serve` on `db` in a process group of its own, until it answers /health; stopped (the whole group)
    on the way out. `env` is added to this process's environment (`clean_env`: without its `PLANHRC_*` settings
    first); the service's output goes to `log_path` (else nowhere). The child is told to stop should this process
    die without cleaning up."""
    port = port or free_port()
    child_env = {k: v for k, v in os.environ.items() if not (clean_env and k.startswith("PLANHRC_"))}
    child_env.update(env or {})
    url = f"http://127.0.0.1:{port}"
    log_file: IO[bytes] | None = log_path.open("wb") if log_path is not None else None
    try:
        proc = subprocess.Popen(serve_command(port, db, args), cwd=cwd, env=child_env,
                                stdout=log_file or subprocess.DEVNULL, stderr=subprocess.STDOUT,
                                start_new_session=True, preexec_fn=die_with_parent)
        try:
            wait_until_serving(proc, url, startup_timeout_s, log_path)
            yield RunningService(url, proc.pid, log_path)
        finally:
            stop_process_group(proc)
    finally:
        if log_file is not None:
            log_file.close()


def settled_health(client: httpx.Client, timeout_s: float = 10) -> dict[str, Any]:
    """`GET /health` once nothing the service does behind its answers changes its counts any more (two answers in a
    row agree on the triples and the plans still to write), so that they can be compared. The store writes nothing
    behind an answer (a plan stays its journal row until a reader of its triples needs it), so the first two agree
    unless a reader is writing plans out."""
    deadline = time.monotonic() + timeout_s
    health: dict[str, Any] = client.get("/health").json()
    while True:
        again: dict[str, Any] = client.get("/health").json()
        if (again["triples"], again["plans_to_write"]) == (health["triples"], health["plans_to_write"]):
            return again
        if time.monotonic() > deadline:
            raise StillWritingError(f"the service's store still changed behind its answers after {timeout_s:g} s")
        health = again
        time.sleep(0.02)

"""VAL runs forked from one `Validate` process that has already started (`ForkServer`), as AFL runs its targets.

Starting `Validate` costs more than a short check itself: the kernel's exec, loading and relocating libVAL.so and
glibc's start-up, about two thirds of a relative 20 x 12 re-plan's check in the service (`perf record`). A small
library (`valfork.c`, compiled here once per user with the system's C compiler into the user's cache folder),
preloaded into `Validate`, stops it after that start-up, before VAL's `main`, and serves requests: each forks a
run that calls VAL's unchanged `main` on the request's files, so it reads and checks them exactly as
`Validate DOMAIN PROBLEM PLAN` does, and writes the same output (the tests compare them). A run is an ordinary
`ValRun` from there (`ForkedProcess` stands for its Popen).

A server past a domain (`start(domain=...)`) goes further, as AFL's deferred fork server does: it runs VAL's `main`
on `Validate DOMAIN <problem stand-in> <plan stand-in>` and serves requests only when VAL opens the problem's
stand-in, the domain read and parsed (VAL reads its files in order). Each run goes on from that `fopen`, on the
request's problem and then its plan, so it does what `Validate DOMAIN PROBLEM PLAN` does after the domain, without
parsing the domain again: the same output byte for byte (the run writes its plan's path over the stand-in that VAL
prints), the same exit code. A request must name the server's own domain file.

The server ends when this process closes its socket or dies (it reads end-of-file), and its runs die with it
(parent-death signal). Without a C compiler, on a platform without glibc, or when the server does not start, there
is no server: the checks run as before (`start`: None).
"""
from __future__ import annotations

import array
import hashlib
import logging
import os
import shutil
import signal
import socket
import subprocess
import sys
import threading
from pathlib import Path
from typing import Sequence

from planhrc.paths import cache_folder

from .errors import PlannerError
from .validate import VAL_ADDRESS_SPACE_BYTES, cap_address_space, val_env, validate_binary

log = logging.getLogger(__name__)

SOURCE = Path(__file__).with_name("valfork.c")
TRAILER = b"\nplanhrc-valfork-status "  # the server writes it, the run's status and CPU, after a run's output
START_TIMEOUT_S = 5.0  # how long the server may take to be ready
REPLY_TIMEOUT_S = 5.0  # how long a request may wait for the run's pid
COMPILE_TIMEOUT_S = 60.0
# A server past a domain: room in its plan's stand-in for a run's plan path, written over it so that the run's
# output names its own plan, as `Validate`'s does
PLAN_PATH_ROOM = 1024


class ForkServerError(PlannerError, OSError):
    """The server could not take a request (it is gone, or refused it): the caller starts VAL cold."""


def library(folder: Path | None = None) -> Path | None:
    """The compiled library: made once per user (a file named after its source's hash, in the user's cache
    folder), or None when there is no folder or C compiler, or the compiler failed (said in the log)."""
    folder = folder if folder is not None else cache_folder()
    compiler = shutil.which("cc") or shutil.which("gcc")
    if folder is None or compiler is None or not sys.platform.startswith("linux"):
        return None
    digest = hashlib.sha256(SOURCE.read_bytes()).hexdigest()[:16]
    target = folder / f"valfork-{digest}.so"
    if target.is_file():
        return target
    partial = folder / f".valfork-{digest}-{os.getpid()}-{threading.get_ident()}.so"
    try:
        subprocess.run([compiler, "-O2", "-shared", "-fPIC", "-o", str(partial), str(SOURCE), "-ldl"], check=True,
                       capture_output=True, timeout=COMPILE_TIMEOUT_S, stdin=subprocess.DEVNULL)
        os.replace(partial, target)  # whole or not at all, whoever compiled it at the same time
    except (OSError, subprocess.SubprocessError) as exc:
        detail = getattr(exc, "stderr", b"") or b""
        log.warning("could not compile VAL's fork server (%s%s): VAL starts a process per check",
                    exc, f": {detail.decode(errors='replace').strip()[:200]}" if detail else "")
        try:
            partial.unlink()
        except OSError:
            pass
        return None
    return target


class ForkedProcess:
    """A run of the server, standing for the `subprocess.Popen` of a cold run: its pid (it leads its own process
    group), its output (standard output and error), and its exit code and CPU once `settle` has read them from the
    end of the output. The server waits for it, not this process."""

    def __init__(self, pid: int, stdout_fd: int) -> None:
        self.pid = pid
        self.stdout = os.fdopen(stdout_fd, "rb", buffering=0)
        self.returncode: int | None = None
        self.cpu_s: float | None = None  # user + system, from the fork on (VAL's start-up was the server's)

    def settle(self, output: bytes) -> bytes:
        """The run's own output, its exit code (`returncode`) and CPU seconds (`cpu_s`) taken from the status
        after it; a run killed before it ended has none: -SIGKILL, CPU unknown."""
        head, found, status = output.rpartition(TRAILER)
        fields = status.split()
        if found and status.endswith(b"\n") and len(fields) == 2 and fields[0].lstrip(b"-").isdigit() \
                and fields[1].isdigit():
            self.returncode = int(fields[0])
            self.cpu_s = int(fields[1]) / 1e6
            return head
        self.returncode = -signal.SIGKILL
        return output

    def poll(self) -> int | None:
        return self.returncode

    def wait(self) -> int:
        """A run whose output was not settled was killed (the server waits for it)."""
        if self.returncode is None:
            self.returncode = -signal.SIGKILL
        return self.returncode


class ForkServer:
    """One `Validate` process serving forked runs (see the module's note); thread-safe. `start()` makes one, or
    None when it cannot be had here."""

    def __init__(self, proc: subprocess.Popen[bytes], sock: socket.socket, domain: str | None = None) -> None:
        self.domain = domain  # the domain file it is past (its runs' first file), or None: any files
        self._proc = proc
        self._sock = sock
        self._lock = threading.Lock()
        self.runs = 0

    @property
    def pid(self) -> int:
        return self._proc.pid

    @classmethod
    def start(cls, folder: Path | None = None, domain: str | None = None) -> ForkServer | None:
        """A server (None when none can be had here); with `domain` (a domain file's absolute path), one past that
        domain (see the module's note), whose runs must name it."""
        lib = library(folder)
        if lib is None:
            return None
        binary = validate_binary()
        ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_SEQPACKET)
        env = val_env(binary)
        env.update({"LD_PRELOAD": str(lib), "PLANHRC_VALFORK_FD": str(theirs.fileno()),
                    "LD_BIND_NOW": "1"})  # every symbol bound once, here, rather than lazily in each run
        argv = [str(binary)]
        if domain is not None:  # stand-ins for a run's problem and plan, paths no file has
            stand_in = f"{domain}.{os.getpid()}-{threading.get_ident()}"
            stand_ins = [f"{stand_in}-problem.absent", f"{stand_in}-plan.absent" + "/" * PLAN_PATH_ROOM]
            env.update({"PLANHRC_VALFORK_AFTER": stand_ins[0], "PLANHRC_VALFORK_PLAN": stand_ins[1]})
            argv += [domain, *stand_ins]
        try:
            proc = subprocess.Popen(argv, env=env, pass_fds=(theirs.fileno(),), stdin=subprocess.DEVNULL,
                                    stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
        except OSError as exc:
            ours.close()
            theirs.close()
            log.warning("could not start VAL's fork server (%s): VAL starts a process per check", exc)
            return None
        theirs.close()
        cap_address_space(proc.pid, VAL_ADDRESS_SPACE_BYTES)  # its runs inherit the limit
        ours.settimeout(START_TIMEOUT_S)
        try:
            ready = ours.recv(1) == b"R"
        except OSError:
            ready = False
        if not ready:  # the library was not taken (Validate ran as usual) or failed: no server
            log.warning("VAL's fork server did not start: VAL starts a process per check")
            ours.close()
            _stop(proc)
            return None
        ours.settimeout(REPLY_TIMEOUT_S)
        return cls(proc, ours, domain)

    def run(self, files: Sequence[str]) -> ForkedProcess:
        """A run of VAL on `files` (absolute paths: domain, problem, plan), started now."""
        read_end, write_end = os.pipe()
        try:
            request = b"0\0" + b"".join(os.fsencode(f) + b"\0" for f in files)
            with self._lock:
                self._sock.sendmsg([request], [(socket.SOL_SOCKET, socket.SCM_RIGHTS, array.array("i", [write_end]))])
                reply = self._sock.recv(4)
            os.close(write_end)
            write_end = -1
            pid = int.from_bytes(reply, sys.byteorder, signed=True) if len(reply) == 4 else -1
            if pid <= 0:
                raise ForkServerError("VAL's fork server refused a run" if reply else "VAL's fork server is gone")
            self.runs += 1
            return ForkedProcess(pid, read_end)
        except BaseException:
            if write_end >= 0:
                os.close(write_end)
            os.close(read_end)
            raise

    def alive(self) -> bool:
        return self._proc.poll() is None

    def close(self) -> None:
        """End the server (its runs end with it)."""
        self._sock.close()
        _stop(self._proc)


def _stop(proc: subprocess.Popen[bytes]) -> None:
    try:
        proc.wait(timeout=2.0)  # it exits on end-of-file
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()

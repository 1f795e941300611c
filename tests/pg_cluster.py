"""A throwaway PostgreSQL cluster for the tests: Debian's `initdb` and `postgres` in a temporary folder, on a free
loopback port, run by an unprivileged user (PostgreSQL refuses root: as root the package's `postgres` user runs
it), stopped and removed at the end of the session. `python3 ./run.py test` installs Debian's `postgresql` when it
is missing; where the binaries or psycopg are missing the PostgreSQL tests skip, saying why (in CI they fail).

The server is a child of the test process that dies with it (a parent-death signal), so an interrupted run leaves
no server behind. It runs without fsync: the tests kill clients, not the machine, and a committed transaction
survives a killed client either way.
"""
from __future__ import annotations

import ctypes
import glob
import os
import pwd
import shutil
import signal
import subprocess
import tempfile
import time
from pathlib import Path
from typing import Callable

from planhrc.service_process import free_port

USER = "planhrc"  # the cluster's superuser (trust authentication on loopback and its socket)
PASSWORD_USER = "secured"  # a role that must give its password (the tests of password files create it)
HBA = f"""local all all trust
host all {PASSWORD_USER} 127.0.0.1/32 scram-sha-256
host all all 127.0.0.1/32 trust
"""
SERVER_USER = "postgres"  # who runs the server when the tests run as root (Debian's package creates it)
PR_SET_PDEATHSIG = 1


class ClusterUnavailable(Exception):
    """No PostgreSQL can be started here; the message says why."""


def find_bindir() -> Path:
    """The folder of `initdb` and `postgres`: on PATH, else the newest of Debian's /usr/lib/postgresql/N/bin."""
    found = shutil.which("initdb")
    candidates = [Path(found).resolve().parent] if found else []
    candidates += [Path(p) for p in sorted(glob.glob("/usr/lib/postgresql/*/bin"),
                                           key=lambda p: int(p.split("/")[-2]) if p.split("/")[-2].isdigit() else 0,
                                           reverse=True)]
    for folder in candidates:
        if (folder / "initdb").exists() and (folder / "postgres").exists():
            return folder
    raise ClusterUnavailable("PostgreSQL's initdb and postgres are not installed (Debian: apt-get install "
                             "postgresql; python3 ./run.py test installs it as root)")


def _as_server_user() -> tuple[Callable[[], None], int | None]:
    """What a child runs before exec: drop root for the `postgres` user, and die with this process."""
    uid = gid = None
    if os.geteuid() == 0:
        try:
            entry = pwd.getpwnam(SERVER_USER)
        except KeyError:
            raise ClusterUnavailable(f"running as root and there is no {SERVER_USER!r} user to run PostgreSQL "
                                     "(Debian's postgresql package creates it)") from None
        uid, gid = entry.pw_uid, entry.pw_gid
    libc = ctypes.CDLL(None, use_errno=True)

    def before_exec() -> None:
        if uid is not None and gid is not None:
            os.setgroups([])
            os.setgid(gid)
            os.setuid(uid)
        libc.prctl(PR_SET_PDEATHSIG, signal.SIGINT)  # after setuid, which clears it

    return before_exec, uid


class Cluster:
    """A running throwaway cluster; `database()` makes a fresh database and gives its URL."""

    def __init__(self) -> None:
        bindir = find_bindir()
        before_exec, uid = _as_server_user()
        self.folder = Path(tempfile.mkdtemp(prefix="planhrc-pg-"))
        if uid is not None:
            os.chown(self.folder, uid, -1)
        data = self.folder / "data"
        self.port = free_port()
        self._count = 0
        self._server: subprocess.Popen[bytes] | None = None
        self._log = open(self.folder / "server.log", "wb")
        done = subprocess.run([str(bindir / "initdb"), "-D", str(data), "-U", USER, "--auth=trust", "-E", "UTF8",
                               "--no-sync", "--no-instructions"], preexec_fn=before_exec, capture_output=True,
                              cwd=self.folder)
        if done.returncode:
            self.close()
            raise ClusterUnavailable(f"initdb failed: {done.stderr.decode(errors='replace')[-500:]}")
        (data / "pg_hba.conf").write_text(HBA)
        self._command = [str(bindir / "postgres"), "-D", str(data), "-p", str(self.port), "-k", str(self.folder),
                         "-c", "listen_addresses=127.0.0.1", "-c", "fsync=off", "-c", "synchronous_commit=off",
                         "-c", "full_page_writes=off", "-c", "max_connections=200"]
        self._before_exec = before_exec
        self._start()

    def _start(self) -> None:
        self._server = subprocess.Popen(self._command, preexec_fn=self._before_exec, stdout=self._log,
                                        stderr=subprocess.STDOUT, cwd=self.folder)
        self._wait_ready()

    def _stop(self) -> None:
        """Fast shutdown: every client's connection is cut, open transactions are rolled back."""
        if self._server is not None:
            self._server.send_signal(signal.SIGINT)
            try:
                self._server.wait(30)
            except subprocess.TimeoutExpired:
                self._server.kill()
                self._server.wait()
            self._server = None

    def restart(self, down_s: float = 0.0) -> None:
        """Stop the server (its clients' connections cut, their transactions rolled back) and, after `down_s`
        seconds without it, start it again on the same port and data."""
        self._stop()
        time.sleep(down_s)
        self._start()

    @property
    def url(self) -> str:
        """The URL of the `postgres` database (where databases are made)."""
        return f"postgresql://{USER}@127.0.0.1:{self.port}/postgres"

    def _wait_ready(self, timeout_s: float = 60) -> None:
        import psycopg

        deadline = time.monotonic() + timeout_s
        while True:
            if self._server is not None and self._server.poll() is not None:
                log = (self.folder / "server.log").read_text(errors="replace")[-1500:]
                self.close()
                raise ClusterUnavailable(f"postgres exited with {self._server.returncode}: {log}")
            try:
                psycopg.connect(self.url, connect_timeout=2).close()
                return
            except psycopg.OperationalError:
                if time.monotonic() > deadline:
                    self.close()
                    raise ClusterUnavailable(f"postgres did not accept connections within {timeout_s:g} s")
                time.sleep(0.1)

    def database(self, prefix: str = "kb") -> str:
        """A new empty database; its URL."""
        import psycopg

        self._count += 1
        name = f"{prefix}_{os.getpid()}_{self._count}"
        with psycopg.connect(self.url, autocommit=True) as conn:
            conn.execute(f'CREATE DATABASE "{name}"')
        return f"postgresql://{USER}@127.0.0.1:{self.port}/{name}"

    def drop(self, url: str) -> None:
        """Drop a database made here (its connections are ended first): each holds megabytes of catalog."""
        import psycopg
        from psycopg import sql

        if self._server is None:
            return
        with psycopg.connect(self.url, autocommit=True) as conn:
            conn.execute(sql.SQL("DROP DATABASE IF EXISTS {} WITH (FORCE)").format(
                sql.Identifier(url.rsplit("/", 1)[1])))

    def database_with_password(self, password: str) -> str:
        """A new database owned by a role that must give `password` (once: the role is made on first use); its
        URL, without the password."""
        import psycopg
        from psycopg import sql

        url = self.database("secured")
        name = url.rsplit("/", 1)[1]
        with psycopg.connect(self.url, autocommit=True) as conn:
            if conn.execute("SELECT 1 FROM pg_roles WHERE rolname = %s", (PASSWORD_USER,)).fetchone() is None:
                conn.execute(sql.SQL("CREATE ROLE {} LOGIN PASSWORD {}").format(
                    sql.Identifier(PASSWORD_USER), sql.Literal(password)))
            conn.execute(sql.SQL("ALTER DATABASE {} OWNER TO {}").format(sql.Identifier(name),
                                                                       sql.Identifier(PASSWORD_USER)))
        return f"postgresql://{PASSWORD_USER}@127.0.0.1:{self.port}/{name}"

    def server_pid(self) -> int | None:
        return self._server.pid if self._server is not None else None

    def close(self) -> None:
        """Stop the server (fast shutdown: clients are disconnected) and remove its folder."""
        self._stop()
        self._log.close()
        shutil.rmtree(self.folder, ignore_errors=True)

#!/usr/bin/env python3
"""Set up `.venv` at the repository root (once, or again when pyproject.toml or constraints.txt changes) and run
a task.

    python3 ./run.py demo [ARGS...]   # the main job: `planhrc demo` on the embedded store
    python3 ./run.py test [ARGS...]   # the whole test suite (every marker)
    python3 ./run.py setup            # only create or update .venv
    python3 ./run.py lock             # rewrite constraints.txt from .venv (pip freeze)
    python3 ./run.py planhrc ARGS...  # any `planhrc` command inside the environment
    python3 ./run.py ros2-bridge --kb URL [ARGS...]  # the ROS 2 bridge, in `.venv-ros2`

`.venv-ros2` (made on first use of `ros2-bridge`, and by `test` so that the ROS 2 tests have their peers) holds
planhrc with the `sim` and `ros2` extras, pinned by constraints.txt and ros2-constraints.txt. The ROS 2 wheels stay
out of `.venv`: they install a start-up hook that re-launches every interpreter of their environment.

The environment gets planhrc (editable) with the `sim` and `test` extras, pinned by constraints.txt (the
versions the suite last passed with), so every machine resolves the same versions. Each step says what it does in
one line; what the installers (pip, apt-get) print goes to a log in `.venv/`, named with its last lines when a step
fails.
Only the standard library is used here, so this works from a fresh clone with nothing but python3; the file
also parses on old interpreters (no newer syntax, annotations as strings) so that they get the version message.
"""
import hashlib
import os
import re
import shutil
import signal
import subprocess
import sys
import time
import venv
from pathlib import Path

ROOT = Path(__file__).resolve().parent
VENV = ROOT / ".venv"
STAMP = VENV / ".planhrc-installed"
INSTALL_LOG = VENV / "install.log"
APT_LOG = VENV / "apt.log"
LOG_TAIL_LINES = 12
CHROMIUM = Path("/usr/bin/chromium")
CONSTRAINTS = ROOT / "constraints.txt"
EXTRAS = "all,test"
CONSTRAINTS_HEADER = """\
# The versions the test suite last passed with: `pip freeze` of run.py's .venv (all extras and the test extra).
# Used as `pip install -c constraints.txt ...` by run.py (so CI), and by the Docker images.
# Regenerate with `python3 ./run.py lock` (delete this file first to let pip resolve fresh versions, then run the
# suite before locking).
"""
ROS2_VENV = ROOT / ".venv-ros2"
ROS2_STAMP = ROS2_VENV / ".planhrc-installed"
ROS2_LOG = ROS2_VENV / "install.log"
ROS2_CONSTRAINTS = ROOT / "ros2-constraints.txt"
ROS2_EXTRAS = "sim,ros2"
ROS2_CONSTRAINTS_HEADER = """\
# The ROS 2 wheels of .venv-ros2 (ROS 2 Kilted from PyPI), pinned beside constraints.txt, which pins the rest.
# Used as `pip install -c constraints.txt -c ros2-constraints.txt ...` by run.py. Regenerate with
# `python3 ./run.py lock` (it writes both files when .venv-ros2 exists).
"""
TASKS = ("demo", "test", "setup", "planhrc", "lock", "ros2-bridge")


class SetupError(Exception):
    """The environment cannot be made here; the message says why and what to do."""


class InstallFailed(SetupError):
    """An installer exited with an error; its output is in a log, whose last lines the message quotes."""

    def __init__(self, what: str, code: int, log: "Path") -> None:
        super().__init__(f"{what} failed (exit status {code}); the last lines of {shown(log)}:\n" + quoted(log))


class Terminated(Exception):
    """SIGTERM arrived: raised from the signal handler so that a running installer is stopped with run.py."""


def say(message: str) -> None:
    print(f"[run.py] {message}", file=sys.stderr, flush=True)


def shown(path: "Path") -> str:
    """A path as the user reads it: relative to the repository when it lies inside."""
    try:
        return str(path.relative_to(ROOT))
    except ValueError:
        return str(path)


def quoted(log: "Path") -> str:
    """The last non-blank lines of a log, indented: where an installer says what went wrong."""
    try:
        lines = log.read_text(encoding="utf-8", errors="replace").splitlines()
    except OSError as exc:
        lines = [f"(the log cannot be read: {exc})"]
    return "\n".join("    " + line for line in [l for l in lines if l.strip()][-LOG_TAIL_LINES:])


def run_logged(cmd: "list[str]", log: "Path", what: str, env: "dict[str, str] | None" = None) -> None:
    """Run an installer with its output appended to `log`; raise InstallFailed (naming the log) when it fails.
    An exception while it runs (Ctrl-C, SIGTERM) kills it before passing on, so nothing is left running."""
    with open(log, "a", encoding="utf-8") as out:
        out.write(f"\n$ {' '.join(cmd)}\n")
        out.flush()
        code = subprocess.run(cmd, stdout=out, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                              env=env).returncode
    if code != 0:
        raise InstallFailed(what, code, log)


def venv_python() -> "Path":
    return VENV / ("Scripts/python.exe" if os.name == "nt" else "bin/python")


def required_python() -> "tuple[int, int]":
    """The minimum (major, minor) of pyproject.toml's `requires-python = ">=X.Y"` (read without tomllib, which an
    old interpreter lacks)."""
    text = (ROOT / "pyproject.toml").read_text(encoding="utf-8")
    match = re.search(r'^requires-python\s*=\s*"\s*>=\s*(\d+)\.(\d+)', text, re.MULTILINE)
    if not match:
        raise SetupError('pyproject.toml: no requires-python = ">=X.Y" line')
    return int(match.group(1)), int(match.group(2))


def check_interpreter() -> None:
    """Refuse an interpreter older than the project needs, before anything is created."""
    need = required_python()
    if sys.version_info[:2] < need:
        have = ".".join(map(str, sys.version_info[:3]))
        raise SetupError(f"Python {need[0]}.{need[1]} or newer is needed, this is {have} ({sys.executable}); "
                         f"run run.py with a newer python3 (nothing was created)")


def requirements_digest() -> str:
    digest = hashlib.sha256((ROOT / "pyproject.toml").read_bytes())
    if CONSTRAINTS.exists():
        digest.update(CONSTRAINTS.read_bytes())
    digest.update(EXTRAS.encode())
    return digest.hexdigest()


def venv_version() -> "tuple[int, int] | None":
    """(major, minor) of the interpreter inside `.venv`, or None when it is missing or does not run."""
    try:
        out = subprocess.run([str(venv_python()), "-c", "import sys; print(*sys.version_info[:2])"],
                             capture_output=True, text=True, timeout=60)
    except (OSError, subprocess.TimeoutExpired):
        return None
    parts = out.stdout.split()
    if out.returncode != 0 or len(parts) != 2 or not all(p.isdigit() for p in parts):
        return None
    return int(parts[0]), int(parts[1])


def venv_problem() -> "str | None":
    """Why the existing `.venv` cannot be kept (made by another interpreter, or half-created), or None."""
    if not VENV.exists():
        return None
    version = venv_version()
    if version is None:
        return "its python is missing or does not run (a half-created environment)"
    if version != sys.version_info[:2]:
        return (f"it was made by Python {version[0]}.{version[1]}, this is "
                f"{sys.version_info[0]}.{sys.version_info[1]}")
    if not STAMP.exists():
        return "an earlier installation did not finish"
    return None


def remove_venv() -> None:
    """Delete `.venv`, but only what looks like a virtual environment (or an empty folder)."""
    if VENV.is_symlink() or not VENV.is_dir():
        raise SetupError(f"{VENV} is not a folder; remove it yourself")
    if not (VENV / "pyvenv.cfg").exists() and any(VENV.iterdir()):
        raise SetupError(f"{VENV} does not look like a virtual environment (no pyvenv.cfg); remove it yourself")
    shutil.rmtree(VENV)


def create_venv() -> None:
    try:
        venv.EnvBuilder(with_pip=True).create(VENV)
    except subprocess.CalledProcessError as exc:  # ensurepip, which venv runs with its output captured
        output = exc.output.decode(errors="replace") if isinstance(exc.output, bytes) else str(exc.output or "")
        INSTALL_LOG.write_text(output + "\n(on Debian or Ubuntu, the python3-venv package provides ensurepip)\n")
        raise InstallFailed("creating .venv (ensurepip)", exc.returncode, INSTALL_LOG) from None


def install_project(py: str) -> None:
    """pip installs the project and its extras, pinned by constraints.txt; pip's output goes to the install log
    (a quiet pip still let the build backend's warnings through, pages of them on a first run)."""
    constraints = ["-c", str(CONSTRAINTS)] if CONSTRAINTS.exists() else []
    run_logged([py, "-m", "pip", "install", "--upgrade", "pip", *constraints], INSTALL_LOG, "upgrading pip")
    run_logged([py, "-m", "pip", "install", *constraints, "-e", f"{ROOT}[{EXTRAS}]"], INSTALL_LOG,
               "installing planhrc")


def ensure_environment() -> "Path":
    """Create `.venv` and install the project when it is missing or stale; rebuild it when it was made by another
    interpreter or left half-made."""
    check_interpreter()
    problem = venv_problem()
    if problem:
        say(f"rebuilding .venv: {problem}")
        remove_venv()
    digest = requirements_digest()
    if STAMP.exists() and STAMP.read_text().strip() == digest and venv_python().exists():
        return venv_python()
    started = time.monotonic()
    if not venv_python().exists():
        say("creating .venv")
        create_venv()
    STAMP.unlink(missing_ok=True)  # until the installation below finishes, the environment counts as half-made
    say(f"installing planhrc and its dependencies (log: {shown(INSTALL_LOG)})")
    install_project(str(venv_python()))
    STAMP.write_text(digest)
    say(f".venv is ready ({time.monotonic() - started:.0f} s)")
    return venv_python()


def write_constraints(py: str) -> None:
    """constraints.txt := `pip freeze` of `.venv` (the project itself left out), with a header saying so."""
    frozen = subprocess.run([py, "-m", "pip", "freeze", "--exclude-editable"], check=True, capture_output=True,
                            text=True).stdout
    lines = sorted((l for l in frozen.splitlines() if l and not l.lower().startswith("planhrc")), key=str.lower)
    CONSTRAINTS.write_text(CONSTRAINTS_HEADER + "\n".join(lines) + "\n")
    say(f"wrote {CONSTRAINTS.name}: {len(lines)} pinned distributions")


def apt_usable() -> bool:
    """Whether Debian's packages can be installed here (root, with apt-get)."""
    return os.name == "posix" and os.geteuid() == 0 and Path("/usr/bin/apt-get").exists()


def apt_install(package: str, purpose: str) -> bool:
    """`apt-get install` one Debian package (after `apt-get update`), its output in APT_LOG; whether it worked (a
    failure is said in one line, naming the log)."""
    say(f"installing Debian's {package} for {purpose} (log: {shown(APT_LOG)})")
    env = {**os.environ, "DEBIAN_FRONTEND": "noninteractive"}
    try:
        run_logged(["apt-get", "update"], APT_LOG, "apt-get update", env=env)
        run_logged(["apt-get", "install", "-y", "--no-install-recommends", package], APT_LOG,
                   f"apt-get install {package}", env=env)
    except InstallFailed as exc:
        say(f"{exc}\nThe tests of {purpose} will skip.")
        return False
    return True


def ensure_chromium() -> None:
    """The browser tests drive Debian's Chromium: install the `chromium` package when it is missing and apt is
    usable (as root). Otherwise say why; those tests then skip with the same reason."""
    if CHROMIUM.exists():
        return
    if not apt_usable():
        say(f"{CHROMIUM} is missing and apt-get cannot be used here (needs root on Debian): "
            "the browser tests will skip")
        return
    if apt_install("chromium", "the browser tests") and not CHROMIUM.exists():
        say(f"apt-get installed chromium but {CHROMIUM} is not there: the browser tests will skip")


def postgresql_bindir() -> "Path | None":
    """The folder of PostgreSQL's initdb and postgres (Debian keeps them in /usr/lib/postgresql/N/bin)."""
    found = shutil.which("initdb")
    folders = [Path(found).resolve().parent] if found else []
    folders += sorted(Path("/usr/lib/postgresql").glob("*/bin"), reverse=True)
    return next((f for f in folders if (f / "initdb").exists() and (f / "postgres").exists()), None)


def ensure_postgresql() -> None:
    """The PostgreSQL store's tests start a throwaway cluster with Debian's server: install the `postgresql`
    package when it is missing and apt is usable (as root). Otherwise say why; those tests then skip (in CI they
    fail: there they must run)."""
    if postgresql_bindir() is not None:
        return
    if not apt_usable():
        say("PostgreSQL (initdb, postgres) is missing and apt-get cannot be used here (needs root on Debian): "
            "the PostgreSQL store's tests will skip")
        return
    if apt_install("postgresql", "the PostgreSQL store") and postgresql_bindir() is None:
        say("apt-get installed postgresql but its initdb is not there: the PostgreSQL store's tests will skip")


PROMETHEUS = Path("/usr/bin/prometheus")


def ensure_prometheus() -> None:
    """The metrics test scrapes the service with Debian's Prometheus server (run by the test as an unprivileged
    user): install the `prometheus` package when it is missing and apt is usable (as root). Otherwise say why;
    that test then skips (in CI it fails: there it must run)."""
    if PROMETHEUS.exists():
        return
    if not apt_usable():
        say(f"{PROMETHEUS} is missing and apt-get cannot be used here (needs root on Debian): the Prometheus test "
            "will skip")
        return
    if apt_install("prometheus", "the Prometheus test") and not PROMETHEUS.exists():
        say(f"apt-get installed prometheus but {PROMETHEUS} is not there: the Prometheus test will skip")


def on_sigterm(signum: int, frame: object) -> None:
    raise Terminated()


def run_task(cmd: "list[str]") -> int:
    """Run the task's command in the foreground; pass a SIGTERM on to it and wait until it has stopped (it stops
    its own children: the demo its service, the tests theirs)."""
    child = subprocess.Popen(cmd, cwd=ROOT)
    while True:
        try:
            code = child.wait()
            return 128 - code if code < 0 else code  # killed by signal N: the shell's 128 + N
        except KeyboardInterrupt:  # the child got the same Ctrl-C and reports it itself
            child.wait()
            return 130
        except Terminated:
            child.terminate()


def ros2_python() -> "Path":
    return ROS2_VENV / "bin/python"


def ros2_venv_version() -> "tuple[int, ...]":
    """(major, minor) of the interpreter `.venv-ros2` was made with, from its pyvenv.cfg (not by running it: its
    start-up hook re-launches the interpreter)."""
    text = (ROS2_VENV / "pyvenv.cfg").read_text(encoding="utf-8")
    match = re.search(r"^version(?:_info)?\s*=\s*(\d+)\.(\d+)", text, re.MULTILINE)
    return (int(match.group(1)), int(match.group(2))) if match else ()


def ros2_digest() -> str:
    digest = hashlib.sha256((ROOT / "pyproject.toml").read_bytes())
    for pins in (CONSTRAINTS, ROS2_CONSTRAINTS):
        if pins.exists():
            digest.update(pins.read_bytes())
    digest.update(ROS2_EXTRAS.encode())
    digest.update(".".join(map(str, sys.version_info[:2])).encode())
    return digest.hexdigest()


def ensure_ros2_environment() -> "Path":
    """Create `.venv-ros2` (planhrc with the sim and ros2 extras) when it is missing or stale. The ROS 2 wheels
    are manylinux builds: elsewhere this says so and creates nothing."""
    if not sys.platform.startswith("linux"):
        raise SetupError("the ROS 2 wheels are built for Linux only: .venv-ros2 was not created")
    if ROS2_VENV.exists() and not (ROS2_VENV / "pyvenv.cfg").exists():
        raise SetupError(f"{ROS2_VENV} does not look like a virtual environment (no pyvenv.cfg); remove it yourself")
    if ROS2_VENV.exists() and (not ROS2_STAMP.exists() or ros2_venv_version() != sys.version_info[:2]):
        shutil.rmtree(ROS2_VENV)  # half-made, or made by another interpreter: start again
    digest = ros2_digest()
    if ROS2_STAMP.exists() and ROS2_STAMP.read_text().strip() == digest and ros2_python().exists():
        return ros2_python()
    if not ros2_python().exists():
        say("creating .venv-ros2 (ROS 2 wheels from PyPI)")
        venv.EnvBuilder(with_pip=True).create(ROS2_VENV)
    ROS2_STAMP.unlink(missing_ok=True)
    say(f"installing planhrc with ROS 2's rclpy into .venv-ros2 (log: {shown(ROS2_LOG)})")
    pins = [arg for path in (CONSTRAINTS, ROS2_CONSTRAINTS) if path.exists() for arg in ("-c", str(path))]
    py = str(ros2_python())
    run_logged([py, "-m", "pip", "install", "--upgrade", "pip", *pins], ROS2_LOG, "upgrading pip in .venv-ros2")
    run_logged([py, "-m", "pip", "install", *pins, "-e", f"{ROOT}[{ROS2_EXTRAS}]"], ROS2_LOG,
               "installing planhrc into .venv-ros2")
    ROS2_STAMP.write_text(digest)
    return ros2_python()


def write_ros2_constraints(py: str) -> None:
    """ros2-constraints.txt := what `pip freeze` of `.venv-ros2` adds to constraints.txt (the ROS 2 wheels)."""
    frozen = subprocess.run([py, "-m", "pip", "freeze", "--exclude-editable"], check=True, capture_output=True,
                            text=True).stdout
    core = {line.split("==")[0].lower() for line in CONSTRAINTS.read_text().splitlines() if "==" in line}
    lines = sorted((l for l in frozen.splitlines() if "==" in l and l.split("==")[0].lower() not in core
                    and not l.lower().startswith("planhrc")), key=str.lower)
    ROS2_CONSTRAINTS.write_text(ROS2_CONSTRAINTS_HEADER + "\n".join(lines) + "\n")
    say(f"wrote {ROS2_CONSTRAINTS.name}: {len(lines)} pinned distributions")


def try_ros2_environment() -> None:
    """For the test task: make `.venv-ros2` if it can be made; otherwise the ROS 2 tests skip, saying why."""
    try:
        ensure_ros2_environment()
    except InstallFailed as exc:
        say(f"{exc}\nThe ROS 2 tests will skip.")
    except (SetupError, OSError) as exc:
        say(f".venv-ros2 could not be made ({exc}): the ROS 2 tests will skip")


def main(argv: "list[str]") -> int:
    if not argv or argv[0] in {"-h", "--help"}:
        print(__doc__)
        return 0
    task, rest = argv[0], argv[1:]
    if task not in TASKS:
        say(f"unknown task {task!r}; use {', '.join(TASKS)}")
        return 2
    signal.signal(signal.SIGTERM, on_sigterm)
    try:
        py = str(ensure_environment())
        if task == "test":
            ensure_chromium()
            ensure_postgresql()
            ensure_prometheus()
            try_ros2_environment()
    except InstallFailed as exc:
        say(f"{exc}\nRun the same command again to retry: the environment will be repaired.")
        return 1
    except SetupError as exc:
        say(str(exc))
        return 2
    except (KeyboardInterrupt, Terminated) as exc:
        say("interrupted; run the same command again to finish the installation")
        return 130 if isinstance(exc, KeyboardInterrupt) else 143
    if task == "setup":
        return 0
    if task == "lock":
        write_constraints(py)
        if ros2_python().exists():
            write_ros2_constraints(str(ros2_python()))
        return 0
    if task == "test":
        say(" ".join(["running the tests: pytest", *rest]))
        cmd = [py, "-m", "pytest", *rest]
    elif task == "ros2-bridge":
        try:
            cmd = [str(ensure_ros2_environment()), "-m", "planhrc.cli", "ros2-bridge", *rest]
        except SetupError as exc:
            say(f"cannot make .venv-ros2: {exc}")
            return 1
    elif task == "demo":
        say(" ".join(["running the demo: planhrc demo", *rest]))
        cmd = [py, "-m", "planhrc.cli", "demo", *rest]
    else:
        cmd = [py, "-m", "planhrc.cli", *rest]
    return run_task(cmd)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

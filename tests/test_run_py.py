"""`run.py` refuses an unknown task and an old interpreter before creating anything, and rebuilds a `.venv` made
by another interpreter or left half-made: those tests work on a copy of run.py + pyproject.toml in a temporary
folder, with the installer replaced where one would start. The tests at the end run run.py for real on a tiny
package of the same shape (a `planhrc.cli` with a `demo`): a real `python -m venv`, real pip, a real build, to see
what a first run prints, where the installers' output goes, and what a failing installation says."""
from __future__ import annotations

import ast
import importlib.util
import os
import shutil
import signal
import subprocess
import sys
import time
import venv
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
# A tiny real package standing where planhrc stands: run.py installs it with the extras it installs planhrc with,
# and its `planhrc.cli` answers the tasks run.py starts.
PROBE_PYPROJECT = """\
[build-system]
requires = ["setuptools>=77.0.3"]
build-backend = "setuptools.build_meta"

[project]
name = "planhrc"
version = "0.0.1"
requires-python = ">=3.11"

[project.optional-dependencies]
all = []
test = []

[tool.setuptools]
packages = ["planhrc"]
"""
PROBE_CLI = """\
import os
import sys
import time
from pathlib import Path


def main(argv):
    if argv[0] == "demo":
        print("[demo] the probe's first line", flush=True)
        return 0
    if argv[0] == "wait":  # wait PIDFILE: stands for a long task
        Path(argv[1]).write_text(str(os.getpid()))
        time.sleep(120)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
"""
# A build backend of the package's own that refuses to build: a real pip run that fails, with its reason last
BROKEN_BACKEND = """\
def _refuse(*args, **kwargs):
    raise RuntimeError("probe-build-refused: this package does not build")


get_requires_for_build_editable = get_requires_for_build_wheel = build_editable = build_wheel = _refuse
"""


@pytest.fixture
def checkout(tmp_path: Path) -> Path:
    for name in ("run.py", "pyproject.toml", "constraints.txt"):
        if (REPO / name).exists():
            shutil.copy(REPO / name, tmp_path / name)
    return tmp_path


def load_run_py(folder: Path):
    spec = importlib.util.spec_from_file_location(f"run_py_{abs(hash(folder))}", folder / "run.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture
def run_py(checkout, monkeypatch):
    """run.py loaded from the copy, with pip replaced by a recorder and venvs made without pip (fast)."""
    module = load_run_py(checkout)
    installs: list[str] = []
    monkeypatch.setattr(module, "install_project", installs.append)
    monkeypatch.setattr(module, "create_venv", lambda: venv.EnvBuilder(with_pip=False).create(module.VENV))
    module.installs = installs
    return module


def test_an_unknown_task_is_refused_before_anything_is_installed(checkout):
    result = subprocess.run([sys.executable, "run.py", "bogus"], cwd=checkout, capture_output=True, text=True,
                            timeout=60)
    assert result.returncode == 2
    assert "bogus" in result.stderr and "unknown task" in result.stderr
    assert not (checkout / ".venv").exists()


def test_an_old_interpreter_is_refused_and_nothing_is_created(checkout):
    text = (checkout / "pyproject.toml").read_text()
    (checkout / "pyproject.toml").write_text(text.replace('requires-python = ">=3.11"', 'requires-python = ">=3.99"'))
    result = subprocess.run([sys.executable, "run.py", "setup"], cwd=checkout, capture_output=True, text=True,
                            timeout=60)
    assert result.returncode == 2
    assert "Python 3.99 or newer is needed" in result.stderr and "Traceback" not in result.stderr
    assert not (checkout / ".venv").exists()


def test_a_fresh_checkout_gets_a_venv_and_one_installation(run_py):
    py = run_py.ensure_environment()
    assert py.exists() and run_py.STAMP.read_text() == run_py.requirements_digest()
    assert len(run_py.installs) == 1
    run_py.ensure_environment()  # up to date: nothing happens
    assert len(run_py.installs) == 1


def test_a_changed_constraints_file_reinstalls_in_place(run_py):
    run_py.ensure_environment()
    marker = run_py.VENV / "kept"
    marker.write_text("")
    run_py.CONSTRAINTS.write_text("# changed\n")
    run_py.ensure_environment()
    assert len(run_py.installs) == 2 and marker.exists()


def test_a_half_created_venv_is_rebuilt(run_py, capsys):
    run_py.VENV.mkdir()
    (run_py.VENV / "pyvenv.cfg").write_text("home = /nowhere\n")  # no interpreter inside
    run_py.ensure_environment()
    assert run_py.venv_version() == sys.version_info[:2]
    assert "half-created" in capsys.readouterr().err


def test_an_interrupted_installation_is_rebuilt(run_py, capsys):
    run_py.ensure_environment()
    run_py.STAMP.unlink()  # as after a failed or interrupted pip run
    leftover = run_py.VENV / "leftover"
    leftover.write_text("")
    run_py.ensure_environment()
    assert not leftover.exists() and run_py.STAMP.exists()
    assert "did not finish" in capsys.readouterr().err


def test_a_venv_of_another_interpreter_is_rebuilt(run_py, capsys):
    run_py.ensure_environment()
    python = run_py.venv_python()
    python.unlink()
    python.write_text("#!/bin/sh\necho 3 8\n")  # answers like a Python 3.8 would
    python.chmod(0o755)
    run_py.ensure_environment()
    assert run_py.venv_version() == sys.version_info[:2]
    assert "made by Python 3.8" in capsys.readouterr().err


def test_a_folder_that_is_not_a_venv_is_not_deleted(run_py):
    run_py.VENV.mkdir()
    (run_py.VENV / "notes.txt").write_text("mine")
    with pytest.raises(run_py.SetupError, match="does not look like a virtual environment"):
        run_py.ensure_environment()
    assert (run_py.VENV / "notes.txt").read_text() == "mine"


def _pins() -> dict[str, str]:
    from packaging.utils import canonicalize_name

    out = {}
    for line in (REPO / "constraints.txt").read_text().splitlines():
        line = line.split("#", 1)[0].strip()
        if line:
            name, _, version = line.partition("==")
            out[canonicalize_name(name)] = version.strip()
    return out


def _required(extras: set[str]) -> dict[str, str]:
    """Every distribution `planhrc[extras]` pulls in, with its installed version (read from the installed
    distributions' metadata: the closure pip resolved)."""
    from importlib import metadata

    from packaging.requirements import Requirement
    from packaging.utils import canonicalize_name

    found: dict[str, str] = {}
    todo = [("planhrc", frozenset(extras))]
    done: set[tuple[str, frozenset[str]]] = set()
    while todo:
        name, wanted = todo.pop()
        if (name, wanted) in done:
            continue
        done.add((name, wanted))
        dist = metadata.distribution(name)
        if name != "planhrc":
            found[name] = dist.version
        for text in dist.requires or []:
            req = Requirement(text)
            if req.marker and not any(req.marker.evaluate({"extra": e}) for e in (*wanted, "")):
                continue
            todo.append((canonicalize_name(req.name), frozenset(req.extras)))
    return found


def test_constraints_pin_everything_the_environment_installs():
    """constraints.txt pins every distribution that planhrc with run.py's extras pulls in (mypy, schemathesis and
    the linters of the test extra too), at the version installed here: a fresh `run.py setup` resolves nothing
    new. `python3 ./run.py lock` rewrites the file."""
    extras = set(load_run_py(REPO).EXTRAS.split(",")) | {"sim", "reasoner", "bench", "postgresql"}  # `all` names these
    pins, required = _pins(), _required(extras)
    missing = sorted(set(required) - set(pins))
    assert not missing, f"not pinned in constraints.txt: {missing} (run `python3 ./run.py lock`)"
    differ = {name: (pins[name], version) for name, version in required.items() if pins[name] != version}
    assert not differ, f"constraints.txt pins other versions than installed: {differ}"


def test_postgresql_is_found_or_its_absence_said_in_one_line(monkeypatch, capsys):
    """`run.py test` installs Debian's postgresql when initdb is missing and apt-get is usable; where it is not
    (not root, not Debian), it says in one line that the PostgreSQL store's tests will skip, and installs nothing."""
    run_py = load_run_py(REPO)
    bindir = run_py.postgresql_bindir()
    if bindir is not None:
        assert (bindir / "initdb").exists() and (bindir / "postgres").exists()
    monkeypatch.setattr(run_py, "postgresql_bindir", lambda: None)
    monkeypatch.setattr(run_py, "apt_usable", lambda: False)
    monkeypatch.setattr(run_py, "apt_install", lambda *a: pytest.fail("apt-get must not run here"))
    run_py.ensure_postgresql()
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and "apt-get cannot be used here" in lines[0] and "will skip" in lines[0], lines


def test_run_py_parses_on_old_interpreters():
    """An old python3 must get run.py's version message, not a SyntaxError: no syntax newer than 3.6."""
    ast.parse((REPO / "run.py").read_text(), feature_version=(3, 6))


def make_probe(folder: Path, pyproject: str = PROBE_PYPROJECT) -> Path:
    folder.mkdir()
    shutil.copy(REPO / "run.py", folder / "run.py")
    (folder / "pyproject.toml").write_text(pyproject)
    (folder / "planhrc").mkdir()
    (folder / "planhrc" / "__init__.py").write_text("")
    (folder / "planhrc" / "cli.py").write_text(PROBE_CLI)
    return folder


def run_py_in(folder: Path, *args: str, timeout: float = 600) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k not in {"PYTHONPATH", "VIRTUAL_ENV"}}
    return subprocess.run([sys.executable, "run.py", *args], cwd=folder, env=env, capture_output=True, text=True,
                          timeout=timeout)


@pytest.fixture(scope="module")
def first_demo(tmp_path_factory) -> tuple[Path, subprocess.CompletedProcess]:
    """A fresh checkout of the probe and what its first `python3 ./run.py demo` did."""
    folder = make_probe(tmp_path_factory.mktemp("probe") / "clone")
    return folder, run_py_in(folder, "demo")


@pytest.mark.slow
@pytest.mark.integration
def test_the_first_demo_says_each_step_in_a_line_and_keeps_pip_in_a_log(first_demo):
    folder, result = first_demo
    assert result.returncode == 0, result.stderr
    assert result.stdout.splitlines() == ["[demo] the probe's first line"]
    lines = result.stderr.splitlines()
    assert lines == [
        "[run.py] creating .venv",
        "[run.py] installing planhrc and its dependencies (log: .venv/install.log)",
        lines[2],
        "[run.py] running the demo: planhrc demo",
    ], result.stderr
    assert lines[2].startswith("[run.py] .venv is ready (") and lines[2].endswith(" s)")
    log = (folder / ".venv" / "install.log").read_text()
    assert "Successfully installed planhrc-0.0.1" in log and "-m pip install --upgrade pip" in log
    assert (folder / ".venv" / ".planhrc-installed").exists()


@pytest.mark.slow
@pytest.mark.integration
def test_a_second_demo_installs_nothing(first_demo):
    folder, _ = first_demo
    log = (folder / ".venv" / "install.log").read_text()
    result = run_py_in(folder, "demo")
    assert result.returncode == 0, result.stderr
    assert result.stderr.splitlines() == ["[run.py] running the demo: planhrc demo"]
    assert (folder / ".venv" / "install.log").read_text() == log


@pytest.mark.slow
@pytest.mark.integration
def test_sigterm_stops_the_task_with_run_py(first_demo, tmp_path):
    """A SIGTERM to run.py reaches the task it runs (a service manager or CI stopping run.py leaves nothing
    running), and run.py answers with the task's status."""
    folder, _ = first_demo
    pidfile = tmp_path / "task.pid"
    env = {k: v for k, v in os.environ.items() if k not in {"PYTHONPATH", "VIRTUAL_ENV"}}
    runner = subprocess.Popen([sys.executable, "run.py", "planhrc", "wait", str(pidfile)], cwd=folder, env=env,
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 60
        while not (pidfile.exists() and pidfile.read_text()) and time.monotonic() < deadline:
            time.sleep(0.05)
        task = int(pidfile.read_text())
        runner.send_signal(signal.SIGTERM)
        assert runner.wait(timeout=30) == 128 + signal.SIGTERM
    finally:
        if runner.poll() is None:
            runner.kill()
    assert not Path(f"/proc/{task}").exists(), "the task outlived run.py"


@pytest.mark.slow
@pytest.mark.integration
def test_a_failing_installation_names_its_log_and_quotes_the_error(tmp_path):
    broken = PROBE_PYPROJECT.replace('requires = ["setuptools>=77.0.3"]\nbuild-backend = "setuptools.build_meta"',
                                     'requires = []\nbuild-backend = "broken_backend"\nbackend-path = ["."]')
    folder = make_probe(tmp_path / "clone", broken)
    (folder / "broken_backend.py").write_text(BROKEN_BACKEND)
    result = run_py_in(folder, "demo")
    assert result.returncode == 1
    assert "[run.py] installing planhrc failed (exit status 1); the last lines of .venv/install.log:" in result.stderr
    assert "probe-build-refused: this package does not build" in result.stderr  # pip's error, quoted from the log
    assert "Run the same command again to retry" in result.stderr
    assert "Traceback" not in result.stderr.split("the last lines of")[0]
    assert "probe-build-refused" in (folder / ".venv" / "install.log").read_text()
    assert not (folder / ".venv" / ".planhrc-installed").exists()  # the next run repairs the environment
    assert "[demo]" not in result.stdout

"""`run.py` refuses an unknown task and an old interpreter before creating anything, and rebuilds a `.venv` made
by another interpreter or left half-made. Each test works on a copy of run.py + pyproject.toml in a temporary
folder; no real installation runs (the installer is replaced where one would start)."""
from __future__ import annotations

import importlib.util
import shutil
import subprocess
import sys
import venv
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


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
    extras = set(load_run_py(REPO).EXTRAS.split(",")) | {"sim", "reasoner", "bench"}  # `all` names these
    pins, required = _pins(), _required(extras)
    missing = sorted(set(required) - set(pins))
    assert not missing, f"not pinned in constraints.txt: {missing} (run `python3 ./run.py lock`)"
    differ = {name: (pins[name], version) for name, version in required.items() if pins[name] != version}
    assert not differ, f"constraints.txt pins other versions than installed: {differ}"

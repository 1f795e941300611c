"""run.py's `.venv-ros2`: made with the ROS 2 pins beside the core's, rebuilt when half-made or made by another
interpreter, and never a reason for the test task to fail (the ROS 2 tests skip instead). Each test works on a
copy of run.py in a temporary folder; pip is replaced by a recorder."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from .test_run_py import load_run_py

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture
def run_py(tmp_path: Path, monkeypatch):
    for name in ("run.py", "pyproject.toml", "constraints.txt", "ros2-constraints.txt"):
        (tmp_path / name).write_bytes((REPO / name).read_bytes())
    module = load_run_py(tmp_path)
    calls: list[list[str]] = []

    def record(cmd, check=False, **kwargs):
        calls.append([str(c) for c in cmd])
        return subprocess.CompletedProcess(cmd, 0)

    monkeypatch.setattr(module.subprocess, "run", record)
    monkeypatch.setattr(module.venv, "EnvBuilder", lambda **kw: _FakeBuilder(module))
    module.calls = calls
    return module


class _FakeBuilder:
    """Makes the folder and pyvenv.cfg of a venv (what run.py reads), without an interpreter."""

    def __init__(self, module) -> None:
        self.module = module

    def create(self, folder: Path) -> None:
        (Path(folder) / "bin").mkdir(parents=True, exist_ok=True)
        (Path(folder) / "bin" / "python").write_text("")
        v = sys.version_info
        (Path(folder) / "pyvenv.cfg").write_text(f"home = /usr/bin\nversion = {v[0]}.{v[1]}.{v[2]}\n")


def test_the_ros2_environment_installs_the_ros2_extra_with_both_pins(run_py):
    py = run_py.ensure_ros2_environment()
    install = run_py.calls[-1]
    assert install[:4] == [str(py), "-m", "pip", "install"] and install[-1].endswith("[sim,ros2]")
    pins = [install[i + 1] for i, arg in enumerate(install) if arg == "-c"]
    assert [Path(p).name for p in pins] == ["constraints.txt", "ros2-constraints.txt"]
    assert run_py.ROS2_STAMP.read_text() == run_py.ros2_digest()
    run_py.calls.clear()
    run_py.ensure_ros2_environment()  # up to date: nothing installed again
    assert run_py.calls == []


def test_new_ros2_pins_reinstall_and_a_half_made_environment_is_rebuilt(run_py):
    run_py.ensure_ros2_environment()
    run_py.ROS2_CONSTRAINTS.write_text(run_py.ROS2_CONSTRAINTS.read_text() + "# changed\n")
    run_py.calls.clear()
    run_py.ensure_ros2_environment()
    assert run_py.calls, "changed pins did not reinstall"
    run_py.ROS2_STAMP.unlink()  # an installation that did not finish
    marker = run_py.ROS2_VENV / "left-over"
    marker.write_text("x")
    run_py.ensure_ros2_environment()
    assert not marker.exists() and run_py.ROS2_STAMP.exists()


def test_an_environment_of_another_python_is_rebuilt(run_py):
    run_py.ensure_ros2_environment()
    cfg = run_py.ROS2_VENV / "pyvenv.cfg"
    cfg.write_text("home = /usr/bin\nversion = 3.9.2\n")
    run_py.ensure_ros2_environment()
    assert "3.9.2" not in cfg.read_text()


def test_a_folder_that_is_not_a_venv_is_left_alone(run_py):
    run_py.ROS2_VENV.mkdir()
    (run_py.ROS2_VENV / "notes.txt").write_text("mine")
    with pytest.raises(run_py.SetupError, match="does not look like a virtual environment"):
        run_py.ensure_ros2_environment()
    assert (run_py.ROS2_VENV / "notes.txt").exists()


def test_the_test_task_goes_on_when_the_ros2_environment_cannot_be_made(run_py, monkeypatch, capsys, tmp_path):
    log = tmp_path / "install.log"
    log.write_text("ERROR: No matching distribution found for ros-rclpy\n")

    def fail():
        raise run_py.InstallFailed("installing planhrc into .venv-ros2", 1, log)

    monkeypatch.setattr(run_py, "ensure_ros2_environment", fail)
    run_py.try_ros2_environment()
    err = capsys.readouterr().err
    assert "The ROS 2 tests will skip" in err and "No matching distribution found for ros-rclpy" in err

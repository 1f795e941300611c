"""The project as a user installs it: a wheel built from the repository, installed into a fresh venv, used
from an unrelated directory.

The wheel is built without dependencies and installed with `--no-deps`; the fresh venv sees the already
resolved dependencies of the test environment through one `.pth` line (their site-packages folder only, so the
repository's editable install is not visible there). `pip check` then proves the wheel's declared requirements
are met by that set. What this test guards is the project's own packaging: one `planhrc` namespace, the TBox and
other data files as package data, every source module in the wheel, and a build that setuptools accepts without a
warning (a deprecation today is a build that stops working on a later setuptools).
"""
from __future__ import annotations

import json
import os
import re
import socket
import subprocess
import sys
import sysconfig
import time
import urllib.request
import zipfile
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
# repository folder -> package it installs as
PACKAGE_DIRS = {
    "planhrc": "planhrc",
    "kb_service": "planhrc/kb_service",
    "translator": "planhrc/translator",
    "planner": "planhrc/planner",
    "robot_sim": "planhrc/robot_sim",
    "ontology": "planhrc/ontology",
    "pipeline": "planhrc/pipeline",
    "bench": "planhrc/bench",
}
# What the build backend says when the project's configuration is one it means to stop accepting: deprecations
# (`project.license` as a table), folders of data it "would ignore" as packages, and any other warning it prints.
BUILD_WARNING = re.compile(r"warning|deprecat|would be ignored|absent from", re.IGNORECASE)
# pip's own words about this machine's package index configuration (an extra index folder without the project
# being looked up), said while it installs the build's requirements: not the build's, and not the project's.
PIP_INDEX_NOTE = re.compile(r"WARNING: Location '[^']*' is ignored: it is neither a file nor a directory")

pytestmark = [pytest.mark.slow, pytest.mark.integration]


@pytest.fixture(scope="module")
def build(tmp_path_factory) -> tuple[Path, str]:
    """The wheel, built as `pip wheel -v --no-deps` builds it, and everything the build printed."""
    out = tmp_path_factory.mktemp("wheel")
    # PYTHONDONTWRITEBYTECODE (set on some machines) makes setuptools say "byte-compiling is disabled, skipping"
    # although a wheel holds no byte code either way: a word about the environment, not the project
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    result = subprocess.run([sys.executable, "-m", "pip", "wheel", "-v", "--no-deps", "-w", str(out), str(REPO)],
                            cwd=out, env=env, capture_output=True, text=True, timeout=600)
    log = result.stdout + result.stderr
    assert result.returncode == 0, log[-4000:]
    (built,) = out.glob("planhrc-*.whl")
    return built, log


@pytest.fixture(scope="module")
def wheel(build: tuple[Path, str]) -> Path:
    return build[0]


def build_warnings(log: str) -> list[str]:
    return [line.strip() for line in log.splitlines() if BUILD_WARNING.search(line) and not PIP_INDEX_NOTE.search(line)]


def test_the_build_says_no_warning(build: tuple[Path, str]):
    warnings = build_warnings(build[1])
    assert not warnings, "the build warns:\n" + "\n".join(warnings[:20])


def test_the_build_warning_filter_catches_what_setuptools_says():
    """The filter above against lines setuptools printed for this project's earlier configuration, and pip's
    index note that it must let pass."""
    said = [
        "/tmp/x/setuptools/config/_apply_pyprojecttoml.py:82: BuildBackendWarning: `project.license` as a TOML "
        "table is deprecated",
        "        By 2027-Feb-18, you need to update your project and remove deprecated calls",
        "/tmp/x/setuptools/command/build_py.py:215: BuildBackendWarning: Package 'planhrc.kb_service.console' is "
        "absent from the `packages` configuration.",
        "        # Package would be ignored #",
        "  SetuptoolsDeprecationWarning: License classifiers are deprecated.",
    ]
    pip_note = "  WARNING: Location 'file:///srv/simple/wheel/' is ignored: it is neither a file nor a directory."
    assert build_warnings("\n".join([*said, pip_note, "  copying planner/ground.py -> build/lib"])) == [
        line.strip() for line in said]


def test_the_wheel_declares_its_license_as_spdx(wheel: Path):
    archive = zipfile.ZipFile(wheel)
    (metadata,) = [n for n in archive.namelist() if n.endswith(".dist-info/METADATA")]
    headers = archive.read(metadata).decode().split("\n\n", 1)[0].splitlines()
    assert "License-Expression: MIT" in headers and not any(h.startswith("License: ") for h in headers)
    assert any(n.endswith(".dist-info/licenses/LICENSE") for n in archive.namelist())


@pytest.fixture(scope="module")
def venv_bin(wheel: Path, tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("venv")
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(root / "v")], check=True)
    py = root / "v" / "bin" / "python"
    site = subprocess.run([str(py), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                          check=True, capture_output=True, text=True).stdout.strip()
    (Path(site) / "planhrc-test-dependencies.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    subprocess.run([sys.executable, "-m", "pip", "--python", str(py), "install", "--quiet", "--no-deps",
                    str(wheel)], check=True)
    return root / "v" / "bin"


def _run(bin_dir: Path, cwd: Path, *args: str, timeout: float = 180) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if not k.startswith("PLANHRC_") and k != "PYTHONPATH"}
    return subprocess.run([str(bin_dir / "planhrc"), *args], cwd=cwd, env=env, capture_output=True, text=True,
                          timeout=timeout)


def test_wheel_holds_one_namespace_and_every_module(wheel: Path):
    names = set(zipfile.ZipFile(wheel).namelist())
    tops = {n.split("/")[0] for n in names if not n.split("/")[0].endswith(".dist-info")}
    assert tops == {"planhrc"}
    assert "planhrc/ontology/planhrc.owl" in names
    assert "planhrc/py.typed" in names
    assert "planhrc/planner/valfork.c" in names  # VAL's fork server is compiled from it where it runs
    for data in ("index.html", "console.js", "console.css"):
        assert f"planhrc/kb_service/console/{data}" in names
    for folder, package in PACKAGE_DIRS.items():
        for source in (REPO / folder).rglob("*.py"):
            if "__pycache__" in source.parts:
                continue
            relative = source.relative_to(REPO / folder).as_posix()
            assert f"{package}/{relative}" in names, f"{folder}/{relative} is not in the wheel"


def test_installed_wheel_runs_from_another_directory(venv_bin: Path, tmp_path: Path):
    python = str(venv_bin / "python")
    check = subprocess.run([sys.executable, "-m", "pip", "--python", python, "check"], capture_output=True,
                           text=True)
    assert check.returncode == 0, check.stdout + check.stderr
    where = subprocess.run([python, "-c", "import planhrc.paths as p; print(p.default_tbox_path())"], cwd=tmp_path,
                           capture_output=True, text=True, check=True).stdout.strip()
    assert not where.startswith(str(REPO)), where

    solve = _run(venv_bin, tmp_path, "solve", "--formulation", "relative", "--orientations", "4",
                 "--init", "0,0,0", "--goal", "90,180,0", "--json")
    assert solve.returncode == 0, solve.stderr
    report = json.loads(solve.stdout)
    assert report["status"] == "solved" and len(report["plan"]) == 3

    for name in ("domain-relative.pddl", "problem-relative-3x4.pddl"):
        (tmp_path / name).write_text((REPO / "tests" / "data" / name).read_text())
    plan = _run(venv_bin, tmp_path, "plan", "domain-relative.pddl", "problem-relative-3x4.pddl", "--json")
    assert plan.returncode == 0, plan.stderr
    assert json.loads(plan.stdout)["status"] == "solved"

    check_onto = _run(venv_bin, tmp_path, "ontology", "check")
    assert check_onto.returncode == 0, check_onto.stderr
    assert "consistent" in check_onto.stdout


def test_installed_wheel_serves_health(venv_bin: Path, tmp_path: Path):
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    env = {k: v for k, v in os.environ.items() if not k.startswith("PLANHRC_") and k != "PYTHONPATH"}
    proc = subprocess.Popen([str(venv_bin / "planhrc"), "serve", "--port", str(port), "--db", "kb.sqlite3"],
                            cwd=tmp_path, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 60
        body = None
        while time.monotonic() < deadline and proc.poll() is None:
            try:
                with urllib.request.urlopen(f"http://127.0.0.1:{port}/health", timeout=2) as r:
                    body = json.loads(r.read())
                break
            except OSError:
                time.sleep(0.2)
        assert body is not None, proc.stderr.read() if proc.poll() is not None else "no answer within 60 s"
        assert body["status"] == "ok"
    finally:
        proc.terminate()
        proc.wait(timeout=20)
    assert (tmp_path / "kb.sqlite3").exists()

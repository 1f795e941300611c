"""mypy over every package, as the package is installed (`planhrc.translator`, not `translator`).

The repository keeps its folders (`translator/`, `planner/`, ...) and maps them into one `planhrc` namespace;
mypy reads modules by path, so the test lays out that namespace in a temporary folder of symbolic links taken from
`pyproject.toml`'s own mapping and runs mypy on it with the configuration in `pyproject.toml` (strict on the
model, the cooperation model, the translator, the planner, the pipeline and the service but its store).
"""
from __future__ import annotations

import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent

pytestmark = pytest.mark.slow


def stage_namespace(target: Path) -> Path:
    """`target/planhrc/...` as the wheel installs it, made of links to the repository's folders."""
    config = tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["setuptools"]
    package_dir: dict[str, str] = config["package-dir"]
    root = target / "planhrc"
    root.mkdir(parents=True)
    for entry in (REPO / package_dir["planhrc"]).iterdir():
        if entry.name != "__pycache__":
            (root / entry.name).symlink_to(entry)
    for package, folder in package_dir.items():
        if package != "planhrc":
            (root / package.split(".", 1)[1]).symlink_to(REPO / folder)
    return target


def test_mypy_finds_no_error(tmp_path: Path):
    stage = stage_namespace(tmp_path / "stage")
    result = subprocess.run(
        [sys.executable, "-m", "mypy", "--config-file", str(REPO / "pyproject.toml"),
         "--cache-dir", str(tmp_path / "cache"), "-p", "planhrc"],
        cwd=stage, capture_output=True, text=True, timeout=600,
    )
    assert result.returncode == 0, result.stdout[-6000:] + result.stderr[-2000:]

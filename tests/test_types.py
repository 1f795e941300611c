"""mypy over every package, as the package is installed (`planhrc.translator`, not `translator`).

The repository keeps its folders (`translator/`, `planner/`, ...) and maps them into one `planhrc` namespace;
mypy reads modules by path, so the test lays out that namespace in a temporary folder of symbolic links taken from
`pyproject.toml`'s own mapping and runs mypy on it with the configuration in `pyproject.toml`: strict (every option
of `mypy --strict`) on every module, a missing import an error except for the dependencies that ship no types.
"""
from __future__ import annotations

import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

from tests.test_layers import modules

REPO = Path(__file__).resolve().parent.parent
MYPY = tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["mypy"]
# What `mypy --strict` turns on beyond the global section's own options.
STRICT = ("disallow_untyped_defs", "disallow_incomplete_defs", "disallow_untyped_calls", "disallow_untyped_decorators",
          "disallow_any_generics", "disallow_subclassing_any", "warn_return_any", "no_implicit_reexport",
          "strict_equality", "extra_checks")
GLOBAL_STRICT = ("warn_unused_configs", "check_untyped_defs", "warn_redundant_casts", "warn_unused_ignores")
# Packages whose strict blocks are still to come (their modules have untyped definitions today).
NOT_YET_STRICT: tuple[str, ...] = ()


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


def matches(module: str, pattern: str) -> bool:
    """mypy's override patterns: `a.b` names one module, `a.b.*` the package and everything below it."""
    if pattern.endswith(".*"):
        return module == pattern[:-2] or module.startswith(pattern[:-1])
    return module == pattern


def test_every_module_is_strict_but_those_still_to_come():
    strict = [pattern for block in MYPY["overrides"] if block.get("disallow_untyped_defs")
              for pattern in block["module"]]
    lax = [m for m in modules() if not any(matches(m, p) for p in strict)
           and not any(m == p or m.startswith(p + ".") for p in NOT_YET_STRICT)]
    assert lax == [], f"modules without a strict override: {lax}"
    assert all(MYPY.get(option) for option in GLOBAL_STRICT)
    for block in MYPY["overrides"]:
        if block.get("disallow_untyped_defs"):
            assert all(block.get(option) for option in STRICT), block["module"]


def test_only_untyped_dependencies_may_be_missing():
    """An import of ours that does not resolve is an error: no global `ignore_missing_imports`, and the overrides
    that set it name third-party modules only."""
    assert "ignore_missing_imports" not in MYPY
    for block in MYPY["overrides"]:
        if block.get("ignore_missing_imports"):
            assert not any(matches("planhrc.x", p) or p.startswith("planhrc") for p in block["module"])


@pytest.mark.slow
def test_mypy_finds_no_error(tmp_path: Path):
    stage = stage_namespace(tmp_path / "stage")
    result = subprocess.run(
        [sys.executable, "-m", "mypy", "--config-file", str(REPO / "pyproject.toml"),
         "--cache-dir", str(tmp_path / "cache"), "-p", "planhrc"],
        cwd=stage, capture_output=True, text=True, timeout=600,
    )
    assert result.returncode == 0, result.stdout[-6000:] + result.stderr[-2000:]

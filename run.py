#!/usr/bin/env python3
"""Set up `.venv` at the repository root (once, or again when pyproject.toml changes) and run a task.

    python3 ./run.py demo [ARGS...]   # the main job: `planhrc demo` on the embedded store
    python3 ./run.py test [ARGS...]   # the whole test suite (every marker)
    python3 ./run.py planhrc ARGS...  # any `planhrc` command inside the environment

Only the standard library is used here, so this works from a fresh clone with nothing but python3.
"""
from __future__ import annotations

import hashlib
import os
import subprocess
import sys
import venv
from pathlib import Path

ROOT = Path(__file__).resolve().parent
VENV = ROOT / ".venv"
STAMP = VENV / ".planhrc-installed"
CHROMIUM = Path("/usr/bin/chromium")


def venv_python() -> Path:
    return VENV / ("Scripts/python.exe" if os.name == "nt" else "bin/python")


def requirements_digest() -> str:
    return hashlib.sha256((ROOT / "pyproject.toml").read_bytes()).hexdigest()


def ensure_environment() -> Path:
    """Create `.venv` and install the project (editable, with test extras) when it is missing or stale."""
    digest = requirements_digest()
    if STAMP.exists() and STAMP.read_text().strip() == digest and venv_python().exists():
        return venv_python()
    if not venv_python().exists():
        print("[run.py] creating .venv", flush=True)
        venv.EnvBuilder(with_pip=True).create(VENV)
    py = str(venv_python())
    print("[run.py] installing planhrc and its dependencies into .venv", flush=True)
    subprocess.run([py, "-m", "pip", "install", "--quiet", "--upgrade", "pip"], check=True)
    subprocess.run([py, "-m", "pip", "install", "--quiet", "-e", f"{ROOT}[test]"], check=True)
    STAMP.write_text(digest)
    return venv_python()


def ensure_chromium() -> None:
    """The browser tests drive Debian's Chromium: install the `chromium` package when it is missing and apt is
    usable (as root). Otherwise say why; those tests then skip with the same reason."""
    if CHROMIUM.exists():
        return
    if os.name != "posix" or os.geteuid() != 0 or not Path("/usr/bin/apt-get").exists():
        print(f"[run.py] {CHROMIUM} is missing and apt-get cannot be used here (needs root on Debian): "
              "the browser tests will skip", flush=True)
        return
    print("[run.py] installing Debian's chromium for the browser tests", flush=True)
    env = {**os.environ, "DEBIAN_FRONTEND": "noninteractive"}
    ok = subprocess.run(["apt-get", "update", "-qq"], env=env).returncode == 0 and subprocess.run(
        ["apt-get", "install", "-y", "-qq", "--no-install-recommends", "chromium"], env=env).returncode == 0
    if not ok or not CHROMIUM.exists():
        print("[run.py] installing chromium failed: the browser tests will skip", flush=True)


def main(argv: list[str]) -> int:
    if not argv or argv[0] in {"-h", "--help"}:
        print(__doc__)
        return 0
    task, rest = argv[0], argv[1:]
    py = str(ensure_environment())
    if task == "setup":
        return 0
    if task == "test":
        ensure_chromium()
        cmd = [py, "-m", "pytest", *rest]
    elif task == "demo":
        cmd = [py, "-m", "planhrc.cli", "demo", *rest]
    elif task == "planhrc":
        cmd = [py, "-m", "planhrc.cli", *rest]
    else:
        print(f"[run.py] unknown task {task!r}; use demo, test, setup or planhrc", file=sys.stderr)
        return 2
    return subprocess.run(cmd, cwd=ROOT).returncode


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

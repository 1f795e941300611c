"""Print the requirements of planhrc's core and the given extras, one a line, from pyproject.toml.

The images install these (pinned by constraints.txt) in a layer of their own, before the sources are copied,
so a change to the code does not reinstall the dependencies:

    python requirements.py            # the core: the KB service
    python requirements.py sim        # the core and the simulator extra: the worker
"""
import sys
import tomllib
from pathlib import Path


def requirements(extras: list[str], pyproject: Path = Path("pyproject.toml")) -> list[str]:
    project = tomllib.loads(pyproject.read_text(encoding="utf-8"))["project"]
    optional = project.get("optional-dependencies", {})
    unknown = [e for e in extras if e not in optional]
    if unknown:
        raise SystemExit(f"requirements.py: unknown extra(s) {', '.join(unknown)}; choose from {', '.join(optional)}")
    lines = list(project["dependencies"])
    for extra in extras:
        lines += [r for r in optional[extra] if not r.startswith(project["name"] + "[")]
    return lines


if __name__ == "__main__":
    print("\n".join(requirements(sys.argv[1:])))

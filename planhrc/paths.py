"""Where the project's data files are: they travel as package data and are found with `importlib.resources`,
so a wheel installed anywhere finds them as a source checkout does."""
from __future__ import annotations

import os
from importlib import resources
from pathlib import Path

from planhrc.errors import PlanhrcError


class DataFileError(PlanhrcError, FileNotFoundError):
    """A data file that should ship with the package is not there (a broken install)."""


def package_file(package: str, name: str) -> Path:
    """The file `name` shipped inside `package`, as a real path (pip installs packages as plain folders)."""
    traversable = resources.files(package) / name
    path = Path(str(traversable))
    if not path.is_file():
        raise DataFileError(f"{name} is missing from the installed package {package}")
    return path


def default_tbox_path() -> Path:
    """The TBox shipped with the package: `planhrc/ontology/planhrc.owl` (the repository's `ontology/`)."""
    return package_file("planhrc.ontology", "planhrc.owl")


def cache_folder() -> Path | None:
    """The user's cache folder for planhrc (made, private), or None when it cannot be."""
    base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    folder = base / "planhrc"
    try:
        folder.mkdir(mode=0o700, parents=True, exist_ok=True)
        if folder.stat().st_uid != os.getuid() or not os.access(folder, os.W_OK):
            return None
    except OSError:
        return None
    return folder

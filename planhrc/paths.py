"""Where the project's files are: the TBox ships in the repository's `ontology/` folder."""
from __future__ import annotations

from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parent.parent


def default_tbox_path() -> Path:
    return REPO_ROOT / "ontology" / "planhrc.owl"

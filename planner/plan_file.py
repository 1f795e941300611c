"""Read plan files written by external planners into lower-case "(action arg ...)" steps."""
from __future__ import annotations

import re
from pathlib import Path

_STEP = re.compile(r"\(\s*([^()\s][^()]*?)\s*\)")
_NUMBERED = re.compile(r"^\s*(?:step\s+)?\d+(?:\.\d+)?\s*:\s*(.*)$", re.IGNORECASE)


def parse_plan_text(text: str) -> tuple[str, ...]:
    """One step per "(name args)" group; ';' comments, "N:" / "STEP N:" prefixes and "[duration]" dropped.

    Also accepts bare "name arg ..." lines after a numbered prefix (some planners omit parentheses).
    """
    steps: list[str] = []
    for raw in text.splitlines():
        line = raw.split(";", 1)[0].strip()
        if not line:
            continue
        numbered = _NUMBERED.match(line)
        body = numbered.group(1) if numbered else line
        body = re.sub(r"\[[^\]]*\]", "", body).strip()
        groups = _STEP.findall(body)
        if groups:
            steps.extend("(" + " ".join(g.lower().split()) + ")" for g in groups)
        elif numbered and body:
            steps.append("(" + " ".join(body.lower().split()) + ")")
    return tuple(steps)


def find_plan_files(directory: Path, stem: str) -> list[Path]:
    """`stem` itself, or anytime-planner files `stem.1`, `stem.2`, ... in numeric order."""
    numbered = []
    for path in directory.glob(stem + ".*"):
        suffix = path.name[len(stem) + 1:]
        if suffix.isdigit():
            numbered.append((int(suffix), path))
    found = [p for _, p in sorted(numbered)]
    single = directory / stem
    if single.is_file():
        found.append(single)
    return found


def read_best_plan(directory: Path, stem: str) -> tuple[str, ...] | None:
    """The last plan an anytime planner wrote (its best), or the single plan file; None when there is none."""
    files = find_plan_files(directory, stem)
    if not files:
        return None
    return parse_plan_text(files[-1].read_text(errors="replace"))

"""Whether a process still runs, as the tests that kill services and their children look at it (Linux /proc)."""
from __future__ import annotations

from pathlib import Path


def alive(pid: int) -> bool:
    """The process exists and has not ended (a zombie, Z, or a dead task, X, has)."""
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state not in ("Z", "X")

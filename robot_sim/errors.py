"""The root of the simulator's errors (the scene, perception, skills, the human, the worker and the demo)."""
from __future__ import annotations

from planhrc.errors import PlanhrcError


class SimError(PlanhrcError):
    """Root of the simulator's errors; the message names the offending field or value."""

"""The root of the benchmarks' errors."""
from __future__ import annotations

from planhrc.errors import PlanhrcError


class BenchError(PlanhrcError):
    """A benchmark cannot go on or its records cannot be read; the message says which run or field."""

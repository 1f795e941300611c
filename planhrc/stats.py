"""Summary statistics the benchmarks report: the one percentile helper of the project, and the machine's name."""
from __future__ import annotations

import platform
from pathlib import Path
from typing import Sequence


def percentile(values: Sequence[float], q: float) -> float:
    """The q-quantile (q in 0..1) by linear interpolation between the closest ranks; NaN for no values."""
    if not values:
        return float("nan")
    ordered = sorted(values)
    k = (len(ordered) - 1) * q
    lo, hi = int(k), min(int(k) + 1, len(ordered) - 1)
    return ordered[lo] + (ordered[hi] - ordered[lo]) * (k - lo)


def cpu_model() -> str:
    """The processor's model name (Linux /proc/cpuinfo), what a measured number is said to come from."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"

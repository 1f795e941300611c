"""Pictures of the planning benchmark: every run drawn, timeouts included, one y-scale per figure pair.

`plot_times(rows, out_dir)` writes `times-<formulation>-<planner>.png` for every (formulation, planner) in the
rows. A row is any record with `formulation`, `planner`, `links`, `orientations`, `status` and `seconds` (the
bench's `Row`, or a line of its CSV). Each run is one dot (no box drawn from two samples); runs are grouped by
number of links on the x axis and coloured by number of orientations K. A run that did not solve (timeout,
unsolvable, error) is drawn as a cross at the time it used, on a line marking the time limit, and counted in
the title: nothing is dropped. The two formulations of one planner share their y-scale, so the pair can be
compared by eye.

    python -m planhrc.bench.plots docs/results/bench.csv [--out DIR] [--timeout S]

redraws the figures from a bench CSV without planning again.
"""
from __future__ import annotations

import argparse
import csv
import math
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Iterable, Sequence

from planhrc.bench.errors import BenchError
from planhrc.vocabulary import PlanStatus, one_of

if TYPE_CHECKING:
    from matplotlib.figure import Figure

K_COLOURS = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f")


class PlotError(BenchError):
    """A benchmark record cannot be drawn (a field is missing or not a number)."""


@dataclass(frozen=True)
class Run:
    """One planner call as the plots need it."""

    formulation: str
    planner: str
    links: int
    orientations: int
    status: PlanStatus
    seconds: float


def run_from(record: Any) -> Run:
    """A `Run` from a bench `Row` or a CSV dict; PlotError names the field that is wrong."""
    get: Callable[[str], Any] = record.get if isinstance(record, dict) else lambda key: getattr(record, key, None)
    values: dict[str, Any] = {}
    fields: tuple[tuple[str, Callable[[Any], Any], str], ...] = (
        ("formulation", str, "str"), ("planner", str, "str"), ("links", int, "int"), ("orientations", int, "int"),
        ("status", PlanStatus, one_of(PlanStatus)), ("seconds", float, "float"))
    for field, kind, expected in fields:
        raw: Any = get(field)
        try:
            values[field] = kind(raw)
        except (TypeError, ValueError):
            raise PlotError(f"{field}: expected {expected}, got {raw!r}") from None
    if not math.isfinite(values["seconds"]) or values["seconds"] < 0:
        raise PlotError(f"seconds: expected a finite time >= 0, got {values['seconds']!r}")
    return Run(**values)


def read_csv(path: Path) -> list[Run]:
    with path.open(newline="") as fh:
        return [run_from(row) for row in csv.DictReader(fh)]


def plot_times(rows: Iterable[Any], out_dir: Path, timeout_s: float | None = None) -> list[Path]:
    """Write one figure per (formulation, planner); the formulations of a planner share one y-scale."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    runs = [run_from(r) for r in rows]
    if not runs:
        return []
    limit = timeout_s if timeout_s is not None else max(
        (r.seconds for r in runs if r.status is not PlanStatus.SOLVED), default=None)
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = []
    for planner in sorted({r.planner for r in runs}):
        mine = [r for r in runs if r.planner == planner]
        low, high = _y_range(mine, limit)
        for formulation in sorted({r.formulation for r in mine}):
            sel = [r for r in mine if r.formulation == formulation]
            fig = _figure(sel, formulation, planner, limit, low, high)
            path = out_dir / f"times-{formulation}-{planner}.png"
            fig.savefig(path, dpi=120)
            plt.close(fig)
            paths.append(path)
    return paths


def _y_range(runs: Sequence[Run], limit: float | None) -> tuple[float, float]:
    """Log-scale bounds that hold every run of a planner (both formulations) and the time limit."""
    times = [max(r.seconds, 1e-5) for r in runs] + ([limit] if limit else [])
    return 10 ** math.floor(math.log10(min(times))), 10 ** math.ceil(math.log10(max(times) * 1.5))


def _figure(runs: Sequence[Run], formulation: str, planner: str, limit: float | None, low: float, high: float
            ) -> Figure:
    import matplotlib.pyplot as plt

    links = sorted({r.links for r in runs})
    ks = sorted({r.orientations for r in runs})
    width = 0.8 / max(len(ks), 1)
    fig, ax = plt.subplots(figsize=(max(8.0, 0.55 * len(links) + 2), 4.5))
    unsolved = [r for r in runs if r.status is not PlanStatus.SOLVED]
    for j, k in enumerate(ks):
        colour = K_COLOURS[j % len(K_COLOURS)]
        for solved, marker in ((True, "o"), (False, "x")):
            sel = [r for r in runs if r.orientations == k and (r.status is PlanStatus.SOLVED) == solved]
            if not sel:
                continue
            xs = [links.index(r.links) - 0.4 + width * (j + 0.5) for r in sel]
            ys = [max(r.seconds, low) for r in sel]
            ax.scatter(xs, ys, s=16 if solved else 36, marker=marker, color=colour, alpha=0.8,
                       linewidths=1.5 if not solved else 0,
                       label=f"K = {k}" if solved else None)
    if limit:
        ax.axhline(limit, color="#c62828", linestyle="--", linewidth=1)
        ax.text(-0.5, limit * 1.08, f"time limit {limit:.3g} s", color="#c62828", va="bottom", ha="left", fontsize=9)
    ax.set_ylim(low, high)
    ax.set_yscale("log")
    ax.set_xticks(range(len(links)), [str(n) for n in links], fontsize=10)
    ax.set_xlim(-0.6, len(links) - 0.4)
    for i in range(len(links) - 1):
        ax.axvline(i + 0.5, color="#dddddd", linewidth=0.6)
    ax.set_xlabel("links (each group: K orientations, by colour)", fontsize=10)
    ax.set_ylabel("planner time per run (s, log)", fontsize=10)
    ax.tick_params(axis="y", labelsize=10)
    counts = ", ".join(f"{n} {status}" for status, n in sorted(_count(unsolved).items()))
    ax.set_title(f"{formulation} formulation, {planner}: {len(runs) - len(unsolved)}/{len(runs)} solved"
                 + (f" ({counts})" if counts else ""), fontsize=11)
    if unsolved:
        ax.scatter([], [], s=36, marker="x", color="black", linewidths=1.5, label="not solved (× at its time)")
    ax.legend(fontsize=8, ncol=len(ks) + 1, loc="upper right", framealpha=0.9)
    fig.tight_layout()
    return fig


def _count(runs: Sequence[Run]) -> dict[str, int]:
    out: dict[str, int] = {}
    for r in runs:
        out[r.status] = out.get(r.status, 0) + 1
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m planhrc.bench.plots", description=__doc__.splitlines()[0])
    parser.add_argument("csv", type=Path, help="bench.csv written by `planhrc bench`")
    parser.add_argument("--out", type=Path, default=None, help="folder for the figures (default: beside the CSV)")
    parser.add_argument("--timeout", type=float, default=None, help="the bench's time limit (default: the "
                        "longest unsolved run)")
    args = parser.parse_args(argv)
    try:
        runs = read_csv(args.csv)
    except (OSError, PlotError) as exc:
        print(f"planhrc.bench.plots: {args.csv}: {exc}", file=sys.stderr)
        return 2
    for path in plot_times(runs, args.out or args.csv.parent, args.timeout):
        print(path)
    return 0


if __name__ == "__main__":
    sys.exit(main())

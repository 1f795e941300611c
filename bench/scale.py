"""`planhrc bench --scale`: how the in-process stages (grounding, planning, VAL, the whole loop) grow with links
and orientations, beyond the paper's sizes; a table and a plot (`bench.grid` runs it)."""
from __future__ import annotations

import logging
from pathlib import Path
from typing import Any, Sequence

log = logging.getLogger(__name__)

SCALE_LINKS = (20, 50, 100, 200)
SCALE_ORIENTATIONS = (12, 36, 72)


def scale_report(formulations: Sequence[str], links: Sequence[int], orientations: Sequence[int], runs: int,
                 val_timeout_s: float) -> dict[str, Any]:
    """Every cell validates one plan; once VAL times out for a formulation and orientation count, larger
    cells skip VAL (and say so) instead of waiting for it again."""
    from planhrc.bench.grid import machine_info, measure_planner

    rows = []
    for f in formulations:
        for k in orientations:
            val_failed_at = None
            for n in links:
                validate = val_failed_at is None
                row = measure_planner(f, n, k, runs=runs, val_timeout_s=val_timeout_s, validate=validate, val_runs=1)
                if not validate:
                    row["validation"] = f"skipped: VAL timed out at {val_failed_at} links"
                elif row["validation"].startswith("VAL timeout"):
                    val_failed_at = n
                log.info("scale %s %dx%d: ground %.1f ms, %s", f, n, k, row["ground_ms"], row.get("validation"))
                rows.append(row)
    return {"machine": machine_info(), "rows": rows}


def scale_table(report: dict[str, Any]) -> str:
    """Medians in ms. "solve from text" is `InprocPlanner.solve` on a new problem text (parse, memoised
    grounding, plan); "loop" adds VAL, and is shown only where VAL ran."""
    lines = [f"machine: {report['machine']['cpu']}, {report['machine']['cores']} cores; medians in ms",
             "| formulation | links | orientations | ground (once) | plan | solve from text | VAL | loop | "
             "plan length | VAL's verdict |", "|---|---|---|---|---|---|---|---|---|---|"]
    for r in report["rows"]:
        validated = r.get("validation") == "valid"
        val = r["validate"]["median_ms"] if validated else "-"
        loop = r["inproc_loop"]["median_ms"] if validated else "-"
        lines.append(f"| {r['formulation']} | {r['links']} | {r['orientations']} | {r['ground_ms']} | "
                     f"{r['plan']['median_ms']} | {r['solve_from_text']['median_ms']} | {val} | {loop} | "
                     f"{r['median_plan_length']} | {r.get('validation', '-')} |")
    return "\n".join(lines)


def scale_plot(report: dict[str, Any], path: Path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = report["rows"]
    formulations = sorted({r["formulation"] for r in rows})
    stages = (("ground_ms", "ground (once)"), ("plan", "plan"), ("solve_from_text", "solve from text"),
              ("validate", "VAL"))
    fig, axes = plt.subplots(1, len(formulations), figsize=(6 * len(formulations), 4), squeeze=False)
    for ax, f in zip(axes[0], formulations):
        for k in sorted({r["orientations"] for r in rows}):
            sel = sorted((r for r in rows if r["formulation"] == f and r["orientations"] == k), key=lambda r: r["links"])
            for (key, label), style in zip(stages, ("-o", "-s", "-^", "-d")):
                ys = [r[key] if key == "ground_ms" else r.get(key, {}).get("median_ms") for r in sel]
                if key == "validate":
                    ys = [y if r.get("validation") == "valid" else None for r, y in zip(sel, ys)]
                pts = [(r["links"], y) for r, y in zip(sel, ys) if y is not None and y == y]
                if pts:
                    ax.plot(*zip(*pts), style, label=f"{label}, K={k}")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("links")
        ax.set_ylabel("ms (median)")
        ax.set_title(f"{f} formulation")
        ax.legend(fontsize=6, ncol=2)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path

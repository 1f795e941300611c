"""`planhrc robot-bench`: the robot on seeded random tasks, alone and beside the simulated human, each formulation.

Each task is one of the demo's random tasks (`robot_sim.demo.random_scenario`: a feasible start, a feasible goal
with three or more links changed, 5 links x 8 orientations, the object placed with its base point), run twice by
the worker against one `planhrc serve` (a separate process, on the embedded store): once with nobody beside the
robot (`--scenario none`: a help request ends the task) and once with the random human of the demo (three
interventions; the human helps when asked). Per task it records whether the goal was reached, the help requests,
the plan steps the robot executed, the robot's skills (`slides`: slides and straightenings), the states perceived off the table and the time to
the goal; beside them, computed for the task's start by the same pipeline the service runs, the shortest plan with
no table around it (`unconstrained`) and the robot's plan that fits the table (`constrained`: its length, robot time,
and whether the search proved it the least robot time, `exact`).

Writes `robot-bench.json` (every task) and `robot-bench.md` (the table) to `--out`; a benchmark, not a test.
"""
from __future__ import annotations

import argparse
import json
import secrets
import statistics
import sys
import time
from dataclasses import replace
from pathlib import Path
from typing import Any, Sequence

from planhrc.cli_args import SubParsers, http_url, non_negative_int, positive_int, writable_dir
from planhrc.client import ProtocolError
from planhrc.geometry import ObjectGeometry
from planhrc.model import make_object, perceive
from planhrc.ordering import Placement
from planhrc.pipeline import plan as plan_task
from planhrc.robot_sim.demo import RANDOM_FORMULATIONS, DemoScenario, kb_service, random_scenario, run_episode
from planhrc.robot_sim.errors import SimError
from planhrc.robot_sim.scene import SceneSpec
from planhrc.vocabulary import DecisionKind

MODES = ("alone", "human")
INTERVENTIONS = 3  # the human's random moves in a task with the human (as the demo's random scenario)
SEARCH_S = 60.0  # the time the constrained plan of a task's start may take (exact where it finishes)
PERCEPTIONS = 40  # the perceptions a task may take at least (the demo's default)


def perceptions_for(shortest: dict[str, Any]) -> int:
    """The perceptions the worker may take on a task: the demo's 40, or room for the robot's own plan twice over
    (a perception after each step, a re-plan's detour) where that plan is longer: a long bimanual plan (centre,
    grasp, turns, release) is not cut short by the bench."""
    return max(PERCEPTIONS, 2 * (shortest["constrained_steps"] or 0) + 10)


def constrained(formulation: str, orientations: int, start: Sequence[float], goal: Sequence[float],
                base: Sequence[float]) -> dict[str, Any]:
    """The robot's plan for the task from its start, as the service makes it at the first perception (with a
    generous deadline), and the unconstrained shortest: their lengths, robot time, the proof and the slides."""
    obj = make_object("task", formulation, len(start), orientations)
    init = perceive(obj, list(start)).atoms
    goal_atoms = frozenset(a for a in perceive(obj, list(goal)).atoms if a[0] == "hasorientation")
    free = plan_task(obj, init, goal_atoms, deadline_at=time.monotonic() + SEARCH_S)
    placement = Placement(ObjectGeometry.of(obj, (float(base[0]), float(base[1]))), tuple(float(a) for a in start),
                          grid_deg=obj.step)
    t = time.perf_counter()
    placed = plan_task(obj, init, goal_atoms, placement=placement, deadline_at=time.monotonic() + SEARCH_S)
    return {"unconstrained_steps": len(free.actions) if free.solved else None,
            "constrained_steps": len(placed.actions) if placed.solved else None,
            "constrained_validated": placed.validated, "constrained": placed.ordering or placed.message,
            "constrained_exact": "(exhaustive search)" in placed.ordering,
            "constrained_slide": placed.slide is not None, "constrained_later_slides": len(placed.later_slides),
            "search_s": round(time.perf_counter() - t, 3)}


def run_bench(tasks: int, formulations: Sequence[str], modes: Sequence[str], seed: int, out_dir: Path,
              kb_url: str | None = None, token: str | None = None,
              given: Sequence[DemoScenario] | None = None) -> dict[str, Any]:
    """Run the tasks (`given`, else `tasks` random ones per formulation from `seed`) in each mode; write the files."""
    out_dir.mkdir(parents=True, exist_ok=True)
    started = time.perf_counter()
    rows: list[dict[str, Any]] = []
    chosen = list(given) if given is not None else [
        random_scenario(seed + i, formulation=f, interventions=0) for f in formulations for i in range(tasks)]

    def run_all(url: str, tok: str | None) -> None:
        for task in chosen:
            task_seed = int(task.name.rsplit("-", 1)[1])
            shortest = constrained(task.formulation, task.orientations, task.initial_deg, task.goal_deg,
                                   task.base_point_xy or SceneSpec().base_xy)
            for mode in modes:
                scenario = replace(task, human=f"random:{task_seed}:{INTERVENTIONS}" if mode == "human" else "none")
                folder = out_dir / f"{task.formulation}-{mode}-{task_seed:03d}"
                result = run_episode(url, tok, scenario, folder, False, "camera", perceptions_for(shortest), task_seed)
                row = _row(task.formulation, mode, task_seed, scenario.initial_deg, scenario.goal_deg,
                           scenario.base_point_xy, result, shortest)
                rows.append(row)
                print(f"[robot-bench] {task.formulation} {mode} {task_seed}: "
                      f"{'reached' if row['reached'] else row['stop_reason']}, {row['help_requests']} help "
                      f"requests, {row['executed_steps']} steps (constrained {row['constrained_steps']}, "
                      f"unconstrained {row['unconstrained_steps']}), {row['slides']} skills, "
                      f"{row['time_to_goal_s']:.1f} s", flush=True)

    if kb_url is None:
        tok = token or secrets.token_urlsafe(16)
        with kb_service(out_dir, tok) as url:
            run_all(url, tok)
    else:
        run_all(kb_url, token)
    lines = table(rows)
    summary = {"command": " ".join(["planhrc", "robot-bench", *sys.argv[2:]]), "tasks": len(chosen),
               "formulations": list(dict.fromkeys(t.formulation for t in chosen)), "modes": list(modes),
               "seed": seed, "wall_s": round(time.perf_counter() - started, 1), "table": lines, "rows": rows}
    (out_dir / "robot-bench.json").write_text(json.dumps(summary, indent=2))
    (out_dir / "robot-bench.md").write_text(markdown(lines))
    return summary


def tasks_from(path: Path, formulations: Sequence[str]) -> list[DemoScenario]:
    """The tasks of an earlier run (its `robot-bench.json`), once each, of the formulations asked for: the same
    tasks for another build of the robot, side by side."""
    try:
        rows = json.loads(path.read_text())["rows"]
        seen: dict[tuple[str, int], DemoScenario] = {}
        for r in rows:
            if r["formulation"] in formulations and (r["formulation"], int(r["seed"])) not in seen:
                seen[(r["formulation"], int(r["seed"]))] = DemoScenario(
                    f"random-{int(r['seed'])}", r["formulation"], int(r.get("orientations", 8)),
                    tuple(float(v) for v in r["start_deg"]), tuple(float(v) for v in r["goal_deg"]), "none",
                    "a task of an earlier run",
                    base_point_xy=(float(r["base_point_xy"][0]), float(r["base_point_xy"][1]))
                    if r["base_point_xy"] else None)
        return list(seen.values())
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise SimError(f"--tasks-from: cannot read the tasks of {path} ({exc})") from None


def _row(formulation: str, mode: str, seed: int, start: Sequence[float], goal: Sequence[float],
         base: Sequence[float] | None, result: dict[str, Any], shortest: dict[str, Any]) -> dict[str, Any]:
    decisions = result["decision_counts"]
    return {"formulation": formulation, "mode": mode, "seed": seed, "orientations": 8, "start_deg": list(start),
            "goal_deg": list(goal),
            "base_point_xy": list(base) if base else None, "reached": result["reached_goal"],
            "stop_reason": result["stop_reason"], "help_requests": len(result["help_reasons"]),
            "help_reasons": result["help_reasons"], "executed_steps": result["executed_steps"],
            "slides": len(result["robot_skills"]), "states_off_table": result["states_off_table"],
            "time_to_goal_s": result["time_to_goal_s"], "replans": decisions.get(DecisionKind.REPLAN, 0),
            "human_assists": result["human_assists"], "actions": len(result["actions"]),
            # the service's plans: proved the least robot time (exhaustive search) or within a stated bound
            "plans_exact": sum("(exhaustive search)" in d["reason"] for d in result["decisions"]),
            "plans_bounded": sum("x the least robot time the table allows" in d["reason"] for d in result["decisions"]),
            **shortest}


def table(rows: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """One line per formulation and mode: the figures the issue's targets are judged by."""
    out = []
    for formulation in dict.fromkeys(r["formulation"] for r in rows):
        for mode in dict.fromkeys(r["mode"] for r in rows):
            mine = [r for r in rows if r["formulation"] == formulation and r["mode"] == mode]
            if not mine:
                continue
            done = [r for r in mine if r["reached"] and not r["help_requests"]]
            measured = [r for r in done if r["constrained_steps"] is not None]
            times = [r["time_to_goal_s"] for r in done]
            out.append({
                "formulation": formulation, "mode": mode, "tasks": len(mine),
                "reached_without_help": len(done), "reached": sum(r["reached"] for r in mine),
                "help_requests": sum(r["help_requests"] for r in mine),
                "executed_steps": sum(r["executed_steps"] for r in measured),
                "constrained_steps": sum(r["constrained_steps"] for r in measured),
                "unconstrained_steps": sum(r["unconstrained_steps"] or 0 for r in measured),
                "constrained_exact": sum(r["constrained_exact"] for r in measured),
                "slides": sum(r["slides"] for r in mine),
                "plans_exact": sum(r.get("plans_exact", 0) for r in mine),
                "plans_bounded": sum(r.get("plans_bounded", 0) for r in mine),
                "states_off_table": sum(r["states_off_table"] for r in mine),
                "time_to_goal_median_s": round(statistics.median(times), 1) if times else None,
            })
    return out


def markdown(lines: Sequence[dict[str, Any]]) -> str:
    head = ("| formulation | beside it | reached without a help request | help requests | executed steps | "
            "constrained shortest (exact) | ratio | unconstrained shortest | skills (slides, straightenings) | "
            "states off the table | time to goal, median s | plans: exact, bounded |\n"
            "|---|---|---|---|---|---|---|---|---|---|---|---|\n")
    body = ""
    for line in lines:
        ratio = (f"{line['executed_steps'] / line['constrained_steps']:.2f}" if line["constrained_steps"] else "-")
        body += (f"| {line['formulation']} | {'nobody' if line['mode'] == 'alone' else 'the human'} | "
                 f"{line['reached_without_help']}/{line['tasks']} | {line['help_requests']} | {line['executed_steps']} | "
                 f"{line['constrained_steps']} ({line['constrained_exact']}) | {ratio} | {line['unconstrained_steps']} | "
                 f"{line['slides']} | {line['states_off_table']} | {line['time_to_goal_median_s']} | "
                 f"{line['plans_exact']}, {line['plans_bounded']} |\n")
    return head + body


def add_robot_bench_parser(subparsers: SubParsers) -> None:
    p = subparsers.add_parser("robot-bench", help="the robot on seeded random tasks, alone and beside the human",
                              description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--tasks", type=positive_int, default=20, help="random tasks per formulation")
    p.add_argument("--formulations", default=",".join(RANDOM_FORMULATIONS),
                   help=f"comma-separated, from {', '.join(RANDOM_FORMULATIONS)}")
    p.add_argument("--modes", default=",".join(MODES), help="alone, human or both (comma-separated)")
    p.add_argument("--seed", type=non_negative_int, default=1000, help="the first task's seed")
    p.add_argument("--out", type=writable_dir, default="robot-bench-out")
    p.add_argument("--kb", type=http_url, default=None, metavar="URL", help="a running service instead of a new one")
    p.add_argument("--token", default=None, help="the bearer token of --kb's service")
    p.add_argument("--tasks-from", type=Path, default=None, metavar="JSON",
                   help="run the tasks of an earlier run's robot-bench.json instead of drawing new ones")
    p.set_defaults(func=run_robot_bench)


def run_robot_bench(args: argparse.Namespace) -> int:
    formulations = [f.strip() for f in args.formulations.split(",") if f.strip()]
    modes = [m.strip() for m in args.modes.split(",") if m.strip()]
    for name, values, allowed in (("--formulations", formulations, RANDOM_FORMULATIONS), ("--modes", modes, MODES)):
        wrong = [v for v in values if v not in allowed]
        if wrong or not values:
            print(f"planhrc robot-bench: argument {name}: expected some of {', '.join(allowed)}, got "
                  f"{','.join(values) or 'nothing'}", file=sys.stderr)
            return 2
    try:
        given = tasks_from(args.tasks_from, formulations) if args.tasks_from is not None else None
        summary = run_bench(args.tasks, formulations, modes, args.seed, Path(args.out), args.kb, args.token, given)
    except (SimError, ProtocolError) as exc:
        print(f"planhrc robot-bench: {exc}", file=sys.stderr)
        return 1
    print(markdown(summary["table"]), end="")
    return 0

"""`planhrc demo`: the KB service and a Baxter worker run a cooperation scenario to the end.

Unless `--kb URL` names a running service, the demo starts `planhrc serve` as a separate process on a free
loopback port, on the embedded SQLite store in the output folder, protected by a fresh token. Each episode
creates an object, sets its goal and runs the worker (PyBullet Baxter, camera perception, simulated human)
until the goal is reached. The output folder gets one `episode-NNN` folder per episode (the worker's
`summary.json` with every step, the camera frames, an animated GIF and a picture of the configuration
sequence like the paper's Figs 10-12) and one `summary.json` with every decision and its reason, the re-plans,
resumes, actions, outcomes with their failure reasons, links seen and unseen, and the time to goal.
"""
from __future__ import annotations

import argparse
import json
import logging
import os
import secrets
import statistics
import sys
import time
from collections import Counter
from contextlib import AbstractContextManager, contextmanager, nullcontext
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Iterator, Sequence

import numpy as np

from planhrc.cli_args import SubParsers, http_url, non_negative_int, positive_int, writable_dir
from planhrc.client import KBClient, ProtocolError
from planhrc.service_process import ServiceStartError, running_service
from planhrc.geometry import PLANNING, configuration_feasible
from planhrc.model import make_object
from planhrc.motion_search import reachable_in_plane
from planhrc.ordering import Placement
from planhrc.robot_sim.bimanual import step_kind
from planhrc.robot_sim.errors import SimError
from planhrc.robot_sim.recording import Recording
from planhrc.robot_sim.scene import SceneSpec, is_feasible, random_orientations
from planhrc.robot_sim.service_link import ServiceLink
from planhrc.vocabulary import ActionOutcome, DecisionKind, Infeasible

if TYPE_CHECKING:
    from planhrc.robot_sim.episode import WorkerSummary

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class DemoScenario:
    """One cell set-up: the object, where it starts, where it should end, and what the human does."""

    name: str
    formulation: str
    orientations: int
    initial_deg: tuple[float, ...]
    goal_deg: tuple[float, ...]
    human: str
    description: str
    base_point_xy: tuple[float, float] | None = None  # where p1 lies on the table (default: the scene's)


DEMO_SCENARIOS: dict[str, DemoScenario] = {
    "paper-3-4": DemoScenario(
        "paper-3-4", "relative", 4, (90.0, 90.0, 90.0), (90.0, 180.0, 270.0), "none",
        "the paper's 3-4 example (Figs 10-11): 3 links, 90 degree resolution, no human",
        base_point_xy=(0.7, 0.2325),  # the plan's first action swings links 2-3 towards the robot
    ),
    "fig13": DemoScenario(
        "fig13", "relative", 4, (90.0,) * 5, (90.0, 90.0, 90.0, 180.0, 90.0), "fig13",
        "Fig 13: the human turns a link while the robot works on another (the goal comes early), then "
        "disturbs a link and the robot restores it",
        base_point_xy=(0.7, 0.3875),  # far enough forward that the disturbed object stays on the table
    ),
    "fig14": DemoScenario(
        "fig14", "absolute", 8, (90.0,) * 5, (90.0, 45.0, 90.0, 135.0, 90.0), "fig14",
        "Fig 14: the robot's gripper lets go half-way through a rotation; the human completes it and also turns "
        "the last link",
        base_point_xy=(0.43, 0.3875),  # the plan's first action swings links 2-5 towards the far edge
    ),
    "bimanual": DemoScenario(
        "bimanual", "bimanual", 8, (90.0,) * 4, (90.0, 90.0, 135.0, 135.0), "bimanual",
        "the bimanual formulation: Baxter's hands grasp the links either side of a joint, turn, release, move to "
        "another joint; while they hold two links the human turns the last one, which then needs a turn of its own",
        base_point_xy=(0.7, 0.31),
    ),
}


def random_goal(rng: np.random.Generator, spec: SceneSpec, start: Sequence[float], formulation: str,
                orientations: int, min_changed: int = 3, max_changed: int = 10, attempts: int = 2_000
                ) -> tuple[float, ...]:
    """A goal drawn uniformly from the feasible configurations (on the table, clear of the robot, within reach,
    see `planhrc.geometry`) in which `min_changed` .. `max_changed` links have another orientation than at the
    start, that keep the clearance every resting configuration of a plan keeps from the table's edges
    (`geometry.PLANNING`), and that somebody turning the links in the plane can reach from the start (a goal
    across a link's own fold or through another link is no task for anybody: `motion_search.reachable_in_plane`).
    The robot turns no link about the table in the relative and bimanual formulations (their states say nothing of
    where l1 points), so their goals keep l1 where it is."""
    step = 360.0 / orientations
    fixed_first = formulation in ("relative", "bimanual")
    limit = min(max_changed, spec.n_links - (1 if fixed_first else 0))
    if limit < min_changed:
        raise SimError(f"n_links: {spec.n_links} links cannot have {min_changed} changed in a {formulation} goal")
    obj = make_object("task", formulation, spec.n_links, orientations)
    placement = Placement(spec.geometry(), tuple(float(v) for v in start), spec.cell())
    for _ in range(attempts):
        goal = random_orientations(rng, spec, step_deg=step)
        if fixed_first:
            goal = (float(start[0]),) + tuple(goal[1:])
            if not is_feasible(spec, goal):
                continue
        changed = sum(1 for a, b in zip(goal, start) if abs((a - b + 180.0) % 360.0 - 180.0) > 1e-6)
        if not min_changed <= changed <= limit:
            continue
        if not configuration_feasible(spec.geometry(), goal, spec.cell(), tolerance=PLANNING, reach_links=()).ok:
            continue
        if reachable_in_plane(placement, obj, goal):
            return tuple(float(v) % 360.0 for v in goal)
    raise SimError(f"no feasible random goal with {min_changed}..{limit} links changed in {attempts} attempts")


RANDOM_FORMULATIONS = ("relative", "absolute", "bimanual")  # `--scenario random` draws them in turn, by seed


def random_scenario(seed: int, n_links: int = 5, orientations: int = 8, interventions: int = 3,
                    formulation: str | None = None) -> DemoScenario:
    """A random feasible start (not always straight), a goal drawn uniformly from the feasible configurations
    with 3 or more links changed (seeded), the formulation given or drawn by seed (relative, absolute, bimanual in
    turn), and `interventions` random human moves at random moments anywhere on the chain (each keeps the object
    feasible; 0: the robot alone).

    A straight start lies where a straight object fits (the scene's default place); any other start has its base
    point drawn in the middle of the table, between the arms, where both can work on the links around it."""
    rng = np.random.default_rng(seed)
    formulation = formulation or RANDOM_FORMULATIONS[seed % len(RANDOM_FORMULATIONS)]
    if formulation not in RANDOM_FORMULATIONS:
        raise SimError(f"formulation: expected one of {', '.join(RANDOM_FORMULATIONS)}, got {formulation!r}")
    step = 360.0 / orientations
    if rng.random() < 0.25:
        spec = SceneSpec(n_links=n_links)
        start = spec.orientations0
    else:
        base = (round(float(rng.uniform(0.5, 0.65)), 3), round(float(rng.uniform(-0.15, 0.15)), 3))
        spec = SceneSpec(n_links=n_links, base_point_xy=base)
        start = random_orientations(rng, spec, step_deg=step)
    goal = random_goal(rng, spec, start, formulation, orientations)
    human = f"random:{seed}:{interventions}" if interventions else "none"
    what = "random start, goal and human interventions" if interventions else "random start and goal, no human"
    return DemoScenario(f"random-{seed}", formulation, orientations, tuple(start), goal, human, what,
                        base_point_xy=spec.base_xy)


# (service URL, token, object id, episode folder) -> the worker's link to the service for that object (the ROS 2
# layer's: a bridge and its topics); without one the worker talks HTTP through the demo's KBClient
WorkerLink = Callable[[str, "str | None", str, Path], AbstractContextManager[ServiceLink]]


@contextmanager
def kb_service(out_dir: Path, token: str, startup_timeout_s: float = 90.0) -> Iterator[str]:
    """`planhrc serve` as a child process on a free loopback port (`planhrc.service_process`); yields its URL,
    stops it afterwards."""
    try:
        with running_service(out_dir / "planhrc.sqlite3", env={"PLANHRC_TOKEN": token},
                             log_path=out_dir / "kb-service.log", startup_timeout_s=startup_timeout_s) as service:
            yield service.url
    except ServiceStartError as exc:
        raise SimError(f"the KB service did not start: {exc}") from None


def serve_until_interrupted(url: str) -> None:
    """Keep the service (and its console) up until Ctrl-C, so a person can look at the episode."""
    print(f"[demo] the service stays up for the console at {url}/ ; Ctrl-C stops it", flush=True)
    try:
        while True:
            time.sleep(1.0)
    except KeyboardInterrupt:
        print("[demo] stopping the service", flush=True)


def run_episode(kb_url: str, token: str | None, scenario: DemoScenario, out_dir: Path, gui: bool,
                perception: str, max_steps: int, seed: int, worker_link: WorkerLink | None = None,
                recording: Recording | None = None) -> dict[str, Any]:
    from planhrc.robot_sim.worker import run_worker

    spec = SceneSpec(n_links=len(scenario.initial_deg), initial_orientations_deg=scenario.initial_deg,
                     base_point_xy=scenario.base_point_xy)
    with KBClient(kb_url, token=token) as kb:
        # placed where the scene puts it: the service checks its plans there
        obj = kb.create_object(scenario.name, len(scenario.initial_deg), scenario.orientations,
                               scenario.formulation, base_point_xy=spec.base_xy)
        print(f"[demo] watch {scenario.name} live: {kb_url}/?object={obj['id']}", flush=True)
        links: AbstractContextManager[ServiceLink] = (
            nullcontext(kb) if worker_link is None else worker_link(kb_url, token, obj["id"], out_dir))
        with links as link:
            summary = run_worker(kb_url, obj["id"], spec, scenario.human, out_dir, gui=gui, max_steps=max_steps,
                                 token=token, perception=perception, goal_link_orientations_deg=scenario.goal_deg,
                                 seed=seed, kb=link, recording=recording)
        events = kb.read_events(obj["id"])
    decisions = [e for e in events if e["kind"] in {str(kind) for kind in DecisionKind}]
    counts = Counter(e["kind"] for e in decisions)
    acted = [s for s in summary.steps if s.action is not None]
    actions = [s.action for s in acted if s.action is not None]
    return {
        "scenario": scenario.name,
        "description": scenario.description,
        "object_id": obj["id"],
        "formulation": scenario.formulation,
        "orientations": scenario.orientations,
        "initial_deg": list(scenario.initial_deg),
        "goal_deg": list(scenario.goal_deg),
        "human": scenario.human,
        "reached_goal": summary.reached_goal,
        "stop_reason": summary.stop_reason,
        "time_to_goal_s": round(summary.wall_s, 3),
        "replans": counts.get(DecisionKind.REPLAN, 0),
        "resumes": counts.get(DecisionKind.RESUME, 0),
        "decision_counts": dict(counts),
        "actions": [{"step": a.get("step"), "last_step": a.get("last_step"), "name": a.get("name"),
                     "joint_index": a.get("joint_index"), "turned_link_index": a.get("turned_link_index"),
                     "held_link_index": a.get("held_link_index"), "delta_deg": a.get("delta_deg")}
                    for a in actions],
        "outcomes": list(summary.outcomes),
        # the plan steps the robot carried out (a macro step counts its steps; a refused turn none)
        "executed_steps": sum(int(s.action.get("last_step") or s.action.get("step") or 0)
                              - int(s.action.get("step") or 0) + 1 for s in acted
                              if s.action is not None and s.outcome in (ActionOutcome.SUCCEEDED, ActionOutcome.PARTIAL)),
        # every dispatched action by what it does (a bimanual plan's centre, grasp, release; any turn), and those
        # the worker reported succeeded
        "action_kinds": dict(Counter(step_kind(str(a.get("name"))) for a in actions)),
        "action_kinds_succeeded": dict(Counter(step_kind(str(s.action.get("name"))) for s in acted
                                               if s.action is not None and s.outcome == ActionOutcome.SUCCEEDED)),
        "failure_reasons": summary.failure_reasons,
        "stop_message": summary.stop_message,
        "human_assists": summary.human_assists,
        "human_help_requests": summary.help_requests,
        "help_requested": [sentence for s in summary.steps for sentence in s.help_requested],
        # every help request the service recorded (a decision, or a worker's stop it turned into one), and why
        "help_reasons": [e["reason"] for e in decisions if e["kind"] == DecisionKind.HUMAN_HELP_REQUESTED],
        "ended_with_help_request": not summary.reached_goal and (
            bool(summary.final_help) or (bool(decisions) and decisions[-1]["kind"] == DecisionKind.HUMAN_HELP_REQUESTED)),
        "final_help": list(summary.final_help),
        "robot_skills": [s.skill for s in summary.steps if s.skill],
        "human_moves_scheduled": summary.human_scheduled,
        "human_moves_performed": summary.human_performed,
        "seen_links": summary.seen_links,
        "unseen_links": summary.unseen_links,
        "links_per_perception": [{"step": s.step, "seen": sum(v is not None for v in s.perceived_deg),
                                  "unseen": list(s.missing_links), "looks": s.looks,
                                  "seen_by": _seen_by(s.seen_by)} for s in summary.steps],
        "links_seen_by": dict(Counter(b for s in summary.steps for b in s.seen_by if b is not None)),
        "action_s": [round(s.action_s, 3) for s in summary.steps if s.action is not None],
        "marker_error_deg": _marker_errors(summary),
        "states_off_table": _states_off_table(summary, spec),
        "decisions": [{"seq": e["seq"], "kind": e["kind"], "reason": e["reason"]} for e in decisions],
        "out_dir": str(out_dir),
    }


def _seen_by(sources: Sequence[str | None]) -> dict[str, list[int]]:
    """Camera -> the links (1-based) it saw in one perception."""
    out: dict[str, list[int]] = {}
    for link, source in enumerate(sources, start=1):
        if source is not None:
            out.setdefault(source, []).append(link)
    return out


def _marker_errors(summary: WorkerSummary) -> list[float]:
    """|camera estimate - simulator's measured pose| of every link seen, in degrees (for evaluation)."""
    out = []
    for s in summary.steps:
        for est, true in zip(s.perceived_deg, s.true_deg):
            if est is not None:
                out.append(round(abs((est - true + 180.0) % 360.0 - 180.0), 2))
    return out


def _states_off_table(summary: WorkerSummary, spec: SceneSpec) -> int:
    """Perceived configurations (measured) with a link off the table or inside the robot."""
    count = 0
    for base, theta in zip(summary.base_points, summary.configurations):
        result = configuration_feasible(spec.geometry(base), theta, spec.cell())
        count += any(r.code in (Infeasible.OFF_TABLE, Infeasible.INSIDE_ROBOT) for r in result.reasons)
    return count


def _why(reason: str) -> str:
    """A help request's reason in a word: what kept the robot from acting."""
    for words, why in (("the robot stopped", "robot_stopped"), ("cannot reach", "out_of_reach"),
                       ("unreachable", "out_of_reach"), ("leaves the table", "off_table"),
                       ("inside the robot", "off_table"), ("folds back", "folded"), ("overlaps", "folded"),
                       ("failed", "repeated_failure")):
        if words in reason:
            return why
    return "other"


def aggregate(results: list[dict[str, Any]]) -> dict[str, Any]:
    """The numbers a run of episodes is judged by."""
    outcomes = Counter(o for r in results for o in r["outcomes"])
    kinds: Counter[str] = Counter()
    for r in results:
        kinds.update(r["action_kinds"])
    reasons: Counter[str] = Counter()
    for r in results:
        reasons.update(r["failure_reasons"])
    action_s = sorted(t for r in results for t in r["action_s"])
    errors = sorted(e for r in results for e in r["marker_error_deg"])
    actions = sum(outcomes.values())
    return {
        "actions": actions,
        "action_success_rate": round(outcomes.get(ActionOutcome.SUCCEEDED, 0) / actions, 3) if actions else None,
        "outcomes": dict(outcomes),
        "action_kinds": dict(kinds),
        "failure_reasons": dict(reasons),
        "stop_reasons": dict(Counter(r["stop_reason"] for r in results)),
        "human_assists": sum(r["human_assists"] for r in results),
        "human_help_requests": sum(r["human_help_requests"] for r in results),
        "help_requests_recorded": sum(len(r["help_reasons"]) for r in results),
        "help_requests_per_episode": round(sum(len(r["help_reasons"]) for r in results) / len(results), 2)
        if results else None,
        "help_why": dict(Counter(_why(reason) for r in results for reason in r["help_reasons"])),
        "reached_goal_without_help": sum(r["reached_goal"] and not r["help_reasons"] and not r["human_assists"]
                                         for r in results),
        "short_of_goal_without_help_request": sum(not r["reached_goal"] and not r["ended_with_help_request"]
                                                  for r in results),
        "robot_skills": sum(len(r["robot_skills"]) for r in results),
        "unreachable_per_action": round(reasons.get("unreachable", 0) / actions, 3) if actions else None,
        "human_moves": {"scheduled": sum(r["human_moves_scheduled"] for r in results),
                        "performed": sum(r["human_moves_performed"] for r in results)},
        "states_off_table": sum(r["states_off_table"] for r in results),
        "links_seen": sum(r["seen_links"] for r in results),
        "links_unseen": sum(r["unseen_links"] for r in results),
        "links_seen_by": dict(sum((Counter(r["links_seen_by"]) for r in results), Counter())),
        "action_s": {"median": round(statistics.median(action_s), 3), "max": round(action_s[-1], 3)} if action_s else None,
        "marker_error_deg": {"mean": round(statistics.fmean(errors), 2), "max": round(errors[-1], 2)} if errors else None,
    }


def run_demo(scenario_name: str, out_dir: Path, gui: bool = False, kb_url: str | None = None,
             token: str | None = None, episodes: int = 1, perception: str = "camera", max_steps: int = 40,
             seed: int = 0, keep_serving: bool = False, worker_link: WorkerLink | None = None,
             recording: Recording | None = None) -> dict[str, Any]:
    out_dir.mkdir(parents=True, exist_ok=True)
    if scenario_name == "random":
        scenarios = [random_scenario(seed + i) for i in range(episodes)]
    elif scenario_name in DEMO_SCENARIOS:
        scenarios = [DEMO_SCENARIOS[scenario_name]] * episodes
    else:
        raise SimError(f"scenario: unknown {scenario_name!r}; choose from {sorted(DEMO_SCENARIOS)} or random")
    started = time.perf_counter()
    results = []

    def run_all(url: str, tok: str | None) -> None:
        for i, sc in enumerate(scenarios):
            folder = out_dir / f"episode-{i + 1:03d}"  # the worker's own records stay beside the demo's summary
            result = run_episode(url, tok, sc, folder, gui, perception, max_steps, seed + i, worker_link, recording)
            results.append(result)
            print(f"[demo] {sc.name}: {'goal reached' if result['reached_goal'] else result['stop_reason']} "
                  f"in {result['time_to_goal_s']:.1f} s, {len(result['actions'])} actions "
                  f"({', '.join(f'{kind} {n}' for kind, n in sorted(result['action_kinds'].items())) or 'none'}), "
                  f"{result['replans']} re-plans, {result['resumes']} resumes", flush=True)

    def summarize() -> dict[str, Any]:
        summary = {
            "scenario": scenario_name,
            "episodes": len(results),
            "reached_goal": sum(r["reached_goal"] for r in results),
            "reached_goal_without_human_assist": sum(r["reached_goal"] and not r["human_assists"] for r in results),
            "perception": perception,
            "worker_link": "ros2" if worker_link is not None else "http",
            "wall_s": round(time.perf_counter() - started, 3),
            **aggregate(results),
            "results": results,
        }
        (out_dir / "summary.json").write_text(json.dumps(summary, indent=2))
        return summary

    if kb_url is None:
        token = token or secrets.token_urlsafe(16)
        with kb_service(out_dir, token) as url:
            print(f"[demo] console: {url}/  (bearer token for goals and perceptions: {token})", flush=True)
            run_all(url, token)
            summary = summarize()
            if keep_serving:
                serve_until_interrupted(url)
        return summary
    run_all(kb_url, token or os.environ.get("PLANHRC_TOKEN"))
    return summarize()


def add_demo_parser(subparsers: SubParsers) -> argparse.ArgumentParser:
    p = subparsers.add_parser("demo", help="KB service + Baxter worker: one cooperation scenario to the end",
                              description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--scenario", default="fig13", choices=sorted(DEMO_SCENARIOS) + ["random"])
    p.add_argument("--gui", action="store_true", help="show the PyBullet window (needs a display)")
    p.add_argument("--out", type=writable_dir, default="demo-out", help="output folder")
    p.add_argument("--kb", type=http_url, default=None, metavar="URL",
                   help="use a running KB service instead of starting one")
    p.add_argument("--token", default=None, help="bearer token of the service given by --kb (or PLANHRC_TOKEN)")
    p.add_argument("--episodes", type=positive_int, default=1,
                   help="episodes to run (random: a new goal and human each)")
    p.add_argument("--perception", choices=["camera", "fallback"], default="camera",
                   help="camera: ArUco markers in rendered images; fallback: simulator poses + Gaussian noise")
    p.add_argument("--max-steps", type=positive_int, default=40)
    p.add_argument("--seed", type=non_negative_int, default=0)
    p.add_argument("--keep-serving", action="store_true",
                   help="leave the started service (and its console at /) up after the episodes, until Ctrl-C")
    p.add_argument("--ros2", action="store_true",
                   help="the worker talks to the service over ROS 2 through a `planhrc ros2-bridge` (in .venv-ros2)")
    p.add_argument("--record", action="store_true",
                   help="write each episode as a rosbag2 bag (MCAP) in its folder, on the bridge's topic names")
    p.set_defaults(func=run_demo_cli)
    return p


def run_demo_cli(args: argparse.Namespace, worker_link: WorkerLink | None = None,
                 recording: Recording | None = None) -> int:
    """The demo's command; `worker_link` is given by the ROS 2 layer for `--ros2`, `recording` for `--record`."""
    from planhrc.robot_sim.worker_cli import display_problem

    if args.ros2 and worker_link is None:
        print("planhrc demo: --ros2: the ROS 2 link is made by `planhrc demo --ros2` in .venv-ros2", file=sys.stderr)
        return 2
    if args.record and recording is None:
        print("planhrc demo: --record: the bag is written by the ROS 2 layer (`planhrc demo --record`)",
              file=sys.stderr)
        return 2
    if args.gui and (problem := display_problem()):
        print(f"planhrc demo: --gui: {problem}", file=sys.stderr)
        return 2
    try:
        summary = run_demo(args.scenario, Path(args.out), args.gui, args.kb, args.token, args.episodes,
                           args.perception, args.max_steps, args.seed, keep_serving=args.keep_serving,
                           worker_link=worker_link, recording=recording)
    except (SimError, ProtocolError) as exc:
        print(f"planhrc demo: {exc}", file=sys.stderr)
        return 1
    print(f"[demo] {summary['reached_goal']}/{summary['episodes']} episodes reached the goal; "
          f"action success rate {summary['action_success_rate']}, failure reasons {summary['failure_reasons']}, "
          f"unseen links {summary['links_unseen']}, states off the table {summary['states_off_table']}; "
          f"summary in {Path(args.out) / 'summary.json'}")
    return 0 if summary["reached_goal"] == summary["episodes"] else 1

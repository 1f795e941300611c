"""`planhrc sim-bench`: what the simulated cell measures, as numbers (a benchmark, not a test).

* marker-based orientation error per link: random valid configurations, the head camera's ArUco estimate
  against the simulator's ground truth (mean, p95, max in degrees, missed markers);
* camera perception time per frame (render + detection);
* wall time of one physical rotation action (plan the arm motions + execute them with the physics stepped),
  in DIRECT mode, with its outcome judged from the world and the turn error (measured against commanded);
* with `--skills`, the robot's time for each skill on the physics clock (`measure_skills`): a turn (its fixed part
  and its time per degree, fitted over turns of 45 to 135 degrees), a slide (fixed part and time per metre), and a
  bimanual robot's centring, grasp and release: the costs `planhrc.motion_search.SkillCosts` plans with.
"""
from __future__ import annotations

import argparse
import json
import statistics
from collections import Counter
import time
from pathlib import Path
from typing import Any

import numpy as np
import pybullet
from pybullet_utils.bullet_client import BulletClient

from planhrc.cli_args import SubParsers, non_negative_int, positive_int, writable_file
from planhrc.motion_search import grip_links, slide_feasible
from planhrc.ordering import Placement
from planhrc.robot_sim.perception import CameraPerception, angle_difference_deg
from planhrc.geometry import sweep_feasible
from planhrc.robot_sim.scene import SceneSpec, build_scene, random_orientations
from planhrc.stats import percentile
from planhrc.robot_sim.skills import Robot, RotationAction, perform_action
from planhrc.robot_sim.bimanual import BothHands, GRASP_LINKS, MOVE_TO_CENTRE, RELEASE_LINKS
from planhrc.robot_sim.acting import Pose
from planhrc.robot_sim.slide import slide
from planhrc.vocabulary import ActionOutcome


def measure(configurations: int = 20, rotations: int = 20, seed: int = 0) -> dict[str, Any]:
    rng = np.random.default_rng(seed)
    client = BulletClient(connection_mode=pybullet.DIRECT)
    spec = SceneSpec()
    scene = build_scene(client, spec)
    try:
        camera = CameraPerception(client, scene)
        errors, frame_s, missed = [], [], 0
        for _ in range(configurations):
            scene.set_configuration(random_orientations(rng, spec, base_point_xy=spec.base_xy), spec.base_xy)
            scene.step(2)
            t = time.perf_counter()
            seen = camera.perceive()
            frame_s.append(time.perf_counter() - t)
            truth = scene.link_orientations_deg()  # the simulator's measured pose, to judge the camera
            for est, true in zip(seen.link_orientations_deg, truth):
                if est is None:
                    missed += 1
                else:
                    errors.append(abs(angle_difference_deg(est, true)))
        robot = Robot(scene)
        rotation_s: list[float] = []
        outcomes: Counter[str] = Counter()
        reasons: Counter[str] = Counter()
        turn_errors: list[float] = []
        scene.set_configuration(spec.orientations0, spec.base_xy)
        while len(rotation_s) < rotations:
            link = int(rng.integers(2, spec.n_links + 1))
            delta = float(rng.choice([-90.0, -45.0, 45.0, 90.0]))
            base, theta = scene.configuration()
            if not sweep_feasible(spec.geometry(base), theta, link, link - 1, delta, cell=spec.cell()).ok:
                if rng.random() < 0.1:
                    scene.set_configuration(spec.orientations0, spec.base_xy)
                continue
            t = time.perf_counter()
            result = perform_action(scene, robot, RotationAction(turned_link=link, held_link=link - 1,
                                                                 delta_deg=delta))
            rotation_s.append(time.perf_counter() - t)
            outcomes[result.outcome.value] += 1
            if result.reason is not None:
                reasons[result.reason.value] += 1
            turn_errors.append(abs(result.reached_deg - delta))
            if result.outcome is not ActionOutcome.SUCCEEDED:
                scene.set_configuration(spec.orientations0, spec.base_xy)
    finally:
        scene.close()
        client.disconnect()
    return {
        "marker_error_deg": {"links": len(errors), "mean": statistics.fmean(errors), "p95": percentile(errors, 0.95),
                             "max": max(errors), "missed_markers": missed},
        "perception_s": {"median": statistics.median(frame_s), "max": max(frame_s)},
        "rotation_action_s": {"median": statistics.median(rotation_s), "max": max(rotation_s),
                              "succeeded": outcomes.get(ActionOutcome.SUCCEEDED.value, 0), "of": len(rotation_s)},
        "rotation_outcomes": dict(outcomes),
        "rotation_failure_reasons": dict(reasons),
        "turn_error_deg": {"median": statistics.median(turn_errors), "max": max(turn_errors)},
        "configurations": configurations,
        "seed": seed,
    }


def measure_skills(turns: int = 24, slides: int = 12, hands: int = 8, seed: int = 0) -> dict[str, Any]:
    """The robot's time for each skill on the physics clock (`Scene.time_s`), from random feasible configurations:
    turns of 45, 90 and 135 degrees (a least-squares line: fixed part + time per degree), slides of 5 to 30 cm
    (fixed part + time per metre), and a bimanual robot's centring, grasp, turn of the links it holds (a line, as
    a turn) and release (medians). Only skills that succeeded count."""
    rng = np.random.default_rng(seed)
    client = BulletClient(connection_mode=pybullet.DIRECT)
    spec = SceneSpec()
    scene = build_scene(client, spec)
    try:
        robot = Robot(scene)
        turn_rows: list[tuple[float, float]] = []
        tries = 0
        while len(turn_rows) < turns and tries < turns * 20:
            tries += 1
            scene.set_configuration(random_orientations(rng, spec, step_deg=45.0, base_point_xy=spec.base_xy),
                                    spec.base_xy)
            scene.step(2)
            link = int(rng.integers(2, spec.n_links + 1))
            delta = float(rng.choice([-135.0, -90.0, -45.0, 45.0, 90.0, 135.0]))
            base, theta = scene.configuration()
            if not sweep_feasible(spec.geometry(base), theta, link, link - 1, delta, cell=spec.cell(),
                                  reach_links=(link, link - 1)).ok:
                continue
            t = scene.time_s
            result = perform_action(scene, robot, RotationAction(turned_link=link, held_link=link - 1, delta_deg=delta))
            if result.outcome is ActionOutcome.SUCCEEDED:
                turn_rows.append((abs(delta), scene.time_s - t))
        slide_rows: list[tuple[float, float]] = []
        tries = 0
        while len(slide_rows) < slides and tries < slides * 30:
            tries += 1
            angles = random_orientations(rng, spec, step_deg=45.0, base_point_xy=spec.base_xy)
            scene.set_configuration(angles, spec.base_xy)
            scene.step(2)
            base, theta = scene.configuration()
            distance = float(rng.uniform(0.05, 0.30))
            heading = float(rng.uniform(0.0, 2 * np.pi))
            to = (float(base[0] + distance * np.cos(heading)), float(base[1] + distance * np.sin(heading)))
            placement = Placement(spec.geometry(base), tuple(theta), spec.cell())
            links = grip_links(placement, to)
            if links is None or not slide_feasible(placement, to, links).ok:
                continue
            t = scene.time_s
            outcome = slide(scene, robot, to, links)
            if outcome.outcome is ActionOutcome.SUCCEEDED:
                slide_rows.append((distance, scene.time_s - t))
        hand_s: dict[str, list[float]] = {"centre": [], "grasp": [], "release": []}
        held_rows: list[tuple[float, float]] = []  # a bimanual turn of links the hands already hold
        tries = 0
        while len(hand_s["release"]) < hands and tries < hands * 30:
            tries += 1
            scene.set_configuration(random_orientations(rng, spec, step_deg=45.0, base_point_xy=spec.base_xy),
                                    spec.base_xy)
            scene.step(2)
            both = BothHands(scene, robot)
            joint = int(rng.integers(1, spec.n_links))
            data = {"params": ["right", "left"]}
            times: dict[str, float] = {}
            delta = float(rng.choice([-90.0, -45.0, 45.0, 90.0]))
            steps = (("centre", MOVE_TO_CENTRE, 0.0), ("grasp", GRASP_LINKS, 0.0),
                     ("turn", "rotateclockwise" if delta > 0 else "rotateanticlockwise", delta),
                     ("release", RELEASE_LINKS, 0.0))
            for kind, name, turn in steps:
                base, theta = scene.configuration()
                pose = Pose(spec.geometry(base), tuple(theta))
                t = scene.time_s
                step = RotationAction(turned_link=joint + 1, held_link=joint, delta_deg=turn, joint_index=joint,
                                      name=name)
                if both.perform([step], data, pose, False, lambda done, total: False, None).outcome \
                        is not ActionOutcome.SUCCEEDED:
                    break
                times[kind] = scene.time_s - t
            if len(times) == len(steps):
                held_rows.append((abs(delta), times.pop("turn")))
                for kind, value in times.items():
                    hand_s[kind].append(value)
            both.let_go()
    finally:
        scene.close()
        client.disconnect()
    turn_fit = _line(turn_rows)
    slide_fit = _line(slide_rows)
    held_fit = _line(held_rows)
    return {
        "turn": {"fixed_s": turn_fit[0], "s_per_deg": turn_fit[1], "turns": len(turn_rows)},
        "held_turn": {"fixed_s": held_fit[0], "s_per_deg": held_fit[1], "turns": len(held_rows)},
        "slide": {"fixed_s": slide_fit[0], "s_per_m": slide_fit[1], "slides": len(slide_rows)},
        **{kind: {"median_s": round(statistics.median(values), 3) if values else None, "n": len(values)}
           for kind, values in hand_s.items()},
        "seed": seed,
    }


def _line(rows: list[tuple[float, float]]) -> tuple[float | None, float | None]:
    """The least-squares line y = a + b x through (x, y) rows (None, None with fewer than two distinct x)."""
    if len({x for x, _ in rows}) < 2:
        return None, None
    x = np.asarray([r[0] for r in rows])
    y = np.asarray([r[1] for r in rows])
    b, a = np.polyfit(x, y, 1)
    return round(float(a), 3), round(float(b), 5)


def add_sim_bench_parser(subparsers: SubParsers) -> None:
    p = subparsers.add_parser("sim-bench", help="marker error, perception time and rotation wall time in simulation",
                              description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--configurations", type=positive_int, default=20, help="random configurations perceived")
    p.add_argument("--rotations", type=positive_int, default=20, help="rotation actions timed")
    p.add_argument("--seed", type=non_negative_int, default=0)
    p.add_argument("--out", type=writable_file, default=None, help="also write the numbers to this JSON file")
    p.add_argument("--skills", action="store_true",
                   help="measure the robot's time per skill (turn, slide, centre, grasp, release) instead")
    p.set_defaults(func=run_sim_bench)


def run_sim_bench(args: argparse.Namespace) -> int:
    result = measure_skills(seed=args.seed) if args.skills else measure(args.configurations, args.rotations, args.seed)
    text = json.dumps(result, indent=2)
    print(text)
    if args.out:
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        Path(args.out).write_text(text)
    return 0

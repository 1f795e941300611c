"""`planhrc sim-bench`: what the simulated cell measures, as numbers (a benchmark, not a test).

* marker-based orientation error per link: random valid configurations, the head camera's ArUco estimate
  against the simulator's ground truth (mean, p95, max in degrees, missed markers);
* camera perception time per frame (render + detection);
* wall time of one physical rotation action (plan the arm motions + execute them with the physics stepped),
  in DIRECT mode, with its outcome judged from the world and the turn error (measured against commanded).
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
from planhrc.robot_sim.perception import CameraPerception, angle_difference_deg
from planhrc.geometry import sweep_feasible
from planhrc.robot_sim.scene import SceneSpec, build_scene, random_orientations
from planhrc.stats import percentile
from planhrc.robot_sim.skills import Robot, RotationAction, perform_action
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


def add_sim_bench_parser(subparsers: SubParsers) -> None:
    p = subparsers.add_parser("sim-bench", help="marker error, perception time and rotation wall time in simulation",
                              description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--configurations", type=positive_int, default=20, help="random configurations perceived")
    p.add_argument("--rotations", type=positive_int, default=20, help="rotation actions timed")
    p.add_argument("--seed", type=non_negative_int, default=0)
    p.add_argument("--out", type=writable_file, default=None, help="also write the numbers to this JSON file")
    p.set_defaults(func=run_sim_bench)


def run_sim_bench(args: argparse.Namespace) -> int:
    result = measure(args.configurations, args.rotations, args.seed)
    text = json.dumps(result, indent=2)
    print(text)
    if args.out:
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        Path(args.out).write_text(text)
    return 0

"""The slide skill: both arms hold the object by two links and slide it along the table, its base point to a place
the service names (`planhrc.vocabulary.Skill.SLIDE`: a plan that does not fit where the object lies fits there).

`slide_skill` plans without moving anything: inverse kinematics for each gripper above and on its link, then for
every 2 cm of the slide, the left arm taking the link further to the robot's left; it returns a `SlideCommand`, or
None when an arm cannot follow (STYLE: a skill returns a command or None). `execute_slide` plays it physically:
both grippers close on their links (grasps hold through constraints made on touch, as in a rotation), both arms
follow the waypoints together through their joint motors while the physics steps, the links between and beyond
the held ones are dragged along by their joints, both let go and go home. The outcome is judged from the world: the
base point measured afterwards against the target, and how much the joints bent on the way.
"""
from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from planhrc.robot_sim.grip import Hands, drive_arm
from planhrc.robot_sim.scene import ARMS, HOME_POSE, Scene, arm_joints, hold_arm, set_arm_joints
from planhrc.robot_sim.skills import Robot
from planhrc.vocabulary import ActionOutcome, FailureReason

log = logging.getLogger(__name__)

SLIDE_STEP_M = 0.02  # one waypoint of the slide
PLACE_TOLERANCE_M = 0.03  # a slide that ends this close to its target succeeded
BEND_TOLERANCE_DEG = 6.0  # ... and bent no joint more than this


@dataclass(frozen=True)
class SlideCommand:
    """Both arms' poses: above and on each held link, then one pair of poses per waypoint of the slide."""

    to_xy: tuple[float, float]
    holds: tuple[tuple[str, int], ...]  # (arm, link) pairs
    above: dict[str, tuple[float, ...]]
    down: dict[str, tuple[float, ...]]
    waypoints: tuple[dict[str, tuple[float, ...]], ...]
    lift: dict[str, tuple[float, ...]]


@dataclass(frozen=True)
class SlideResult:
    outcome: ActionOutcome
    reason: FailureReason | None
    message: str
    moved_m: float


def slide_skill(scene: Scene, robot: Robot, to_xy: Sequence[float], links: Sequence[int]) -> SlideCommand | None:
    """The command sliding the object's base point to `to_xy` holding `links` (two links), or None when an arm
    cannot reach one of its poses. Nothing moves (the arms are put back where they were)."""
    if len(links) != 2 or links[0] == links[1]:
        return None
    base = np.asarray(scene.base_point())
    shift = np.asarray(to_xy, dtype=float) - base
    theta = scene.link_orientations_deg()
    centres = {k: scene.link_center(k) for k in links}
    left_link = max(links, key=lambda k: float(centres[k][1]))
    holds = (("left", left_link), ("right", next(k for k in links if k != left_link)))
    z_grasp = scene.link_center_z + robot.grasp_height_m
    z_above = z_grasp + robot.approach_height_m
    n = max(1, math.ceil(float(np.linalg.norm(shift)) / SLIDE_STEP_M))
    saved = {arm: arm_joints(scene, arm) for arm in ARMS}
    try:
        above, down, lift = {}, {}, {}
        waypoints: list[dict[str, tuple[float, ...]]] = [{} for _ in range(n)]
        for arm, link in holds:
            yaw = -math.radians(theta[link - 1])
            xy = centres[link]
            pose = _reach(robot, arm, (xy[0], xy[1], z_above), yaw)
            if pose is None:
                log.info("slide: the %s arm does not reach above link %d", arm, link)
                return None
            above[arm] = pose
            pose = _reach(robot, arm, (xy[0], xy[1], z_grasp), yaw)
            if pose is None:
                return None
            down[arm] = pose
            for i in range(1, n + 1):
                p = xy + shift * i / n
                pose = _reach(robot, arm, (p[0], p[1], z_grasp), yaw)
                if pose is None:
                    log.info("slide: the %s arm cannot follow link %d to x=%.2f, y=%.2f", arm, link, p[0], p[1])
                    return None
                waypoints[i - 1][arm] = pose
            end = xy + shift
            pose = _reach(robot, arm, (end[0], end[1], z_above), yaw)
            if pose is None:
                return None
            lift[arm] = pose
        return SlideCommand((float(to_xy[0]), float(to_xy[1])), holds, above, down, tuple(waypoints), lift)
    finally:
        for arm, q in saved.items():
            set_arm_joints(scene, arm, q)


def _reach(robot: Robot, arm: str, position: Sequence[float], yaw: float) -> tuple[float, ...] | None:
    """An arm pose with the gripper at `position`, pointing down at `yaw` or half a turn from it."""
    for turn in (0.0, math.pi):
        pose, _ = robot.solve_ik(arm, position, yaw + turn, max_twist_deg=robot.hold_twist_deg)
        if pose is not None:
            return pose
    return None


def execute_slide(scene: Scene, robot: Robot, command: SlideCommand | None) -> SlideResult:
    """Play the slide physically and judge it from the world (see the module's note)."""
    if command is None:
        return SlideResult(ActionOutcome.FAILED, FailureReason.UNREACHABLE, "no arm pose slides the object there", 0.0)
    start_base = np.asarray(scene.base_point())
    start_theta = scene.link_orientations_deg()
    hands = Hands(scene, robot)
    problem: str | None = None
    try:
        for arm, _ in command.holds:
            for pose in (command.above[arm], command.down[arm]):
                if not drive_arm(scene, robot, arm, pose):
                    problem = f"the {arm} arm did not reach its pose"
        for arm, link in command.holds:
            if problem is None and not hands.grasp(arm, link):
                problem = f"the {arm} gripper closed on nothing at link {link}"
        if problem is None:
            for waypoint in command.waypoints:
                _follow_together(scene, robot, waypoint)
            scene.step(robot.arc_steps)  # hold still until the object has stopped moving, then let go
    finally:
        hands.release_all()
    scene.step(3)
    for arm, _ in command.holds:
        drive_arm(scene, robot, arm, command.lift[arm] if problem is None else command.above[arm])
        drive_arm(scene, robot, arm, HOME_POSE[arm])
    scene.step(6)
    end_base = np.asarray(scene.base_point())
    moved = float(np.linalg.norm(end_base - start_base))
    off = float(np.linalg.norm(end_base - np.asarray(command.to_xy)))
    bent = max(abs((a - b + 180.0) % 360.0 - 180.0) for a, b in zip(scene.link_orientations_deg(), start_theta))
    where = f"base point at ({end_base[0]:.2f}, {end_base[1]:.2f}), {off * 100:.0f} cm from the target"
    if problem is not None:
        return SlideResult(ActionOutcome.FAILED, FailureReason.GRASP_LOST, f"{problem}; {where}", moved)
    if scene.off_table_links():
        return SlideResult(ActionOutcome.FAILED, FailureReason.LEFT_TABLE,
                           f"link {scene.off_table_links()[0]} left the table; {where}", moved)
    if off <= PLACE_TOLERANCE_M and bent <= BEND_TOLERANCE_DEG:
        return SlideResult(ActionOutcome.SUCCEEDED, None, f"slid {moved * 100:.0f} cm: {where}", moved)
    outcome = ActionOutcome.PARTIAL if moved > SLIDE_STEP_M else ActionOutcome.FAILED
    reason = FailureReason.SLIP if moved > SLIDE_STEP_M else FailureReason.STALL
    return SlideResult(outcome, reason, f"slid {moved * 100:.0f} cm, joints bent up to {bent:.0f} deg: {where}", moved)


def _follow_together(scene: Scene, robot: Robot, targets: dict[str, tuple[float, ...]]) -> None:
    """Both arms to their next waypoint at once, the motor targets interpolated over `robot.arc_steps` steps."""
    starts = {arm: np.asarray(arm_joints(scene, arm)) for arm in targets}
    for i in range(1, robot.arc_steps + 1):
        for arm, goal in targets.items():
            hold_arm(scene, arm, starts[arm] + (np.asarray(goal) - starts[arm]) * (i / robot.arc_steps))
        scene.step()
        if robot.realtime_s:
            time.sleep(robot.realtime_s)
    scene.step(robot.arc_steps // 2)


def slide(scene: Scene, robot: Robot, to_xy: Sequence[float], links: Sequence[int]) -> SlideResult:
    """Plan and execute a slide; one that cannot be planned is FAILED and nothing moves."""
    return execute_slide(scene, robot, slide_skill(scene, robot, to_xy, links))

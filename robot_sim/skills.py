"""Skills: a plan's rotation action becomes a command (a list of primitives) that the simulator executes.

`rotate_skill` plans without moving anything visible: it solves inverse kinematics for every arm pose the
action needs and returns ``None`` when one of them cannot be reached within tolerance. `execute` then plays
the command: arms move by setting joint states (interpolated), the object turns kinematically about its joint.
"""
from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass
from enum import Enum
from typing import Any, Callable, Mapping, Sequence, Union

import numpy as np

from planhrc.robot_sim.scene import (
    ARMS,
    HOME_POSE,
    Scene,
    SimError,
    arm_joints,
    joint_between,
    rotate_point,
    set_arm_joints,
    set_gripper,
)

log = logging.getLogger(__name__)


class Outcome(str, Enum):
    SUCCEEDED = "succeeded"
    FAILED = "failed"
    PARTIAL = "partial"


@dataclass(frozen=True)
class RotationAction:
    """One plan action: turn `turned_link` about its joint with `held_link` (0 = the table) by `delta_deg`
    (+ = clockwise seen from above). `joint_index` is the plan's joint number, kept for the record."""

    turned_link: int
    held_link: int
    delta_deg: float
    joint_index: int | None = None
    action_id: str | None = None
    name: str = ""

    @classmethod
    def from_api(cls, data: Mapping[str, Any]) -> "RotationAction":
        """Build from the KB service's `next_action` object; a missing field raises a `SimError` naming it."""
        try:
            return cls(
                turned_link=int(data["turned_link_index"]),
                held_link=int(data["held_link_index"]),
                delta_deg=float(data["delta_deg"]),
                joint_index=int(data["joint_index"]) if data.get("joint_index") is not None else None,
                action_id=str(data["id"]) if data.get("id") is not None else None,
                name=str(data.get("name", "")),
            )
        except KeyError as exc:
            raise SimError(f"next_action.{exc.args[0]}: missing") from exc
        except (TypeError, ValueError) as exc:
            raise SimError(f"next_action: malformed ({exc})") from exc


# -- primitives ------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class MoveArm:
    arm: str
    joint_positions: tuple[float, ...]


@dataclass(frozen=True)
class Grip:
    arm: str
    close: bool


@dataclass(frozen=True)
class RotateObject:
    """Turn one side of joint point `joint` by `delta_deg` (see `Scene.rotate_at_joint`)."""

    joint: int
    delta_deg: float
    turned: str = "downstream"


Primitive = Union[MoveArm, Grip, RotateObject]


@dataclass(frozen=True)
class Command:
    primitives: tuple[Primitive, ...]
    joint: int
    turned: str
    delta_deg: float

    @property
    def rotation_steps(self) -> int:
        return sum(1 for p in self.primitives if isinstance(p, RotateObject))


# -- the robot: inverse kinematics for Baxter's arms ---------------------------------------------------------
class Robot:
    """Baxter's arms in a scene: IK within joint limits, checked by forward kinematics."""

    def __init__(
        self,
        scene: Scene,
        tolerance_m: float = 0.03,
        step_deg: float = 5.0,
        approach_height_m: float = 0.10,
        grasp_height_m: float = 0.01,
        interpolation_steps: int = 8,
        realtime_s: float = 0.0,
    ) -> None:
        if scene.robot is None:
            raise SimError("scene: was built without the robot (load_robot=False)")
        self.scene = scene
        self.client = scene.client
        self.tolerance_m = tolerance_m
        self.step_deg = step_deg
        self.approach_height_m = approach_height_m
        self.grasp_height_m = grasp_height_m
        self.interpolation_steps = interpolation_steps
        self.realtime_s = realtime_s
        c, body = self.client, scene.robot
        self._movable = [j for j in range(c.getNumJoints(body)) if c.getJointInfo(body, j)[2] != 4]  # 4 = fixed
        self._lower = [c.getJointInfo(body, j)[8] for j in self._movable]
        self._upper = [c.getJointInfo(body, j)[9] for j in self._movable]
        self._ranges = [u - lo for lo, u in zip(self._lower, self._upper)]

    def end_effector_pose(self, arm: str) -> tuple[np.ndarray, tuple[float, ...]]:
        state = self.client.getLinkState(self.scene.robot, self.scene.arms[arm].end_effector, computeForwardKinematics=True)
        return np.array(state[4]), state[5]

    def solve_ik(self, arm: str, position: Sequence[float], yaw: float, iterations: int = 6) -> tuple[float, ...] | None:
        """Joint positions putting `arm`'s gripper at `position`, pointing down, turned by `yaw` (radians).

        Leaves the arm at the solution (planning replays poses in order); returns None when the reached
        position is farther than the tolerance or a joint would leave its limits.
        """
        info = self.scene.arms[arm]
        c, body = self.client, self.scene.robot
        target = np.asarray(position, dtype=float)
        orientation = c.getQuaternionFromEuler([math.pi, 0.0, yaw])
        rest = [c.getJointState(body, j)[0] for j in self._movable]
        solution: tuple[float, ...] = arm_joints(self.scene, arm)
        for _ in range(iterations):
            q = c.calculateInverseKinematics(
                body,
                info.end_effector,
                target.tolist(),
                orientation,
                lowerLimits=self._lower,
                upperLimits=self._upper,
                jointRanges=self._ranges,
                restPoses=rest,
                maxNumIterations=100,
                residualThreshold=1e-5,
            )
            solution = tuple(float(q[self._movable.index(j)]) for j in info.joints)
            solution = tuple(float(np.clip(v, lo, hi)) for v, lo, hi in zip(solution, info.lower, info.upper))
            set_arm_joints(self.scene, arm, solution)
            reached, _ = self.end_effector_pose(arm)
            if np.linalg.norm(reached - target) < 1e-3:
                break
        reached, _ = self.end_effector_pose(arm)
        error = float(np.linalg.norm(reached - target))
        if error > self.tolerance_m:
            log.info("IK: %s arm misses %s by %.3f m", arm, np.round(target, 3).tolist(), error)
            return None
        return solution

    def closer_arm(self, point_xy: np.ndarray) -> str:
        """Left arm for points on the robot's left (+y), right arm otherwise."""
        return "left" if point_xy[1] >= 0.0 else "right"

    def arm_assignments(self, held_xy: np.ndarray | None, turned_xy: np.ndarray) -> list[tuple[str | None, str]]:
        """(arm holding, arm turning) pairs, best first: the closer arm turns when nothing is held, else the
        pairing with the shorter total shoulder distance; the other pairing is the fallback."""
        if held_xy is None:
            first = self.closer_arm(turned_xy)
            return [(None, first), (None, "right" if first == "left" else "left")]

        def dist(arm: str, p: np.ndarray) -> float:
            return float(np.linalg.norm(np.asarray(self.scene.arms[arm].shoulder_xy) - p))

        left_holds = dist("left", held_xy) + dist("right", turned_xy)
        right_holds = dist("right", held_xy) + dist("left", turned_xy)
        pairs: list[tuple[str | None, str]] = [("left", "right"), ("right", "left")]
        return pairs if left_holds <= right_holds else pairs[::-1]


def _unwrap_yaw(yaw: float, previous: float | None) -> float:
    """The gripper is symmetric under a half turn: pick yaw or yaw + pi, whichever is nearer `previous`."""
    if previous is None:
        return yaw
    candidates = [yaw + k * math.pi for k in range(-3, 4)]
    return min(candidates, key=lambda a: abs(a - previous))


def rotate_skill(scene: Scene, robot: Robot, action: RotationAction) -> Command | None:
    """Plan a rotation action as a command, or return None when an arm pose cannot be reached."""
    joint_k, side = joint_between(action.turned_link, action.held_link, scene.n_links)
    turned_xy = scene.link_center(action.turned_link)
    held_xy = scene.link_center(action.held_link) if action.held_link >= 1 else None
    saved = {arm: arm_joints(scene, arm) for arm in ARMS}
    try:
        for holder, turner in robot.arm_assignments(held_xy, turned_xy):
            command = _plan_rotation(scene, robot, action, joint_k, side, holder, turner)
            if command is not None:
                return command
            for arm, q in saved.items():
                set_arm_joints(scene, arm, q)
        return None
    finally:
        for arm, q in saved.items():
            set_arm_joints(scene, arm, q)


def _plan_rotation(
    scene: Scene, robot: Robot, action: RotationAction, joint_k: int, side: str, holder: str | None, turner: str
) -> Command | None:
    (_, theta) = scene.configuration()
    pivot = scene.joint_points()[joint_k - 1]
    turned_xy = scene.link_center(action.turned_link)
    held_xy = scene.link_center(action.held_link) if action.held_link >= 1 else None
    z_grasp = scene.link_center_z + robot.grasp_height_m
    z_above = z_grasp + robot.approach_height_m
    primitives: list[Primitive] = []

    def reach(arm: str, xy: np.ndarray, z: float, yaw: float) -> bool:
        q = robot.solve_ik(arm, [xy[0], xy[1], z], yaw)
        if q is None:
            return False
        primitives.append(MoveArm(arm, q))
        return True

    if holder is not None:
        held_yaw = -math.radians(theta[action.held_link - 1])
        if not (reach(holder, held_xy, z_above, held_yaw) and reach(holder, held_xy, z_grasp, held_yaw)):
            return None
        primitives.append(Grip(holder, True))
    turned_yaw = -math.radians(theta[action.turned_link - 1])
    if not (reach(turner, turned_xy, z_above, turned_yaw) and reach(turner, turned_xy, z_grasp, turned_yaw)):
        return None
    primitives.append(Grip(turner, True))

    n = max(1, math.ceil(abs(action.delta_deg) / robot.step_deg))
    increment = action.delta_deg / n
    yaw = turned_yaw
    for i in range(1, n + 1):
        angle = increment * i
        xy = rotate_point(turned_xy, pivot, angle)
        yaw = _unwrap_yaw(turned_yaw - math.radians(angle), yaw)
        primitives.append(RotateObject(joint_k, increment, side))
        if not reach(turner, xy, z_grasp, yaw):
            return None
    final_xy = rotate_point(turned_xy, pivot, action.delta_deg)
    primitives.append(Grip(turner, False))
    if holder is not None:
        primitives.append(Grip(holder, False))
    if not reach(turner, final_xy, z_above, yaw):
        return None
    if holder is not None and not reach(holder, held_xy, z_above, -math.radians(theta[action.held_link - 1])):
        return None
    for arm in (turner, holder):
        if arm is not None:
            primitives.append(MoveArm(arm, HOME_POSE[arm]))
    return Command(tuple(primitives), joint_k, side, float(action.delta_deg))


# -- execution -----------------------------------------------------------------------------------------------
Interrupt = Callable[[int, int], bool]


def _move_arm(scene: Scene, robot: Robot, arm: str, target: Sequence[float]) -> None:
    start = np.array(arm_joints(scene, arm))
    goal = np.array(target)
    steps = max(1, robot.interpolation_steps)
    for i in range(1, steps + 1):
        set_arm_joints(scene, arm, start + (goal - start) * (i / steps))
        if robot.realtime_s:
            time.sleep(robot.realtime_s)


def execute(
    scene: Scene,
    command: Command | None,
    robot: Robot | None = None,
    interrupt: Interrupt | None = None,
    stop_fraction: float | None = None,
) -> Outcome:
    """Play `command`; FAILED when there is none, PARTIAL when the rotation stopped before its full amount.

    `interrupt(done, total)` is called before each rotation increment (it may change the scene, as a human
    would) and stops the rotation by returning True; `stop_fraction` stops it once that share is done.
    After a stop both grippers open and the arms go home.
    """
    if command is None:
        return Outcome.FAILED
    robot = robot or Robot(scene)
    total = command.rotation_steps
    done = 0.0  # rotation increments performed (the last one may be a fraction)
    stopped = False
    for primitive in command.primitives:
        if isinstance(primitive, RotateObject):
            if stopped:
                continue
            if interrupt is not None and interrupt(int(done), total):
                stopped = True
                continue
            share = 1.0
            if stop_fraction is not None:
                share = min(1.0, max(0.0, stop_fraction * total - done))
                if share <= 1e-9:
                    stopped = True
                    continue
            scene.rotate_at_joint(primitive.joint, primitive.delta_deg, primitive.turned, fraction=share)
            done += share
            if share < 1.0:
                stopped = True
        elif isinstance(primitive, Grip):
            set_gripper(scene, primitive.arm, primitive.close)
        elif isinstance(primitive, MoveArm):
            if stopped and not _is_home(primitive):
                continue  # skip the following motion; open grippers and go home below
            _move_arm(scene, robot, primitive.arm, primitive.joint_positions)
        else:  # pragma: no cover - the union is closed
            raise SimError(f"primitive: unknown {primitive!r}")
    if stopped:
        for arm in ARMS:
            set_gripper(scene, arm, close=False)
            _move_arm(scene, robot, arm, HOME_POSE[arm])
        return Outcome.PARTIAL if done > 0 else Outcome.FAILED
    return Outcome.SUCCEEDED


def _is_home(primitive: MoveArm) -> bool:
    return tuple(primitive.joint_positions) == tuple(HOME_POSE[primitive.arm])


def perform_action(
    scene: Scene,
    robot: Robot,
    action: RotationAction,
    interrupt: Interrupt | None = None,
    stop_fraction: float | None = None,
) -> Outcome:
    """Plan and execute one action; an action that cannot be planned is FAILED and nothing moves."""
    return execute(scene, rotate_skill(scene, robot, action), robot, interrupt, stop_fraction)

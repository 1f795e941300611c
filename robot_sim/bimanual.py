"""The bimanual steps: Baxter's two arms work at one joint of the object, one planned step at a time, as the
bimanual formulation plans them (docs/planning.md, "The bimanual formulation as knowledge").

* ``movetocentre``: the centre is the joint both hands work at. Both open hands go to their pre-grasp poses,
  above the two links that joint joins (the keeper's gripper over the upstream link, the other over the downstream
  one, the approach height above the links); nothing touches the object, so the next perception sees it where it
  was. Hands that hide a link from the head camera there step back home when the perception misses it
  (`BothHands.step_back`): the joint stays at the centre, the next ``grasplinks`` approaches from home.
* ``grasplinks``: each arm goes from above its link down onto it and closes its fingers; a grasp holds by a
  constraint made once the fingers touch the link (`grip.Hands`) and stays through the following actions until
  ``releaselinks`` or a failure. The grippers take their links a quarter of a link from the centre, never on the
  marker at the centre: the turning gripper towards the joint where it reaches (a shorter arc), the keeper on the
  side nearer its shoulder (its arm does not reach over the marker). The head camera still sees the links in most
  poses while the robot holds two; a link a hand or an arm hides is reported unseen, as any other.
* the turns (``rotateclockwise``/``rotateanticlockwise``, their 45° macros, and merged steps: one arc): the one
  judge (`acting.judge`) first, from the pose the worker perceived; then the arm holding the downstream link
  carries it along the arc about the centred joint while the keeper holds the upstream link still
  (`skills.execute` on the held hands: contact, slip and the measured turn judge it as any turn).
* ``releaselinks``: both hands open where they are, lift off their links and go back home, out of the head
  camera's view of the object (hands hovering over the links hide markers from it); the joint stays at the centre
  in the plan's sense: the next ``grasplinks`` there approaches its links from home.

The plan names the grippers (the turning one, then the keeper: the action's last two parameters); when the named
arm cannot reach its link the other pairing is used and the result says so. On a failed or partial step both hands
open and the arms go home (the service's `planhrc.control.after_failure`: the grasps are gone, the centre stays),
and the next ``grasplinks`` approaches from there.
"""
from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import Any, Mapping, Sequence

import numpy as np

from planhrc.robot_sim.acting import Pose, perform_parts
from planhrc.robot_sim.grip import Hands, drive_arm
from planhrc.robot_sim.scene import ARMS, HOME_POSE, Scene, arm_joints, direction, joint_between, set_arm_joints
from planhrc.robot_sim.skills import (ActionResult, ArcMiss, Command, Interrupt, Robot, RotationAction, Unreachable,
                                      arc_turns, execute)
from planhrc.vocabulary import ActionOutcome, FailureReason

log = logging.getLogger(__name__)

MOVE_TO_CENTRE, GRASP_LINKS, RELEASE_LINKS = "movetocentre", "grasplinks", "releaselinks"
HAND_STEPS = (MOVE_TO_CENTRE, GRASP_LINKS, RELEASE_LINKS)  # the bimanual domain's steps that turn nothing
STEP_KINDS = {MOVE_TO_CENTRE: "centre", GRASP_LINKS: "grasp", RELEASE_LINKS: "release"}


def step_kind(name: str) -> str:
    """What a plan action does, in a word: `centre`, `grasp`, `release`, or `turn` (every other action turns)."""
    return STEP_KINDS.get(name, "turn")


@dataclass(frozen=True)
class Station:
    """Where each arm works at the centred joint: arm -> (link, grasp point on the table, gripper yaw), and the
    arm poses above and on those points."""

    turned_link: int
    held_link: int
    points: Mapping[str, tuple[int, np.ndarray, float]]
    above: Mapping[str, tuple[float, ...]]
    down: Mapping[str, tuple[float, ...]]
    swapped: bool  # the arms work the other way round from the plan's grippers


def named_arms(data: Mapping[str, Any]) -> tuple[str, str]:
    """(turning arm, keeper arm) as the action names them (its last two parameters), else Baxter's usual ones."""
    params = [str(p) for p in data.get("params") or ()]
    if len(params) >= 2 and params[-2] in ARMS and params[-1] in ARMS and params[-2] != params[-1]:
        return params[-2], params[-1]
    return "right", "left"


class BothHands:
    """What Baxter's hands do across a bimanual plan's steps: where they work and what they hold."""

    def __init__(self, scene: Scene, robot: Robot) -> None:
        self.scene, self.robot = scene, robot
        self.hands = Hands(scene, robot)

    def held_links(self) -> tuple[int, ...]:
        return tuple(sorted(link for _, link in self.hands.held.values()))

    def perform(self, parts: Sequence[RotationAction], data: Mapping[str, Any], pose: Pose, final: bool,
                interrupt: Interrupt, stop_fraction: float | None) -> ActionResult:
        """Do one dispatched step (a turn may come as its single steps, `parts`); on anything but success both
        hands open and the arms go home."""
        first = parts[0]
        if first.name in HAND_STEPS:
            result = {MOVE_TO_CENTRE: self._move_to_centre, GRASP_LINKS: self._grasp,
                      RELEASE_LINKS: self._release}[first.name](first, named_arms(data))
        else:
            result = self._turn_parts(parts, pose, final, interrupt, stop_fraction)
        if result.outcome is not ActionOutcome.SUCCEEDED:
            self.let_go()
        return result

    def let_go(self) -> None:
        """Both hands open and the arms go home (after a failure)."""
        if self.hands.held:
            self.scene.step(self.robot.arc_steps)  # hold still until the object has stopped moving
        self.hands.release_all()
        self.scene.step(3)
        for arm in ARMS:
            drive_arm(self.scene, self.robot, arm, HOME_POSE[arm])

    def step_back(self) -> bool:
        """Open hands waiting over the links go home, out of the head camera's view (the centre stays: it is
        where the hands work next); True when they moved."""
        if self.hands.held or all(np.allclose(arm_joints(self.scene, arm), HOME_POSE[arm], atol=0.05) for arm in ARMS):
            return False
        for arm in ARMS:
            drive_arm(self.scene, self.robot, arm, HOME_POSE[arm])
        return True

    # -- the steps that turn nothing ---------------------------------------------------------------------------
    def _move_to_centre(self, action: RotationAction, arms: tuple[str, str]) -> ActionResult:
        self.hands.release_all()  # the plan moves open hands: none is holding now
        station = plan_station(self.scene, self.robot, action, arms)
        if isinstance(station, Unreachable):
            return _hand_failure(FailureReason.UNREACHABLE, f"not at the centre: {station.message}")
        for arm, q in station.above.items():
            if not drive_arm(self.scene, self.robot, arm, q):
                return _hand_failure(FailureReason.STALL, f"the {arm} arm did not reach its pose over "
                                     f"link {station.points[arm][0]}")
        return _hand_success(f"both hands over links {action.held_link} and {action.turned_link}{_swap(station)}")

    def _grasp(self, action: RotationAction, arms: tuple[str, str]) -> ActionResult:
        # the links may have moved since the hands came over them: the approach is planned from where they lie now
        station = plan_station(self.scene, self.robot, action, arms)
        if isinstance(station, Unreachable):
            return _hand_failure(FailureReason.UNREACHABLE, f"no grasp: {station.message}")
        for arm in station.above:
            for q in (station.above[arm], station.down[arm]):
                if not drive_arm(self.scene, self.robot, arm, q):
                    return _hand_failure(FailureReason.STALL, f"the {arm} arm did not reach its grasp pose")
        for arm, (link, _, _) in station.points.items():
            if not self.hands.grasp(arm, link):
                return _hand_failure(FailureReason.GRASP_LOST, f"the {arm} gripper closed on nothing at link {link}")
        held = ", ".join(f"the {arm} hand holds link {link}" for arm, (link, _, _) in station.points.items())
        return _hand_success(f"{held}{_swap(station)}")

    def _release(self, action: RotationAction, arms: tuple[str, str]) -> ActionResult:
        holding = dict(self.hands.held)
        if holding:
            self.scene.step(self.robot.arc_steps)  # hold still until the object has stopped moving, then let go
        self.hands.release_all()
        self.scene.step(3)
        lifted = []
        for arm in holding:
            position, yaw = self.robot.end_effector_pose(arm)[0], _gripper_yaw(self.scene, self.robot, arm)
            saved = {a: arm_joints(self.scene, a) for a in ARMS}
            q, _ = self.robot.solve_ik(arm, [position[0], position[1], position[2] + self.robot.approach_height_m],
                                       yaw, max_twist_deg=self.robot.hold_twist_deg)
            for a, s in saved.items():
                set_arm_joints(self.scene, a, s)
            if q is not None:
                drive_arm(self.scene, self.robot, arm, q)
            lifted.append(arm)
        for arm in ARMS:  # out of the head camera's view of the links
            drive_arm(self.scene, self.robot, arm, HOME_POSE[arm])
        return _hand_success(f"both hands open{', lifted' if lifted else ' (they held nothing)'} and back home")

    # -- the turns ----------------------------------------------------------------------------------------------
    def _turn_parts(self, parts: Sequence[RotationAction], pose: Pose, final: bool, interrupt: Interrupt,
                    stop_fraction: float | None) -> ActionResult:
        """Each part judged from the pose the ones before leave, then turned with the links held
        (`acting.perform_parts`)."""
        return perform_parts(self.scene, self.robot, pose, parts, final, interrupt, stop_fraction,
                             turn=lambda part: self._turn(part, interrupt, stop_fraction))

    def _turn(self, action: RotationAction, interrupt: Interrupt, stop_fraction: float | None) -> ActionResult:
        by_link = {link: arm for arm, (_, link) in self.hands.held.items()}
        missing = [k for k in (action.turned_link, action.held_link) if k not in by_link]
        if missing:
            return ActionResult(ActionOutcome.FAILED, FailureReason.GRASP_LOST,
                                f"not started: link {missing[0]} is not held", action.delta_deg, 0.0)
        command = plan_turn(self.scene, self.robot, action, by_link[action.turned_link])
        if isinstance(command, Unreachable):
            return ActionResult(ActionOutcome.FAILED, FailureReason.UNREACHABLE, f"not started: {command.message}",
                                action.delta_deg, 0.0)
        return execute(self.scene, command, self.robot, interrupt, stop_fraction, hands=self.hands)


def _hand_success(message: str) -> ActionResult:
    return ActionResult(ActionOutcome.SUCCEEDED, None, message, 0.0, 0.0)


def _hand_failure(reason: FailureReason, message: str) -> ActionResult:
    return ActionResult(ActionOutcome.FAILED, reason, message, 0.0, 0.0)


def _swap(station: Station) -> str:
    return " (the arms swapped: the named ones do not reach)" if station.swapped else ""


def _gripper_yaw(scene: Scene, robot: Robot, arm: str) -> float:
    _, quat = robot.end_effector_pose(arm)
    frame = np.asarray(scene.client.getMatrixFromQuaternion(quat)).reshape(3, 3)
    return math.atan2(frame[1, 0], frame[0, 0])


def _grasp_points(scene: Scene, link: int, toward: float | None) -> list[np.ndarray]:
    """Where a gripper may take `link`, best first: a quarter of a link from its centre, towards the joint first
    (`toward`: +1 when the joint lies along the link's direction, -1 against it), or with `toward` None on the
    side away from the head camera first (the hand then does not stand between the camera and the marker)."""
    along = direction(scene.link_orientations_deg()[link - 1])
    quarter = scene.spec.link_length_m / 4.0
    points = [scene.link_center(link) + s * quarter * along for s in (-1.0, 1.0)]
    if toward is not None:
        return [points[1], points[0]] if toward > 0 else points
    eye = _eye_xy(scene)
    return sorted(points, key=lambda p: -float(np.linalg.norm(p - eye)))


def _eye_xy(scene: Scene) -> np.ndarray:
    """The head camera's place on the table plane."""
    if scene.head_camera is None:
        return np.zeros(2)
    state = scene.client.getLinkState(scene.robot, scene.head_camera, computeForwardKinematics=True)
    return np.asarray(state[4][:2], dtype=float)


def plan_station(scene: Scene, robot: Robot, action: RotationAction, arms: tuple[str, str]) -> Station | Unreachable:
    """The arm poses above and on the two links at the action's joint, the named pairing first (turning arm on the
    downstream link, keeper on the upstream one), else the other; nothing moves. The grasp points are
    `_grasp_points` (see the module's note)."""
    _, side = joint_between(action.turned_link, action.held_link, scene.n_links)
    theta = scene.link_orientations_deg()
    z_grasp = scene.link_center_z + robot.grasp_height_m
    z_above = z_grasp + robot.approach_height_m
    # +1: the joint lies at the link's end (direction of the link), -1: at its start
    toward = {action.turned_link: -1.0 if side == "downstream" else 1.0,
              action.held_link: 1.0 if side == "downstream" else -1.0}
    saved = {arm: arm_joints(scene, arm) for arm in ARMS}
    worst: Unreachable | None = None
    try:
        for pairing, swapped in ((arms, False), (arms[::-1], True)):
            turner, keeper = pairing
            points, above, down = {}, {}, {}
            for arm, link in ((keeper, action.held_link), (turner, action.turned_link)):
                yaw0 = -math.radians(theta[link - 1])
                twist = robot.turn_twist_deg if link == action.turned_link else robot.hold_twist_deg
                found = None
                for xy in _grasp_points(scene, link, toward[link] if link == action.turned_link else None):
                    for yaw in (yaw0, yaw0 + math.pi):
                        q_above, miss = robot.solve_ik(arm, [xy[0], xy[1], z_above], yaw, max_twist_deg=twist)
                        q_down = None
                        if q_above is not None:
                            q_down, miss = robot.solve_ik(arm, [xy[0], xy[1], z_grasp], yaw, max_twist_deg=twist)
                        if q_above is not None and q_down is not None:
                            found = (xy, yaw, q_above, q_down)
                            break
                        missed = Unreachable(link, miss, f"{arm} arm over link {link} at x={xy[0]:.2f} m, "
                                                         f"y={xy[1]:.2f} m")
                        worst = missed if worst is None or missed.miss_m < worst.miss_m else worst
                    if found is not None:
                        break
                if found is None:
                    break
                points[arm] = (link, found[0], found[1])
                above[arm], down[arm] = found[2], found[3]
            if len(points) == 2:
                return Station(action.turned_link, action.held_link, points, above, down, swapped)
        assert worst is not None
        return worst
    finally:
        for arm, q in saved.items():
            set_arm_joints(scene, arm, q)


def plan_turn(scene: Scene, robot: Robot, action: RotationAction, turner: str) -> Command | Unreachable:
    """The turning arm's waypoints along the arc about the centred joint from where its gripper holds the link
    now, the gripper turning with the link; nothing moves."""
    joint_k, side = joint_between(action.turned_link, action.held_link, scene.n_links)
    pivot = scene.joint_points()[joint_k - 1]
    position, _ = robot.end_effector_pose(turner)
    saved = {arm: arm_joints(scene, arm) for arm in ARMS}
    try:
        arc = arc_turns(robot, turner, np.asarray(position[:2], dtype=float), float(position[2]), pivot,
                        action.delta_deg, _gripper_yaw(scene, robot, turner))
    finally:
        for arm, q in saved.items():
            set_arm_joints(scene, arm, q)
    if isinstance(arc, ArcMiss):
        return Unreachable(action.turned_link, arc.miss_m, f"{turner} arm turning, {arc.angle_deg:+.0f} deg at "
                           f"x={arc.xy[0]:.2f} m, y={arc.xy[1]:.2f} m")
    return Command(arc[0], joint_k, side, float(action.delta_deg), action.turned_link, action.held_link)


def single_steps(action: RotationAction) -> tuple[RotationAction, ...]:
    """A merged turn as its single steps (a step that turns nothing stays itself)."""
    return (action,) if action.name in HAND_STEPS else action.split()


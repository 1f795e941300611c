"""Skills: a plan's rotation action becomes a command (a list of primitives) that the simulator executes.

`rotate_skill` plans without moving anything: it solves inverse kinematics for every arm pose the action
needs and returns an `Unreachable` (which link, by how much) when one of them cannot be reached. `execute`
then plays the command physically, as the paper's three steps: the holding gripper closes on the link that
stays, the turning gripper closes on the link that turns (a grasp holds by a constraint made only once the
fingers touch the link), the turning arm follows the arc about the joint through its joint motors while the
physics steps, and both let go. The outcome is judged from the world afterwards: the measured joint angle
against the commanded one, what the arms touched on the way, grasps lost, links off the table.
"""
from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass
from typing import Any, Callable, Mapping, Sequence, Union

import numpy as np

from planhrc.geometry import reach_shortfall
from planhrc.vocabulary import ActionOutcome, FailureReason  # the words of a result, shared with the service
from planhrc.robot_sim.errors import SimError
from planhrc.robot_sim.grip import Hands, drive_arm
from planhrc.robot_sim.scene import (
    ARMS,
    HOME_POSE,
    Scene,
    arm_joints,
    direction,
    hold_arm,
    joint_between,
    rotate_point,
    set_arm_joints,
)

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class RotationAction:
    """One plan action: turn `turned_link` about its joint with `held_link` (0 = the table) by `delta_deg`
    (+ = clockwise seen from above). `joint_index` is the plan's joint number, kept for the record;
    `macro_steps` says how many plan steps were merged into this one motion."""

    turned_link: int
    held_link: int
    delta_deg: float
    joint_index: int | None = None
    action_id: str | None = None
    name: str = ""
    macro_steps: int = 1

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
                macro_steps=int(data.get("macro_steps") or 1),
            )
        except KeyError as exc:
            raise SimError(f"next_action.{exc.args[0]}: missing") from exc
        except (TypeError, ValueError) as exc:
            raise SimError(f"next_action: malformed ({exc})") from exc

    def split(self) -> tuple["RotationAction", ...]:
        """The macro step as its single steps (itself when it is one step)."""
        if self.macro_steps <= 1:
            return (self,)
        one = self.delta_deg / self.macro_steps
        return tuple(RotationAction(self.turned_link, self.held_link, one, self.joint_index, self.action_id,
                                    self.name, 1) for _ in range(self.macro_steps))


@dataclass(frozen=True)
class ActionResult:
    """What an action did, judged from the world: the outcome, why (None when it succeeded), a sentence,
    and the turn measured after release against the commanded one (degrees, + = clockwise)."""

    outcome: ActionOutcome
    reason: FailureReason | None
    message: str
    commanded_deg: float
    reached_deg: float
    refusal: Mapping[str, Any] | None = None  # a turn not started: the geometric fact, for the service
    hands_open: bool = False  # after the action the hands opened and went home (`BothHands`): the grasps are gone

    @property
    def value(self) -> str:
        return self.outcome.value


# -- primitives ------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class MoveArm:
    """Drive `arm`'s joint motors to `joint_positions` (interpolated in joint space)."""

    arm: str
    joint_positions: tuple[float, ...]


@dataclass(frozen=True)
class Grasp:
    """Close `arm`'s fingers on `link`; the grasp holds once the fingers touch it."""

    arm: str
    link: int


@dataclass(frozen=True)
class Release:
    arm: str


@dataclass(frozen=True)
class Turn:
    """One waypoint of the turning arm along the arc: `angle_deg` of the rotation done when it is reached."""

    arm: str
    joint_positions: tuple[float, ...]
    angle_deg: float


Primitive = Union[MoveArm, Grasp, Release, Turn]


@dataclass(frozen=True)
class Command:
    primitives: tuple[Primitive, ...]
    joint: int
    turned: str
    delta_deg: float
    turned_link: int
    held_link: int

    @property
    def rotation_steps(self) -> int:
        return sum(1 for p in self.primitives if isinstance(p, Turn))


@dataclass(frozen=True)
class Unreachable:
    """A command that cannot be planned: `link` cannot be reached by any arm, missing it by `miss_m`."""

    link: int
    miss_m: float
    where: str

    @property
    def message(self) -> str:
        return f"link {self.link} unreachable: {self.miss_m:.2f} m beyond reach ({self.where})"


# -- the robot: inverse kinematics for Baxter's arms ---------------------------------------------------------
class Robot:
    """Baxter's arms in a scene: IK within joint limits, checked by forward kinematics."""

    def __init__(
        self,
        scene: Scene,
        tolerance_m: float = 0.015,
        step_deg: float = 5.0,
        approach_height_m: float = 0.08,
        grasp_height_m: float = 0.005,
        arc_steps: int = 8,
        realtime_s: float = 0.0,
        success_tolerance_deg: float = 4.0,
        hold_twist_deg: float = 25.0,
        turn_twist_deg: float = 6.0,
    ) -> None:
        if scene.robot is None:
            raise SimError("scene: was built without the robot (load_robot=False)")
        self.scene = scene
        self.client = scene.client
        self.tolerance_m = tolerance_m
        self.step_deg = step_deg
        self.approach_height_m = approach_height_m
        self.grasp_height_m = grasp_height_m
        self.arc_steps = arc_steps  # physics steps per waypoint of a turn: 5 deg in 8 steps of 1/120 s = 75 deg/s
        self.realtime_s = realtime_s
        self.success_tolerance_deg = success_tolerance_deg
        self.hold_twist_deg = hold_twist_deg  # a bar held still may sit a little off square in the fingers
        self.turn_twist_deg = turn_twist_deg  # the turning gripper carries the link's yaw: it must match
        c, body = self.client, scene.robot
        self._movable = [j for j in range(c.getNumJoints(body)) if c.getJointInfo(body, j)[2] != 4]  # 4 = fixed
        self._lower = [c.getJointInfo(body, j)[8] for j in self._movable]
        self._upper = [c.getJointInfo(body, j)[9] for j in self._movable]
        self._ranges = [u - lo for lo, u in zip(self._lower, self._upper)]
        # the links of each arm that must touch nothing (everything from the shoulder to the wrist)
        self.arm_links: dict[str, tuple[int, ...]] = {}
        self.hand_links: dict[str, tuple[int, ...]] = {}
        names = {j: c.getJointInfo(body, j)[12].decode() for j in range(c.getNumJoints(body))}
        for arm in ARMS:
            prefix = f"{arm}_"
            hand = tuple(j for j, n in names.items()
                         if n.startswith((f"{arm[0]}_gripper", f"{prefix}gripper", f"{prefix}hand")))
            self.hand_links[arm] = hand
            self.arm_links[arm] = tuple(j for j, n in names.items()
                                        if n.startswith(prefix) and j not in hand and c.getCollisionShapeData(body, j))

    def end_effector_pose(self, arm: str) -> tuple[np.ndarray, tuple[float, ...]]:
        state = self.client.getLinkState(self.scene.robot, self.scene.arms[arm].end_effector, computeForwardKinematics=True)
        return np.array(state[4]), state[5]

    def solve_ik(self, arm: str, position: Sequence[float], yaw: float, iterations: int = 6,
                 max_twist_deg: float = 6.0) -> tuple[tuple[float, ...] | None, float]:
        """(joint positions putting `arm`'s gripper at `position`, pointing down, turned by `yaw` (radians), or
        None when it misses by more than the tolerance or tilts; the miss in metres).

        Leaves the arm at the solution (planning replays poses in order)."""
        info = self.scene.arms[arm]
        c, body = self.client, self.scene.robot
        target = np.asarray(position, dtype=float)
        orientation = c.getQuaternionFromEuler([math.pi, 0.0, yaw])
        rest = [c.getJointState(body, j)[0] for j in self._movable]
        solution: tuple[float, ...] = arm_joints(self.scene, arm)
        for _ in range(iterations):
            q = c.calculateInverseKinematics(
                body, info.end_effector, target.tolist(), orientation,
                lowerLimits=self._lower, upperLimits=self._upper, jointRanges=self._ranges, restPoses=rest,
                maxNumIterations=100, residualThreshold=1e-5,
            )
            solution = tuple(float(q[self._movable.index(j)]) for j in info.joints)
            solution = tuple(float(np.clip(v, lo, hi)) for v, lo, hi in zip(solution, info.lower, info.upper))
            set_arm_joints(self.scene, arm, solution)
            reached, _ = self.end_effector_pose(arm)
            if np.linalg.norm(reached - target) < 1e-3:
                break
        reached, quat = self.end_effector_pose(arm)
        error = float(np.linalg.norm(reached - target))
        frame = np.asarray(c.getMatrixFromQuaternion(quat)).reshape(3, 3)
        tilt = math.degrees(math.acos(float(np.clip(-frame[2, 2], -1.0, 1.0))))
        reached_yaw = math.atan2(frame[1, 0], frame[0, 0])
        twist = abs(math.degrees((reached_yaw - yaw + math.pi) % (2 * math.pi) - math.pi))
        if error > self.tolerance_m or tilt > 10.0 or twist > max_twist_deg:
            log.debug("IK: %s arm misses %s by %.3f m (tilt %.0f deg, twist %.0f deg)", arm,
                        np.round(target, 3).tolist(), error, tilt, twist)
            return None, max(error, 0.01 if error <= self.tolerance_m else error)
        return solution, error

    def arm_assignments(self, held_xy: np.ndarray | None, turned_xy: np.ndarray) -> list[tuple[str | None, str]]:
        """(arm holding, arm turning) pairs, best first: the closer arm turns when nothing is held, else the
        pairing with the shorter total shoulder distance; the other pairing is the fallback."""
        if held_xy is None:
            first = "left" if turned_xy[1] >= 0.0 else "right"
            return [(None, first), (None, "right" if first == "left" else "left")]

        def dist(arm: str, p: np.ndarray) -> float:
            return float(np.linalg.norm(np.asarray(self.scene.arms[arm].shoulder_xy) - p))

        left_holds = dist("left", held_xy) + dist("right", turned_xy)
        right_holds = dist("right", held_xy) + dist("left", turned_xy)
        pairs: list[tuple[str | None, str]] = [("left", "right"), ("right", "left")]
        return pairs if left_holds <= right_holds else pairs[::-1]


def unwrap_yaw(yaw: float, previous: float | None) -> float:
    """The gripper is symmetric under a half turn: pick yaw or yaw + pi, whichever is nearer `previous`."""
    if previous is None:
        return yaw
    candidates = [yaw + k * math.pi for k in range(-3, 4)]
    return min(candidates, key=lambda a: abs(a - previous))


@dataclass(frozen=True)
class ArcMiss:
    """Where along an arc the turning arm finds no pose: the gripper's point, the miss, the turn done by then."""

    xy: np.ndarray
    miss_m: float
    angle_deg: float


def arc_turns(robot: Robot, arm: str, grasp_xy: np.ndarray, z: float, pivot: np.ndarray, delta_deg: float,
              start_yaw: float) -> tuple[tuple[Turn, ...], float] | ArcMiss:
    """The waypoints of `arm` carrying a link it holds at `grasp_xy` (height `z`, gripper yaw `start_yaw`) by
    `delta_deg` about `pivot`, the gripper turning with the link, and its yaw at the end; or where it misses.
    Leaves the arm at the last pose solved (planning replays poses in order)."""
    n = max(1, math.ceil(abs(delta_deg) / robot.step_deg))
    yaw = start_yaw
    turns = []
    for i in range(1, n + 1):
        angle = delta_deg * i / n
        xy = rotate_point(grasp_xy, pivot, angle)
        yaw = unwrap_yaw(start_yaw - math.radians(angle), yaw)
        q, miss = robot.solve_ik(arm, [xy[0], xy[1], z], yaw, max_twist_deg=robot.turn_twist_deg)
        if q is None:
            return ArcMiss(xy, miss, angle)
        turns.append(Turn(arm, q, angle))
    return tuple(turns), yaw


def rotate_skill(scene: Scene, robot: Robot, action: RotationAction, turned_so_far: float = 0.0,
                 near_joint: bool = False) -> Command | Unreachable:
    """Plan a rotation action as a command, or say which link cannot be reached (nothing moves). With
    `turned_so_far`, the command for the rest of a turn whose first `turned_so_far` degrees another command
    does first (the turned link is planned where that leaves it); with `near_joint`, the turning gripper takes
    the link between its centre and the joint (a shorter arc) rather than at its centre first."""
    joint_k, _ = joint_between(action.turned_link, action.held_link, scene.n_links)  # refuses non-neighbours
    turned_xy = rotate_point(scene.link_center(action.turned_link), scene.joint_points()[joint_k - 1], turned_so_far)
    held_xy = scene.link_center(action.held_link) if action.held_link >= 1 else None
    saved = {arm: arm_joints(scene, arm) for arm in ARMS}
    worst: Unreachable | None = None
    try:
        for holder, turner in robot.arm_assignments(held_xy, turned_xy):
            for flip in (0.0, math.pi):
                planned = _plan_rotation(scene, robot, action, holder, turner, flip, turned_so_far, near_joint)
                if isinstance(planned, Command):
                    return planned
                if worst is None or planned.miss_m < worst.miss_m:
                    worst = planned
                for arm, q in saved.items():
                    set_arm_joints(scene, arm, q)
        assert worst is not None
        log.info("cannot plan %s: %s", action.name or f"turning l{action.turned_link}", worst.message)
        return worst
    finally:
        for arm, q in saved.items():
            set_arm_joints(scene, arm, q)


def _plan_rotation(scene: Scene, robot: Robot, action: RotationAction, holder: str | None, turner: str,
                   flip: float = 0.0, turned_so_far: float = 0.0, near_joint: bool = False) -> Command | Unreachable:
    """The command with `holder` holding and `turner` turning, the turning gripper grasping at the link's yaw
    plus `flip` (0 or pi: the wrist's range decides which way round the turn can be followed). Each gripper
    takes the first grasp point it reaches along its link (the centre, then a quarter of the link to either
    side); the holding gripper may meet its link up to `robot.hold_twist_deg` off square, either way round."""
    joint_k, side = joint_between(action.turned_link, action.held_link, scene.n_links)
    theta = list(scene.link_orientations_deg())
    theta[action.turned_link - 1] += turned_so_far
    pivot = scene.joint_points()[joint_k - 1]
    z_grasp = scene.link_center_z + robot.grasp_height_m
    z_above = z_grasp + robot.approach_height_m
    quarter = scene.spec.link_length_m / 4.0
    primitives: list[Primitive] = []

    def unreachable(arm: str, link: int, xy: np.ndarray, miss: float, what: str) -> Unreachable:
        beyond = max(miss, reach_shortfall((float(xy[0]), float(xy[1])), scene.spec.cell().robot))
        return Unreachable(link, beyond, f"{arm} arm, {what} at x={xy[0]:.2f} m, y={xy[1]:.2f} m")

    def approach(arm: str, link: int, yaws: Sequence[float], twist: float, what: str
                 ) -> tuple[np.ndarray, float] | Unreachable:
        """Above the link, then down onto it: the grasp point and yaw used, or the smallest miss."""
        centre, along = scene.link_center(link), direction(theta[link - 1])
        offsets: tuple[float, ...] = (0.0, -quarter, quarter)
        if link == action.turned_link:
            centre = rotate_point(centre, pivot, turned_so_far)
            if near_joint:  # the quarter towards the joint, then half-way between it and the centre
                toward = -1.0 if side == "downstream" else 1.0
                offsets = (toward * quarter, toward * quarter / 2)
        best: Unreachable | None = None
        for offset in offsets:
            xy = centre + offset * along
            for yaw in yaws:
                above, miss = robot.solve_ik(arm, [xy[0], xy[1], z_above], yaw, max_twist_deg=twist)
                down = None
                if above is not None:
                    down, miss = robot.solve_ik(arm, [xy[0], xy[1], z_grasp], yaw, max_twist_deg=twist)
                if above is not None and down is not None:
                    primitives.extend((MoveArm(arm, above), MoveArm(arm, down)))
                    return xy, yaw
                found = unreachable(arm, link, xy, miss, what)
                best = found if best is None or found.miss_m < best.miss_m else best
        assert best is not None
        return best

    held: tuple[np.ndarray, float] | None = None
    if holder is not None:
        held_yaw = -math.radians(theta[action.held_link - 1])
        reached = approach(holder, action.held_link, (held_yaw, held_yaw + math.pi), robot.hold_twist_deg, "holding")
        if isinstance(reached, Unreachable):
            return reached
        held = reached
        primitives.append(Grasp(holder, action.held_link))
    reached = approach(turner, action.turned_link, (-math.radians(theta[action.turned_link - 1]) + flip,),
                       robot.turn_twist_deg, "grasping")
    if isinstance(reached, Unreachable):
        return reached
    grasp_xy, turned_yaw = reached
    primitives.append(Grasp(turner, action.turned_link))

    arc = arc_turns(robot, turner, grasp_xy, z_grasp, pivot, action.delta_deg, turned_yaw)
    if isinstance(arc, ArcMiss):
        return unreachable(turner, action.turned_link, arc.xy, arc.miss_m, f"turning, {arc.angle_deg:+.0f} deg")
    turns, yaw = arc
    primitives.extend(turns)
    primitives.append(Release(turner))
    if holder is not None:
        primitives.append(Release(holder))
    final_xy = rotate_point(grasp_xy, pivot, action.delta_deg)
    lifts = [(turner, action.turned_link, final_xy, yaw)] + ([(holder, action.held_link, held[0], held[1])]
                                                              if holder is not None and held is not None else [])
    for arm, link, xy, arm_yaw in lifts:
        q, miss = robot.solve_ik(arm, [xy[0], xy[1], z_above], arm_yaw, max_twist_deg=robot.hold_twist_deg)
        if q is None:
            return unreachable(arm, link, xy, miss, "lifting")
        primitives.append(MoveArm(arm, q))
    for home in (turner, holder):
        if home is not None:
            primitives.append(MoveArm(home, HOME_POSE[home]))
    return Command(tuple(primitives), joint_k, side, float(action.delta_deg), action.turned_link, action.held_link)


# -- execution -----------------------------------------------------------------------------------------------
Interrupt = Callable[[int, int], bool]


def _follow(scene: Scene, robot: Robot, arm: str, target: Sequence[float], tolerance_rad: float = 0.03) -> bool:
    """Move `arm` smoothly to the next waypoint of an arc (the motor targets interpolated over
    `robot.arc_steps` physics steps, so the object is carried, not jerked); False when the arm lags behind."""
    start = np.asarray(arm_joints(scene, arm))
    goal = np.asarray(target, dtype=float)
    for i in range(1, robot.arc_steps + 1):
        hold_arm(scene, arm, start + (goal - start) * (i / robot.arc_steps))
        scene.step()
        if robot.realtime_s:
            time.sleep(robot.realtime_s)
    for _ in range(robot.arc_steps):
        if float(np.max(np.abs(np.asarray(arm_joints(scene, arm)) - goal))) < tolerance_rad:
            return True
        scene.step()
    return False


def _relative_deg(scene: Scene, turned: int, held: int) -> float:
    theta = scene.link_orientations_deg()
    return theta[turned - 1] - (theta[held - 1] if held >= 1 else 0.0)


def _signed_turn(now: float, before: float, commanded: float) -> float:
    """The turn from `before` to `now` (degrees), taken on the side of a full circle nearest `commanded`."""
    d = (now - before) % 360.0
    return min((d - 360.0, d, d + 360.0), key=lambda v: abs(v - commanded))


def _arm_contact(scene: Scene, robot: Robot, arms: Sequence[str]) -> str | None:
    """What an arm (shoulder to wrist) touches now: a link of the object, the table, or None."""
    for arm in arms:
        for link_index in robot.arm_links[arm]:
            for k in range(1, scene.n_links + 1):
                if scene.near(scene.robot, link_index, scene.body, scene.object_link_index(k), 0.0):
                    return f"the {arm} arm hits link {k}"
            if scene.near(scene.robot, link_index, scene.table, None, 0.0):
                return f"the {arm} arm hits the table"
    return None


def execute(
    scene: Scene,
    command: Command | Unreachable | None,
    robot: Robot | None = None,
    interrupt: Interrupt | None = None,
    stop_fraction: float | None = None,
    hands: Hands | None = None,
) -> ActionResult:
    """Play `command` physically and judge the outcome from the world.

    `interrupt(done, total)` is called before each waypoint of the turn (the human may start acting then; it
    acts on the physics clock) and stops the turn by returning True; `stop_fraction` makes the turning gripper
    lose its grasp once that share of the turn is done (a scripted fault). After a stop both grippers open and
    the arms go home. `hands` are grasps made before the command (a bimanual plan's): they stay held after it
    unless it stopped.
    """
    if command is None or isinstance(command, Unreachable):
        message = command.message if isinstance(command, Unreachable) else "no command"
        return ActionResult(ActionOutcome.FAILED, FailureReason.UNREACHABLE, message, 0.0, 0.0)
    robot = robot or Robot(scene)
    own_hands = hands is None
    hands = hands if hands is not None else Hands(scene, robot)
    total = command.rotation_steps
    done = 0
    before = _relative_deg(scene, command.turned_link, command.held_link)
    problem: tuple[FailureReason, str] | None = None
    arms_used = tuple(dict.fromkeys(p.arm for p in command.primitives))
    try:
        for primitive in command.primitives:
            if isinstance(primitive, MoveArm):
                if problem is not None and primitive.joint_positions != tuple(HOME_POSE[primitive.arm]):
                    continue
                if not drive_arm(scene, robot, primitive.arm, primitive.joint_positions) and problem is None:
                    problem = (FailureReason.STALL, f"the {primitive.arm} arm did not reach its pose")
            elif isinstance(primitive, Grasp):
                if problem is not None:
                    continue
                if not hands.grasp(primitive.arm, primitive.link):
                    problem = (FailureReason.GRASP_LOST, f"the {primitive.arm} gripper closed on nothing at link {primitive.link}")
            elif isinstance(primitive, Release):
                if primitive.arm in hands.held:
                    scene.step(robot.arc_steps)  # hold still until the object has stopped moving, then let go
                hands.release(primitive.arm)
                scene.step(3)
            elif isinstance(primitive, Turn):
                if problem is not None:
                    continue
                if interrupt is not None and interrupt(done, total):
                    problem = (FailureReason.STALL, "stopped on request")
                    continue
                if stop_fraction is not None and done >= stop_fraction * total:
                    hands.release(primitive.arm)
                    problem = (FailureReason.GRASP_LOST, f"the {primitive.arm} gripper let go of link {command.turned_link}")
                    continue
                if not _follow(scene, robot, primitive.arm, primitive.joint_positions):
                    problem = (FailureReason.STALL, f"the {primitive.arm} arm could not follow the arc")
                done += 1
                if (hit := _arm_contact(scene, robot, arms_used)) is not None:
                    problem = (FailureReason.COLLISION, hit)
                elif any(hands.offset(arm) > 0.02 for arm in hands.held):
                    slipping = next(arm for arm in hands.held if hands.offset(arm) > 0.02)
                    problem = (FailureReason.SLIP, f"link {hands.held[slipping][1]} slipped in the {slipping} gripper")
                if problem is not None:
                    hands.release_all()
    finally:
        if own_hands or problem is not None:
            hands.release_all()
    if problem is not None:  # the rest of the command was skipped: the arms go home with open hands
        for arm in arms_used:
            drive_arm(scene, robot, arm, HOME_POSE[arm])
    scene.step(6)
    return _judge(scene, robot, command, before, problem)


def _judge(scene: Scene, robot: Robot, command: Command, before: float, problem: tuple[FailureReason, str] | None
           ) -> ActionResult:
    reached = _signed_turn(_relative_deg(scene, command.turned_link, command.held_link), before, command.delta_deg)
    commanded = command.delta_deg
    short = commanded - reached
    link = command.turned_link
    off = scene.off_table_links()
    if off:
        reason, sentence = FailureReason.LEFT_TABLE, f"link {off[0]} left the table"
    elif problem is not None:
        reason, sentence = problem
    elif abs(short) > robot.success_tolerance_deg:
        reason = FailureReason.SLIP if abs(reached) > 1.0 else FailureReason.STALL
        sentence = f"link {link} {'slipped' if reason is FailureReason.SLIP else 'did not turn'}"
    else:
        return ActionResult(ActionOutcome.SUCCEEDED, None, f"link {link} turned {reached:+.1f} deg of {commanded:+.0f}",
                            commanded, reached)
    if abs(short) <= robot.success_tolerance_deg and reason is not FailureReason.LEFT_TABLE:
        # the turn itself is complete; the problem (a touch on the way back) is reported with it
        return ActionResult(ActionOutcome.SUCCEEDED, None, f"link {link} turned {reached:+.1f} deg of {commanded:+.0f} "
                            f"({sentence})", commanded, reached)
    moved = abs(reached) > 1.0 and reached * commanded > 0
    outcome = ActionOutcome.PARTIAL if moved else ActionOutcome.FAILED
    detail = f"{sentence}: turned {reached:+.1f} of {commanded:+.0f} deg, short by {abs(short):.1f} deg"
    return ActionResult(outcome, reason, detail, commanded, reached)


def perform_action(
    scene: Scene,
    robot: Robot,
    action: RotationAction,
    interrupt: Interrupt | None = None,
    stop_fraction: float | None = None,
) -> ActionResult:
    """Plan and execute one action; an action that cannot be planned is FAILED and nothing moves."""
    return execute(scene, rotate_skill(scene, robot, action), robot, interrupt, stop_fraction)

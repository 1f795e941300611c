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
from dataclasses import dataclass, replace
from typing import Any, Callable, Iterator, Mapping, Sequence

import numpy as np

from planhrc.robot_sim.acting import Pose, perform_parts
from planhrc.robot_sim.grip import Hands, drive_arm
from planhrc.robot_sim.perception import Perception
from planhrc.robot_sim.scene import ARMS, HOME_POSE, Scene, arm_joints, direction, joint_between, set_arm_joints
from planhrc.robot_sim.sightlines import Sightlines
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

    @property
    def key(self) -> tuple[Any, ...]:
        """Where the hands take the links, to the millimetre and the hundredth of a radian."""
        return tuple(sorted((arm, link, round(float(xy[0]), 3), round(float(xy[1]), 3), round(yaw, 2))
                            for arm, (link, xy, yaw) in self.points.items()))


def named_arms(data: Mapping[str, Any]) -> tuple[str, str]:
    """(turning arm, keeper arm) as the action names them (its last two parameters), else Baxter's usual ones."""
    params = [str(p) for p in data.get("params") or ()]
    if len(params) >= 2 and params[-2] in ARMS and params[-1] in ARMS and params[-2] != params[-1]:
        return params[-2], params[-1]
    return "right", "left"


class BothHands:
    """What Baxter's hands do across a bimanual plan's steps: where they work and what they hold."""

    def __init__(self, scene: Scene, robot: Robot, sight: Sightlines | None = None,
                 look: Callable[[], Perception] | None = None) -> None:
        self.scene, self.robot, self.sight, self.look = scene, robot, sight, look
        self.looked: Perception | None = None  # the look that ended the last step, every link seen
        self.hands = Hands(scene, robot)
        self.centred: tuple[Station, Pose] | None = None  # the station the hands came over, and the pose it was for

    def held_links(self) -> tuple[int, ...]:
        return tuple(sorted(link for _, link in self.hands.held.values()))

    def perform(self, parts: Sequence[RotationAction], data: Mapping[str, Any], pose: Pose, final: bool,
                interrupt: Interrupt, stop_fraction: float | None,
                then: RotationAction | None = None) -> ActionResult:
        """Do one dispatched step (a turn may come as its single steps, `parts`); on anything but success both
        hands open and the arms go home. `then`: the turn the plan makes next with the hands this step puts on
        the links (the stations are chosen so that the cameras see the links through it)."""
        first = parts[0]
        self.looked = None
        if first.name in HAND_STEPS:
            result = {MOVE_TO_CENTRE: self._move_to_centre, GRASP_LINKS: self._grasp,
                      RELEASE_LINKS: self._release}[first.name](first, named_arms(data), pose, then)
        else:
            result = self._turn_parts(parts, pose, final, interrupt, stop_fraction)
            if result.outcome is ActionOutcome.SUCCEEDED:
                result = self._looked_at(result)
        if result.outcome is not ActionOutcome.SUCCEEDED:
            self.let_go()
        return result

    def take_look(self) -> Perception | None:
        """The look that ended the last step (every link seen, the hands as they stay), once; None when there was
        none."""
        looked, self.looked = self.looked, None
        return looked

    def _looked_at(self, result: ActionResult) -> ActionResult:
        """With `look`, a held turn done is looked at: when the hands hide a link from every camera they let go and
        go home (the service then counts on open hands: `ActionResult.hands_open`), else the look is kept."""
        if self.look is None or not self.hands.held:
            return result
        seen = self.look()
        if not seen.missing_links:
            self.looked = seen
            return result
        log.info("after the held turn link(s) %s are hidden from every camera: the hands let go", seen.missing_links)
        self._put_down()
        return replace(result, hands_open=True, message=f"{result.message}; then both hands opened and went home: "
                       f"they hid link(s) {', '.join(map(str, seen.missing_links))} from every camera")

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
    def _move_to_centre(self, action: RotationAction, arms: tuple[str, str], pose: Pose,
                        then: RotationAction | None) -> ActionResult:
        self.hands.release_all()  # the plan moves open hands: none is holding now
        station = plan_station(self.scene, self.robot, action, arms, self.sight, pose, then)
        self.centred = None
        if isinstance(station, Unreachable):
            return _hand_failure(FailureReason.UNREACHABLE, f"not at the centre: {station.message}")
        self.centred = (station, pose)
        for arm, q in station.above.items():
            if not drive_arm(self.scene, self.robot, arm, q):
                return _hand_failure(FailureReason.STALL, f"the {arm} arm did not reach its pose over "
                                     f"link {station.points[arm][0]}")
        return _hand_success(f"both hands over links {action.held_link} and {action.turned_link}{_swap(station)}")

    def _grasp(self, action: RotationAction, arms: tuple[str, str], pose: Pose,
               then: RotationAction | None) -> ActionResult:
        """Take the two links; with `look` (the cameras), then look: a grasp that hides a link from every camera
        is let go and the next-best station taken, up to `GRASP_TRIES` stations (the robot's model of its arms and
        cameras is not exact; a link a hand hides is a link the service cannot follow)."""
        # the station the hands came over, unless the links have moved since: then the approach is planned from
        # where they lie now
        centred, self.centred = self.centred, None
        station = (centred[0] if centred is not None and _same_place(centred[1], pose)
                   and (centred[0].turned_link, centred[0].held_link) == (action.turned_link, action.held_link)
                   else plan_station(self.scene, self.robot, action, arms, self.sight, pose, then))
        tried: list[tuple[Any, ...]] = []
        hidden: Sequence[int] = ()
        while True:
            if isinstance(station, Unreachable):
                if tried:
                    break
                return _hand_failure(FailureReason.UNREACHABLE, f"no grasp: {station.message}")
            failure = self._take(station)
            if failure is not None:
                return failure
            seen = self.look() if self.look is not None else None
            hidden = seen.missing_links if seen is not None else ()
            if not hidden:
                self.looked = seen
                held = ", ".join(f"the {arm} hand holds link {link}" for arm, (link, _, _) in station.points.items())
                again = f" (grasp {len(tried) + 1}: the ones before hid a link)" if tried else ""
                return _hand_success(f"{held}{_swap(station)}{again}")
            tried.append(station.key)
            log.info("grasp at l%d/l%d: link(s) %s hidden from every camera; letting go for another grasp",
                     action.held_link, action.turned_link, list(hidden))
            self._open_and_lift()
            if len(tried) >= GRASP_TRIES:
                break
            station = plan_station(self.scene, self.robot, action, arms, self.sight, pose, then, avoid=tried)
        # `perform` then sends the open hands home
        return _hand_failure(FailureReason.UNREACHABLE,
                             f"no grasp at links {action.held_link} and {action.turned_link} leaves every link in a "
                             f"camera's sight: link(s) {', '.join(map(str, hidden))} hidden at each of the "
                             f"{len(tried)} grasps tried")

    def _take(self, station: Station) -> ActionResult | None:
        """The hands down onto the station's points and closed; None when both hold."""
        for arm in station.above:
            for q in (station.above[arm], station.down[arm]):
                if not drive_arm(self.scene, self.robot, arm, q):
                    return _hand_failure(FailureReason.STALL, f"the {arm} arm did not reach its grasp pose")
        for arm, (link, _, _) in station.points.items():
            if not self.hands.grasp(arm, link):
                return _hand_failure(FailureReason.GRASP_LOST, f"the {arm} gripper closed on nothing at link {link}")
        return None

    def _put_down(self) -> list[str]:
        """`_open_and_lift`, then both arms home, out of the head camera's view of the links; the arms that
        lifted."""
        lifted = self._open_and_lift()
        for arm in ARMS:
            drive_arm(self.scene, self.robot, arm, HOME_POSE[arm])
        return lifted

    def _open_and_lift(self) -> list[str]:
        """Both hands open where they are and each that held lifts straight up off its link; the arms that
        lifted."""
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
        return lifted

    def _release(self, action: RotationAction, arms: tuple[str, str], pose: Pose,
                 then: RotationAction | None) -> ActionResult:
        lifted = self._put_down()
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


def _same_place(a: Pose, b: Pose, angle_deg: float = 1.0, distance_m: float = 0.005) -> bool:
    """Whether the object lies where it lay (every link within `angle_deg`, the base point within `distance_m`)."""
    return (float(np.hypot(*np.subtract(a.geometry.base_point_xy, b.geometry.base_point_xy))) <= distance_m
            and all(abs((x - y + 180.0) % 360.0 - 180.0) <= angle_deg for x, y in zip(a.angles, b.angles)))


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


GRASP_TRIES = 3  # the grasps tried at one centre before the step fails: each looked at, the next-best after
OUTER_GRASP = 0.38  # of a link's length from its centre: the grasp points tried after the quarter ones


def _grasp_points(scene: Scene, link: int, joint_side: float, turning: bool, outer: bool) -> list[np.ndarray]:
    """Where a gripper may take `link`, best first: a quarter of a link from its centre (never on the marker at the
    centre), the turning gripper towards the joint first (`joint_side`: +1 when the joint lies along the link's
    direction, -1 against it), the keeper on the side away from the head camera first (its hand then does not
    stand between that camera and the marker); with `outer`, then `OUTER_GRASP` from the centre on the side away
    from the joint (clear of the other gripper)."""
    along = direction(scene.link_orientations_deg()[link - 1])
    centre, length = scene.link_center(link), scene.spec.link_length_m
    points = [centre + s * length / 4.0 * along for s in (-1.0, 1.0)]
    if turning:
        points = [points[1], points[0]] if joint_side > 0 else points
    else:
        eye = _eye_xy(scene)
        points = sorted(points, key=lambda p: -float(np.linalg.norm(p - eye)))
    return points + ([centre - joint_side * OUTER_GRASP * length * along] if outer else [])


def _eye_xy(scene: Scene) -> np.ndarray:
    """The head camera's place on the table plane."""
    if scene.head_camera is None:
        return np.zeros(2)
    state = scene.client.getLinkState(scene.robot, scene.head_camera, computeForwardKinematics=True)
    return np.asarray(state[4][:2], dtype=float)


def plan_station(scene: Scene, robot: Robot, action: RotationAction, arms: tuple[str, str],
                 sight: Sightlines | None = None, pose: Pose | None = None,
                 then: RotationAction | None = None, avoid: Sequence[tuple[Any, ...]] = ()) -> Station | Unreachable:
    """The arm poses above and on the two links at the action's joint, the named pairing first (turning arm on the
    downstream link, keeper on the upstream one), else the other; nothing moves. The grasp points are
    `_grasp_points` (see the module's note), each arm's in turn. Without `sight`: the first station the arms
    reach. With `sight` (and the object as perceived, `pose`): the first station, in that order, from which every
    link's marker stays in some camera's clear sight with the hands on the links and, when the plan
    turns `then` while they hold, at the end of that turn (which the turning arm must be able to follow); else the
    one that covers the markers least (`Sightlines.cover`, summed), a station whose turn the arm cannot follow
    last. Stations whose `Station.key` is in `avoid` (grasps tried already) are passed over: the first other
    station the arms reach, of every grasp point, without `sight`."""
    joint_k, side = joint_between(action.turned_link, action.held_link, scene.n_links)
    theta = scene.link_orientations_deg()
    z_grasp = scene.link_center_z + robot.grasp_height_m
    z_above = z_grasp + robot.approach_height_m
    # +1: the joint lies at the link's end (direction of the link), -1: at its start
    toward = {action.turned_link: -1.0 if side == "downstream" else 1.0,
              action.held_link: 1.0 if side == "downstream" else -1.0}
    if then is not None and (then.turned_link, then.held_link) != (action.turned_link, action.held_link):
        then = None
    saved = {arm: arm_joints(scene, arm) for arm in ARMS}
    every = sight is not None or bool(avoid)  # every grasp point and yaw, not only the first that reaches
    misses: list[Unreachable] = []
    best: tuple[bool, float, Station] | None = None
    survey = None
    if sight is not None and pose is not None:
        survey = sight.survey({"held": pose, "turned": pose.after(then) if then is not None else pose})

    def options(arm: str, link: int) -> Iterator[tuple[np.ndarray, float, tuple[float, ...], tuple[float, ...]]]:
        """Where `arm` can take `link`, best first: each grasp point with the first gripper yaw that reaches it
        (when the cameras' sight decides, then with the other yaw too: the wrist turns another way)."""
        yaw0 = -math.radians(theta[link - 1])
        twist = robot.turn_twist_deg if link == action.turned_link else robot.hold_twist_deg
        later = []
        for xy in _grasp_points(scene, link, toward[link], link == action.turned_link, every):
            for i, yaw in enumerate((yaw0, yaw0 + math.pi)):
                q_above, miss = robot.solve_ik(arm, [xy[0], xy[1], z_above], yaw, max_twist_deg=twist)
                q_down = None
                if q_above is not None:
                    q_down, miss = robot.solve_ik(arm, [xy[0], xy[1], z_grasp], yaw, max_twist_deg=twist)
                if q_above is not None and q_down is not None:
                    yield xy, yaw, q_above, q_down
                    if not every:
                        return
                    if i == 0:
                        later.append((xy, yaw + math.pi))
                    break
                misses.append(Unreachable(link, miss, f"{arm} arm over link {link} at x={xy[0]:.2f} m, "
                                                      f"y={xy[1]:.2f} m"))
        for xy, yaw in later:
            q_above, _ = robot.solve_ik(arm, [xy[0], xy[1], z_above], yaw, max_twist_deg=twist)
            if q_above is not None:
                q_down, _ = robot.solve_ik(arm, [xy[0], xy[1], z_grasp], yaw, max_twist_deg=twist)
                if q_down is not None:
                    yield xy, yaw, q_above, q_down

    arc_ends: dict[tuple[str, float, float, float], tuple[float, ...] | None] = {}

    def arc_end(station: Station, turner: str) -> tuple[float, ...] | None:
        """The turning arm's joints at the end of the held turn from the station's grasp (None: it cannot follow
        the arc)."""
        assert then is not None
        _, grasp_xy, yaw = station.points[turner]
        key = (turner, round(float(grasp_xy[0]), 5), round(float(grasp_xy[1]), 5), round(yaw, 5))
        if key not in arc_ends:
            set_arm_joints(scene, turner, station.down[turner])
            arc = arc_turns(robot, turner, grasp_xy, z_grasp, scene.joint_points()[joint_k - 1], then.delta_deg, yaw)
            arc_ends[key] = None if isinstance(arc, ArcMiss) else arc[0][-1].joint_positions
        return arc_ends[key]

    def cover(station: Station, turner: str) -> tuple[bool, float]:
        """(whether the turning arm can follow the held turn, the markers' cover summed over the postures)."""
        assert survey is not None
        total = sum(survey.cover("held", station.down))
        if then is None:
            return True, total
        end = arc_end(station, turner)
        if end is None:
            return False, total
        return True, total + sum(survey.cover("turned", {**station.down, turner: end}))

    try:
        for pairing, swapped in ((arms, False), (arms[::-1], True)):
            turner, keeper = pairing
            keeps = list(options(keeper, action.held_link))
            turns = list(options(turner, action.turned_link)) if keeps else []
            for kept in keeps:
                for turned in turns:
                    station = Station(action.turned_link, action.held_link,
                                      {keeper: (action.held_link, kept[0], kept[1]),
                                       turner: (action.turned_link, turned[0], turned[1])},
                                      {keeper: kept[2], turner: turned[2]}, {keeper: kept[3], turner: turned[3]},
                                      swapped)
                    if station.key in avoid:
                        continue
                    if survey is None:
                        return station
                    follows, covered = cover(station, turner)
                    if log.isEnabledFor(logging.DEBUG):
                        log.debug("station at j%d: %s, cover %.2f%s", joint_k - 1,
                                  ", ".join(f"{arm} on l{link} at ({xy[0]:.3f}, {xy[1]:.3f})"
                                            for arm, (link, xy, _) in station.points.items()),
                                  covered, "" if follows else " (turn not followed)")
                    if follows and covered == 0.0:
                        return station
                    if best is None or (not follows, covered) < (not best[0], best[1]):
                        best = (follows, covered, station)
        if best is not None:
            log.info("grasp at j%d: no station the arms reach keeps every marker in clear sight; the one covering "
                     "them least (%.2f%s)", joint_k - 1, best[1], "" if best[0] else ", its turn not followed")
            return best[2]
        if not misses:  # every station the arms reach was tried already
            return Unreachable(action.turned_link, 0.0, f"no grasp at joint {joint_k} left untried")
        return min(misses, key=lambda m: m.miss_m)
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


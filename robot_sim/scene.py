"""The simulated work cell: Baxter, a table and a physical articulated object with ArUco markers.

Frames and angles (CONVENTIONS.md): the world's +x is the robot's forward axis, +y its left, +z up. A link's
orientation theta is in degrees, clockwise seen from above, from +x; its direction on the table is
(cos theta, -sin theta) and its PyBullet yaw is -radians(theta).

The object is a physical body: one PyBullet multibody whose base is l1 and whose links l2 .. lN hang on
revolute joints about the vertical, each with friction (a velocity motor with a force limit) and damping; it
lies on the table under gravity and moves only when the simulation is stepped (`Scene.step`) and something
pushes it: the robot's grippers or the human's hands, through constraints made once they touch a link.
`configuration()` and `link_orientations_deg()` measure the bodies' poses; `set_configuration` places the
object (to set a scene up, never to carry out an action). Link lK runs from joint point pK to pK+1; pK joins
l(K-1) and lK, p1 joins l1 to the table (the absolute formulation's numbering).

The robot does not collide with anything (its arms are moved by position motors along planned paths); its
grippers hold a link by a fixed constraint made when the fingers touch the link, and what the arms touch is
checked with closest-point queries (`touching`). Markers are visual bodies that follow their links when the
scene is rendered (`sync_markers`).

The caller owns the ``BulletClient``; nothing here touches a global PyBullet connection.
"""
from __future__ import annotations

import importlib.metadata
import math
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Callable, Sequence

import numpy as np
import pybullet

from planhrc.geometry import (EXECUTION, STRICT, Cell, Infeasibility, ObjectGeometry, RobotBody, Table, Tolerance,
                              configuration_feasible, rotated)
from planhrc.robot_sim.camera import Board
from planhrc.robot_sim.errors import SimError
from planhrc.robot_sim.markers import MarkerAsset, write_marker_asset
from planhrc.vocabulary import Infeasible

if TYPE_CHECKING:
    from pybullet_utils.bullet_client import BulletClient

BAXTER_URDF = "robots/baxter_description/urdf/baxter.urdf"
PACKAGE_PREFIX = "package://example-robot-data/"
ARMS = ("left", "right")
ARM_JOINTS = ("s0", "s1", "e0", "e1", "w0", "w1", "w2")
# A pose with both hands raised and out to the sides, clear of the head camera's view of the table.
HOME_POSE = {
    "left": (1.0, -0.9, -0.3, 1.6, 0.0, 0.9, 0.0),
    "right": (-1.0, -0.9, 0.3, 1.6, 0.0, 0.9, 0.0),
}
TIME_STEP_S = 1.0 / 120.0  # a coarse step keeps an action well under a second of wall time


@dataclass(frozen=True)
class SceneSpec:
    """Everything needed to build a scene; immutable so a worker can rebuild the same cell."""

    n_links: int = 5
    link_length_m: float = 0.155
    link_width_m: float = 0.03
    link_height_m: float = 0.015
    marker_size_m: float = 0.03
    base_point_xy: tuple[float, float] | None = None  # default: x = 0.6, the straight object centred on y = 0
    initial_orientations_deg: tuple[float, ...] | None = None  # default: every link at 90 (to the right)
    table_center_xy: tuple[float, float] = (0.6, 0.0)  # Baxter's grippers reach x ~ 0.35 .. 0.8 at table height
    table_size_xy: tuple[float, float] = (0.6, 1.3)
    table_top_z: float = -0.18
    load_robot: bool = True
    link_mass_kg: float = 0.2
    joint_friction_nm: float = 1.0  # stiff enough that the links beyond a turned one move with it (A1)
    joint_damping: float = 0.05
    unmarked_links: tuple[int, ...] = ()  # links whose marker is painted over (the camera cannot see them)
    table_friction: float = 0.15  # Bullet multiplies the two bodies' coefficients: the links have 1.0
    board: Board | None = None  # calibration markers lying on the table (`camera.SIM_BOARD`); none by default

    def __post_init__(self) -> None:
        if self.board is not None and any(m.marker_id < self.n_links for m in self.board.markers):
            raise SimError(f"board: marker ids {sorted(self.board.ids)} must not be links' (0..{self.n_links - 1})")
        if self.n_links < 1:
            raise SimError(f"n_links: must be at least 1, got {self.n_links}")
        if self.n_links > 50:
            raise SimError(f"n_links: at most 50 markers exist in DICT_4X4_50, got {self.n_links}")
        if any(not 1 <= k <= self.n_links for k in self.unmarked_links):
            raise SimError(f"unmarked_links: links are numbered 1..{self.n_links}, got {self.unmarked_links}")
        if self.initial_orientations_deg is not None and len(self.initial_orientations_deg) != self.n_links:
            raise SimError(
                f"initial_orientations_deg: expected {self.n_links} values, got {len(self.initial_orientations_deg)}"
            )

    @property
    def orientations0(self) -> tuple[float, ...]:
        if self.initial_orientations_deg is None:
            return (90.0,) * self.n_links
        return tuple(float(v) for v in self.initial_orientations_deg)

    @property
    def base_xy(self) -> tuple[float, float]:
        if self.base_point_xy is not None:
            return float(self.base_point_xy[0]), float(self.base_point_xy[1])
        return 0.6, round(self.n_links * self.link_length_m / 2.0, 4)

    def cell(self) -> Cell:
        """The table and robot of this scene, for `planhrc.geometry`."""
        return Cell(Table(self.table_center_xy, self.table_size_xy, self.table_top_z), RobotBody())

    def geometry(self, base_point_xy: Sequence[float] | None = None) -> ObjectGeometry:
        base = self.base_xy if base_point_xy is None else (float(base_point_xy[0]), float(base_point_xy[1]))
        return ObjectGeometry((self.link_length_m,) * self.n_links, base, self.link_width_m)


@dataclass(frozen=True)
class ArmInfo:
    """Joint indices of one Baxter arm inside the robot body."""

    name: str
    joints: tuple[int, ...]
    lower: tuple[float, ...]
    upper: tuple[float, ...]
    end_effector: int
    fingers: tuple[int, ...]
    finger_open: tuple[float, ...]
    finger_closed: tuple[float, ...]
    shoulder_xy: tuple[float, float]


def direction(theta_deg: float) -> np.ndarray:
    """Unit vector on the table of a link at orientation theta (clockwise from +x, seen from above)."""
    t = math.radians(theta_deg)
    return np.array([math.cos(t), -math.sin(t)])


def eased(fraction: float) -> float:
    """How much of a human's turn is done at `fraction` of its time: a half cosine, speeding up and slowing down
    smoothly. The links beyond the turned one are held by joint friction alone, and the point l1 turns about by
    nothing but the table: a turn at full speed from its first tick to its last jerked them (a human's turn of
    l1 slid the base point by 4 cm). The robot's arc keeps its even pace: eased the same way, its longer turns
    dragged the links before a held one further (docs/results.md, the robot)."""
    return 0.5 - 0.5 * math.cos(math.pi * min(1.0, max(0.0, fraction)))


def rotate_point(point: np.ndarray, pivot: np.ndarray, delta_deg: float) -> np.ndarray:
    """Rotate a table point about `pivot` by `delta_deg` clockwise seen from above."""
    t = -math.radians(delta_deg)
    c, s = math.cos(t), math.sin(t)
    d = point - pivot
    turned: np.ndarray = pivot + np.array([c * d[0] - s * d[1], s * d[0] + c * d[1]])
    return turned


def baxter_urdf_source() -> Path:
    """The installed example-robot-data Baxter URDF (found through the distribution's file list)."""
    dist = importlib.metadata.distribution("example-robot-data")
    for entry in dist.files or ():
        if str(entry).endswith(BAXTER_URDF):
            return Path(str(dist.locate_file(entry)))
    raise SimError("example-robot-data: baxter.urdf not found in the installed distribution")


def write_baxter_urdf(directory: Path) -> Path:
    """Copy the Baxter URDF into `directory` with `package://example-robot-data/` made an absolute path."""
    source = baxter_urdf_source()
    share = str(source)[: -len(BAXTER_URDF)]
    target = directory / "baxter.urdf"
    target.write_text(source.read_text().replace(PACKAGE_PREFIX, share))
    return target


class Scene:
    """A built work cell. Create it with `build_scene`; call `close` to remove its temporary files."""

    def __init__(self, client: BulletClient, spec: SceneSpec, workdir: tempfile.TemporaryDirectory[str]) -> None:
        self.client = client
        self.spec = spec
        self._workdir = workdir
        self.directory = Path(workdir.name)
        self.robot: int | None = None
        self.arms: dict[str, ArmInfo] = {}
        self.head_pan: int | None = None
        self.head_camera: int | None = None
        self.table: int = -1
        self.body: int = -1  # the object: its base is l1, its PyBullet link K-2 is lK
        self.marker_bodies: list[int] = []
        self.board_bodies: dict[int, int] = {}  # the calibration board's marker id -> its body
        self.markers: list[MarkerAsset] = []
        self.time_s = 0.0  # the physics clock
        self.gripped: set[int] = set()  # links a robot gripper holds now
        self._tickers: list[Callable[["Scene"], None]] = []

    # -- the object, measured from its bodies ---------------------------------------------------------------
    @property
    def n_links(self) -> int:
        return self.spec.n_links

    @property
    def link_center_z(self) -> float:
        return self.spec.table_top_z + self.spec.link_height_m / 2.0

    @property
    def marker_z(self) -> float:
        return self.spec.table_top_z + self.spec.link_height_m + 0.001

    @staticmethod
    def object_link_index(link: int) -> int:
        """PyBullet's index of link `link` (1-based) in the object body (-1 = the base, l1)."""
        return -1 if link == 1 else link - 2

    def link_pose(self, link: int) -> tuple[np.ndarray, tuple[float, float, float, float]]:
        """World position of link `link`'s centre (1-based) and its orientation quaternion."""
        self._check_link(link)
        if link == 1:
            position, quat = self.client.getBasePositionAndOrientation(self.body)
        else:
            state = self.client.getLinkState(self.body, link - 2, computeForwardKinematics=True)
            position, quat = state[0], state[1]  # the inertial frame: the link's centre
        return np.asarray(position, dtype=float), tuple(quat)

    def link_orientations_deg(self) -> tuple[float, ...]:
        """Each link's orientation measured from its body (degrees in [0, 360))."""
        out = []
        for link in range(1, self.n_links + 1):
            yaw = self.client.getEulerFromQuaternion(self.link_pose(link)[1])[2]
            out.append((-math.degrees(yaw)) % 360.0)
        return tuple(out)

    def link_center(self, link: int) -> np.ndarray:
        """Centre (x, y) of link `link` (1-based)."""
        return self.link_pose(link)[0][:2]

    def joint_points(self) -> list[np.ndarray]:
        """p1 .. p(N+1) on the table (x, y), from the links' measured poses."""
        theta = self.link_orientations_deg()
        half = self.spec.link_length_m / 2.0
        points = [self.link_center(1) - half * direction(theta[0])]
        for k in range(1, self.n_links + 1):
            points.append(self.link_center(k) + half * direction(theta[k - 1]))
        return points

    def base_point(self) -> tuple[float, float]:
        p = self.joint_points()[0]
        return float(p[0]), float(p[1])

    def configuration(self) -> tuple[tuple[float, float], tuple[float, ...]]:
        """The measured state: (base point, link orientations in degrees)."""
        return self.base_point(), self.link_orientations_deg()

    def off_table_links(self) -> tuple[int, ...]:
        """Links beyond the table's edge or fallen below its top (measured)."""
        base, theta = self.configuration()
        result = configuration_feasible(self.spec.geometry(base), theta, self.spec.cell())
        beyond = {r.link for r in result.reasons if r.code is Infeasible.OFF_TABLE}
        fallen = {k for k in range(1, self.n_links + 1) if self.link_pose(k)[0][2] < self.spec.table_top_z - 0.01}
        return tuple(sorted(beyond | fallen))

    def set_configuration(self, orientations_deg: Sequence[float], base_point_xy: Sequence[float] | None = None) -> None:
        """Place the object at rest (to set a scene up, never to carry out an action): link orientations and
        the base point p1 (default: where it is now)."""
        if len(orientations_deg) != self.n_links:
            raise SimError(f"orientations_deg: expected {self.n_links} values, got {len(orientations_deg)}")
        theta = [float(v) % 360.0 for v in orientations_deg]
        if base_point_xy is not None:
            base = np.asarray(base_point_xy, dtype=float)
        else:
            base = np.asarray(self.base_point())
        c = self.client
        centre = base + self.spec.link_length_m / 2.0 * direction(theta[0])
        quat = c.getQuaternionFromEuler([0.0, 0.0, -math.radians(theta[0])])
        c.resetBasePositionAndOrientation(self.body, [centre[0], centre[1], self.link_center_z], quat)
        c.resetBaseVelocity(self.body, [0, 0, 0], [0, 0, 0])
        for k in range(2, self.n_links + 1):
            # PyBullet's joint angle turns counter-clockwise: minus the clockwise relative orientation
            relative = (theta[k - 1] - theta[k - 2] + 180.0) % 360.0 - 180.0
            c.resetJointState(self.body, k - 2, -math.radians(relative), 0.0)
        self.sync_markers()

    # -- the physics clock ----------------------------------------------------------------------------------
    def add_ticker(self, ticker: Callable[["Scene"], None]) -> None:
        """Call `ticker(scene)` before every physics step: whatever acts in parallel with the robot."""
        self._tickers.append(ticker)

    def remove_ticker(self, ticker: Callable[["Scene"], None]) -> None:
        if ticker in self._tickers:
            self._tickers.remove(ticker)

    def step(self, n: int = 1) -> None:
        for _ in range(n):
            for ticker in tuple(self._tickers):
                ticker(self)
            self.client.stepSimulation()
            self.time_s += TIME_STEP_S

    # -- contacts -------------------------------------------------------------------------------------------
    def near(self, body: int | None, link: int, other: int | None, other_link: int | None = None,
             distance_m: float = 0.0) -> bool:
        """Whether `body`'s `link` comes within `distance_m` of `other` (its `other_link`, or any part of it);
        False while either body is not in the scene."""
        if body is None or other is None:
            return False
        if other_link is None:
            points = self.client.getClosestPoints(body, other, distance_m, linkIndexA=link)
        else:
            points = self.client.getClosestPoints(body, other, distance_m, linkIndexA=link, linkIndexB=other_link)
        return bool(points)

    # -- bodies ---------------------------------------------------------------------------------------------
    def _check_link(self, link: int) -> None:
        if not 1 <= link <= self.n_links:
            raise SimError(f"link: must be in 1..{self.n_links}, got {link}")

    def sync_markers(self) -> None:
        """Put each marker quad on its link's top face (markers are painted on: they have no body of their own)."""
        for k, marker in enumerate(self.marker_bodies, start=1):
            position, quat = self.link_pose(k)
            up = np.asarray(self.client.getMatrixFromQuaternion(quat)).reshape(3, 3)[:, 2]
            top = position + up * (self.spec.link_height_m / 2.0 + 0.001)
            self.client.resetBasePositionAndOrientation(marker, top.tolist(), quat)

    def take_board_away(self) -> None:
        """Take the calibration board's markers off the table (a cell's camera once calibrated needs them no more,
        and a link lying on a board marker's black square would lose its own marker's white border)."""
        for body in self.board_bodies.values():
            self.client.removeBody(body)
        self.board_bodies.clear()

    def close(self) -> None:
        """Remove the scene's temporary files (the caller disconnects its own client)."""
        self._workdir.cleanup()

    def __enter__(self) -> "Scene":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def is_feasible(spec: SceneSpec, orientations_deg: Sequence[float], base_point_xy: Sequence[float] | None = None) -> bool:
    """On the table, clear of the robot, within reach and not overlapping itself (`planhrc.geometry`)."""
    return configuration_feasible(spec.geometry(base_point_xy), orientations_deg, spec.cell()).ok


# what a turn must not cause; reach is the robot's matter
HAZARDS = (Infeasible.OFF_TABLE, Infeasible.INSIDE_ROBOT, Infeasible.OVERLAP)


def baseline_problems(geometry: ObjectGeometry, orientations_deg: Sequence[float], cell: Cell,
                      tolerance: Tolerance = STRICT) -> frozenset[tuple[Infeasible, int]]:
    """(code, link) of the problems a configuration has already (strictly, or judged with `tolerance`): acting on
    it does not cause them."""
    return frozenset((r.code, r.link)
                     for r in configuration_feasible(geometry, orientations_deg, cell, tolerance=tolerance).reasons)


def added_hazards(geometry: ObjectGeometry, orientations_deg: Sequence[float], cell: Cell,
                  baseline: frozenset[tuple[Infeasible, int]], hazards: Sequence[Infeasible] = HAZARDS,
                  tolerance: Tolerance = EXECUTION) -> tuple[Infeasibility, ...]:
    """The problems among `hazards` that the configuration has beyond `baseline`, judged with the tolerance a
    physical execution is given on its way (`planhrc.geometry.EXECUTION`), or `tolerance`."""
    result = configuration_feasible(geometry, orientations_deg, cell, tolerance=tolerance)
    return tuple(r for r in result.reasons if r.code in hazards and (r.code, r.link) not in baseline)


def sweep_hazard(geometry: ObjectGeometry, orientations_deg: Sequence[float], cell: Cell, turned_link: int,
                 held_link: int, delta_deg: float, baseline: frozenset[tuple[Infeasible, int]],
                 hazards: Sequence[Infeasible] = HAZARDS, increment_deg: float = 5.0,
                 end_tolerance: Tolerance = EXECUTION) -> Infeasibility | None:
    """The first problem among `hazards` (beyond `baseline`) that turning `turned_link` about its joint with
    `held_link` by `delta_deg` causes somewhere along its sweep (every `increment_deg`), or None; where the
    turn comes to rest is judged with `end_tolerance` (`STRICT`: the object is left there, and perceived)."""
    n = max(1, math.ceil(abs(delta_deg) / increment_deg))
    for i in range(1, n + 1):
        placed, values = rotated(geometry, orientations_deg, turned_link, held_link, delta_deg * i / n)
        found = added_hazards(placed, values, cell, baseline, hazards)
        if i == n and not found and end_tolerance != EXECUTION:
            found = added_hazards(placed, values, cell, baseline, hazards, end_tolerance)
        if found:
            return found[0]
    return None


def turn_hazard(scene: Scene, turned_link: int, held_link: int, delta_deg: float,
                increment_deg: float = 5.0, hazards: Sequence[Infeasible] = HAZARDS) -> Infeasibility | None:
    """The first problem turning `turned_link` about its joint with `held_link` by `delta_deg` would cause
    somewhere along its sweep (a link past the table's edge, inside the robot, folded onto or across another,
    beyond `planhrc.geometry.EXECUTION`'s tolerance) or where it comes to rest (as drawn, `STRICT`: a turn may
    brush the edge on its way, but must not leave the object hanging over it), from the object's measured
    pose; None when the turn is safe. Problems the object already has before the turn, and links out of the
    robot's reach, do not count; `hazards` narrows what counts."""
    base, theta = scene.configuration()
    geometry, cell = scene.spec.geometry(base), scene.spec.cell()
    return sweep_hazard(geometry, theta, cell, turned_link, held_link, delta_deg,
                        baseline_problems(geometry, theta, cell), hazards, increment_deg, end_tolerance=STRICT)


def new_hazards(scene: Scene, geometry: ObjectGeometry, orientations_deg: Sequence[float]) -> tuple[Infeasibility, ...]:
    """The problems (`HAZARDS`, with `planhrc.geometry.EXECUTION`'s tolerance) the object placed as `geometry`
    with `orientations_deg` would have that it does not have now (measured). The human brings the object to the
    end the robot asks for with this tolerance: asked for an end just past the edge as drawn (a relative goal
    turned with `l1`), the human does it, and the state is counted off the table, rather than refusing until the
    worker gives up."""
    base, theta = scene.configuration()
    cell = scene.spec.cell()
    return added_hazards(geometry, orientations_deg, cell, baseline_problems(scene.spec.geometry(base), theta, cell))


def random_orientations(
    rng: np.random.Generator, spec: SceneSpec, step_deg: float | None = None, attempts: int = 2_000,
    base_point_xy: Sequence[float] | None = None,
) -> tuple[float, ...]:
    """A random feasible configuration about the base point (continuous, or multiples of `step_deg`), drawn
    link by link: each link's angle uniformly among the values that keep the chain so far feasible; a dead end
    starts again."""
    geometry = spec.geometry(base_point_xy)
    cell = spec.cell()
    for _ in range(attempts):
        chosen: list[float] = []
        for k in range(spec.n_links):
            if step_deg:
                options = [float(v) * step_deg for v in range(int(round(360 / step_deg)))]
            else:
                options = [float(v) for v in rng.uniform(0.0, 360.0, size=24)]
            partial = ObjectGeometry(geometry.link_lengths_m[: k + 1], geometry.base_point_xy, geometry.link_width_m)
            good = [v for v in options if configuration_feasible(partial, chosen + [v], cell).ok]
            if not good:
                break
            chosen.append(good[int(rng.integers(len(good)))])
        if len(chosen) == spec.n_links:
            return tuple(chosen)
    raise SimError(f"random_orientations: no feasible configuration found in {attempts} attempts")


def joint_between(turned_link: int, held_link: int, n_links: int) -> tuple[int, str]:
    """(joint point index K, turned side) for turning `turned_link` while `held_link` stays (0 = the table)."""
    if not 1 <= turned_link <= n_links:
        raise SimError(f"turned_link_index: must be in 1..{n_links}, got {turned_link}")
    if not 0 <= held_link <= n_links or abs(turned_link - held_link) != 1:
        raise SimError(
            f"held_link_index: must be a neighbour of link {turned_link} (0 = the table), got {held_link}"
        )
    if turned_link > held_link:
        return turned_link, "downstream"
    return held_link, "upstream"


# -- building ------------------------------------------------------------------------------------------------
def _load_robot(scene: Scene) -> None:
    c = scene.client
    urdf = write_baxter_urdf(scene.directory)
    robot = c.loadURDF(str(urdf), basePosition=[0, 0, 0], useFixedBase=True)
    scene.robot = robot
    by_name = {}
    link_by_name = {}
    for j in range(c.getNumJoints(robot)):
        info = c.getJointInfo(robot, j)
        by_name[info[1].decode()] = (j, info[8], info[9])
        link_by_name[info[12].decode()] = j
        # the arms follow planned paths through their motors; they push nothing (grasps are constraints)
        c.setCollisionFilterGroupMask(robot, j, 0, 0)
    c.setCollisionFilterGroupMask(robot, -1, 0, 0)
    scene.head_pan = by_name["head_pan"][0]
    scene.head_camera = link_by_name["head_camera_link"]
    for arm in ARMS:
        joints = [by_name[f"{arm}_{n}"] for n in ARM_JOINTS]
        prefix = arm[0]
        fingers = [by_name[f"{prefix}_gripper_l_finger_joint"], by_name[f"{prefix}_gripper_r_finger_joint"]]
        shoulder = c.getLinkState(robot, by_name[f"{arm}_s0"][0])[4]
        scene.arms[arm] = ArmInfo(
            name=arm,
            joints=tuple(j for j, _, _ in joints),
            lower=tuple(lo for _, lo, _ in joints),
            upper=tuple(hi for _, _, hi in joints),
            end_effector=link_by_name[f"{arm}_gripper"],
            fingers=tuple(j for j, _, _ in fingers),
            finger_open=(fingers[0][2], fingers[1][1]),
            finger_closed=(0.0, 0.0),
            shoulder_xy=(shoulder[0], shoulder[1]),
        )
        set_arm_joints(scene, arm, HOME_POSE[arm])
        hold_arm(scene, arm, HOME_POSE[arm])
        drive_gripper(scene, arm, close=False)
        for j, q in zip(scene.arms[arm].fingers, scene.arms[arm].finger_open):
            c.resetJointState(robot, j, q)
    c.setJointMotorControl2(robot, scene.head_pan, pybullet.POSITION_CONTROL, targetPosition=0.0, force=50.0)


def set_arm_joints(scene: Scene, arm: str, positions: Sequence[float]) -> None:
    """Put an arm's joints at `positions` at once: for planning (inverse kinematics) and building, not motion."""
    info = scene.arms[arm]
    for j, q in zip(info.joints, positions):
        scene.client.resetJointState(scene.robot, j, float(q))


def hold_arm(scene: Scene, arm: str, positions: Sequence[float]) -> None:
    """Drive an arm's joint motors towards `positions` (the physics steps move it, at most 10 rad/s)."""
    info = scene.arms[arm]
    for j, q in zip(info.joints, positions):
        scene.client.setJointMotorControl2(scene.robot, j, pybullet.POSITION_CONTROL, targetPosition=float(q),
                                           targetVelocity=0.0, force=400.0, positionGain=0.3, velocityGain=1.0,
                                           maxVelocity=10.0)


def arm_joints(scene: Scene, arm: str) -> tuple[float, ...]:
    info = scene.arms[arm]
    return tuple(scene.client.getJointState(scene.robot, j)[0] for j in info.joints)


def drive_gripper(scene: Scene, arm: str, close: bool) -> None:
    """Drive the finger motors open or closed (the physics steps move them)."""
    info = scene.arms[arm]
    values = info.finger_closed if close else info.finger_open
    scene.client.setJointMotorControlArray(scene.robot, list(info.fingers), pybullet.POSITION_CONTROL,
                                           targetPositions=list(values), forces=[40.0, 40.0])


def _load_table(scene: Scene) -> None:
    c, s = scene.client, scene.spec
    half = [s.table_size_xy[0] / 2, s.table_size_xy[1] / 2, 0.02]
    visual = c.createVisualShape(pybullet.GEOM_BOX, halfExtents=half, rgbaColor=[0.92, 0.92, 0.9, 1])
    collision = c.createCollisionShape(pybullet.GEOM_BOX, halfExtents=half)
    scene.table = c.createMultiBody(
        baseMass=0,
        baseCollisionShapeIndex=collision,
        baseVisualShapeIndex=visual,
        basePosition=[s.table_center_xy[0], s.table_center_xy[1], s.table_top_z - half[2]],
    )
    c.changeDynamics(scene.table, -1, lateralFriction=s.table_friction)
    for marker in s.board.markers if s.board is not None else ():
        asset = write_marker_asset(scene.directory / "board", marker.marker_id, marker.size_m)
        mesh = c.createVisualShape(pybullet.GEOM_MESH, fileName=str(asset.obj_path), meshScale=[1, 1, 1])
        body = c.createMultiBody(baseMass=0, baseCollisionShapeIndex=-1, baseVisualShapeIndex=mesh,
                                 basePosition=[marker.x, marker.y, marker.z],
                                 baseOrientation=c.getQuaternionFromEuler([0.0, 0.0, marker.yaw_rad]))
        c.changeVisualShape(body, -1, textureUniqueId=c.loadTexture(str(asset.image_path)), rgbaColor=[1, 1, 1, 1])
        scene.board_bodies[marker.marker_id] = body


def _load_object(scene: Scene) -> None:
    """The object as one multibody: l1 is the base, lK hangs on a revolute joint (vertical axis) at pK."""
    c, s = scene.client, scene.spec
    half = [s.link_length_m / 2, s.link_width_m / 2, s.link_height_m / 2]
    n = s.n_links
    colour = [0.65, 0.8, 0.95, 1]
    # l1 is the base, its frame at its centre; lK's frame sits at its joint point pK, its shapes half a link on
    offset = [[0.0, 0.0, 0.0]] + [[s.link_length_m / 2, 0.0, 0.0]] * (n - 1)
    visual = [c.createVisualShape(pybullet.GEOM_BOX, halfExtents=half, rgbaColor=colour, visualFramePosition=o)
              for o in offset]
    collision = [c.createCollisionShape(pybullet.GEOM_BOX, halfExtents=half, collisionFramePosition=o) for o in offset]
    scene.body = c.createMultiBody(
        baseMass=s.link_mass_kg,
        baseCollisionShapeIndex=collision[0],
        baseVisualShapeIndex=visual[0],
        basePosition=[0.0, 0.0, scene.link_center_z],
        linkMasses=[s.link_mass_kg] * (n - 1),
        linkCollisionShapeIndices=collision[1:],
        linkVisualShapeIndices=visual[1:],
        linkPositions=[[s.link_length_m / 2, 0.0, 0.0]] + [[s.link_length_m, 0.0, 0.0]] * (n - 2),
        linkOrientations=[[0, 0, 0, 1]] * (n - 1),
        linkInertialFramePositions=offset[1:],
        linkInertialFrameOrientations=[[0, 0, 0, 1]] * (n - 1),
        linkParentIndices=list(range(n - 1)),  # 0 = the base; the parent of PyBullet link i is link i - 1
        linkJointTypes=[pybullet.JOINT_REVOLUTE] * (n - 1),
        linkJointAxis=[[0, 0, 1]] * (n - 1),
    )
    for link in range(-1, n - 1):
        c.changeDynamics(scene.body, link, lateralFriction=1.0, linearDamping=0.04, angularDamping=0.04,
                         jointDamping=s.joint_damping)
    for j in range(n - 1):
        # joint friction: a velocity motor at rest with a limited torque
        c.setJointMotorControl2(scene.body, j, pybullet.VELOCITY_CONTROL, targetVelocity=0.0, force=s.joint_friction_nm)
    marker_dir = scene.directory / "markers"
    for i in range(n):
        asset = write_marker_asset(marker_dir, marker_id=i, size_m=s.marker_size_m)
        scene.markers.append(asset)
        mesh = c.createVisualShape(pybullet.GEOM_MESH, fileName=str(asset.obj_path), meshScale=[1, 1, 1])
        body = c.createMultiBody(baseMass=0, baseCollisionShapeIndex=-1, baseVisualShapeIndex=mesh)
        texture = c.loadTexture(str(asset.image_path))
        visible = (i + 1) not in s.unmarked_links
        c.changeVisualShape(body, -1, textureUniqueId=texture, rgbaColor=[1, 1, 1, 1 if visible else 0])
        scene.marker_bodies.append(body)
    scene.set_configuration(s.orientations0, s.base_xy)


def build_scene(client: BulletClient, spec: SceneSpec | None = None) -> Scene:
    """Load Baxter (optional), the table and the object into `client`; the caller keeps the client."""
    spec = spec or SceneSpec()
    workdir = tempfile.TemporaryDirectory(prefix="planhrc-scene-")
    scene = Scene(client, spec, workdir)
    try:
        client.setGravity(0, 0, -9.81)
        client.setPhysicsEngineParameter(fixedTimeStep=TIME_STEP_S, numSubSteps=1, numSolverIterations=150)
        if spec.load_robot:
            _load_robot(scene)
        _load_table(scene)
        _load_object(scene)
        scene.step(10)  # the object settles on the table
    except Exception:
        workdir.cleanup()
        raise
    return scene

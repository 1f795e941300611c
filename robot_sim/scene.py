"""The simulated work cell: Baxter, a table and a kinematic articulated object with ArUco markers.

Frames and angles (CONVENTIONS.md): the world's +x is the robot's forward axis, +y its left, +z up. A link's
orientation theta is in degrees, clockwise seen from above, from +x; its direction on the table is
(cos theta, -sin theta) and its PyBullet yaw is -radians(theta).

The object is kinematic: its configuration (base point p1 and one orientation per link) is the source of
truth, and each link body (a box plus a marker quad on top) is placed from it with
``resetBasePositionAndOrientation``. Link lK runs from joint point pK to pK+1; joint point pK joins l(K-1) and
lK, p1 joins l1 to the table (the absolute formulation's numbering).

The caller owns the ``BulletClient``; nothing here touches a global PyBullet connection.
"""
from __future__ import annotations

import importlib.metadata
import math
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np
import pybullet

from planhrc.robot_sim.markers import MarkerAsset, write_marker_asset

BAXTER_URDF = "robots/baxter_description/urdf/baxter.urdf"
PACKAGE_PREFIX = "package://example-robot-data/"
ARMS = ("left", "right")
ARM_JOINTS = ("s0", "s1", "e0", "e1", "w0", "w1", "w2")
# A pose with both hands raised and out to the sides, clear of the head camera's view of the table.
HOME_POSE = {
    "left": (1.0, -0.9, -0.3, 1.6, 0.0, 0.9, 0.0),
    "right": (-1.0, -0.9, 0.3, 1.6, 0.0, 0.9, 0.0),
}


class SimError(Exception):
    """Root of the simulator's errors; the message names the offending field or value."""


@dataclass(frozen=True)
class SceneSpec:
    """Everything needed to build a scene; immutable so a worker can rebuild the same cell."""

    n_links: int = 5
    link_length_m: float = 0.155
    link_width_m: float = 0.03
    link_height_m: float = 0.015
    marker_size_m: float = 0.03
    base_point_xy: tuple[float, float] = (0.6, 0.39)
    initial_orientations_deg: tuple[float, ...] | None = None  # default: every link at 90 (to the right)
    table_center_xy: tuple[float, float] = (0.6, 0.0)  # Baxter's grippers reach x ~ 0.35 .. 0.8 at table height
    table_size_xy: tuple[float, float] = (0.6, 1.3)
    table_top_z: float = -0.18
    load_robot: bool = True

    def __post_init__(self) -> None:
        if self.n_links < 1:
            raise SimError(f"n_links: must be at least 1, got {self.n_links}")
        if self.n_links > 50:
            raise SimError(f"n_links: at most 50 markers exist in DICT_4X4_50, got {self.n_links}")
        if self.initial_orientations_deg is not None and len(self.initial_orientations_deg) != self.n_links:
            raise SimError(
                f"initial_orientations_deg: expected {self.n_links} values, got {len(self.initial_orientations_deg)}"
            )

    @property
    def orientations0(self) -> tuple[float, ...]:
        if self.initial_orientations_deg is None:
            return (90.0,) * self.n_links
        return tuple(float(v) for v in self.initial_orientations_deg)


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


def rotate_point(point: np.ndarray, pivot: np.ndarray, delta_deg: float) -> np.ndarray:
    """Rotate a table point about `pivot` by `delta_deg` clockwise seen from above."""
    t = -math.radians(delta_deg)
    c, s = math.cos(t), math.sin(t)
    d = point - pivot
    return pivot + np.array([c * d[0] - s * d[1], s * d[0] + c * d[1]])


def baxter_urdf_source() -> Path:
    """The installed example-robot-data Baxter URDF (found through the distribution's file list)."""
    dist = importlib.metadata.distribution("example-robot-data")
    for entry in dist.files or ():
        if str(entry).endswith(BAXTER_URDF):
            return Path(dist.locate_file(entry))
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

    def __init__(self, client, spec: SceneSpec, workdir: tempfile.TemporaryDirectory) -> None:
        self.client = client
        self.spec = spec
        self._workdir = workdir
        self.directory = Path(workdir.name)
        self.robot: int | None = None
        self.arms: dict[str, ArmInfo] = {}
        self.table: int = -1
        self.link_bodies: list[int] = []
        self.marker_bodies: list[int] = []
        self.markers: list[MarkerAsset] = []
        self._base = np.array(spec.base_point_xy, dtype=float)
        self._theta = list(spec.orientations0)

    # -- geometry of the object ----------------------------------------------------------------------
    @property
    def n_links(self) -> int:
        return self.spec.n_links

    @property
    def link_center_z(self) -> float:
        return self.spec.table_top_z + self.spec.link_height_m / 2.0

    @property
    def marker_z(self) -> float:
        return self.spec.table_top_z + self.spec.link_height_m + 0.001

    def joint_points(self) -> list[np.ndarray]:
        """p1 .. p(N+1) on the table (x, y)."""
        points = [self._base.copy()]
        for theta in self._theta:
            points.append(points[-1] + self.spec.link_length_m * direction(theta))
        return points

    def link_center(self, link: int) -> np.ndarray:
        """Centre (x, y) of link `link` (1-based)."""
        self._check_link(link)
        points = self.joint_points()
        return (points[link - 1] + points[link]) / 2.0

    def base_point(self) -> tuple[float, float]:
        return float(self._base[0]), float(self._base[1])

    def configuration(self) -> tuple[tuple[float, float], tuple[float, ...]]:
        """The kinematic state: (base point, link orientations in degrees)."""
        return self.base_point(), tuple(self._theta)

    def set_configuration(self, orientations_deg: Sequence[float], base_point_xy: Sequence[float] | None = None) -> None:
        if len(orientations_deg) != self.n_links:
            raise SimError(f"orientations_deg: expected {self.n_links} values, got {len(orientations_deg)}")
        self._theta = [float(v) % 360.0 for v in orientations_deg]
        if base_point_xy is not None:
            self._base = np.array([float(base_point_xy[0]), float(base_point_xy[1])])
        self._place_bodies()

    def link_orientations_deg(self) -> tuple[float, ...]:
        """Ground truth read back from the simulator's link bodies (degrees in [0, 360))."""
        out = []
        for body in self.link_bodies:
            _, quat = self.client.getBasePositionAndOrientation(body)
            yaw = self.client.getEulerFromQuaternion(quat)[2]
            out.append((-math.degrees(yaw)) % 360.0)
        return tuple(out)

    def rotate_at_joint(self, joint_k: int, delta_deg: float, turned: str = "downstream", fraction: float = 1.0) -> None:
        """Turn one side of joint point pK by `delta_deg * fraction` (+ = clockwise seen from above).

        ``downstream`` turns lK .. lN about pK (the base point stays); ``upstream`` turns l1 .. l(K-1) about pK,
        which moves the base point. Every link beyond the turned one moves with it (inertial assumption A1).
        """
        if not 1 <= joint_k <= self.n_links:
            raise SimError(f"joint_k: must be in 1..{self.n_links}, got {joint_k}")
        delta = float(delta_deg) * float(fraction)
        if turned == "downstream":
            for i in range(joint_k - 1, self.n_links):
                self._theta[i] = (self._theta[i] + delta) % 360.0
        elif turned == "upstream":
            if joint_k == 1:
                raise SimError("turned: joint 1 joins l1 to the table; its upstream side cannot turn")
            pivot = self.joint_points()[joint_k - 1]
            self._base = rotate_point(self._base, pivot, delta)
            for i in range(0, joint_k - 1):
                self._theta[i] = (self._theta[i] + delta) % 360.0
        else:
            raise SimError(f"turned: must be 'downstream' or 'upstream', got {turned!r}")
        self._place_bodies()

    def rotate_link(self, turned_link: int, held_link: int, delta_deg: float, fraction: float = 1.0) -> None:
        """Turn `turned_link` about its joint with `held_link` (0 = the table), as a plan action names it."""
        joint_k, side = joint_between(turned_link, held_link, self.n_links)
        self.rotate_at_joint(joint_k, delta_deg, side, fraction)

    # -- bodies ------------------------------------------------------------------------------------------
    def _check_link(self, link: int) -> None:
        if not 1 <= link <= self.n_links:
            raise SimError(f"link: must be in 1..{self.n_links}, got {link}")

    def _place_bodies(self) -> None:
        points = self.joint_points()
        for i, (body, marker) in enumerate(zip(self.link_bodies, self.marker_bodies)):
            center = (points[i] + points[i + 1]) / 2.0
            quat = self.client.getQuaternionFromEuler([0.0, 0.0, -math.radians(self._theta[i])])
            self.client.resetBasePositionAndOrientation(body, [center[0], center[1], self.link_center_z], quat)
            self.client.resetBasePositionAndOrientation(marker, [center[0], center[1], self.marker_z], quat)

    def close(self) -> None:
        """Remove the scene's temporary files (the caller disconnects its own client)."""
        self._workdir.cleanup()

    def __enter__(self) -> "Scene":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def segment_distance(a0: np.ndarray, a1: np.ndarray, b0: np.ndarray, b1: np.ndarray) -> float:
    """Smallest distance between two segments of the plane."""

    def point_segment(p: np.ndarray, s0: np.ndarray, s1: np.ndarray) -> float:
        d = s1 - s0
        t = float(np.clip(np.dot(p - s0, d) / max(float(np.dot(d, d)), 1e-12), 0.0, 1.0))
        return float(np.linalg.norm(p - (s0 + t * d)))

    def cross(o: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
        return float((a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0]))

    if cross(a0, a1, b0) * cross(a0, a1, b1) < 0 and cross(b0, b1, a0) * cross(b0, b1, a1) < 0:
        return 0.0
    return min(point_segment(a0, b0, b1), point_segment(a1, b0, b1), point_segment(b0, a0, a1), point_segment(b1, a0, a1))


def is_valid_configuration(
    spec: SceneSpec,
    orientations_deg: Sequence[float],
    base_point_xy: Sequence[float] | None = None,
    max_fold_deg: float = 150.0,
    region: tuple[float, float, float, float] | None = None,
) -> bool:
    """No two links overlap, no joint folds beyond `max_fold_deg`, and every joint point lies in `region`
    (x_min, x_max, y_min, y_max; default: the table shrunk by 5 cm)."""
    base = np.array(base_point_xy if base_point_xy is not None else spec.base_point_xy, dtype=float)
    points = [base]
    for theta in orientations_deg:
        points.append(points[-1] + spec.link_length_m * direction(theta))
    if region is None:
        cx, cy = spec.table_center_xy
        hx, hy = spec.table_size_xy[0] / 2 - 0.05, spec.table_size_xy[1] / 2 - 0.05
        region = (cx - hx, cx + hx, cy - hy, cy + hy)
    if not all(region[0] <= p[0] <= region[1] and region[2] <= p[1] <= region[3] for p in points):
        return False
    for a, b in zip(orientations_deg, orientations_deg[1:]):
        d = (b - a) % 360.0
        if min(d, 360.0 - d) > max_fold_deg:
            return False
    n = len(orientations_deg)
    for i in range(n):
        for j in range(i + 2, n):
            if segment_distance(points[i], points[i + 1], points[j], points[j + 1]) < 2 * spec.link_width_m:
                return False
    return True


# Where Baxter's grippers reach on the table (x forward, y left), with a margin: measured by IK in this scene.
REACH_REGION: tuple[float, float, float, float] = (0.40, 0.78, -0.55, 0.55)


def is_workable(spec: SceneSpec, orientations_deg: Sequence[float],
                base_point_xy: Sequence[float] | None = None) -> bool:
    """A valid configuration whose every joint point lies where the robot can grasp the links."""
    return is_valid_configuration(spec, orientations_deg, base_point_xy, region=REACH_REGION)


def random_orientations(
    rng: np.random.Generator, spec: SceneSpec, step_deg: float | None = None, attempts: int = 10_000
) -> tuple[float, ...]:
    """A random valid configuration about the spec's base point (continuous, or multiples of `step_deg`)."""
    for _ in range(attempts):
        if step_deg:
            values = rng.integers(0, int(round(360 / step_deg)), size=spec.n_links) * step_deg
        else:
            values = rng.uniform(0.0, 360.0, size=spec.n_links)
        candidate = tuple(float(v) for v in values)
        if is_valid_configuration(spec, candidate):
            return candidate
    raise SimError(f"random_orientations: no valid configuration found in {attempts} attempts")


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
        set_gripper(scene, arm, close=False)


def set_arm_joints(scene: Scene, arm: str, positions: Sequence[float]) -> None:
    info = scene.arms[arm]
    for j, q in zip(info.joints, positions):
        scene.client.resetJointState(scene.robot, j, float(q))


def arm_joints(scene: Scene, arm: str) -> tuple[float, ...]:
    info = scene.arms[arm]
    return tuple(scene.client.getJointState(scene.robot, j)[0] for j in info.joints)


def set_gripper(scene: Scene, arm: str, close: bool) -> None:
    info = scene.arms[arm]
    values = info.finger_closed if close else info.finger_open
    for j, q in zip(info.fingers, values):
        scene.client.resetJointState(scene.robot, j, q)


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


def _load_object(scene: Scene) -> None:
    c, s = scene.client, scene.spec
    half = [s.link_length_m / 2, s.link_width_m / 2, s.link_height_m / 2]
    marker_dir = scene.directory / "markers"
    for i in range(s.n_links):
        visual = c.createVisualShape(pybullet.GEOM_BOX, halfExtents=half, rgbaColor=[0.65, 0.8, 0.95, 1])
        collision = c.createCollisionShape(pybullet.GEOM_BOX, halfExtents=half)
        scene.link_bodies.append(
            c.createMultiBody(baseMass=0, baseCollisionShapeIndex=collision, baseVisualShapeIndex=visual)
        )
        asset = write_marker_asset(marker_dir, marker_id=i, size_m=s.marker_size_m)
        scene.markers.append(asset)
        mesh = c.createVisualShape(pybullet.GEOM_MESH, fileName=str(asset.obj_path), meshScale=[1, 1, 1])
        body = c.createMultiBody(baseMass=0, baseCollisionShapeIndex=-1, baseVisualShapeIndex=mesh)
        texture = c.loadTexture(str(asset.image_path))
        c.changeVisualShape(body, -1, textureUniqueId=texture, rgbaColor=[1, 1, 1, 1])
        scene.marker_bodies.append(body)
    scene._place_bodies()


def build_scene(client, spec: SceneSpec | None = None) -> Scene:
    """Load Baxter (optional), the table and the object into `client`; the caller keeps the client."""
    spec = spec or SceneSpec()
    workdir = tempfile.TemporaryDirectory(prefix="planhrc-scene-")
    scene = Scene(client, spec, workdir)
    try:
        client.setGravity(0, 0, -9.81)
        if spec.load_robot:
            _load_robot(scene)
        _load_table(scene)
        _load_object(scene)
    except Exception:
        workdir.cleanup()
        raise
    return scene

"""Perception of the object's link orientations: a camera with ArUco markers, or noisy simulator poses.

`CameraPerception` is a camera on Baxter's head (where the paper's Kinect sat): it takes the head camera
link's pose and the head's pan from the simulated robot, renders what it sees with TinyRenderer, detects one
ArUco marker per link and turns each marker's corners into a table angle. It reads nothing else from the
simulator: a link whose marker it does not see is reported as unseen (None). `look` looks again with the head
turned, keeping what each view saw. The base point p1 is measured too, from the first link's marker: its centre
on the table, half a link back along the link's measured direction (None while that marker is unseen). Instead of reading the angle off the image
(whose axes are tilted by the oblique view and flipped: image rows grow downwards), every corner is cast
back through the camera onto the plane of the marker tops, and the angle is measured on the table in
the world frame: theta = atan2(-dy, dx), clockwise seen from above from +x.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol

import cv2
import numpy as np
import pybullet

from planhrc.robot_sim.errors import SimError
from planhrc.robot_sim.markers import aruco_dictionary
from planhrc.robot_sim.scene import Scene

if TYPE_CHECKING:
    from pybullet_utils.bullet_client import BulletClient


@dataclass(frozen=True)
class Perception:
    """One perception: an orientation per link (None when the link was not seen) and the camera frame."""

    link_orientations_deg: tuple[float | None, ...]
    frame: np.ndarray | None = None
    looks: int = 1  # views taken (more than one: the head turned to look again)
    base_point_xy: tuple[float, float] | None = None  # p1 on the table as measured (None: l1 not seen)

    @property
    def complete(self) -> bool:
        return all(v is not None for v in self.link_orientations_deg)

    @property
    def missing_links(self) -> tuple[int, ...]:
        """1-based indices of the links whose marker was not seen."""
        return tuple(i + 1 for i, v in enumerate(self.link_orientations_deg) if v is None)


class Perceiver(Protocol):
    """What the worker perceives with: the camera or the explicit no-camera mode."""

    def perceive(self) -> Perception: ...

    def look(self) -> Perception:
        """`perceive`, looking again (as the camera can) while links are missing."""
        ...


@dataclass(frozen=True)
class CameraSpec:
    """The head camera: mounted on Baxter's head camera link, pitched down to look at the table."""

    look_at: tuple[float, float, float] = (0.6, 0.0, -0.18)  # where it looks with the head pan at 0
    fov_deg: float = 50.0  # vertical
    width: int = 960
    height: int = 720
    near: float = 0.05
    far: float = 5.0
    # Markers are only ~20 px wide: detect on enlarged copies, trying each scale until every marker is found.
    upscales: tuple[int, ...] = (2, 1, 3)
    # head pans tried in turn when a marker was not seen: a marker near the view's edge may need the wider turn
    look_again_pans_rad: tuple[float, ...] = (0.35, -0.35, 0.7, -0.7)


def circular_mean_deg(angles: list[float]) -> float:
    s = sum(math.sin(math.radians(a)) for a in angles)
    c = sum(math.cos(math.radians(a)) for a in angles)
    return math.degrees(math.atan2(s, c)) % 360.0


def angle_difference_deg(a: float, b: float) -> float:
    """Signed smallest difference a - b in (-180, 180]."""
    d = (a - b) % 360.0
    return d - 360.0 if d > 180.0 else d


def table_angle(vector_xy: np.ndarray) -> float:
    """Orientation of a table vector: degrees clockwise seen from above from +x."""
    return math.degrees(math.atan2(-vector_xy[1], vector_xy[0])) % 360.0


class CameraPerception:
    """Render, detect markers, back-project their corners onto the table and measure each link's angle."""

    def __init__(self, client: BulletClient, scene: Scene, camera: CameraSpec | None = None) -> None:
        if scene.head_camera is None:
            raise SimError("scene: the head camera needs the robot (load_robot=True)")
        self.client = client
        self.scene = scene
        self.camera = camera or CameraSpec()
        self._detector = cv2.aruco.ArucoDetector(aruco_dictionary(), self._detector_parameters())
        self._aim()

    def _aim(self) -> None:
        """View and projection matrices from the head camera link's pose and the head's pan."""
        c, cam, scene = self.client, self.camera, self.scene
        eye = np.asarray(c.getLinkState(scene.robot, scene.head_camera, computeForwardKinematics=True)[4])
        pan = c.getJointState(scene.robot, scene.head_pan)[0]
        ahead = np.asarray(cam.look_at) - eye
        cos, sin = math.cos(pan), math.sin(pan)
        ahead = np.array([cos * ahead[0] - sin * ahead[1], sin * ahead[0] + cos * ahead[1], ahead[2]])
        forward = np.array([math.cos(pan), math.sin(pan), 0.0])
        self._view = c.computeViewMatrix(eye.tolist(), (eye + ahead).tolist(), forward.tolist())
        self._proj = c.computeProjectionMatrixFOV(cam.fov_deg, cam.width / cam.height, cam.near, cam.far)
        view = np.array(self._view, dtype=float).reshape(4, 4).T  # PyBullet matrices are column-major
        proj = np.array(self._proj, dtype=float).reshape(4, 4).T
        self._inverse = np.linalg.inv(proj @ view)

    def turn_head(self, pan_rad: float, max_steps: int = 120, settled_rad: float = 5e-4) -> None:
        """Turn the head (its pan motor, on the physics clock) until it has settled at `pan_rad` (within
        `settled_rad`, 0.03°) and aim the camera from there. Waiting for it to settle makes a look at a pan the
        same look whichever pan the head came from: stopping 0.01 rad short left it where its path put it, and a
        marker at the edge of the view was read or not depending on which pans were tried before."""
        c, scene = self.client, self.scene
        c.setJointMotorControl2(scene.robot, scene.head_pan, pybullet.POSITION_CONTROL, targetPosition=pan_rad,
                                force=50.0, maxVelocity=4.0)
        for _ in range(max_steps):
            scene.step()
            if abs(c.getJointState(scene.robot, scene.head_pan)[0] - pan_rad) < settled_rad:
                break
        self._aim()

    @staticmethod
    def _detector_parameters() -> cv2.aruco.DetectorParameters:
        params = cv2.aruco.DetectorParameters()
        params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_CONTOUR
        params.minMarkerPerimeterRate = 0.01
        params.adaptiveThreshWinSizeMin = 3
        params.adaptiveThreshWinSizeMax = 23
        params.adaptiveThreshWinSizeStep = 4
        params.polygonalApproxAccuracyRate = 0.05
        params.perspectiveRemovePixelPerCell = 8
        params.perspectiveRemoveIgnoredMarginPerCell = 0.25
        return params

    def render(self) -> np.ndarray:
        cam = self.camera
        self.scene.sync_markers()
        _, _, rgba, _, _ = self.client.getCameraImage(
            cam.width, cam.height, self._view, self._proj, renderer=pybullet.ER_TINY_RENDERER
        )
        return np.reshape(np.asarray(rgba, dtype=np.uint8), (cam.height, cam.width, 4))[:, :, :3].copy()

    def pixel_to_table(self, u: float, v: float, z: float) -> np.ndarray:
        """The (x, y) where the ray through pixel (u, v) meets the horizontal plane at height z."""
        cam = self.camera
        x_ndc = 2.0 * (u + 0.5) / cam.width - 1.0
        y_ndc = 1.0 - 2.0 * (v + 0.5) / cam.height
        near = self._inverse @ np.array([x_ndc, y_ndc, -1.0, 1.0])
        far = self._inverse @ np.array([x_ndc, y_ndc, 1.0, 1.0])
        near, far = near[:3] / near[3], far[:3] / far[3]
        t = (z - near[2]) / (far[2] - near[2])
        point: np.ndarray = (near + t * (far - near))[:2]
        return point

    def marker_angle(self, corners: np.ndarray) -> float:
        """Table angle of a marker's corner 0 -> corner 1 direction, averaged over its four edges."""
        return self.marker_pose(corners)[0]

    def marker_pose(self, corners: np.ndarray) -> tuple[float, np.ndarray]:
        """(table angle, centre (x, y) on the table) of a marker from its four corners in pixels."""
        z = self.scene.marker_z
        tl, tr, br, bl = (self.pixel_to_table(float(u), float(v), z) for u, v in corners)
        along = [table_angle(tr - tl), table_angle(br - bl)]
        across = [table_angle(bl - tl) - 90.0, table_angle(br - tr) - 90.0]
        return circular_mean_deg(along + across), (tl + tr + br + bl) / 4.0

    def base_point(self, first: tuple[float, np.ndarray] | None) -> tuple[float, float] | None:
        """p1 from the first link's marker pose (its centre is the link's centre), or None when it was not seen."""
        if first is None:
            return None
        angle, centre = first
        t = math.radians(angle)
        half = self.scene.spec.link_length_m / 2.0
        return float(centre[0] - half * math.cos(t)), float(centre[1] + half * math.sin(t))

    def perceive(self) -> Perception:
        """One look from where the head points now."""
        self._aim()
        frame = self.render()
        link_ids = [asset.marker_id for asset in self.scene.markers]
        found = self.detect_poses(frame, set(link_ids))
        return Perception(tuple(found[m][0] if m in found else None for m in link_ids), frame,
                          base_point_xy=self.base_point(found.get(link_ids[0])))

    def look(self) -> Perception:
        """Look; while markers are missing, look again with the head turned to each side, keeping what each
        view saw (the first view's frame is kept); the head turns back afterwards."""
        seen = self.perceive()
        if seen.complete:
            return seen
        values = list(seen.link_orientations_deg)
        base = seen.base_point_xy
        for pan in self.camera.look_again_pans_rad:
            self.turn_head(pan)
            again = self.perceive()
            values = [v if v is not None else a for v, a in zip(values, again.link_orientations_deg)]
            base = base or again.base_point_xy
            if all(v is not None for v in values):
                break
        self.turn_head(0.0)
        return Perception(tuple(values), seen.frame, looks=1 + len(self.camera.look_again_pans_rad),
                          base_point_xy=base)

    def detect(self, frame: np.ndarray, wanted: set[int]) -> dict[int, float]:
        """Marker id -> table angle for the wanted markers seen in `frame`."""
        return {m: angle for m, (angle, _) in self.detect_poses(frame, wanted).items()}

    def detect_poses(self, frame: np.ndarray, wanted: set[int]) -> dict[int, tuple[float, np.ndarray]]:
        """Marker id -> (table angle, centre on the table) for the wanted markers seen in `frame`."""
        grey = cv2.cvtColor(frame, cv2.COLOR_RGB2GRAY)
        found: dict[int, tuple[float, np.ndarray]] = {}
        for k in self.camera.upscales:
            image = grey if k == 1 else cv2.resize(grey, None, fx=k, fy=k, interpolation=cv2.INTER_CUBIC)
            corners, ids, _ = self._detector.detectMarkers(image)
            if ids is not None:
                for marker_corners, marker_id in zip(corners, ids.ravel()):
                    if int(marker_id) in wanted and int(marker_id) not in found:
                        # corner (x, y) of the enlarged image -> pixel coordinates of the frame
                        pixels = (marker_corners.reshape(4, 2) + 0.5) / k - 0.5
                        found[int(marker_id)] = self.marker_pose(pixels)
            if wanted <= found.keys():
                break
        return found


class FallbackPerception:
    """Ground-truth link orientations from the simulator plus Gaussian noise (sigma in degrees, seeded): the
    explicit no-camera mode, never a stand-in for what the camera missed."""

    def __init__(self, scene: Scene, sigma_deg: float = 1.0, seed: int = 0) -> None:
        self.scene = scene
        self.sigma_deg = sigma_deg
        self._rng = np.random.default_rng(seed)

    def look(self) -> Perception:
        return self.perceive()

    def perceive(self) -> Perception:
        truth = self.scene.link_orientations_deg()
        noise = self._rng.normal(0.0, self.sigma_deg, size=len(truth)) if self.sigma_deg > 0 else np.zeros(len(truth))
        base = self.scene.base_point()
        return Perception(tuple(float((t + n) % 360.0) for t, n in zip(truth, noise)), None,
                          base_point_xy=(round(base[0], 4), round(base[1], 4)))

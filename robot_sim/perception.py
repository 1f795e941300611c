"""Perception of the object's link orientations: a camera with ArUco markers, or noisy simulator poses.

`CameraPerception` is a camera on Baxter's head (where the paper's Kinect sat): it takes the head camera
link's pose and the head's pan from the simulated robot (the robot's own kinematics: where its camera is), renders
what it sees with TinyRenderer and reads the object from the image with the same code as `planhrc perceive-node`
reads a real camera's (`vision`): one ArUco marker per link, each placed on the plane of the marker tops by
fitting its four corners, its turn measured on the table in the world frame (theta = atan2(-dy, dx), clockwise
seen from above from +x). It reads nothing else from the simulator: a link whose marker it does not see, or
measures too poorly to trust (`vision.Limits`), is reported as unseen (None). `look` looks again with the head
turned, keeping what each view saw. The base point p1 is measured too, from the first link's marker: its centre
on the table, half a link back along the link's measured direction (None while that marker is unseen).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol

import numpy as np
import pybullet

from planhrc.robot_sim.camera import CameraPose, Intrinsics
from planhrc.robot_sim.errors import SimError
from planhrc.robot_sim.scene import Scene
from planhrc.robot_sim.vision import (Limits, MarkerFinder, ObjectMarkers, ObjectReading, find_links, grey_image,
                                      measure_marker, read_object)
from planhrc.robot_sim.vision import base_point as first_link_base_point

if TYPE_CHECKING:
    from pybullet_utils.bullet_client import BulletClient


@dataclass(frozen=True)
class Perception:
    """One perception: an orientation per link (None when the link was not seen) and the camera frame."""

    link_orientations_deg: tuple[float | None, ...]
    frame: np.ndarray | None = None
    looks: int = 1  # views taken (more than one: the head turned to look again, or another camera looked)
    base_point_xy: tuple[float, float] | None = None  # p1 on the table as measured (None: l1 not seen)
    seen_by: tuple[str | None, ...] | None = None  # the camera that saw each link (None: unseen; all None: unsaid)

    @property
    def sources(self) -> tuple[str | None, ...]:
        """The camera that saw each link (`head` when the perception does not say), None for a link unseen."""
        by = self.seen_by or (None,) * len(self.link_orientations_deg)
        return tuple(None if v is None else (b or "head") for v, b in zip(self.link_orientations_deg, by))

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


def angle_difference_deg(a: float, b: float) -> float:
    """Signed smallest difference a - b in (-180, 180]."""
    d = (a - b) % 360.0
    return d - 360.0 if d > 180.0 else d


class CameraPerception:
    """Render from the head camera and read the object's markers in the image (`vision`)."""

    def __init__(self, client: BulletClient, scene: Scene, camera: CameraSpec | None = None,
                 limits: Limits = Limits()) -> None:
        if scene.head_camera is None:
            raise SimError("scene: the head camera needs the robot (load_robot=True)")
        self.client = client
        self.scene = scene
        self.camera = camera or CameraSpec()
        self.limits = limits
        self.intrinsics = Intrinsics.from_fov(self.camera.width, self.camera.height, self.camera.fov_deg)
        self.markers = ObjectMarkers("object", tuple(asset.marker_id for asset in scene.markers),
                                     scene.spec.link_length_m, scene.spec.marker_size_m, scene.marker_z)
        self._finder = MarkerFinder(self.camera.upscales)
        self._aim()

    def _aim(self) -> None:
        """View and projection matrices from the head camera link's pose and the head's pan; the camera's pose
        (`vision` reads the image with it) from the view matrix."""
        c, cam, scene = self.client, self.camera, self.scene
        eye = np.asarray(c.getLinkState(scene.robot, scene.head_camera, computeForwardKinematics=True)[4])
        pan = c.getJointState(scene.robot, scene.head_pan)[0]
        ahead = np.asarray(cam.look_at) - eye
        cos, sin = math.cos(pan), math.sin(pan)
        ahead = np.array([cos * ahead[0] - sin * ahead[1], sin * ahead[0] + cos * ahead[1], ahead[2]])
        forward = np.array([math.cos(pan), math.sin(pan), 0.0])
        self._view = c.computeViewMatrix(eye.tolist(), (eye + ahead).tolist(), forward.tolist())
        self._proj = c.computeProjectionMatrixFOV(cam.fov_deg, cam.width / cam.height, cam.near, cam.far)
        self.pose = CameraPose.from_gl_view(self._view)

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

    def render(self) -> np.ndarray:
        cam = self.camera
        self.scene.sync_markers()
        _, _, rgba, _, _ = self.client.getCameraImage(
            cam.width, cam.height, self._view, self._proj, renderer=pybullet.ER_TINY_RENDERER
        )
        return np.reshape(np.asarray(rgba, dtype=np.uint8), (cam.height, cam.width, 4))[:, :, :3].copy()

    def pixel_to_table(self, u: float, v: float, z: float) -> np.ndarray:
        """The (x, y) where the ray through pixel (u, v) meets the horizontal plane at height z."""
        point: np.ndarray = self.pose.onto_plane(np.array([[u, v]]), z, self.intrinsics)[0]
        return point

    def marker_pose(self, corners: np.ndarray) -> tuple[float, np.ndarray]:
        """(table angle, centre (x, y) on the table) of a link marker from its four corners in pixels."""
        measure = measure_marker(corners, self.intrinsics, self.pose, self.scene.marker_z, self.markers.marker_size_m)
        if measure is None:
            raise SimError("marker: its corners do not lie on the table as this camera sees it")
        return measure.angle_deg, np.asarray(measure.centre_xy)

    def base_point(self, first: tuple[float, np.ndarray] | None) -> tuple[float, float] | None:
        """p1 from the first link's marker pose (its centre is the link's centre), or None when it was not seen."""
        if first is None:
            return None
        return first_link_base_point(first[0], (float(first[1][0]), float(first[1][1])), self.scene.spec.link_length_m)

    def read(self, frame: np.ndarray) -> ObjectReading:
        """The object as `frame` (taken from where the camera is aimed now) shows it."""
        found = find_links(grey_image(frame), self._finder, [self.markers], self.intrinsics, self.pose)
        return read_object(found, self.markers, self.intrinsics, self.pose, self.limits)

    def perceive(self) -> Perception:
        """One look from where the head points now."""
        self._aim()
        frame = self.render()
        reading = self.read(frame)
        return Perception(reading.link_orientations_deg, frame, base_point_xy=reading.base_point_xy,
                          seen_by=tuple("head" if v is not None else None for v in reading.link_orientations_deg))

    def look(self) -> Perception:
        """Look; while markers are missing, look again with the head turned to each side, keeping what each
        view saw (the first view's frame is kept); the head turns back afterwards."""
        seen = self.perceive()
        if seen.complete:
            return seen
        again = self.look_again(seen)
        values = tuple(v if v is not None else a for v, a in zip(seen.link_orientations_deg,
                                                                   again.link_orientations_deg))
        return Perception(values, seen.frame, looks=1 + again.looks,
                          base_point_xy=seen.base_point_xy or again.base_point_xy,
                          seen_by=tuple("head" if v is not None else None for v in values))

    def look_again(self, seen: Perception) -> Perception:
        """The links `seen` misses, as the head turned to each side sees them (each pan in turn until none is
        missing), then the head turns back; `looks` counts the pans, the frame is none."""
        values: list[float | None] = [None] * len(seen.link_orientations_deg)
        base = None
        for pan in self.camera.look_again_pans_rad:
            self.turn_head(pan)
            again = self.perceive()
            values = [v if v is not None else a for v, a in zip(values, again.link_orientations_deg)]
            base = base or again.base_point_xy
            if all(v is not None or s is not None for v, s in zip(values, seen.link_orientations_deg)):
                break
        self.turn_head(0.0)
        return Perception(tuple(values), None, looks=len(self.camera.look_again_pans_rad), base_point_xy=base,
                          seen_by=tuple("head" if v is not None else None for v in values))

    def detect(self, frame: np.ndarray, wanted: set[int]) -> dict[int, float]:
        """Marker id -> table angle for the wanted link markers seen (and trusted) in `frame`."""
        reading = self.read(frame)
        return {s.marker_id: s.measure.angle_deg for s in reading.sightings
                if s.seen and s.measure is not None and s.marker_id in wanted}


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
                          base_point_xy=(round(base[0], 4), round(base[1], 4)), seen_by=("fallback",) * len(truth))

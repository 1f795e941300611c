"""Which link markers the robot's own arms would hide from its cameras, in a posture it has not taken yet.

The robot knows its body (the model it moves by), where its cameras are (the head camera by its kinematics, the
cell camera by its calibration) and where the links lie (as it last perceived them). `Sightlines` sets the arms to
a candidate posture in that model, draws from each camera which pixels the robot's body covers (a small render: the
body's segmentation only) and projects each link's marker there, its square widened by a margin (ArUco reads only
whole markers, and the model is not exact): the share of that square the body covers, 0 for a marker in clear sight.
A link's cover is the least over the cameras. Nothing is measured: the arms go back where they were.

The bimanual steps use it to choose where the hands take their links (`bimanual.plan_station`): of the grasp
stations the arms reach, the first that leaves every marker in some camera's clear sight, else the one that covers
the least.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Mapping, Sequence

import cv2
import numpy as np
import pybullet

from planhrc.geometry import link_centres
from planhrc.robot_sim.camera import CameraPose, Intrinsics, square_corners
from planhrc.robot_sim.scene import ARMS, HOME_POSE, Scene, arm_joints, set_arm_joints

if TYPE_CHECKING:
    from planhrc.robot_sim.acting import Pose


@dataclass(frozen=True)
class SightCamera:
    """A camera as the robot knows it: its pose and intrinsics, and how much coarser than its own pixels the check
    draws (`shrink`)."""

    name: str
    pose: CameraPose
    intrinsics: Intrinsics
    shrink: int = 2


@dataclass(frozen=True)
class Window:
    """A rectangle of a camera's image, drawn `shrink` times coarser: its top-left pixel and size in drawn pixels."""

    u0: float
    v0: float
    width: int
    height: int
    shrink: int

    def to_window(self, pixels: np.ndarray) -> np.ndarray:
        """The camera's pixel coordinates -> the window's drawn pixel coordinates."""
        out: np.ndarray = (np.asarray(pixels, dtype=float) - np.array([self.u0, self.v0]) + 0.5) / self.shrink - 0.5
        return out


def gl_matrices(pose: CameraPose, camera: Intrinsics, window: Window, near: float = 0.05, far: float = 5.0
                ) -> tuple[list[float], list[float]]:
    """PyBullet's (view, projection) matrices drawing `window` of a pinhole camera at `pose` (the view is the inverse
    of `CameraPose.from_gl_view`; the projection an off-centre frustum through the window's pixel edges)."""
    flip = np.diag([1.0, -1.0, -1.0])
    view = np.eye(4)
    view[:3, :3] = flip @ pose.r
    view[:3, 3] = flip @ pose.t
    fx, _, cx, _, fy, cy = camera.k[:6]
    u_left, v_top = window.u0 - 0.5, window.v0 - 0.5
    u_right, v_bottom = u_left + window.width * window.shrink, v_top + window.height * window.shrink
    left, right = (u_left - cx) / fx * near, (u_right - cx) / fx * near
    top, bottom = (cy - v_top) / fy * near, (cy - v_bottom) / fy * near
    projection = pybullet.computeProjectionMatrix(left, right, bottom, top, near, far)
    return [float(v) for v in view.T.ravel()], [float(v) for v in projection]


class Sightlines:
    """The robot's cameras as it knows them, and its body: `survey` draws what the arms would cover."""

    def __init__(self, scene: Scene, cameras: Sequence[SightCamera], margin: float = 0.2) -> None:
        self.scene, self.cameras, self.margin = scene, tuple(cameras), margin
        client, robot = scene.client, scene.robot
        names = {j: client.getJointInfo(robot, j)[12].decode() for j in range(client.getNumJoints(robot))}
        # each arm's links as the segmentation names them (shoulder to finger tips)
        self.arm_links = {arm: frozenset(j for j, n in names.items() if n.startswith((f"{arm}_", f"{arm[0]}_gripper")))
                          for arm in ARMS}
        self.renders = 0  # drawn so far (one per camera, arm and posture a survey needed)

    def survey(self, moments: Mapping[str, "Pose"]) -> "Survey":
        """A survey of arm postures with the object lying as each named moment says (e.g. held, then turned)."""
        return Survey(self, moments)

    def cover(self, postures: Mapping[str, Sequence[float]], pose: "Pose") -> tuple[float, ...]:
        """`Survey.cover` of one posture of both arms (an arm not named: where it is), the object as `pose`."""
        here = {arm: postures.get(arm, arm_joints(self.scene, arm)) for arm in ARMS}
        return self.survey({"now": pose}).cover("now", here)


class Survey:
    """The arms' pixels in each camera's view of the object, drawn once per (camera, arm, posture) and combined
    for any pair of postures: each arm is drawn with the other at home (out of the view of the table), and the
    rest of the body once per camera."""

    def __init__(self, sight: Sightlines, moments: Mapping[str, "Pose"]) -> None:
        self.sight, self.scene = sight, sight.scene
        side = self.scene.spec.marker_size_m * (1.0 + sight.margin)
        self.squares = {name: [square_corners((float(c[0]), float(c[1]), self.scene.marker_z), -math.radians(a), side)
                               for c, a in zip(link_centres(pose.geometry, pose.angles), pose.angles)]
                        for name, pose in moments.items()}
        self.windows: dict[str, Window | None] = {}
        self.masks: dict[tuple[str, str, tuple[float, ...]], np.ndarray] = {}
        self.bodies: dict[str, np.ndarray] = {}

    def cover(self, moment: str, postures: Mapping[str, Sequence[float]]) -> tuple[float, ...]:
        """Per link, the least share of its marker's square (widened by the margin) that the robot's body covers
        in any camera's image with the arms at `postures` (arm -> joints, both arms) and the object as `moment`
        says: 0 where some camera has it in clear sight, 1 where every camera has it wholly covered or out of its
        image."""
        squares = self.squares[moment]
        least = [1.0] * len(squares)
        for camera in self.sight.cameras:
            if not any(least):
                break
            window = self._window(camera)
            if window is None:
                continue
            robot = self.bodies.get(camera.name)
            for arm in ARMS:
                mask = self._arm(camera, window, arm, tuple(float(v) for v in postures[arm]))
                robot = mask if robot is None else robot | mask
            assert robot is not None
            shares = [_share(robot, window, camera.pose.project(square, camera.intrinsics), camera.intrinsics)
                      for square in squares]
            least = [min(a, b) for a, b in zip(least, shares)]
        return tuple(least)

    def _window(self, camera: SightCamera) -> Window | None:
        """The part of the camera's image holding every moment's marker squares (None: none inside the image)."""
        if camera.name not in self.windows:
            k = camera.intrinsics
            corners = [camera.pose.project(square, k) for squares in self.squares.values() for square in squares]
            inside = [c for c in corners if _inside(c, k)]
            window = None
            if inside:
                seen = np.vstack(inside)
                u0, v0 = np.floor(seen.min(axis=0)).astype(int) - 2
                u1, v1 = np.ceil(seen.max(axis=0)).astype(int) + 2
                window = Window(float(u0), float(v0), max(int(math.ceil((u1 - u0) / camera.shrink)), 1),
                                max(int(math.ceil((v1 - v0) / camera.shrink)), 1), camera.shrink)
            self.windows[camera.name] = window
        return self.windows[camera.name]

    def _arm(self, camera: SightCamera, window: Window, arm: str, q: tuple[float, ...]) -> np.ndarray:
        """The pixels of `arm` at joints `q` in the camera's window (drawn the first time it is asked for)."""
        key = (camera.name, arm, q)
        if key not in self.masks:
            scene = self.scene
            saved = {a: arm_joints(scene, a) for a in ARMS}
            try:
                for a in ARMS:
                    set_arm_joints(scene, a, q if a == arm else HOME_POSE[a])
                view, projection = gl_matrices(camera.pose, camera.intrinsics, window)
                _, _, _, _, segmentation = scene.client.getCameraImage(
                    window.width, window.height, view, projection, renderer=pybullet.ER_TINY_RENDERER,
                    flags=pybullet.ER_SEGMENTATION_MASK_OBJECT_AND_LINKINDEX)
                self.sight.renders += 1
            finally:
                for a, s in saved.items():
                    set_arm_joints(scene, a, s)
            seg = np.reshape(np.asarray(segmentation, dtype=np.int64), (window.height, window.width))
            robot = (seg >= 0) & ((seg & ((1 << 24) - 1)) == scene.robot)
            link = (seg >> 24) - 1
            arms = {a: robot & np.isin(link, list(self.sight.arm_links[a])) for a in ARMS}
            self.masks[key] = arms[arm]
            if camera.name not in self.bodies:
                self.bodies[camera.name] = robot & ~arms["left"] & ~arms["right"]
        return self.masks[key]


def _inside(corners: np.ndarray, camera: Intrinsics) -> bool:
    return bool(np.all(np.isfinite(corners)) and corners[:, 0].min() >= 0 and corners[:, 1].min() >= 0
                and corners[:, 0].max() <= camera.width - 1 and corners[:, 1].max() <= camera.height - 1)


def _share(robot: np.ndarray, window: Window, corners: np.ndarray, camera: Intrinsics) -> float:
    """The share of a marker square (its corners in the camera's pixels) the robot's pixels cover (1 outside the
    image)."""
    if not _inside(corners, camera):
        return 1.0
    square = np.zeros(robot.shape, np.uint8)
    cv2.fillConvexPoly(square, np.round(window.to_window(corners) * 16).astype(np.int32), 1, cv2.LINE_8, 4)
    if not square.any():  # under a pixel: the pixel it falls in
        x, y = np.clip(np.round(window.to_window(corners).mean(axis=0)).astype(int), 0,
                       [window.width - 1, window.height - 1])
        square[y, x] = 1
    area = square > 0
    return float((robot & area).sum()) / float(area.sum())

"""The cell's own camera: fixed on a post beyond the table's far edge, facing the robot, calibrated from the board's
markers on the table as a real cell's camera is (`planhrc perceive-calibrate`, docs/perception.md).

Baxter's head camera looks down past its shoulders: while both hands hold links its arms stand between it and the
table, and often hide most markers. The cell camera sees the object from the other side, under the arms; the worker
looks through it when the head camera misses links (`TwoCameras`). It is simulated as any camera is: PyBullet renders
what it sees from where it is mounted (`CellCameraSpec`, the truth of the mount); what it reads is read with the pose
its calibration found from the board (`camera.calibrate` on the board's markers found in its images, the arms at
home; the board is then taken off the table), never with the mount's truth. Its links are read with the same code
as the head camera's and the perceive node's (`vision`): a link whose marker it does not see, or measures too
poorly to trust, is unseen.

`TwoCameras` looks with the head first (straight ahead), then through the cell camera for the links the head
missed, then with the head turned for those both missed; each link's orientation comes from the first camera that
saw it, and the perception says which (`seen_by`: `head` or `cell` per link, None: unseen). The base point comes
from whichever camera saw l1, the head first.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import pybullet

from planhrc.robot_sim.camera import Calibration, CalibrationError, CameraPose, Intrinsics, calibrate
from planhrc.robot_sim.errors import SimError
from planhrc.robot_sim.perception import CameraPerception, Perception
from planhrc.robot_sim.scene import Scene
from planhrc.robot_sim.vision import Limits, MarkerFinder, ObjectMarkers, find_links, grey_image, read_object

if TYPE_CHECKING:
    from pybullet_utils.bullet_client import BulletClient

HEAD, CELL = "head", "cell"


@dataclass(frozen=True)
class CellCameraSpec:
    """Where the cell camera is mounted (its eye and the point it looks at, in the cell's frame) and its image."""

    eye: tuple[float, float, float] = (1.35, 0.0, 0.8)
    target: tuple[float, float, float] = (0.6, 0.0, -0.18)
    width: int = 1280
    height: int = 960
    fov_deg: float = 50.0  # vertical
    near: float = 0.05
    far: float = 5.0
    upscales: tuple[int, ...] = (2, 1, 3)

    @property
    def intrinsics(self) -> Intrinsics:
        return Intrinsics.from_fov(self.width, self.height, self.fov_deg)


class CellCamera:
    """The fixed camera: renders from its mount, reads the board to calibrate, then the object's links."""

    def __init__(self, client: BulletClient, scene: Scene, spec: CellCameraSpec = CellCameraSpec(),
                 limits: Limits = Limits()) -> None:
        if scene.spec.board is None:
            raise SimError("scene: the cell camera is calibrated from the board's markers (SceneSpec.board)")
        self.client, self.scene, self.spec, self.limits = client, scene, spec, limits
        self.intrinsics = spec.intrinsics
        self._view = client.computeViewMatrix(list(spec.eye), list(spec.target), [0.0, 0.0, 1.0])
        self._proj = client.computeProjectionMatrixFOV(spec.fov_deg, spec.width / spec.height, spec.near, spec.far)
        self.markers = ObjectMarkers("object", tuple(asset.marker_id for asset in scene.markers),
                                     scene.spec.link_length_m, scene.spec.marker_size_m, scene.marker_z)
        self._finder = MarkerFinder(spec.upscales)
        self.calibration: Calibration | None = None

    @property
    def pose(self) -> CameraPose:
        """Where the cell believes the camera is: its calibration's pose (calibrate first)."""
        if self.calibration is None:
            raise SimError("cell camera: not calibrated")
        return self.calibration.pose

    def render(self) -> np.ndarray:
        self.scene.sync_markers()
        _, _, rgba, _, _ = self.client.getCameraImage(self.spec.width, self.spec.height, self._view, self._proj,
                                                      renderer=pybullet.ER_TINY_RENDERER)
        return np.reshape(np.asarray(rgba, dtype=np.uint8), (self.spec.height, self.spec.width, 4))[:, :, :3].copy()

    def calibrate(self) -> Calibration:
        """The camera's pose from the board's markers in one of its images (nothing in the cell moves meanwhile, so
        more images would be the same image): `camera.calibrate`, as `planhrc perceive-calibrate` does it."""
        board = self.scene.spec.board
        assert board is not None
        found = MarkerFinder(self.spec.upscales).find(grey_image(self.render()), board.ids)
        try:
            self.calibration = calibrate([found], self.intrinsics, board)
        except CalibrationError as exc:
            raise SimError(f"cell camera: {exc}") from None
        return self.calibration

    def perceive(self) -> Perception:
        frame = self.render()
        found = find_links(grey_image(frame), self._finder, [self.markers], self.intrinsics, self.pose)
        reading = read_object(found, self.markers, self.intrinsics, self.pose, self.limits)
        return Perception(reading.link_orientations_deg, frame, base_point_xy=reading.base_point_xy,
                          seen_by=tuple(CELL if v is not None else None for v in reading.link_orientations_deg))


class TwoCameras:
    """The head camera first, the cell camera for what the head missed, the head turned for what both missed."""

    def __init__(self, head: CameraPerception, cell: CellCamera) -> None:
        self.head, self.cell = head, cell
        self.last_cell_frame: np.ndarray | None = None  # the cell camera's image of the last look that needed it

    def perceive(self) -> Perception:
        return self.look()

    def look(self) -> Perception:
        seen = self.head.perceive()
        self.last_cell_frame = None
        if seen.complete:
            return seen
        through = self.cell.perceive()
        self.last_cell_frame = through.frame
        merged = _merge(seen, through, looks=2)
        if merged.complete:
            return merged
        again = self.head.look_again(merged)
        return _merge(merged, again, looks=merged.looks + again.looks)


def _merge(first: Perception, second: Perception, looks: int) -> Perception:
    """Each link from the first perception that saw it; the base point likewise; the first one's frame."""
    values = tuple(a if a is not None else b for a, b in zip(first.link_orientations_deg,
                                                              second.link_orientations_deg))
    by = tuple(a if a is not None else b for a, b in zip(first.sources, second.sources))
    return Perception(values, first.frame, looks=looks,
                      base_point_xy=first.base_point_xy or second.base_point_xy, seen_by=by)

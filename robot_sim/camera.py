"""A pinhole camera looking at the table, in OpenCV's conventions: its intrinsics (what a `sensor_msgs/CameraInfo`
carries), its pose in the cell's frame, and the calibration of that pose from ArUco markers laid on the table.

Frames: the cell's (`base`): +x the robot's forward axis, +y its left, +z up (REP 103). The camera's (OpenCV's
optical frame): +x to the image's right, +y down the image, +z along the view. A pose maps a point of the cell into
the camera: p_cam = R p_cell + t. Pixel coordinates put (0, 0) at the centre of the top-left pixel, as OpenCV and
CameraInfo's K do.

A calibration board is a set of markers lying on the table at known places in the cell's frame (a `Board`: its
JSON says where each one lies). `calibrate` finds the camera's pose from the corners of the board's markers in one
or more images taken from where the camera stays (all corners of all images in one perspective-n-point fit), and
says how well the pose explains them (the reprojection error). Nothing here reads a simulator: the simulated
cell's renders are images like any other.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping, Sequence

import cv2
import numpy as np

from planhrc.robot_sim.errors import SimError

# CameraInfo's distortion models as OpenCV reads their coefficients (plumb_bob: k1 k2 t1 t2 k3; rational: 8)
DISTORTION_LENGTHS = (0, 4, 5, 8, 12, 14)
CALIBRATION_FORMAT = "planhrc-camera-calibration/1"


class CalibrationError(SimError):
    """A calibration that cannot be made or read; the message names the field or says what the images lacked."""


def _finite(name: str, values: Sequence[float]) -> tuple[float, ...]:
    try:
        out = tuple(float(v) for v in values)
    except (TypeError, ValueError):
        raise CalibrationError(f"{name}: expected numbers, got {values!r}") from None
    if not all(math.isfinite(v) for v in out):
        raise CalibrationError(f"{name}: expected finite numbers, got {list(out)}")
    return out


@dataclass(frozen=True)
class Intrinsics:
    """What the camera's lens and sensor do: image size, K (row-major, CameraInfo.k) and the distortion
    coefficients (CameraInfo.d; empty or zeros: none)."""

    width: int
    height: int
    k: tuple[float, ...]
    d: tuple[float, ...] = ()

    def __post_init__(self) -> None:
        if self.width < 1 or self.height < 1:
            raise CalibrationError(f"camera.size: width and height must be positive, got {self.width} x {self.height}")
        if len(self.k) != 9 or not all(math.isfinite(v) for v in self.k):
            raise CalibrationError(f"camera.k: expected 9 finite numbers (row-major 3 x 3), got {list(self.k)}")
        if self.k[0] <= 0 or self.k[4] <= 0:
            raise CalibrationError(f"camera.k: focal lengths fx, fy must be positive, got {self.k[0]}, {self.k[4]}")
        if len(self.d) not in DISTORTION_LENGTHS or not all(math.isfinite(v) for v in self.d):
            raise CalibrationError(f"camera.d: expected {', '.join(map(str, DISTORTION_LENGTHS))} finite "
                                   f"coefficients, got {list(self.d)}")

    @classmethod
    def from_fov(cls, width: int, height: int, fov_y_deg: float) -> "Intrinsics":
        """An ideal pinhole with square pixels and a vertical field of view (PyBullet's renders)."""
        f = (height / 2.0) / math.tan(math.radians(fov_y_deg) / 2.0)
        return cls(width, height, (f, 0.0, width / 2.0 - 0.5, 0.0, f, height / 2.0 - 0.5, 0.0, 0.0, 1.0))

    @property
    def matrix(self) -> np.ndarray:
        return np.asarray(self.k, dtype=float).reshape(3, 3)

    @property
    def distorted(self) -> bool:
        return any(v != 0.0 for v in self.d)

    @property
    def distortion(self) -> np.ndarray:
        return np.asarray(self.d or (0.0,) * 5, dtype=float)

    def normalized(self, pixels: np.ndarray) -> np.ndarray:
        """Pixels (N x 2) -> points on the plane z = 1 of the camera's frame, the lens's distortion removed."""
        pixels = np.asarray(pixels, dtype=float).reshape(-1, 2)
        if self.distorted:
            return np.asarray(cv2.undistortPoints(pixels.reshape(-1, 1, 2), self.matrix, self.distortion)).reshape(-1, 2)
        fx, _, cx, _, fy, cy = self.k[:6]
        out: np.ndarray = (pixels - np.array([cx, cy])) / np.array([fx, fy])
        return out

    def to_data(self) -> dict[str, Any]:
        return {"width": self.width, "height": self.height, "k": list(self.k), "d": list(self.d)}

    @classmethod
    def of_data(cls, data: Mapping[str, Any], field: str = "camera") -> "Intrinsics":
        try:
            return cls(int(data["width"]), int(data["height"]), _finite(f"{field}.k", data["k"]),
                       _finite(f"{field}.d", data.get("d") or ()))
        except KeyError as exc:
            raise CalibrationError(f"{field}.{exc.args[0]}: missing") from None
        except (TypeError, ValueError) as exc:
            raise CalibrationError(f"{field}: malformed ({exc})") from None


@dataclass(frozen=True)
class CameraPose:
    """Where the camera is: the rotation R (row-major 3 x 3) and translation t with p_cam = R p_cell + t."""

    rotation: tuple[float, ...]
    translation: tuple[float, float, float]

    def __post_init__(self) -> None:
        if len(self.rotation) != 9 or len(self.translation) != 3:
            raise CalibrationError("pose: expected a 3 x 3 rotation and 3 translation values")
        r = self.r
        if not np.allclose(r @ r.T, np.eye(3), atol=1e-6) or np.linalg.det(r) < 0:
            raise CalibrationError("pose.rotation: not a rotation matrix")

    @classmethod
    def of_arrays(cls, r: np.ndarray, t: np.ndarray) -> "CameraPose":
        # re-orthonormalised: a rotation read back from text or from a fit is exact to the last digit
        u, _, vt = np.linalg.svd(np.asarray(r, dtype=float).reshape(3, 3))
        return cls(tuple(float(v) for v in (u @ vt).ravel()), tuple(float(v) for v in np.ravel(t)[:3]))  # type: ignore[arg-type]

    @classmethod
    def look_at(cls, eye: Sequence[float], target: Sequence[float], up: Sequence[float] = (0.0, 0.0, 1.0)
                ) -> "CameraPose":
        """A camera at `eye` looking at `target`, `up` pointing up in its image."""
        eye_v = np.asarray(eye, dtype=float)
        forward = np.asarray(target, dtype=float) - eye_v
        forward /= np.linalg.norm(forward)
        right = np.cross(forward, np.asarray(up, dtype=float))
        if np.linalg.norm(right) < 1e-9:
            raise CalibrationError("pose: the view direction and `up` are parallel")
        right /= np.linalg.norm(right)
        down = np.cross(forward, right)
        r = np.vstack([right, down, forward])
        return cls.of_arrays(r, -r @ eye_v)

    @classmethod
    def from_gl_view(cls, view: Sequence[float]) -> "CameraPose":
        """From an OpenGL view matrix (PyBullet's `computeViewMatrix`, column-major): its eye frame has +y up and
        looks along -z, the optical frame +y down and looks along +z."""
        gl = np.asarray(view, dtype=float).reshape(4, 4).T
        flip = np.diag([1.0, -1.0, -1.0])
        return cls.of_arrays(flip @ gl[:3, :3], flip @ gl[:3, 3])

    @property
    def r(self) -> np.ndarray:
        return np.asarray(self.rotation, dtype=float).reshape(3, 3)

    @property
    def t(self) -> np.ndarray:
        return np.asarray(self.translation, dtype=float)

    @property
    def position(self) -> np.ndarray:
        """The camera's centre in the cell's frame."""
        position: np.ndarray = -self.r.T @ self.t
        return position

    def project(self, points: np.ndarray, camera: Intrinsics) -> np.ndarray:
        """Points of the cell (N x 3) -> pixels (N x 2)."""
        points = np.asarray(points, dtype=float).reshape(-1, 3)
        if camera.distorted:
            rvec, _ = cv2.Rodrigues(self.r)
            pixels, _ = cv2.projectPoints(points, rvec, self.t, camera.matrix, camera.distortion)
            return np.asarray(pixels).reshape(-1, 2)
        in_camera = points @ self.r.T + self.t
        fx, _, cx, _, fy, cy = camera.k[:6]
        return np.column_stack([fx * in_camera[:, 0] / in_camera[:, 2] + cx, fy * in_camera[:, 1] / in_camera[:, 2] + cy])

    def onto_plane(self, pixels: np.ndarray, z: float, camera: Intrinsics) -> np.ndarray:
        """Where the rays through `pixels` (N x 2) meet the horizontal plane at height `z` (N x 2 in the cell's
        frame); NaN for a ray that never meets it in front of the camera."""
        rays = np.column_stack([camera.normalized(pixels), np.ones(len(np.atleast_2d(pixels)))]) @ self.r
        origin = self.position
        with np.errstate(divide="ignore", invalid="ignore"):
            s = (z - origin[2]) / rays[:, 2]
        s = np.where(np.isfinite(s) & (s > 0), s, np.nan)
        points: np.ndarray = origin[:2] + s[:, None] * rays[:, :2]
        return points

    def to_data(self) -> dict[str, Any]:
        return {"rotation": [list(self.rotation[i:i + 3]) for i in (0, 3, 6)], "translation": list(self.translation),
                "camera_position_m": [round(float(v), 6) for v in self.position]}

    @classmethod
    def of_data(cls, data: Mapping[str, Any], field: str = "pose") -> "CameraPose":
        try:
            rows = data["rotation"]
            r = np.array([_finite(f"{field}.rotation", row) for row in rows], dtype=float)
            t = np.array(_finite(f"{field}.translation", data["translation"]), dtype=float)
        except KeyError as exc:
            raise CalibrationError(f"{field}.{exc.args[0]}: missing") from None
        except (TypeError, ValueError) as exc:
            raise CalibrationError(f"{field}: malformed ({exc})") from None
        if r.shape != (3, 3) or t.shape != (3,):
            raise CalibrationError(f"{field}: expected a 3 x 3 rotation and 3 translation values")
        if not np.allclose(r @ r.T, np.eye(3), atol=1e-4) or np.linalg.det(r) < 0:
            raise CalibrationError(f"{field}.rotation: not a rotation matrix")
        return cls.of_arrays(r, t)


def square_corners(centre: Sequence[float], yaw_rad: float, size_m: float) -> np.ndarray:
    """The four corners (4 x 3) of a flat square marker in ArUco's order (its image's top-left, top-right,
    bottom-right, bottom-left), lying at `centre` with its image's left-to-right direction turned `yaw_rad`
    counter-clockwise from +x (REP 103) and its image's top towards the left of that direction."""
    h = size_m / 2.0
    c, s = math.cos(yaw_rad), math.sin(yaw_rad)
    local = np.array([[-h, h], [h, h], [h, -h], [-h, -h]])
    xy = local @ np.array([[c, s], [-s, c]]) + np.asarray(centre[:2], dtype=float)
    return np.column_stack([xy, np.full(4, float(centre[2]))])


@dataclass(frozen=True)
class BoardMarker:
    """One marker of the calibration board: its id, its centre in the cell's frame (metres), its turn (radians,
    REP 103) and its side (metres, the black border's outer edge)."""

    marker_id: int
    x: float
    y: float
    z: float
    yaw_rad: float
    size_m: float

    def corners(self) -> np.ndarray:
        return square_corners((self.x, self.y, self.z), self.yaw_rad, self.size_m)


@dataclass(frozen=True)
class Board:
    """The markers laid on the table to calibrate a camera's pose (ArUco DICT_4X4_50, like the links' markers)."""

    markers: tuple[BoardMarker, ...]

    def __post_init__(self) -> None:
        ids = [m.marker_id for m in self.markers]
        if len(set(ids)) != len(ids):
            raise CalibrationError(f"board.markers: an id is given twice: {ids}")
        if not self.markers:
            raise CalibrationError("board.markers: at least one marker is needed")
        for m in self.markers:
            if not 0 <= m.marker_id < 50:
                raise CalibrationError(f"board.markers: id {m.marker_id} is not in DICT_4X4_50 (0..49)")
            if not m.size_m > 0:
                raise CalibrationError(f"board.markers[{m.marker_id}].size_m: must be positive, got {m.size_m}")

    @property
    def ids(self) -> frozenset[int]:
        return frozenset(m.marker_id for m in self.markers)

    def marker(self, marker_id: int) -> BoardMarker:
        return next(m for m in self.markers if m.marker_id == marker_id)

    def to_data(self) -> dict[str, Any]:
        return {"dictionary": "DICT_4X4_50",
                "markers": [{"id": m.marker_id, "x": m.x, "y": m.y, "z": m.z, "yaw_rad": m.yaw_rad,
                             "size_m": m.size_m} for m in self.markers]}

    @classmethod
    def of_data(cls, data: Mapping[str, Any], field: str = "board") -> "Board":
        if not isinstance(data, Mapping) or not isinstance(data.get("markers"), list):
            raise CalibrationError(f"{field}.markers: expected a list of markers")
        if data.get("dictionary", "DICT_4X4_50") != "DICT_4X4_50":
            raise CalibrationError(f"{field}.dictionary: only DICT_4X4_50 is read, got {data.get('dictionary')!r}")
        markers = []
        for i, item in enumerate(data["markers"]):
            where = f"{field}.markers[{i}]"
            if not isinstance(item, Mapping):
                raise CalibrationError(f"{where}: expected an object")
            try:
                x, y, z, yaw, size = _finite(where, [item["x"], item["y"], item["z"], item.get("yaw_rad", 0.0),
                                                     item["size_m"]])
                marker_id = item["id"]
            except KeyError as exc:
                raise CalibrationError(f"{where}.{exc.args[0]}: missing") from None
            if isinstance(marker_id, bool) or not isinstance(marker_id, int):
                raise CalibrationError(f"{where}.id: expected an integer, got {marker_id!r}")
            markers.append(BoardMarker(marker_id, x, y, z, yaw, size))
        return cls(tuple(markers))

    @classmethod
    def read(cls, path: str | Path) -> "Board":
        return cls.of_data(_read_json(path, "board"), "board")


def _read_json(path: str | Path, field: str) -> Any:
    try:
        return json.loads(Path(path).read_text())
    except OSError as exc:
        raise CalibrationError(f"{field}: cannot read {path}: {exc.strerror or exc}") from None
    except ValueError as exc:
        raise CalibrationError(f"{field}: {path} is not JSON ({exc})") from None


# The simulated cell's board: six markers of 6 cm along the table's long edges, where the object seldom lies
# (the table spans x 0.3 .. 0.9 m, y -0.65 .. 0.65 m; its top is at z = -0.18 m in Baxter's base frame).
SIM_TABLE_TOP_Z = -0.18
SIM_BOARD = Board(tuple(BoardMarker(44 + i, x, y, SIM_TABLE_TOP_Z + 0.0005, 0.0, 0.06)
                        for i, (x, y) in enumerate(((0.34, 0.6), (0.34, 0.0), (0.34, -0.6),
                                                    (0.86, 0.6), (0.86, 0.0), (0.86, -0.6)))))


@dataclass(frozen=True)
class Calibration:
    """The camera's pose found from a board, with what it was found from and how well it fits."""

    pose: CameraPose
    camera: Intrinsics
    board: Board
    markers_used: tuple[int, ...]
    frames: int
    reprojection_rms_px: float
    reprojection_max_px: float
    frame_id: str = "base"

    def to_data(self) -> dict[str, Any]:
        return {"format": CALIBRATION_FORMAT, "frame_id": self.frame_id, "camera": self.camera.to_data(),
                "pose": self.pose.to_data(), "board": self.board.to_data(), "markers_used": list(self.markers_used),
                "frames": self.frames, "reprojection_rms_px": round(self.reprojection_rms_px, 4),
                "reprojection_max_px": round(self.reprojection_max_px, 4)}

    @classmethod
    def of_data(cls, data: Any) -> "Calibration":
        if not isinstance(data, Mapping):
            raise CalibrationError("calibration: expected a JSON object")
        if data.get("format") != CALIBRATION_FORMAT:
            raise CalibrationError(f"calibration.format: expected {CALIBRATION_FORMAT!r}, got {data.get('format')!r}")
        try:
            return cls(CameraPose.of_data(data["pose"], "calibration.pose"),
                       Intrinsics.of_data(data["camera"], "calibration.camera"),
                       Board.of_data(data["board"], "calibration.board"),
                       tuple(int(v) for v in data.get("markers_used") or ()), int(data.get("frames") or 0),
                       float(data.get("reprojection_rms_px") or 0.0), float(data.get("reprojection_max_px") or 0.0),
                       str(data.get("frame_id") or "base"))
        except KeyError as exc:
            raise CalibrationError(f"calibration.{exc.args[0]}: missing") from None
        except (TypeError, ValueError) as exc:
            raise CalibrationError(f"calibration: malformed ({exc})") from None

    @classmethod
    def read(cls, path: str | Path) -> "Calibration":
        return cls.of_data(_read_json(path, "calibration"))

    def write(self, path: str | Path) -> Path:
        target = Path(path)
        target.parent.mkdir(parents=True, exist_ok=True)
        text = json.dumps(self.to_data(), indent=2) + "\n"
        partial = target.with_name(target.name + ".partial")
        partial.write_text(text)
        partial.replace(target)  # a reader never sees half a file
        return target


def _fit_pose(obj: np.ndarray, img: np.ndarray, camera: Intrinsics) -> CameraPose | None:
    ok, rvec, tvec = cv2.solvePnP(obj, img, camera.matrix, camera.distortion, flags=cv2.SOLVEPNP_SQPNP)
    if not ok:
        return None
    rvec, tvec = cv2.solvePnPRefineLM(obj, img, camera.matrix, camera.distortion, rvec, tvec)
    r, _ = cv2.Rodrigues(rvec)
    return CameraPose.of_arrays(r, tvec)


def calibrate(views: Sequence[Mapping[int, np.ndarray]], camera: Intrinsics, board: Board, min_markers: int = 3,
              max_rms_px: float = 1.5, frame_id: str = "base") -> Calibration:
    """The camera's pose from the board's markers found in `views` (marker id -> its 4 corners in pixels, one
    mapping per image, all taken from the same place): one perspective-n-point fit of every corner. At least
    `min_markers` different board markers must be seen (one square alone leaves the pose ambiguous, two far-off
    ones barely fix it), and the fit must explain their corners within `max_rms_px`; while it does not, the marker
    it explains worst is left out (a marker half hidden, or read wrong), as long as enough are left."""
    corners: dict[int, list[np.ndarray]] = {}
    for view in views:
        for marker_id, found in view.items():
            if marker_id in board.ids:
                corners.setdefault(marker_id, []).append(np.asarray(found, dtype=float).reshape(4, 2))
    used = sorted(corners)
    while True:
        if len(used) < min_markers:
            raise CalibrationError(f"calibration: {len(used)} of the board's markers read well ({used}), at least "
                                   f"{min_markers} of {sorted(board.ids)} are needed in view")
        obj = np.vstack([board.marker(m).corners() for m in used for _ in corners[m]])
        img = np.vstack([c for m in used for c in corners[m]])
        pose = _fit_pose(obj, img, camera)
        if pose is None:
            raise CalibrationError("calibration: no camera pose fits the board's corners")
        residuals = np.linalg.norm(pose.project(obj, camera) - img, axis=1)
        rms = float(np.sqrt(np.mean(residuals ** 2)))
        if rms <= max_rms_px:
            break
        if len(used) <= min_markers:
            raise CalibrationError(f"calibration: the best pose misses the board's corners by {rms:.2f} px (RMS), "
                                   f"more than {max_rms_px} px: is the board file right, and K that of this camera?")
        per_marker, at = {}, 0
        for m in used:
            n = 4 * len(corners[m])
            per_marker[m] = float(np.mean(residuals[at:at + n]))
            at += n
        used.remove(max(per_marker, key=lambda m: per_marker[m]))
    return Calibration(pose, camera, board, tuple(used), len(views), rms, float(residuals.max()), frame_id)

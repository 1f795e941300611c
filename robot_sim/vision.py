"""The links' markers seen by a camera whose pose is known: find the ArUco markers in an image, measure each link's
marker on the table and read an object from them. OpenCV and numpy only: the simulated worker's head camera and
`planhrc perceive-node` (a real camera's images over ROS 2) run the same code.

A marker lies flat on its link's top face, at a known height, its image's left-to-right direction along the link
(`markers.py`). So three numbers place it: its centre (x, y) on that plane and its turn. They start from the
detected corners cast back through the camera onto the plane, and are then fitted (Gauss-Newton) so that the
marker they describe projects onto the four detected corners as closely as it can. What is left over is the
reprojection error (RMS, pixels); with the fit's Jacobian it also gives the orientation's standard error. A marker
is reported only while both are small (`Limits`): a marker too small, too slanted, too blurred or not lying where
its link should (lifted, tilted) is reported unseen, never guessed.

Orientations are the service's: degrees in [0, 360), clockwise seen from above from +x (CONVENTIONS.md).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Mapping, Sequence

import cv2
import numpy as np

from planhrc.robot_sim.camera import CameraPose, Intrinsics, square_corners
from planhrc.robot_sim.markers import aruco_dictionary

# The corners' noise is never taken below this (pixels), however well four corners happen to fit
CORNER_NOISE_FLOOR_PX = 0.3


@dataclass(frozen=True)
class Limits:
    """When a measured marker counts as seen."""

    max_reprojection_px: float = 2.5
    max_angle_sigma_deg: float = 1.0  # the orientation's standard error (its corners' noise taken >= 0.3 px)


@dataclass(frozen=True)
class MarkerMeasure:
    """One marker placed on its plane: turn (service degrees), centre, and how well that explains its corners."""

    angle_deg: float
    centre_xy: tuple[float, float]
    reprojection_px: float
    angle_sigma_deg: float
    side_px: float  # the detected square's mean side, in pixels

    def problem(self, limits: Limits) -> str | None:
        """Why this measure is not good enough to report, or None."""
        if not self.reprojection_px <= limits.max_reprojection_px:
            return f"reprojection error {self.reprojection_px:.2f} px > {limits.max_reprojection_px} px"
        if not self.angle_sigma_deg <= limits.max_angle_sigma_deg:
            return f"orientation uncertain: sigma {self.angle_sigma_deg:.2f} deg > {limits.max_angle_sigma_deg} deg"
        return None


def detector_parameters() -> cv2.aruco.DetectorParameters:
    params = cv2.aruco.DetectorParameters()
    params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_CONTOUR
    params.minMarkerPerimeterRate = 0.01
    # two thresholding windows (3 and 13 pixels): six (3 .. 23 by 4) found 5 % more markers in 64 held-out views at
    # 2.5 times the cost; the 3-pixel window finds the small markers on a bright, washed-out link
    params.adaptiveThreshWinSizeMin = 3
    params.adaptiveThreshWinSizeMax = 13
    params.adaptiveThreshWinSizeStep = 10
    params.polygonalApproxAccuracyRate = 0.05
    params.perspectiveRemovePixelPerCell = 8
    params.perspectiveRemoveIgnoredMarginPerCell = 0.25
    return params


def grey_image(image: np.ndarray, order: str = "rgb") -> np.ndarray:
    """A grey-scale view of an image (H x W, or H x W x 3 in `order` rgb or bgr, or x 4 with alpha)."""
    if image.ndim == 2:
        return image
    code = cv2.COLOR_RGB2GRAY if order == "rgb" else cv2.COLOR_BGR2GRAY
    return np.asarray(cv2.cvtColor(np.ascontiguousarray(image[..., :3]), code))


class MarkerFinder:
    """ArUco markers (DICT_4X4_50) in an image. Small markers are looked for again on enlarged copies (`upscales`,
    tried in turn until every wanted marker is found). Each marker found is then looked at again on a small crop
    around it, enlarged twice, with AprilTag's corner refinement (it fits the square's edges as lines): on a
    slanted or blurred marker the contour's corners stray by a pixel or more, which turns a small marker by
    degrees. Over the whole image that refinement costs several times the detection; on the crops of the wanted
    markers only, it costs about as much again (docs/perception.md)."""

    def __init__(self, upscales: Sequence[int] = (1,), refine: bool = True) -> None:
        self.upscales = tuple(upscales)
        self.refine = refine
        self._detector = cv2.aruco.ArucoDetector(aruco_dictionary(), detector_parameters())
        fine = detector_parameters()
        fine.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_APRILTAG
        self._fine = cv2.aruco.ArucoDetector(aruco_dictionary(), fine)

    def find(self, grey: np.ndarray, wanted: set[int] | frozenset[int] | None = None) -> dict[int, np.ndarray]:
        """Marker id -> its four corners (4 x 2, pixels of `grey`) for the markers found (only `wanted` ones,
        when given)."""
        found: dict[int, np.ndarray] = {}
        for k in self.upscales:
            image = grey if k == 1 else cv2.resize(grey, None, fx=k, fy=k, interpolation=cv2.INTER_CUBIC)
            corners, ids, _ = self._detector.detectMarkers(image)
            if ids is not None:
                for marker_corners, marker_id in zip(corners, ids.ravel()):
                    m = int(marker_id)
                    if (wanted is None or m in wanted) and m not in found:
                        # corner (x, y) of the enlarged image -> pixel coordinates of the frame
                        found[m] = (np.asarray(marker_corners, dtype=float).reshape(4, 2) + 0.5) / k - 0.5
            if wanted is not None and wanted <= found.keys():
                break
        if self.refine:
            found = {m: self._refined(grey, m, corners) for m, corners in found.items()}
        return found

    def find_in(self, grey: np.ndarray, box: tuple[int, int, int, int], wanted: set[int] | frozenset[int],
                scale: int = 2) -> dict[int, np.ndarray]:
        """The wanted markers found in the image's region `box` (x0, y0, x1, y1), enlarged `scale` times first."""
        x0, y0 = max(box[0], 0), max(box[1], 0)
        x1, y1 = min(box[2], grey.shape[1]), min(box[3], grey.shape[0])
        if x1 - x0 < 8 or y1 - y0 < 8:
            return {}
        crop = cv2.resize(grey[y0:y1, x0:x1], None, fx=scale, fy=scale, interpolation=cv2.INTER_CUBIC)
        corners, ids, _ = self._detector.detectMarkers(crop)
        found: dict[int, np.ndarray] = {}
        for marker_corners, marker_id in zip(corners, ids.ravel() if ids is not None else ()):
            if int(marker_id) in wanted:
                found[int(marker_id)] = (np.asarray(marker_corners, dtype=float).reshape(4, 2) + 0.5) / scale - 0.5 \
                    + np.array([x0, y0])
        if self.refine:
            found = {m: self._refined(grey, m, corners) for m, corners in found.items()}
        return found

    def _refined(self, grey: np.ndarray, marker_id: int, corners: np.ndarray) -> np.ndarray:
        """The marker's corners found again on a crop around it (the contour's corners when it is not); a crop of
        a marker under 32 pixels is enlarged twice first."""
        side = float(np.linalg.norm(corners - np.roll(corners, -1, axis=0), axis=1).max())
        scale = 2 if side < 32.0 else 1
        pad = max(0.5 * side, 10.0)
        x0, y0 = np.maximum(np.floor(corners.min(axis=0) - pad).astype(int), 0)
        x1, y1 = np.ceil(corners.max(axis=0) + pad).astype(int)
        crop = grey[y0:y1, x0:x1]
        if scale > 1:
            crop = cv2.resize(crop, None, fx=scale, fy=scale, interpolation=cv2.INTER_CUBIC)
        again, ids, _ = self._fine.detectMarkers(crop)
        for marker_corners, found_id in zip(again, ids.ravel() if ids is not None else ()):
            if int(found_id) == marker_id:
                refined: np.ndarray = (np.asarray(marker_corners, dtype=float).reshape(4, 2) + 0.5) / scale - 0.5
                refined += np.array([x0, y0])
                return refined
        return corners


def table_angle(vector_xy: np.ndarray) -> float:
    """Orientation of a table vector: degrees clockwise seen from above from +x."""
    return math.degrees(math.atan2(-vector_xy[1], vector_xy[0])) % 360.0


def _circular_mean_deg(angles: Sequence[float]) -> float:
    s = sum(math.sin(math.radians(a)) for a in angles)
    c = sum(math.cos(math.radians(a)) for a in angles)
    return math.degrees(math.atan2(s, c)) % 360.0


def _model(params: np.ndarray, z: float, size_m: float) -> np.ndarray:
    return square_corners((params[0], params[1], z), params[2], size_m)


def measure_marker(corners_px: np.ndarray, camera: Intrinsics, pose: CameraPose, z: float, size_m: float,
                   iterations: int = 6) -> MarkerMeasure | None:
    """Place a marker of side `size_m` lying at height `z` from its four detected corners; None when a corner's
    ray does not meet that plane in front of the camera."""
    corners_px = np.asarray(corners_px, dtype=float).reshape(4, 2)
    tl, tr, br, bl = pose.onto_plane(corners_px, z, camera)
    if not np.all(np.isfinite([tl, tr, br, bl])):
        return None
    # the start: the corners cast onto the plane, the turn averaged over the square's four edges
    angle = _circular_mean_deg([table_angle(tr - tl), table_angle(br - bl),
                                table_angle(bl - tl) - 90.0, table_angle(br - tr) - 90.0])
    centre = (tl + tr + br + bl) / 4.0
    params = np.array([centre[0], centre[1], -math.radians(angle)])
    target = corners_px.ravel()
    steps = np.diag([1e-5, 1e-5, 1e-4])
    for _ in range(iterations):
        # the marker where it is and moved a little along each parameter, projected at once (16 corners)
        corners = np.vstack([_model(moved, z, size_m) for moved in (params, *(params + steps))])
        projected = pose.project(corners, camera).reshape(4, 8)
        residual = projected[0] - target
        jacobian = ((projected[1:] - projected[0]) / np.diag(steps)[:, None]).T
        try:
            delta = np.linalg.lstsq(jacobian, -residual, rcond=None)[0]
        except np.linalg.LinAlgError:
            return None
        params = params + delta
        if abs(delta[2]) < 1e-7 and np.hypot(delta[0], delta[1]) < 1e-8:
            break
    residual = pose.project(_model(params, z, size_m), camera).ravel() - target
    jacobian = np.column_stack([(pose.project(_model(params + step, z, size_m), camera).ravel() - target - residual)
                                / step.max() for step in steps])
    rms = float(np.sqrt(np.mean(residual.reshape(4, 2) ** 2 @ np.ones(2))))
    noise = max(float(np.sqrt(np.sum(residual ** 2) / (8 - 3))), CORNER_NOISE_FLOOR_PX)
    try:
        covariance = noise ** 2 * np.linalg.inv(jacobian.T @ jacobian)
        sigma = math.degrees(math.sqrt(max(float(covariance[2, 2]), 0.0)))
    except np.linalg.LinAlgError:
        sigma = math.inf
    sides = np.linalg.norm(corners_px - np.roll(corners_px, -1, axis=0), axis=1)
    return MarkerMeasure(angle_deg=(-math.degrees(params[2])) % 360.0, centre_xy=(float(params[0]), float(params[1])),
                         reprojection_px=rms, angle_sigma_deg=sigma, side_px=float(sides.mean()))


@dataclass(frozen=True)
class ObjectMarkers:
    """Which markers an object's links carry (link K carries `marker_ids[K-1]`) and where they lie: on the links'
    top faces, their tops at height `marker_z_m` in the cell's frame."""

    object_id: str
    marker_ids: tuple[int, ...]
    link_length_m: float
    marker_size_m: float
    marker_z_m: float

    @property
    def n_links(self) -> int:
        return len(self.marker_ids)


@dataclass(frozen=True)
class LinkSighting:
    """What the camera made of one link's marker: its measure (None: not found) and, when it is not reported,
    why."""

    link: int
    marker_id: int
    measure: MarkerMeasure | None
    problem: str | None  # None: reported seen

    @property
    def seen(self) -> bool:
        return self.measure is not None and self.problem is None


@dataclass(frozen=True)
class ObjectReading:
    """An object as one image shows it: each link's orientation (None: not seen), the base point p1 (None while l1
    is not seen) and every link's sighting."""

    object_id: str
    link_orientations_deg: tuple[float | None, ...]
    base_point_xy: tuple[float, float] | None
    sightings: tuple[LinkSighting, ...]

    @property
    def missing_links(self) -> tuple[int, ...]:
        return tuple(k for k, v in enumerate(self.link_orientations_deg, start=1) if v is None)


def base_point(angle_deg: float, centre_xy: Sequence[float], link_length_m: float) -> tuple[float, float]:
    """p1 from the first link's marker: its centre is the link's centre, p1 half a link back along the link."""
    t = math.radians(angle_deg)
    half = link_length_m / 2.0
    return float(centre_xy[0] - half * math.cos(t)), float(centre_xy[1] + half * math.sin(t))


def find_links(grey: np.ndarray, finder: MarkerFinder, objects: Sequence[ObjectMarkers], camera: Intrinsics,
               pose: CameraPose) -> dict[int, np.ndarray]:
    """The objects' markers in one image: found over the whole image, then, for a link whose marker was not and
    whose neighbour's was, looked for again, enlarged twice, around the only places the chain leaves it: its centre
    lies half a link from the joint it shares with that neighbour. (Enlarging the whole image twice found 16 % more
    of the visible markers in the held-out views, at several times the cost; the regions are small.) What is found
    there is measured and reported like any other marker."""
    wanted = frozenset(m for o in objects for m in o.marker_ids)
    found = finder.find(grey, wanted)
    for markers in objects:
        for box, marker_id in _regions(found, markers, camera, pose):
            if marker_id not in found:
                found.update(finder.find_in(grey, box, {marker_id}))
    return found


def _regions(found: Mapping[int, np.ndarray], markers: ObjectMarkers, camera: Intrinsics,
             pose: CameraPose) -> list[tuple[tuple[int, int, int, int], int]]:
    """(pixel box, marker id) where each missing link's marker can be, from its neighbours found."""
    ids = markers.marker_ids
    out = []
    half = markers.link_length_m / 2.0
    circle = np.linspace(0.0, 2.0 * math.pi, 16, endpoint=False)
    for k, marker_id in enumerate(ids):
        if marker_id in found:
            continue
        for neighbour, side in ((k - 1, 1.0), (k + 1, -1.0)):  # the joint after the link before, or before the next
            if not 0 <= neighbour < len(ids) or ids[neighbour] not in found:
                continue
            measure = measure_marker(found[ids[neighbour]], camera, pose, markers.marker_z_m, markers.marker_size_m)
            if measure is None:
                continue
            t = math.radians(measure.angle_deg)
            joint = np.array(measure.centre_xy) + side * half * np.array([math.cos(t), -math.sin(t)])
            reach = half + markers.marker_size_m
            ring = np.column_stack([joint[0] + reach * np.cos(circle), joint[1] + reach * np.sin(circle),
                                    np.full(len(circle), markers.marker_z_m)])
            pixels = pose.project(ring, camera)
            if not np.all(np.isfinite(pixels)):
                continue
            x0, y0 = np.floor(pixels.min(axis=0)).astype(int)
            x1, y1 = np.ceil(pixels.max(axis=0)).astype(int)
            out.append(((int(x0), int(y0), int(x1), int(y1)), marker_id))
    return out


def read_object(found: Mapping[int, np.ndarray], markers: ObjectMarkers, camera: Intrinsics, pose: CameraPose,
                limits: Limits = Limits()) -> ObjectReading:
    """The object's links from the markers found in one image (marker id -> corners in pixels)."""
    sightings = []
    for link, marker_id in enumerate(markers.marker_ids, start=1):
        corners = found.get(marker_id)
        if corners is None:
            sightings.append(LinkSighting(link, marker_id, None, "marker not found"))
            continue
        measure = measure_marker(corners, camera, pose, markers.marker_z_m, markers.marker_size_m)
        problem = "not on the links' plane" if measure is None else measure.problem(limits)
        sightings.append(LinkSighting(link, marker_id, measure, problem))
    values = tuple(s.measure.angle_deg if s.seen and s.measure else None for s in sightings)
    first = sightings[0] if sightings else None
    base = (base_point(first.measure.angle_deg, first.measure.centre_xy, markers.link_length_m)
            if first is not None and first.seen and first.measure is not None else None)
    return ObjectReading(markers.object_id, values, base, tuple(sightings))

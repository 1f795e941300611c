"""Camera views of the simulated cell that the worker never takes, with their truth: images to test the marker
perception on (`planhrc render-views`, `planhrc perceive-bench`, the set kept in tests/data/perception/).

A `Rig` is a camera placed around the table (anywhere but where Baxter's head looks from): its pose, resolution
and field of view, with the calibration board (`camera.SIM_BOARD`) on the table in view. A `Shot` is one picture
from it: the object in a random feasible configuration, a light from some direction and colour, hands (dark boxes)
hovering over links or a marker painted over, then blur, sensor noise and an encoding (rgb8, bgr8, mono8). The
truth of a view is the simulator's: each link's orientation from its body, the base point, the camera's true pose,
and how much of each link's marker the camera can see (the renderer's segmentation against the marker's whole
projected square): a marker seen less than `HIDDEN_FRACTION` is hidden, and a perception that reports it is wrong.
"""
from __future__ import annotations

import argparse
import json
import math
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Iterator, Sequence

import cv2
import numpy as np
import pybullet
from pybullet_utils.bullet_client import BulletClient

from planhrc.cli_args import SubParsers, non_negative_int, positive_int, writable_dir
from planhrc.robot_sim.camera import SIM_BOARD, CameraPose, Intrinsics, square_corners
from planhrc.robot_sim.errors import SimError
from planhrc.robot_sim.scene import Scene, SceneSpec, build_scene, random_orientations

ENCODINGS = ("rgb8", "bgr8", "mono8")
RESOLUTIONS = ((640, 480), (800, 600), (1280, 720), (1024, 768))
HIDDEN_FRACTION = 0.5  # a marker showing less than this share of its square is hidden
WORKER_HEAD_XY = (0.06, 0.0)  # roughly where Baxter's head camera looks from: no rig stands near it
# the worker's own camera: no rig uses its resolution with its field of view, nor its clean, evenly lit images
WORKER_CAMERA = (960, 720, 50.0)


@dataclass(frozen=True, kw_only=True)
class Rig:
    name: str
    eye: tuple[float, float, float]
    target: tuple[float, float, float]
    width: int
    height: int
    fov_deg: float

    @property
    def intrinsics(self) -> Intrinsics:
        return Intrinsics.from_fov(self.width, self.height, self.fov_deg)

    @property
    def pose(self) -> CameraPose:
        return CameraPose.look_at(self.eye, self.target)


@dataclass(frozen=True, kw_only=True)
class Shot:
    name: str
    orientations_deg: tuple[float, ...]
    base_xy: tuple[float, float]
    light_direction: tuple[float, float, float]
    light_colour: tuple[float, float, float]
    ambient: float
    diffuse: float
    specular: float
    shadow: bool
    blur_px: float  # Gaussian blur's sigma
    noise: float  # Gaussian noise's sigma, in grey levels
    seed: int
    hands: tuple[tuple[float, float, float, float], ...] = ()  # boxes: centre x, y, height above the table, side
    unmarked_links: tuple[int, ...] = ()
    encoding: str = "rgb8"


def _round(values: Sequence[float], digits: int = 4) -> tuple[float, ...]:
    return tuple(round(float(v), digits) for v in values)


def random_rig(rng: np.random.Generator, name: str, resolution: tuple[int, int] | None = None) -> Rig:
    """A camera around the table looking at its middle: any side but the robot's, 0.3 to 0.8 m away and 0.35 to
    0.8 m above the table, with a field of view of 35 to 60 degrees."""
    while True:
        target = (0.6 + float(rng.uniform(-0.08, 0.08)), float(rng.uniform(-0.15, 0.15)), SIM_BOARD.markers[0].z)
        azimuth = float(rng.uniform(-math.pi, math.pi))
        reach = float(rng.uniform(0.3, 0.8))
        eye = (target[0] + reach * math.cos(azimuth), target[1] + reach * math.sin(azimuth),
               target[2] + float(rng.uniform(0.35, 0.8)))
        if math.dist(eye[:2], WORKER_HEAD_XY) < 0.35:
            continue
        width, height = resolution or RESOLUTIONS[int(rng.integers(len(RESOLUTIONS)))]
        fov = float(rng.uniform(35.0, 60.0))
        if (width, height) == WORKER_CAMERA[:2] and abs(fov - WORKER_CAMERA[2]) < 3.0:
            continue
        rig = Rig(name=name, eye=_round(eye), target=_round(target), width=width, height=height,  # type: ignore[arg-type]
                  fov_deg=round(fov, 2))
        if board_markers_in_view(rig) >= 4:  # placed, as a cell's camera is, to see its calibration board
            return rig


def board_markers_in_view(rig: Rig, margin_px: float = 8.0, min_side_px: float = 20.0) -> int:
    """How many of the board's markers the rig's camera has wholly inside its image, each edge at least
    `min_side_px` long (the truth, before rendering)."""
    count = 0
    for marker in SIM_BOARD.markers:
        pixels = rig.pose.project(marker.corners(), rig.intrinsics)
        inside = ((pixels[:, 0] >= margin_px) & (pixels[:, 0] <= rig.width - margin_px) & (pixels[:, 1] >= margin_px)
                  & (pixels[:, 1] <= rig.height - margin_px))
        sides = np.linalg.norm(pixels - np.roll(pixels, -1, axis=0), axis=1)
        count += bool(inside.all() and sides.min() >= min_side_px)
    return count


def random_shot(rng: np.random.Generator, name: str, spec: SceneSpec, seed: int) -> Shot:
    """The object somewhere in the middle of the table in a random feasible configuration, lit from a random side,
    sometimes with hands over links or a marker painted over, blurred and noisy to random degrees."""
    base = (round(float(rng.uniform(0.45, 0.7)), 4), round(float(rng.uniform(-0.25, 0.25)), 4))
    orientations = random_orientations(rng, spec, base_point_xy=base)
    elevation, azimuth = float(rng.uniform(0.3, 1.4)), float(rng.uniform(-math.pi, math.pi))
    light = (math.cos(elevation) * math.cos(azimuth), math.cos(elevation) * math.sin(azimuth), math.sin(elevation))
    tint = rng.uniform(0.75, 1.0, size=3)
    hands: list[tuple[float, float, float, float]] = []
    if rng.random() < 0.35:
        for link in rng.choice(spec.n_links, size=int(rng.integers(1, 3)), replace=False):
            theta = math.radians(orientations[int(link)])
            centre = _link_centre(base, orientations, int(link) + 1, spec.link_length_m)
            along = float(rng.uniform(-0.03, 0.03))
            hands.append((round(centre[0] + along * math.cos(theta), 4), round(centre[1] - along * math.sin(theta), 4),
                          round(float(rng.uniform(0.05, 0.12)), 4), round(float(rng.uniform(0.05, 0.09)), 4)))
    unmarked = (int(rng.integers(1, spec.n_links + 1)),) if rng.random() < 0.15 else ()
    return Shot(name=name, orientations_deg=_round(orientations, 3), base_xy=base,
                light_direction=_round(light), light_colour=_round(tint, 3),  # type: ignore[arg-type]
                ambient=round(float(rng.uniform(0.35, 0.8)), 3), diffuse=round(float(rng.uniform(0.3, 0.8)), 3),
                specular=round(float(rng.uniform(0.0, 0.4)), 3), shadow=bool(rng.random() < 0.5),
                blur_px=round(float(rng.choice([0.0, float(rng.uniform(0.3, 1.2))])), 3),
                noise=round(float(rng.choice([0.0, float(rng.uniform(1.0, 6.0))])), 3), seed=seed,
                hands=tuple(hands), unmarked_links=unmarked, encoding=ENCODINGS[int(rng.integers(len(ENCODINGS)))])


def _link_centre(base: Sequence[float], orientations: Sequence[float], link: int, length: float) -> tuple[float, float]:
    x, y = float(base[0]), float(base[1])
    for k, theta in enumerate(orientations[:link], start=1):
        t = math.radians(theta)
        step = length / 2.0 if k == link else length
        x, y = x + step * math.cos(t), y - step * math.sin(t)
    return x, y


@dataclass(frozen=True)
class View:
    """One rendered view: the image (in its encoding's channel order) and its truth."""

    rig: Rig
    shot: Shot
    image: np.ndarray
    truth: dict[str, Any]


class Studio:
    """One PyBullet client and a scene with the board, reused for every shot of the same object."""

    def __init__(self, n_links: int = 5) -> None:
        self.client = BulletClient(connection_mode=pybullet.DIRECT)
        self.spec = SceneSpec(n_links=n_links, load_robot=False, board=SIM_BOARD)
        self.scene: Scene = build_scene(self.client, self.spec)

    def close(self) -> None:
        self.scene.close()
        self.client.disconnect()

    def __enter__(self) -> "Studio":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def render(self, rig: Rig, shot: Shot) -> View:
        c, scene = self.client, self.scene
        scene.set_configuration(shot.orientations_deg, shot.base_xy)
        for k, body in enumerate(scene.marker_bodies, start=1):
            c.changeVisualShape(body, -1, rgbaColor=[1, 1, 1, 0 if k in shot.unmarked_links else 1])
        hands = []
        for x, y, height, side in shot.hands:
            shape = c.createVisualShape(pybullet.GEOM_BOX, halfExtents=[side / 2, side / 2, 0.02],
                                        rgbaColor=[0.45, 0.3, 0.25, 1])
            hands.append(c.createMultiBody(baseMass=0, baseVisualShapeIndex=shape,
                                           basePosition=[x, y, scene.marker_z + height]))
        try:
            view = c.computeViewMatrix(list(rig.eye), list(rig.target), [0.0, 0.0, 1.0])
            proj = c.computeProjectionMatrixFOV(rig.fov_deg, rig.width / rig.height, 0.05, 6.0)
            _, _, rgba, _, seg = c.getCameraImage(
                rig.width, rig.height, view, proj, renderer=pybullet.ER_TINY_RENDERER,
                lightDirection=list(shot.light_direction), lightColor=list(shot.light_colour),
                lightAmbientCoeff=shot.ambient, lightDiffuseCoeff=shot.diffuse,
                lightSpecularCoeff=shot.specular, shadow=int(shot.shadow))
        finally:
            for body in hands:
                c.removeBody(body)
        rgb = np.reshape(np.asarray(rgba, dtype=np.uint8), (rig.height, rig.width, 4))[:, :, :3]
        segmentation = np.reshape(np.asarray(seg), (rig.height, rig.width))
        image = degrade(rgb, shot)
        return View(rig, shot, image, self.truth(rig, shot, segmentation))

    def truth(self, rig: Rig, shot: Shot, segmentation: np.ndarray) -> dict[str, Any]:
        scene = self.scene
        pose, camera = rig.pose, rig.intrinsics
        links = []
        for k, (theta, body) in enumerate(zip(scene.link_orientations_deg(), scene.marker_bodies), start=1):
            centre = scene.link_center(k)
            corners = pose.project(square_corners((centre[0], centre[1], scene.marker_z), -math.radians(theta),
                                                  self.spec.marker_size_m), camera)
            square = np.zeros(segmentation.shape, np.uint8)
            cv2.fillConvexPoly(square, np.round(corners * 16).astype(np.int32), 1, cv2.LINE_8, 4)
            area = int(square.sum())
            shown = 0 if k in shot.unmarked_links else int(((segmentation == body) & (square > 0)).sum())
            fraction = shown / area if area else 0.0
            links.append({"link": k, "deg": round(theta, 4), "visible_fraction": round(fraction, 3),
                          "hidden": fraction < HIDDEN_FRACTION,
                          "side_px": round(float(np.linalg.norm(corners[1] - corners[0])), 2)})
        base = scene.base_point()
        return {"links": links, "base_point_xy": [round(base[0], 5), round(base[1], 5)],
                "camera": camera.to_data(), "pose": pose.to_data(), "marker_z_m": round(scene.marker_z, 5),
                "link_length_m": self.spec.link_length_m, "marker_size_m": self.spec.marker_size_m}


def degrade(rgb: np.ndarray, shot: Shot) -> np.ndarray:
    """Blur, sensor noise (seeded) and the shot's encoding: H x W x 3 in RGB or BGR order, or H x W grey."""
    image: np.ndarray = rgb.astype(np.float32)
    if shot.blur_px > 0:
        image = cv2.GaussianBlur(image, (0, 0), shot.blur_px)
    if shot.noise > 0:
        image = image + np.random.default_rng(shot.seed).normal(0.0, shot.noise, image.shape).astype(np.float32)
    out = np.clip(np.round(image), 0, 255).astype(np.uint8)
    if shot.encoding == "mono8":
        return np.asarray(cv2.cvtColor(out, cv2.COLOR_RGB2GRAY))
    return out[:, :, ::-1].copy() if shot.encoding == "bgr8" else out


def held_out_views(rigs: int, shots: int, seed: int, resolution: tuple[int, int] | None = None) -> Iterator[View]:
    """`rigs` random cameras with `shots` random pictures each, all drawn from `seed`."""
    rng = np.random.default_rng(seed)
    with Studio() as studio:
        for r in range(rigs):
            rig = random_rig(rng, f"rig{seed}-{r}", resolution)
            for s in range(shots):
                shot = random_shot(rng, f"{rig.name}-shot{s}", studio.spec, seed=seed * 1000 + r * 100 + s)
                yield studio.render(rig, shot)


def write_views(views: Sequence[View] | Iterator[View], out: Path, quality: int = 92) -> Path:
    """Each view as a JPEG (a camera's usual way of keeping pictures) beside `views.json` (the rig, the shot, the
    file, its encoding and the truth) and `board.json`, the calibration board's markers."""
    out.mkdir(parents=True, exist_ok=True)
    entries = []
    for view in views:
        name = f"{view.shot.name}.jpg"
        image = view.image[:, :, ::-1] if view.shot.encoding == "rgb8" else view.image  # imwrite takes BGR
        cv2.imwrite(str(out / name), image, [cv2.IMWRITE_JPEG_QUALITY, quality])
        entries.append({"file": name, "encoding": view.shot.encoding, "rig": asdict(view.rig),
                        "shot": asdict(view.shot), "truth": view.truth})
    path = out / "views.json"
    path.write_text(json.dumps({"views": entries}, indent=1) + "\n")
    (out / "board.json").write_text(json.dumps(SIM_BOARD.to_data(), indent=1) + "\n")  # what a cell's lab writes
    return path


def read_image(path: Path, encoding: str) -> np.ndarray:
    """A kept view's image in its encoding's channel order."""
    flag = cv2.IMREAD_GRAYSCALE if encoding == "mono8" else cv2.IMREAD_COLOR
    image = cv2.imread(str(path), flag)
    if image is None:
        raise SimError(f"view: cannot read {path}")
    return np.asarray(image[:, :, ::-1] if encoding == "rgb8" else image)


def add_render_views_parser(subparsers: SubParsers) -> None:
    p = subparsers.add_parser("render-views", help="camera views of the simulated cell the worker never takes",
                              description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", type=writable_dir, required=True, help="folder for the images and views.json")
    p.add_argument("--rigs", type=positive_int, default=2, help="cameras placed around the table")
    p.add_argument("--shots", type=positive_int, default=4, help="pictures from each camera")
    p.add_argument("--seed", type=non_negative_int, default=0)
    p.set_defaults(func=run_render_views)


def run_render_views(args: argparse.Namespace) -> int:
    path = write_views(held_out_views(args.rigs, args.shots, args.seed), Path(args.out))
    print(f"[render-views] {args.rigs * args.shots} views in {path}")
    return 0

"""ArUco marker images and the UV-mapped quad meshes that show them in PyBullet renders.

A texture on a PyBullet ``GEOM_BOX`` does not show the image; a quad mesh with ``vt`` coordinates does
(see NOTES.md). Each marker gets a PNG and an OBJ/MTL pair in a directory owned by the caller (the scene
creates a temporary directory and removes it on close).

Texture layout: the image's left-to-right direction (ArUco corner 0 -> corner 1) lies along the mesh's
local +x axis, and the image's top along local +y. The scene places the mesh with local +x along the link,
so the detected corner 0 -> corner 1 direction is the link's direction (checked in TinyRenderer renders:
the mean signed angle error over random configurations is ~0, so there is no 90/180 degree offset).
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

ARUCO_DICTIONARY = cv2.aruco.DICT_4X4_50


@dataclass(frozen=True)
class MarkerAsset:
    marker_id: int
    image_path: Path
    obj_path: Path
    size_m: float


def aruco_dictionary() -> cv2.aruco.Dictionary:
    return cv2.aruco.getPredefinedDictionary(ARUCO_DICTIONARY)


def make_marker_image(marker_id: int, pixels: int = 240, border_cells: int = 0) -> np.ndarray:
    """A grey-scale marker image with a white quiet zone of `border_cells` cells around the black border.

    The scene uses no quiet zone: the marker covers the link's whole 3 cm width, and the light link and table
    around it give the contrast the detector needs (a dark table hides the border: markers go undetected).
    """
    dictionary = aruco_dictionary()
    n_cells = dictionary.markerSize + 2  # data cells plus the black border
    cell = pixels // (n_cells + 2 * border_cells)
    inner = cv2.aruco.generateImageMarker(dictionary, marker_id, cell * n_cells)
    pad = cell * border_cells
    return cv2.copyMakeBorder(inner, pad, pad, pad, pad, cv2.BORDER_CONSTANT, value=255)


def _quad_obj_text(size_m: float, mtl_name: str) -> str:
    h = size_m / 2.0
    return "\n".join(
        [
            f"mtllib {mtl_name}",
            "o marker",
            f"v {-h:.6f} {-h:.6f} 0",
            f"v {h:.6f} {-h:.6f} 0",
            f"v {h:.6f} {h:.6f} 0",
            f"v {-h:.6f} {h:.6f} 0",
            "vt 0 0",
            "vt 1 0",
            "vt 1 1",
            "vt 0 1",
            "vn 0 0 1",
            "usemtl marker",
            "f 1/1/1 2/2/1 3/3/1",
            "f 1/1/1 3/3/1 4/4/1",
            "",
        ]
    )


def write_marker_asset(directory: Path, marker_id: int, size_m: float) -> MarkerAsset:
    """Write `marker_<id>.png`, `.mtl` and `.obj` into `directory` and describe them."""
    directory.mkdir(parents=True, exist_ok=True)
    stem = f"marker_{marker_id}"
    image_path = directory / f"{stem}.png"
    cv2.imwrite(str(image_path), make_marker_image(marker_id))
    mtl_path = directory / f"{stem}.mtl"
    mtl_path.write_text(
        "newmtl marker\nKa 1 1 1\nKd 1 1 1\nKs 0 0 0\nillum 1\n" f"map_Kd {image_path.name}\n"
    )
    obj_path = directory / f"{stem}.obj"
    obj_path.write_text(_quad_obj_text(size_m, mtl_path.name))
    return MarkerAsset(marker_id=marker_id, image_path=image_path, obj_path=obj_path, size_m=size_m)

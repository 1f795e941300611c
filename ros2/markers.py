"""What the markers topic shows, as plain values (no rclpy): the node turns each `Shape` into a
visualization_msgs/Marker in the cell's frame.

Three namespaces, one line strip each (plus the perceived joints as spheres): `perceived` (solid), `goal` (a
translucent ghost) and `expected` (after the next action). A shape with no points deletes its marker, so a
latched MarkerArray never keeps a stale ghost.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

from planhrc.geometry import GeometryError, ObjectGeometry, Table, joint_points, rotated

LINE_STRIP, SPHERE_LIST = "line_strip", "sphere_list"
RGBA = tuple[float, float, float, float]
COLOURS: dict[str, RGBA] = {"perceived": (0.1, 0.45, 0.9, 1.0), "joints": (0.95, 0.95, 0.95, 1.0),
                            "goal": (0.1, 0.8, 0.3, 0.35), "expected": (0.95, 0.6, 0.1, 0.8)}
NAMESPACES = ("perceived", "joints", "goal", "expected")
LINK_WIDTH_M = 0.03  # the bars' width on the table (planhrc.geometry's default)


@dataclass(frozen=True)
class Shape:
    namespace: str
    kind: str
    points: tuple[tuple[float, float, float], ...]  # empty: delete this marker
    rgba: RGBA
    scale_m: float


def _polyline(geometry: ObjectGeometry, angles: Sequence[float], z: float) -> tuple[tuple[float, float, float], ...]:
    return tuple((float(p[0]), float(p[1]), z) for p in joint_points(geometry, angles))


def object_shapes(link_lengths_m: Sequence[float], base_point_xy: Sequence[float] | None,
                  perceived_deg: Sequence[float | None] | None, goal_deg: Sequence[float] | None,
                  next_turn: tuple[int, int, float] | None, table_z: float | None = None) -> tuple[Shape, ...]:
    """The markers of one object: `next_turn` is (turned, held, delta_deg) of the next action, if any. A
    configuration with an unseen link is not drawn (its place is unknown)."""
    z = Table().top_z if table_z is None else table_z
    geometry = ObjectGeometry(tuple(link_lengths_m)) if base_point_xy is None else \
        ObjectGeometry(tuple(link_lengths_m), (float(base_point_xy[0]), float(base_point_xy[1])))
    seen = None if perceived_deg is None or any(v is None for v in perceived_deg) else \
        tuple(float(v) for v in perceived_deg if v is not None)
    perceived = _polyline(geometry, seen, z) if seen else ()
    goal = _polyline(geometry, goal_deg, z + 0.001) if goal_deg and len(goal_deg) == len(link_lengths_m) else ()
    expected: tuple[tuple[float, float, float], ...] = ()
    if seen and next_turn is not None:
        try:
            placed, after = rotated(geometry, seen, *next_turn)
        except GeometryError:  # an action that does not fit the perceived object is not drawn
            placed, after = geometry, ()
        expected = _polyline(placed, after, z + 0.002) if after else ()
    return (Shape("perceived", LINE_STRIP, perceived, COLOURS["perceived"], LINK_WIDTH_M),
            Shape("joints", SPHERE_LIST, perceived, COLOURS["joints"], LINK_WIDTH_M * 1.3),
            Shape("goal", LINE_STRIP, goal, COLOURS["goal"], LINK_WIDTH_M),
            Shape("expected", LINE_STRIP, expected, COLOURS["expected"], LINK_WIDTH_M * 0.6))

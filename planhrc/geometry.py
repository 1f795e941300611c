"""Where an articulated object may lie in the cell: the table, Baxter's body and the reach of its arms.

A pure layer-0 module (it imports only `planhrc.model` and numpy): the simulator uses it to draw random goals
and human moves, the service can use it to check every expected state of a plan before dispatching it.

Frames and angles follow CONVENTIONS.md: +x is the robot's forward axis, +y its left; a link's orientation is
in degrees clockwise seen from above from +x, so its direction on the table is (cos theta, -sin theta). Link lK
runs from joint point pK to pK+1; p1 is the object's base point.

`configuration_feasible(geometry, angles)` answers with a `Feasibility`: ok, and one `Infeasibility` per
problem (a machine-readable code, the link it concerns and a sentence), checking that

* every link lies on the table (``off_table``),
* no link is inside the robot's body (``inside_robot``),
* every grasp point (a link's centre) is within reach of one of the arms (``out_of_reach``),
* no two links overlap or fold onto each other (``overlap``).

`sweep_feasible` checks the configurations a rotation passes through, in small increments; `rotated` gives
the configuration after one (the inertial assumption A1: every link beyond the turned one moves with it).

Plans are checked as drawn (`STRICT`). A physical execution is never exactly the plan: a measured pose differs
from the planned one by a few degrees and a centimetre or two. Whoever acts on the object (the robot's worker,
the simulated human) judges a turn from the measured pose with `EXECUTION`, the one definition of how far a
measured configuration may be past the table's edge or closer between links than the plan's and still be safe
to act on: the service plans strictly, the hands tolerate what physics does to the plan.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Collection, Mapping, Sequence

import numpy as np

from planhrc.model import ArticulatedObject, ModelError
from planhrc.vocabulary import Infeasible


@dataclass(frozen=True)
class Tolerance:
    """How much a configuration may differ from the strict checks and still count as feasible: a link whose end
    lies `overhang_m` past the table's edge (its centre of mass well inside: a 15.5 cm bar rests on the table),
    two links whose centre lines come `overlap_m` closer than a link's width (bars side by side); or, the other
    way, the `clearance_m` every link keeps from the table's edges."""

    overhang_m: float = 0.0
    overlap_m: float = 0.0
    clearance_m: float = 0.0


STRICT = Tolerance()  # goals and the counts of states off the table: the geometry as drawn
# Acting on a measured pose: a few degrees of drift on a 0.78 m chain move its end by about 3 cm.
EXECUTION = Tolerance(overhang_m=0.03, overlap_m=0.01)
# The configurations a plan comes to rest in on its way to the goal keep 1.5 cm from the table's edges, so that a
# physical turn ending a degree or two off (1-2 cm at the chain's end) still leaves the object on the table.
PLANNING = Tolerance(clearance_m=0.015)
# What an order of a plan's steps keeps where it can: a turn dragging three or four links along the table may
# flex the joints beyond the turned one by 5° or so, which moves the chain's end 4-5 cm.
ROOMY = Tolerance(clearance_m=0.05)


class GeometryError(ModelError):
    """A geometric input that cannot describe an object on the table; the message names the field."""


@dataclass(frozen=True)
class Table:
    """The table top: a rectangle (centre and size in metres) at height `top_z`."""

    center_xy: tuple[float, float] = (0.6, 0.0)
    size_xy: tuple[float, float] = (0.6, 1.3)
    top_z: float = -0.18

    def bounds(self, margin_m: float = 0.0) -> tuple[float, float, float, float]:
        """(x_min, x_max, y_min, y_max), shrunk by `margin_m` on every side."""
        (cx, cy), (sx, sy) = self.center_xy, self.size_xy
        return (cx - sx / 2 + margin_m, cx + sx / 2 - margin_m, cy - sy / 2 + margin_m, cy + sy / 2 - margin_m)


@dataclass(frozen=True)
class RobotBody:
    """Baxter on its pedestal at the origin: its body's footprint and where its grippers reach at table height.

    An arm reaches a table point whose horizontal distance from its shoulder is at most `reach_m` and that lies
    either in front of `near_x_m` or on the arm's own side beyond `own_side_y_m` (across the body, close to the
    torso, the wrist cannot point down at every yaw). Measured by inverse kinematics in the simulated cell, with
    a margin: both gripper yaws (along and across the robot's forward axis) reach every such point.
    """

    footprint_xy: tuple[float, float, float, float] = (-0.35, 0.28, -0.38, 0.38)  # x_min, x_max, y_min, y_max
    left_shoulder_xy: tuple[float, float] = (0.064, 0.259)
    right_shoulder_xy: tuple[float, float] = (0.064, -0.259)
    reach_m: float = 0.78
    near_x_m: float = 0.42
    own_side_y_m: float = 0.2


@dataclass(frozen=True)
class Cell:
    """The table and the robot: everything an object's configuration is checked against."""

    table: Table = Table()
    robot: RobotBody = RobotBody()


@dataclass(frozen=True)
class ObjectGeometry:
    """An object's links as bars on the table: lengths, width and where its base point p1 lies."""

    link_lengths_m: tuple[float, ...]
    base_point_xy: tuple[float, float] = (0.6, 0.39)
    link_width_m: float = 0.03

    def __post_init__(self) -> None:
        if not self.link_lengths_m:
            raise GeometryError("link_lengths_m: an object has at least one link")
        if any(not (math.isfinite(v) and v > 0) for v in self.link_lengths_m):
            raise GeometryError(f"link_lengths_m: every length must be a positive number, got {self.link_lengths_m}")
        if len(self.base_point_xy) != 2 or not all(math.isfinite(v) for v in self.base_point_xy):
            raise GeometryError(f"base_point_xy: expected two finite numbers, got {self.base_point_xy}")
        if not (math.isfinite(self.link_width_m) and self.link_width_m > 0):
            raise GeometryError(f"link_width_m: must be a positive number, got {self.link_width_m}")

    @property
    def n_links(self) -> int:
        return len(self.link_lengths_m)

    @classmethod
    def of(cls, obj: ArticulatedObject, base_point_xy: tuple[float, float] | None = None) -> "ObjectGeometry":
        """The geometry of a KB object placed with its base point at `base_point_xy` (default: the cell's)."""
        if base_point_xy is None:
            return cls(tuple(obj.link_lengths_m))
        return cls(tuple(obj.link_lengths_m), (float(base_point_xy[0]), float(base_point_xy[1])))

    def placed(self, base_point_xy: Sequence[float]) -> "ObjectGeometry":
        return ObjectGeometry(self.link_lengths_m, (float(base_point_xy[0]), float(base_point_xy[1])), self.link_width_m)


@dataclass(frozen=True)
class Infeasibility:
    """One reason a configuration is not feasible: its code, the 1-based link, and a sentence."""

    code: Infeasible
    link: int
    message: str
    distance_m: float = 0.0  # how far off (beyond the table's edge or its clearance, beyond reach); 0 when not one
    against: str = ""  # what it runs against: which edge of the table, the robot's body, another link, the reach

    def __str__(self) -> str:
        return self.message


@dataclass(frozen=True)
class Feasibility:
    ok: bool
    reasons: tuple[Infeasibility, ...] = ()

    @property
    def links(self) -> tuple[int, ...]:
        """The links named by the reasons, in order, each once."""
        return tuple(dict.fromkeys(r.link for r in self.reasons))

    @property
    def codes(self) -> tuple[Infeasible, ...]:
        return tuple(dict.fromkeys(r.code for r in self.reasons))

    def sentence(self) -> str:
        return "feasible" if self.ok else "; ".join(r.message for r in self.reasons)


def direction(theta_deg: float) -> np.ndarray:
    """Unit vector on the table of a link at orientation theta (clockwise from +x, seen from above)."""
    t = math.radians(theta_deg)
    return np.array([math.cos(t), -math.sin(t)])


def _check_angles(geometry: ObjectGeometry, angles: Sequence[float]) -> tuple[float, ...]:
    if len(angles) != geometry.n_links:
        raise GeometryError(f"angles: expected {geometry.n_links} values (one per link), got {len(angles)}")
    try:
        values = tuple(float(a) for a in angles)
    except (TypeError, ValueError) as exc:
        raise GeometryError(f"angles: expected numbers, got {list(angles)!r}") from exc
    if not all(math.isfinite(v) for v in values):
        raise GeometryError(f"angles: expected finite numbers, got {list(angles)!r}")
    return values


def joint_points(geometry: ObjectGeometry, angles: Sequence[float]) -> tuple[np.ndarray, ...]:
    """p1 .. p(N+1) on the table, for link orientations `angles` (degrees)."""
    return tuple(_points(geometry, _check_angles(geometry, angles)))


def _points(geometry: ObjectGeometry, values: Sequence[float]) -> np.ndarray:
    """`joint_points` as one (N+1) x 2 array, for checked `values`."""
    t = np.radians(np.asarray(values, dtype=float))
    steps = np.asarray(geometry.link_lengths_m)[:, None] * np.stack((np.cos(t), -np.sin(t)), axis=1)
    points = np.empty((len(values) + 1, 2))
    points[0] = geometry.base_point_xy
    np.cumsum(steps, axis=0, out=points[1:])
    points[1:] += points[0]
    return points


def link_centres(geometry: ObjectGeometry, angles: Sequence[float]) -> tuple[np.ndarray, ...]:
    """The grasp point of each link: its centre."""
    points = joint_points(geometry, angles)
    return tuple((a + b) / 2.0 for a, b in zip(points, points[1:]))


def reach_shortfall(point_xy: Sequence[float] | np.ndarray, robot: RobotBody | None = None) -> float:
    """How far a table point lies beyond the reach of the nearer arm that could take it (0 when reachable)."""
    robot = robot or RobotBody()
    p = np.asarray(point_xy, dtype=float)
    best = math.inf
    for shoulder, side in ((robot.left_shoulder_xy, 1.0), (robot.right_shoulder_xy, -1.0)):
        beyond = max(0.0, float(np.hypot(p[0] - shoulder[0], p[1] - shoulder[1])) - robot.reach_m)
        if p[0] < robot.near_x_m and side * p[1] < robot.own_side_y_m:
            beyond = max(beyond, min(robot.near_x_m - p[0], robot.own_side_y_m - side * p[1]))
        best = min(best, beyond)
    return best


@dataclass(frozen=True)
class Measures:
    """What `configuration_feasible` measures of B configurations of one object at once (arrays, the batch first):
    how far each link lies past the table's edges for each clearance asked for, whether it enters the robot's
    body, how far its centre lies beyond each arm's reach, which neighbours fold onto each other and which other
    pairs of links come closer than their width. The one place these checks are computed: the verdicts and the
    reasons are read off it (`configuration_feasible`, and `planhrc.judge.TurnJudge` for many turns at once)."""

    points: np.ndarray  # (B, N+1, 2): joint points p1 .. p(N+1)
    outside: Mapping[float, np.ndarray]  # clearance -> (B, N+1): how far each point lies past the shrunk table
    off: Mapping[float, np.ndarray]  # clearance -> (B, N): the larger of each link's two ends
    inside: np.ndarray  # (B, N) bool: the link enters the robot's body
    short: np.ndarray  # (B, N, 2): how far each link's centre lies beyond the left, the right arm's reach
    folds: np.ndarray  # (B, N-1) bool: link k+2 folds back onto link k+1
    pairs: tuple[np.ndarray, np.ndarray]  # the non-neighbouring pairs (i, j), i < j - 1, 0-based
    close: Mapping[float, np.ndarray]  # overlap tolerance -> (B, P) bool: the pair comes closer than its limit

    @property
    def reach(self) -> np.ndarray:
        """(B, N): how far each link's centre lies beyond the nearer arm's reach (0 when one reaches it)."""
        return np.asarray(self.short.min(axis=2))


def measure_configurations(geometry: ObjectGeometry, values: np.ndarray, cell: Cell,
                           tolerances: Collection[Tolerance] = (STRICT,), min_fold_gap_deg: float = 25.0,
                           base_points: np.ndarray | None = None) -> Measures:
    """`Measures` of B configurations: link orientations `values` (B, N, degrees) with the base point at
    `base_points` (B, 2; default: `geometry`'s), for the clearances and overlap tolerances of `tolerances`."""
    values = np.asarray(values, dtype=float)
    b, n = values.shape
    bases = (np.broadcast_to(np.asarray(geometry.base_point_xy, dtype=float), (b, 2)) if base_points is None
             else np.asarray(base_points, dtype=float))
    t = np.radians(values)
    steps = np.asarray(geometry.link_lengths_m)[None, :, None] * np.stack((np.cos(t), -np.sin(t)), axis=2)
    points = np.empty((b, n + 1, 2))
    points[:, 0] = bases
    np.cumsum(steps, axis=1, out=points[:, 1:])
    points[:, 1:] += points[:, :1]
    half_width = geometry.link_width_m / 2.0
    outside, off = {}, {}
    for clearance in sorted({tol.clearance_m for tol in tolerances}):
        x0, x1, y0, y1 = cell.table.bounds(margin_m=half_width + clearance)
        px, py = points[..., 0], points[..., 1]
        outside[clearance] = np.hypot(np.maximum(np.maximum(x0 - px, 0.0), px - x1),
                                      np.maximum(np.maximum(y0 - py, 0.0), py - y1))
        off[clearance] = np.maximum(outside[clearance][:, :-1], outside[clearance][:, 1:])
    a, e = points[:, :-1].reshape(-1, 2), points[:, 1:].reshape(-1, 2)
    inside = _segments_enter_box(a, e, cell.robot.footprint_xy, half_width).reshape(b, n)
    short = arm_shortfalls((a + e) / 2.0, cell.robot).reshape(b, n, 2)
    folds = (np.abs((np.diff(values, axis=1) % 360.0) - 180.0) < min_fold_gap_deg) if n > 1 else np.zeros((b, 0), bool)
    i, j = np.triu_indices(n, k=2) if n > 2 else (np.zeros(0, dtype=int), np.zeros(0, dtype=int))
    close = {}
    for overlap in sorted({tol.overlap_m for tol in tolerances}):
        limit = geometry.link_width_m - overlap
        out = np.zeros((b, len(i)), dtype=bool)
        if len(i):
            pa, pb = points[:, :-1], points[:, 1:]
            lo, hi = np.minimum(pa, pb), np.maximum(pa, pb)  # pairs whose bounding boxes lie `limit` apart are far
            near = np.all((lo[:, i] - hi[:, j] < limit) & (lo[:, j] - hi[:, i] < limit), axis=2)
            rows, cols = np.nonzero(near)
            if len(rows):
                out[rows, cols] = _segment_distances(pa[rows, i[cols]], pb[rows, i[cols]], pa[rows, j[cols]],
                                                     pb[rows, j[cols]]) < limit
        close[overlap] = out
    return Measures(points, outside, off, inside, short, folds, (i, j), close)


def configuration_feasible(geometry: ObjectGeometry, angles: Sequence[float], cell: Cell | None = None,
                           min_fold_gap_deg: float = 25.0, reach_links: Collection[int] | None = None,
                           tolerance: Tolerance = STRICT) -> Feasibility:
    """Whether the object with link orientations `angles` lies on the table, clear of the robot, graspable,
    and without overlapping itself; every problem found is named (see the module's docstring).

    `reach_links` restricts the reach check to those links (the ones a rotation grasps); None checks every link.
    `tolerance` (see `Tolerance`) forgives a small overhang past the table's edge and between links.
    The checks are vectorised over links and link pairs (`measure_configurations`): a plan's ordering calls this
    thousands of times."""
    cell = cell or Cell()
    values = _check_angles(geometry, angles)
    m = measure_configurations(geometry, np.asarray([values]), cell, (tolerance,), min_fold_gap_deg)
    reasons = reasons_of(m, 0, geometry, cell, reach_links, tolerance)
    return Feasibility(not reasons, tuple(reasons))


def reasons_of(m: Measures, row: int, geometry: ObjectGeometry, cell: Cell, reach_links: Collection[int] | None,
               tolerance: Tolerance) -> list[Infeasibility]:
    """Every problem of configuration `row` of `m` (`measure_configurations` with `tolerance` among its
    tolerances), as `configuration_feasible` names them: one batch of measures serves many configurations."""
    n = geometry.n_links
    points, outside, off = m.points[row], m.outside[tolerance.clearance_m][row], m.off[tolerance.clearance_m][row]
    x0, x1, y0, y1 = cell.table.bounds(margin_m=geometry.link_width_m / 2.0 + tolerance.clearance_m)
    short = m.reach[row]
    checked = range(1, n + 1) if reach_links is None else sorted(k for k in set(reach_links) if 1 <= k <= n)
    reach = set(checked)
    reasons: list[Infeasibility] = []
    for k in range(1, n + 1):
        if off[k - 1] > tolerance.overhang_m + 1e-9:
            d = float(off[k - 1])  # past the edge, or past the clearance the tolerance keeps from it
            past = d - tolerance.clearance_m
            sentence = (f"link {k} leaves the table: {past:.2f} m past its edge" if past > 1e-9 else
                        f"link {k} comes within {tolerance.clearance_m - d:.2f} m of the table's edge")
            end = points[k - 1] if outside[k - 1] >= outside[k] else points[k]
            reasons.append(Infeasibility(Infeasible.OFF_TABLE, k, sentence, d, _edge(end, (x0, x1, y0, y1))))
        if m.inside[row, k - 1]:
            reasons.append(Infeasibility(Infeasible.INSIDE_ROBOT, k, f"link {k} lies inside the robot's body",
                                         against="the robot's body"))
        if k in reach and short[k - 1] > 1e-9:
            d = float(short[k - 1])
            reasons.append(Infeasibility(Infeasible.OUT_OF_REACH, k, f"link {k} unreachable: {d:.2f} m beyond reach",
                                         d, "the arms' reach"))
    for fold in np.flatnonzero(m.folds[row]):  # neighbours fold onto each other
        reasons.append(Infeasibility(Infeasible.OVERLAP, int(fold) + 2,
                                     f"link {int(fold) + 2} folds back onto link {int(fold) + 1}",
                                     against=f"link {int(fold) + 1}"))
    i, j = m.pairs
    close = m.close[tolerance.overlap_m][row]
    for pi, pj in zip(i[close], j[close]):
        reasons.append(Infeasibility(Infeasible.OVERLAP, int(pj) + 1,
                                     f"link {int(pj) + 1} overlaps link {int(pi) + 1}",
                                     against=f"link {int(pi) + 1}"))
    return reasons


def _edge(point: np.ndarray, bounds: tuple[float, float, float, float]) -> str:
    """Which edge of the table a point outside `bounds` (x_min, x_max, y_min, y_max) lies furthest past: the near
    one (towards the robot), the far one, or the robot's left or right one."""
    x0, x1, y0, y1 = bounds
    past = {"the table's near edge": x0 - point[0], "the table's far edge": point[0] - x1,
            "the table's right edge": y0 - point[1], "the table's left edge": point[1] - y1}
    return max(past, key=lambda name: past[name])


def arm_shortfalls(points: np.ndarray, robot: RobotBody) -> np.ndarray:
    """How far each table point lies beyond each arm's reach: an (n, 2) array, the left arm's then the right's
    (0 where the arm reaches it)."""
    points = np.atleast_2d(np.asarray(points, dtype=float))
    out = np.empty((len(points), 2))
    for column, (shoulder, side) in enumerate(((robot.left_shoulder_xy, 1.0), (robot.right_shoulder_xy, -1.0))):
        beyond = np.maximum(0.0, np.hypot(points[:, 0] - shoulder[0], points[:, 1] - shoulder[1]) - robot.reach_m)
        awkward = (points[:, 0] < robot.near_x_m) & (side * points[:, 1] < robot.own_side_y_m)
        across = np.minimum(robot.near_x_m - points[:, 0], robot.own_side_y_m - side * points[:, 1])
        out[:, column] = np.where(awkward, np.maximum(beyond, across), beyond)
    return out


def _segments_enter_box(a: np.ndarray, b: np.ndarray, box: tuple[float, float, float, float],
                        pad: float) -> np.ndarray:
    """For each bar from a[i] to b[i] (half width `pad`), whether it enters the rectangle `box` (clipping the
    segment against the grown rectangle, Liang-Barsky)."""
    lo = np.array([box[0] - pad, box[2] - pad])
    hi = np.array([box[1] + pad, box[3] + pad])
    d = b - a
    t0 = np.zeros(len(a))
    t1 = np.ones(len(a))
    ok = np.ones(len(a), dtype=bool)
    for axis in (0, 1):
        da, pa = d[:, axis], a[:, axis]
        still = np.abs(da) < 1e-12
        ok &= ~(still & ((pa < lo[axis]) | (pa > hi[axis])))
        with np.errstate(divide="ignore", invalid="ignore"):
            ta = np.where(still, -np.inf, (lo[axis] - pa) / da)
            tb = np.where(still, np.inf, (hi[axis] - pa) / da)
        t0 = np.maximum(t0, np.minimum(ta, tb))
        t1 = np.minimum(t1, np.maximum(ta, tb))
    return ok & (t0 <= t1)


def _segment_distances(a0: np.ndarray, a1: np.ndarray, b0: np.ndarray, b1: np.ndarray) -> np.ndarray:
    """Distance between segments a0[i]-a1[i] and b0[i]-b1[i] for every i (0 when they cross)."""
    def point_segment(p: np.ndarray, s0: np.ndarray, s1: np.ndarray) -> np.ndarray:
        d = s1 - s0
        t = np.clip(np.einsum("ij,ij->i", p - s0, d) / np.maximum(np.einsum("ij,ij->i", d, d), 1e-12), 0.0, 1.0)
        return np.asarray(np.linalg.norm(p - (s0 + t[:, None] * d), axis=1))

    def cross(o: np.ndarray, p: np.ndarray, q: np.ndarray) -> np.ndarray:
        return np.asarray((p[:, 0] - o[:, 0]) * (q[:, 1] - o[:, 1]) - (p[:, 1] - o[:, 1]) * (q[:, 0] - o[:, 0]))

    crossing = (cross(a0, a1, b0) * cross(a0, a1, b1) < 0) & (cross(b0, b1, a0) * cross(b0, b1, a1) < 0)
    nearest = np.minimum(np.minimum(point_segment(a0, b0, b1), point_segment(a1, b0, b1)),
                         np.minimum(point_segment(b0, a0, a1), point_segment(b1, a0, a1)))
    return np.asarray(np.where(crossing, 0.0, nearest))


def rotated(geometry: ObjectGeometry, angles: Sequence[float], turned_link: int, held_link: int,
            delta_deg: float) -> tuple[ObjectGeometry, tuple[float, ...]]:
    """The object after turning `turned_link` by `delta_deg` (+ = clockwise) about its joint with `held_link`
    (0 = the table). A downstream turn moves the turned link and every link after it; an upstream turn moves
    the links before the joint and so the base point."""
    values = _check_angles(geometry, angles)
    n = geometry.n_links
    if not 1 <= turned_link <= n:
        raise GeometryError(f"turned_link: must be in 1..{n}, got {turned_link}")
    if not 0 <= held_link <= n or abs(turned_link - held_link) != 1:
        raise GeometryError(f"held_link: must be a neighbour of link {turned_link} (0 = the table), got {held_link}")
    if turned_link > held_link:
        return geometry, tuple((v + delta_deg) % 360.0 if i >= turned_link - 1 else v for i, v in enumerate(values))
    pivot = joint_points(geometry, values)[held_link - 1]
    t = -math.radians(delta_deg)
    d = np.asarray(geometry.base_point_xy) - pivot
    base = pivot + np.array([math.cos(t) * d[0] - math.sin(t) * d[1], math.sin(t) * d[0] + math.cos(t) * d[1]])
    new_values = tuple((v + delta_deg) % 360.0 if i < held_link - 1 else v for i, v in enumerate(values))
    return geometry.placed(base), new_values


def sweep_feasible(geometry: ObjectGeometry, angles: Sequence[float], turned_link: int, held_link: int,
                   delta_deg: float, increment_deg: float = 5.0, cell: Cell | None = None,
                   reach_links: Collection[int] | None = None) -> Feasibility:
    """Whether every configuration a rotation passes through is feasible (checked every `increment_deg`); the
    first infeasible one's reasons are returned. `reach_links` as in `configuration_feasible`."""
    n = max(1, int(math.ceil(abs(delta_deg) / increment_deg)))
    for i in range(1, n + 1):
        placed, values = rotated(geometry, angles, turned_link, held_link, delta_deg * i / n)
        result = configuration_feasible(placed, values, cell, reach_links=reach_links)
        if not result.ok:
            return result
    return Feasibility(True)

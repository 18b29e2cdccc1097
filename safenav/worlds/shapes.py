"""Obstacle shapes: planar outlines standing on the floor as vertical prisms, with exact signed distances.

* :class:`Box`: a rectangle of ``size`` around ``center``, turned by ``yaw``;
* :class:`Cylinder`: a disk of ``radius`` around ``center``;
* :class:`Wall`: a rectangle of ``thickness`` centred on the segment from ``start`` to
  ``end`` and squared off half a thickness past both ends, so walls that share an end
  point close the corner without a gap (:func:`room` builds a closed polyline of them).

Every shape gives its outline as a polygon (the simulator's mesh) and its signed distance
to points (negative inside); :func:`gap` is the exact distance between two shapes.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Iterable
from dataclasses import dataclass
from types import SimpleNamespace
from typing import Any, NamedTuple

import numpy as np

from safenav._checks import number, positive, vector
from safenav._kernels import KernelGroup, plain
from safenav._optional import require
from safenav.errors import InvalidConfig
from safenav.geometry import counter_clockwise

__all__ = ["WALL_THICKNESS", "Box", "Cylinder", "Obstacle", "Wall", "gap", "room"]

WALL_THICKNESS = 0.1
"""Thickness of the walls the world builders make [m]."""


def _point(name: str, value: Any) -> tuple[float, float]:
    x, y = vector(name, value, 2, expected="a pair (x, y) of finite numbers [m]")
    return (x, y)


@dataclass(frozen=True)
class Box:
    """A rectangular block.

    Attributes:
        center: centre of the rectangle in the world frame [m].
        size: side lengths along the box's own x and y axes [m], both > 0.
        yaw: rotation of the box's x axis from the world x axis [rad].
    """

    center: tuple[float, float]
    size: tuple[float, float]
    yaw: float = 0.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "center", _point("Box.center", self.center))
        size = _point("Box.size", self.size)
        if min(size) <= 0.0:
            raise InvalidConfig(f"Box.size must be two lengths > 0 [m], got {self.size!r}")
        object.__setattr__(self, "size", size)
        object.__setattr__(self, "yaw", number("Box.yaw", self.yaw))

    @property
    def half_size(self) -> tuple[float, float]:
        """Half the side lengths [m]."""
        return (0.5 * self.size[0], 0.5 * self.size[1])

    def corners(self) -> np.ndarray:
        """The four corners, counter-clockwise from (+x, +y) in the box frame, as a read-only ``(4, 2)`` array [m]."""
        return self._corners

    @functools.cached_property
    def _corners(self) -> np.ndarray:
        hx, hy = self.half_size
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        local = np.array([(hx, hy), (-hx, hy), (-hx, -hy), (hx, -hy)])
        corners = np.column_stack((self.center[0] + c * local[:, 0] - s * local[:, 1],
                                   self.center[1] + s * local[:, 0] + c * local[:, 1]))
        corners.flags.writeable = False
        return corners

    @functools.cached_property
    def _row(self) -> np.ndarray:
        return box_array((self,))

    def polygon(self, tolerance: float = 0.0) -> np.ndarray:
        """The outline as a counter-clockwise ``(4, 2)`` polygon [m] (exact; ``tolerance`` is unused)."""
        return self.corners().copy()

    def signed_distance(self, points: np.ndarray) -> np.ndarray:
        """Signed distance from each of ``points`` ``(N, 2)`` to the rectangle [m], negative inside."""
        return box_distance(np.asarray(points, dtype=float).reshape(-1, 2), self._row)[:, 0]

    @property
    def radius(self) -> float:
        """Radius of the circumscribed circle [m]."""
        return math.hypot(*self.half_size)


@dataclass(frozen=True)
class Cylinder:
    """A round post.

    Attributes:
        center: centre of the disk in the world frame [m].
        radius: radius of the disk [m], > 0.
    """

    center: tuple[float, float]
    radius: float

    def __post_init__(self) -> None:
        object.__setattr__(self, "center", _point("Cylinder.center", self.center))
        object.__setattr__(self, "radius", positive("Cylinder.radius", self.radius))

    def polygon(self, tolerance: float = 0.001) -> np.ndarray:
        """The circumscribed regular polygon that lies within ``tolerance`` of the circle, ``(n, 2)`` [m].

        The polygon contains the disk (its edges touch the circle at their midpoints) and
        its vertices lie ``radius * (1 / cos(pi / n) - 1) <= tolerance`` outside it, so a ray
        cast against the polygon reads at most ``tolerance`` short of the true circle and
        never long. ``n`` is the smallest count that meets the tolerance, between 12 and 256.

        Args:
            tolerance: largest distance between the polygon and the circle [m], > 0.
        """
        tolerance = positive("Cylinder.polygon tolerance", tolerance)
        n = min(max(math.ceil(math.pi / math.acos(self.radius / (self.radius + tolerance))), 12), 256)
        circumradius = self.radius / math.cos(math.pi / n)
        # Vertices at half-step angles put an edge midpoint (a tangent point) on the +x axis.
        angles = (np.arange(n) + 0.5) * (2.0 * math.pi / n)
        return np.column_stack((self.center[0] + circumradius * np.cos(angles),
                                self.center[1] + circumradius * np.sin(angles)))

    def signed_distance(self, points: np.ndarray) -> np.ndarray:
        """Signed distance from each of ``points`` ``(N, 2)`` to the disk [m], negative inside."""
        p = np.asarray(points, dtype=float).reshape(-1, 2)
        return np.hypot(p[:, 0] - self.center[0], p[:, 1] - self.center[1]) - self.radius


@dataclass(frozen=True)
class Wall:
    """A straight wall, ``thickness`` wide and centred on the segment from ``start`` to ``end``.

    Its ends are squared off half a thickness past ``start`` and ``end``, so walls that
    share an end point close the corner: a room is a closed polyline of walls.

    Attributes:
        start: one end of the centre line [m].
        end: the other end of the centre line [m], different from ``start``.
        thickness: width of the wall [m], > 0.
    """

    start: tuple[float, float]
    end: tuple[float, float]
    thickness: float = WALL_THICKNESS

    def __post_init__(self) -> None:
        object.__setattr__(self, "start", _point("Wall.start", self.start))
        object.__setattr__(self, "end", _point("Wall.end", self.end))
        object.__setattr__(self, "thickness", positive("Wall.thickness", self.thickness))
        if self.start == self.end:
            raise InvalidConfig(f"Wall.end must differ from Wall.start, got both {self.start!r}")

    @functools.cached_property
    def box(self) -> Box:
        """The wall as the :class:`Box` it occupies."""
        dx, dy = self.end[0] - self.start[0], self.end[1] - self.start[1]
        return Box(center=(0.5 * (self.start[0] + self.end[0]), 0.5 * (self.start[1] + self.end[1])),
                   size=(math.hypot(dx, dy) + self.thickness, self.thickness), yaw=math.atan2(dy, dx))

    def polygon(self, tolerance: float = 0.0) -> np.ndarray:
        """The outline as a counter-clockwise ``(4, 2)`` polygon [m]."""
        return self.box.corners().copy()

    def signed_distance(self, points: np.ndarray) -> np.ndarray:
        """Signed distance from each of ``points`` ``(N, 2)`` to the wall [m], negative inside."""
        return self.box.signed_distance(points)


Obstacle = Box | Cylinder | Wall
"""Any obstacle a :class:`~safenav.worlds.World` can hold."""


def room(*corners: tuple[float, float], closed: bool = True) -> tuple[Wall, ...]:
    """Walls of :data:`WALL_THICKNESS` along a polyline through ``corners`` [m], closed back to the first by default."""
    points = list(corners) + ([corners[0]] if closed else [])
    return tuple(Wall(points[i], points[i + 1]) for i in range(len(points) - 1))


def primitive(obstacle: Obstacle) -> Box | Cylinder:
    """The obstacle as a box or a cylinder (a wall is the box it occupies)."""
    return obstacle.box if isinstance(obstacle, Wall) else obstacle


def box_array(boxes: Iterable[Box]) -> np.ndarray:
    """Rows ``(cx, cy, hx, hy, cos yaw, sin yaw)`` of the boxes, for :func:`box_distance`."""
    rows = [(*b.center, *b.half_size, math.cos(b.yaw), math.sin(b.yaw)) for b in boxes]
    return np.array(rows, dtype=float).reshape(-1, 6)


def box_distance(points: np.ndarray, boxes: np.ndarray) -> np.ndarray:
    """Signed distance ``(N, M)`` from ``points`` ``(N, 2)`` to the boxes of :func:`box_array` [m]."""
    dx = points[:, None, 0] - boxes[None, :, 0]
    dy = points[:, None, 1] - boxes[None, :, 1]
    c, s = boxes[None, :, 4], boxes[None, :, 5]
    qx = np.abs(c * dx + s * dy) - boxes[None, :, 2]
    qy = np.abs(-s * dx + c * dy) - boxes[None, :, 3]
    outside = np.hypot(np.maximum(qx, 0.0), np.maximum(qy, 0.0))
    return outside + np.minimum(np.maximum(qx, qy), 0.0)


def gap(a: Obstacle, b: Obstacle) -> float:
    """Distance between the outlines of two obstacles [m]; negative when they overlap.

    Exact for every pair of shapes when they are apart. When they overlap the value is
    minus the penetration depth (the shortest translation that separates them).
    """
    a, b = primitive(a), primitive(b)
    if isinstance(a, Cylinder) and isinstance(b, Cylinder):
        return math.hypot(a.center[0] - b.center[0], a.center[1] - b.center[1]) - a.radius - b.radius
    if isinstance(a, Cylinder):
        a, b = b, a
    if isinstance(b, Cylinder):
        return float(a.signed_distance(np.array([b.center]))[0]) - b.radius
    # Two rectangles: the separating-axis test says whether they overlap and by how much;
    # apart, the closest pair is a corner of one and a side of the other.
    corners_a, corners_b = a.corners(), b.corners()
    depth = math.inf
    for yaw in (a.yaw, b.yaw):
        for axis in (np.array([math.cos(yaw), math.sin(yaw)]), np.array([-math.sin(yaw), math.cos(yaw)])):
            pa, pb = corners_a @ axis, corners_b @ axis
            overlap = min(pa.max(), pb.max()) - max(pa.min(), pb.min())
            if overlap <= 0.0:
                return float(min(a.signed_distance(corners_b).min(), b.signed_distance(corners_a).min()))
            depth = min(depth, overlap)
    return -depth


def box_corners(boxes: np.ndarray) -> np.ndarray:
    """``(M, 4, 2)`` the corners, counter-clockwise, of the boxes of :func:`box_array` [m]."""
    local = np.array([(1.0, 1.0), (-1.0, 1.0), (-1.0, -1.0), (1.0, -1.0)])
    x = local[None, :, 0] * boxes[:, None, 2]
    y = local[None, :, 1] * boxes[:, None, 3]
    c, s = boxes[:, None, 4], boxes[:, None, 5]
    return np.stack((boxes[:, None, 0] + c * x - s * y, boxes[:, None, 1] + s * x + c * y), axis=-1)


def _segment_distances(points: np.ndarray, start: np.ndarray, edge: np.ndarray) -> np.ndarray:
    """Distance [m] from ``points`` to the segments ``start`` .. ``start + edge`` (broadcast over the leading axes)."""
    x, y = points[..., 0] - start[..., 0], points[..., 1] - start[..., 1]
    ex, ey = edge[..., 0], edge[..., 1]
    t = np.minimum(np.maximum((x * ex + y * ey) / (ex * ex + ey * ey), 0.0), 1.0)
    return np.hypot(x - t * ex, y - t * ey)


class BoxSides(NamedTuple):
    """The static part of :func:`polygon_gaps` for a set of boxes, computed once per world."""

    boxes: np.ndarray
    """``(M, 6)`` rows of :func:`box_array`."""
    corners: np.ndarray
    """``(M, 4, 2)`` their corners, counter-clockwise [m]."""
    normals: np.ndarray
    """``(M, 4, 2)`` the outward unit normals of their sides (corner ``i`` to ``i + 1``)."""
    radii: np.ndarray
    """``(M,)`` the radii of their circumscribed circles [m]."""

    def take(self, index: np.ndarray) -> BoxSides:
        """The boxes picked by ``index`` (a mask or indices)."""
        return BoxSides(*(array[index] for array in self))


def box_sides(boxes: np.ndarray) -> BoxSides:
    """The corners, side normals and circumscribed radii of the boxes of :func:`box_array`."""
    corners = box_corners(boxes)
    edges = _next_vertex(corners) - corners
    normals = np.stack((edges[..., 1], -edges[..., 0]), axis=-1) / np.hypot(edges[..., 0], edges[..., 1])[..., None]
    return BoxSides(boxes, corners, normals, np.hypot(boxes[:, 2], boxes[:, 3]))


def _next_vertex(polygons: np.ndarray) -> np.ndarray:
    """``polygons`` ``(..., V, 2)`` with every vertex replaced by the next one (``np.roll(-1)`` along ``V``)."""
    return np.concatenate((polygons[..., 1:, :], polygons[..., :1, :]), axis=-2)


def _candidates(polygons: np.ndarray, sides: BoxSides, circles: np.ndarray) -> tuple[BoxSides, np.ndarray]:
    """The obstacles that can be the nearest to one of ``polygons`` (the others cannot change the minimum).

    Seen from circumscribed circles, an obstacle is at least its centre distance less both radii away (less
    than its penetration depth when they overlap), and the nearest is at most the smallest centre distance
    away (both centres lie inside their shapes).
    """
    centre = polygons.mean(axis=1)                                          # (K, 2)
    radius = np.sqrt(((polygons - centre[:, None]) ** 2).sum(axis=2)).max(axis=1)
    box_centres = np.hypot(centre[:, None, 0] - sides.boxes[None, :, 0], centre[:, None, 1] - sides.boxes[None, :, 1])
    circle_centres = np.hypot(centre[:, None, 0] - circles[None, :, 0], centre[:, None, 1] - circles[None, :, 1])
    ceiling = np.minimum(box_centres.min(axis=1, initial=math.inf), circle_centres.min(axis=1, initial=math.inf))
    near_box = np.any(box_centres - sides.radii[None] - radius[:, None] <= ceiling[:, None], axis=0)
    near_circle = np.any(circle_centres - circles[None, :, 2] - radius[:, None] <= ceiling[:, None], axis=0)
    if not near_box.all():
        sides = sides.take(near_box)
    return sides, circles if near_circle.all() else circles[near_circle]


def polygon_gaps(polygons: np.ndarray, boxes: np.ndarray | BoxSides, circles: np.ndarray,
                 compiled: SimpleNamespace | None = None) -> np.ndarray:
    """Exact signed distance ``(K,)`` [m] from each convex polygon to the nearest box or circle.

    Args:
        polygons: ``(K, V, 2)`` convex polygons, counter-clockwise [m].
        boxes: ``(M, 6)`` rows of :func:`box_array`, or their :func:`box_sides` (a world computes them once).
        circles: ``(C, 3)`` rows ``(cx, cy, radius)`` [m].
        compiled: the compiled kernels (:data:`COMPILED_GAPS`), or ``None``: numpy (the reference; the same values).

    Returns:
        Per polygon, the distance to the nearest obstacle when apart, minus the penetration depth (the
        shortest translation that separates them) when they overlap; ``inf`` without obstacles.
    """
    sides = boxes if isinstance(boxes, BoxSides) else box_sides(boxes)
    if compiled is not None:
        return compiled.polygon_gaps(plain(polygons), plain(sides.boxes), plain(sides.corners), plain(sides.normals),
                                     plain(circles))
    if sides.boxes.shape[0] + circles.shape[0] > 1:
        sides, circles = _candidates(polygons, sides, circles)
    start = polygons
    edge = _next_vertex(polygons) - polygons                                # (K, V, 2)
    normal = np.stack((edge[..., 1], -edge[..., 0]), axis=-1) / np.hypot(edge[..., 0], edge[..., 1])[..., None]
    best = np.full(polygons.shape[0], math.inf)
    if sides.boxes.size:
        corners = sides.corners                                             # (M, 4, 2)
        # Separating axes: the polygon's edge normals (the box's corners beyond each edge) and the box's.
        beyond = np.einsum("kvmcd,kvd->kvmc", corners[None, None] - start[:, :, None, None], normal)
        separation = beyond.min(axis=3).max(axis=1)                         # (K, M)
        outside = np.einsum("kvmed,med->kvme", polygons[:, :, None, None] - corners[None, None], sides.normals)
        separation = np.maximum(separation, outside.min(axis=1).max(axis=2))
        # Apart, the nearest pair is a corner of one and a side of the other.
        corner_to_box = box_distance(polygons.reshape(-1, 2), sides.boxes).reshape(polygons.shape[0], -1,
                                                                                   sides.boxes.shape[0]).min(axis=1)
        box_to_polygon = _segment_distances(corners[None, :, :, None], start[:, None, None], edge[:, None, None])
        apart = np.minimum(corner_to_box, box_to_polygon.min(axis=(2, 3)))
        best = np.minimum(best, np.where(separation > 0.0, apart, separation).min(axis=1))
    if circles.size:
        centres = circles[None, None, :, :2]                                # (1, 1, C, 2)
        relative = centres - start[:, :, None]                              # (K, V, C, 2)
        depth = np.einsum("kvcd,kvd->kvc", relative, normal).max(axis=1)    # < 0 inside the polygon
        nearest = _segment_distances(centres, start[:, :, None], edge[:, :, None]).min(axis=1)
        signed = np.where(depth < 0.0, depth, nearest) - circles[None, :, 2]
        best = np.minimum(best, signed.min(axis=1))
    return best


def placed_polygons(poses: np.ndarray, polygon: np.ndarray) -> np.ndarray:
    """``(K, V, 2)`` the base-frame ``polygon`` ``(V, 2)`` at each of ``poses`` ``(K, 3)``, counter-clockwise [m]."""
    polygon = counter_clockwise(polygon)
    poses = np.asarray(poses, dtype=float).reshape(-1, 3)
    c, s = np.cos(poses[:, 2])[:, None], np.sin(poses[:, 2])[:, None]
    return np.stack((poses[:, None, 0] + c * polygon[None, :, 0] - s * polygon[None, :, 1],
                     poses[:, None, 1] + s * polygon[None, :, 0] + c * polygon[None, :, 1]), axis=-1)


class RayFan(NamedTuple):
    """Lidars' rays in a base frame, for :meth:`~safenav.worlds.World.ray_reach`: lidar ``l`` at ``mounts[l] = (x
    [m], y [m], its first beam's angle [rad])``, ``counts[l]`` beams ``increments[l]`` [rad] apart; then every ray,
    the lidars' in order, by its unit ``directions`` ``(R, 2)`` and ``lengths`` ``(R,)`` [m]."""

    mounts: np.ndarray
    increments: np.ndarray
    counts: np.ndarray
    directions: np.ndarray
    lengths: np.ndarray


def _build_gaps() -> SimpleNamespace:
    require("numba", extra="fast", purpose="the compiled kernels (kernels='numba')")
    from safenav.worlds import _compiled_gaps

    kernels = SimpleNamespace(polygon_gaps=_compiled_gaps.polygon_gaps, ray_reach=_compiled_gaps.ray_reach,
                              signed_distance=_compiled_gaps.signed_distance)
    square = np.array([[[0.5, 0.5], [-0.5, 0.5], [-0.5, -0.5], [0.5, -0.5]]])
    sides = box_sides(np.array([[2.0, 0.0, 0.5, 0.5, 1.0, 0.0]]))
    circles = np.array([[0.0, 2.0, 0.3]])
    kernels.polygon_gaps(square, sides.boxes, sides.corners, sides.normals, circles)
    kernels.ray_reach(0.0, 0.0, 0.0, np.zeros((1, 3)), np.array([0.5 * math.pi]), np.array([4], dtype=np.intp),
                      square[0] / math.sqrt(0.5), np.full(4, 5.0), sides.boxes, circles, 0.01)
    kernels.signed_distance(square[0], sides.boxes, circles)
    return kernels


#: The simulator's compiled kernels (:attr:`safenav.sim_bullet.SimConfig.kernels`): the exact clearance of a convex
#: polygon (:func:`polygon_gaps` with ``compiled=``, the footprint truth), of points (``signed_distance``, the disk
#: truth, :meth:`~safenav.worlds.World.signed_distance` with ``compiled=``) and how far each lidar ray must reach
#: (``ray_reach``, which shortens the rays PyBullet casts).
COMPILED_GAPS = KernelGroup(_build_gaps, "the simulator measures clearance with numpy and casts full-length rays "
                                         "(the same values, slower)")

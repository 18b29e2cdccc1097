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
from typing import Any

import numpy as np

from safenav._checks import number, positive, vector
from safenav.errors import InvalidConfig

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

"""The robot's body as the filters see it: one disk, or a cover of the footprint by a few disks.

A barrier on the distance from a point of the body to an obstacle point needs a smooth
distance, and a disk gives one. :class:`BodyModel` describes the body as disks in the
base frame (REP-103, x forward):

* ``BodyModel.disk(robot)``: the circumscribed disk of radius ``robot.radius`` around the
  base origin (the classic model; a point of it needs a look-ahead to be steered, since
  turning in place does not move the origin);
* ``BodyModel.polygon(robot)``: the footprint polygon itself (convex), for the exact
  point-to-polygon barrier (:func:`~safenav.filters.rows.polygon_geometry`): no area excess,
  and the polygon's corners move sideways when the robot turns, so it steers without any
  look-ahead;
* ``BodyModel.cover(robot, n)``: ``n`` equal disks whose centres lie along the base x axis
  (the direction of travel, so that the width the disks add to the footprint's is as small
  as possible in a door), each the circumscribed disk of one ``1/n`` slice of the
  footprint's bounding rectangle. Their union contains the footprint, so keeping every disk ``margin`` away from
  an obstacle point keeps the footprint at least ``margin`` away. Disks off the base origin
  move sideways when the robot turns, so they steer without any look-ahead.

:meth:`BodyModel.boundary` samples the outline (the footprint polygon when there is one,
else the disk) with outward normals, for the unknown-region logic
(:mod:`safenav.filters.perception`).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from safenav import _checks
from safenav._kernels import plain
from safenav.geometry import counter_clockwise, is_convex
from safenav.robot import RobotSpec

__all__ = ["BodyModel", "inside_polygon", "polygon_distance"]

#: Angular spacing of the outline samples [rad] (well below the 5-degree gap bridged by the filters).
BOUNDARY_STEP = math.radians(2.0)


def polygon_distance(polygon: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Signed distance from each point to a convex polygon (negative inside) [m].

    Args:
        polygon: ``(V, 2)`` vertices in order (either orientation) [m].
        points: ``(N, 2)`` points [m].
    """
    points = np.asarray(points, dtype=float).reshape(-1, 2)
    a = np.asarray(polygon, dtype=float)
    b = np.roll(a, -1, axis=0)
    edge = b - a
    length2 = np.maximum(np.einsum("ij,ij->i", edge, edge), 1e-300)
    relative = points[:, None, :] - a[None, :, :]
    t = np.clip(np.einsum("nvi,vi->nv", relative, edge) / length2, 0.0, 1.0)
    nearest = a[None] + t[..., None] * edge[None]
    distance = np.min(np.hypot(*(points[:, None, :] - nearest).transpose(2, 0, 1)), axis=1)
    cross = edge[None, :, 0] * relative[..., 1] - edge[None, :, 1] * relative[..., 0]
    inside = np.all(cross >= 0.0, axis=1) | np.all(cross <= 0.0, axis=1)
    return np.where(inside, -distance, distance)


def inside_polygon(polygon: np.ndarray, points: np.ndarray, compiled: Any = None) -> np.ndarray:
    """Mask of ``points`` ``(N, 2)`` inside ``polygon`` ``(V, 2)`` (any simple polygon; even-odd rule) [m].

    Only the points in the polygon's bounding box are tested edge by edge: a point outside it crosses no edge
    (above, below or to the right) or every edge its row straddles, an even number (to the left).
    ``compiled``: the kernels of :mod:`~safenav.filters.kernels` (the same mask, by one compiled loop).
    """
    points = np.asarray(points, dtype=float).reshape(-1, 2)
    a = np.asarray(polygon, dtype=float)
    if compiled is not None:
        return compiled.inside_polygon(plain(a), plain(points))
    low, high = a.min(axis=0), a.max(axis=0)
    boxed = np.flatnonzero((points[:, 0] >= low[0]) & (points[:, 0] <= high[0]) & (points[:, 1] >= low[1])
                           & (points[:, 1] <= high[1]))
    inside = np.zeros(points.shape[0], dtype=bool)
    if boxed.size:
        inside[boxed] = _even_odd(a, points[boxed])
    return inside


def _even_odd(a: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Even-odd rule of ``points`` ``(N, 2)`` against the polygon ``a`` ``(V, 2)``, every edge for every point."""
    b = np.roll(a, -1, axis=0)
    x, y = points[:, None, 0], points[:, None, 1]
    straddles = (a[None, :, 1] > y) != (b[None, :, 1] > y)
    with np.errstate(divide="ignore", invalid="ignore"):
        crossing_x = a[None, :, 0] + (y - a[None, :, 1]) * (b[None, :, 0] - a[None, :, 0]) / (b[None, :, 1] -
                                                                                            a[None, :, 1])
    return np.count_nonzero(straddles & (x < crossing_x), axis=1) % 2 == 1


def inscribed_radius(robot: RobotSpec) -> float:
    """Radius of the largest disk about the base origin inside the robot's body [m]: its radius for a round
    robot, the distance to the nearest edge of a convex footprint (0 for a concave one)."""
    if robot.footprint is None:
        return float(robot.radius)
    polygon = np.asarray(robot.footprint, dtype=float)
    if not is_convex(counter_clockwise(polygon)):
        return 0.0
    return max(-float(polygon_distance(polygon, np.zeros((1, 2)))[0]), 0.0)


@dataclass(frozen=True, eq=False)
class BodyModel:
    """The body as disks in the base frame, and its outline.

    Attributes:
        centres: ``(D, 2)`` disk centres in the base frame [m].
        radii: ``(D,)`` disk radii [m].
        outline: ``(V, 2)`` the footprint polygon the disks cover, counter-clockwise [m]
            (``None`` for the plain disk model, whose outline is its disk).
        name: ``"disk"`` or ``"cover<n>"``.
    """

    centres: np.ndarray
    radii: np.ndarray
    outline: np.ndarray | None
    name: str

    @classmethod
    def disk(cls, robot: RobotSpec) -> BodyModel:
        """The circumscribed disk of radius ``robot.radius`` around the base origin."""
        return cls(np.zeros((1, 2)), np.array([robot.radius]), None, "disk")

    @classmethod
    def polygon(cls, robot: RobotSpec) -> BodyModel:
        """The footprint polygon (a round robot without one keeps its disk).

        Raises:
            InvalidConfig: the footprint is not convex (the exact barrier needs a convex polygon).
        """
        if robot.footprint is None:
            return cls.disk(robot)
        polygon = counter_clockwise(robot.footprint)
        if not is_convex(polygon):
            raise _checks.InvalidConfig(f"the polygon body model needs a convex footprint, got {robot.footprint!r}; "
                                        "use body='cover' for a concave one")
        return cls(np.zeros((1, 2)), np.array([robot.radius]), polygon, "polygon")

    @classmethod
    def cover(cls, robot: RobotSpec, n_disks: int) -> BodyModel:
        """``n_disks`` equal disks along the base x axis that cover the footprint's bounding rectangle.

        A robot without a footprint (a round robot) keeps its disk.
        """
        n_disks = _checks.integer("n_disks", n_disks, low=1, high=16)
        if robot.footprint is None:
            return cls.disk(robot)
        polygon = counter_clockwise(robot.footprint)
        low, high = polygon.min(axis=0), polygon.max(axis=0)
        size = high - low
        axis = 0
        slices = (np.arange(n_disks) + 0.5) / n_disks
        centres = np.tile(0.5 * (low + high), (n_disks, 1))
        centres[:, axis] = low[axis] + slices * size[axis]
        half = 0.5 * size.copy()
        half[axis] = 0.5 * size[axis] / n_disks
        radius = float(np.hypot(*half))
        return cls(centres, np.full(n_disks, radius), polygon, f"cover{n_disks}")

    @functools.cached_property
    def key(self) -> tuple[bytes, float]:
        """A hashable description of the outline, for caches: the polygon's bytes, or the disk's radius."""
        return (self.outline.tobytes(), 0.0) if self.outline is not None else (b"", float(self.radii[0]))

    @property
    def n_disks(self) -> int:
        return int(self.radii.size)

    @functools.cached_property
    def reach(self) -> float:
        """Largest distance from the base origin to any point of the disks [m]."""
        return float(np.max(np.hypot(self.centres[:, 0], self.centres[:, 1]) + self.radii))

    @property
    def half_width(self) -> float:
        """Largest distance of the body (its polygon, or its disks) from the base's x axis [m]: half the width
        of the narrowest straight corridor it drives along."""
        if self.name == "polygon":
            return float(np.max(np.abs(self.outline[:, 1])))
        return float(np.max(np.abs(self.centres[:, 1]) + self.radii))

    def clearance(self, points: np.ndarray) -> float:
        """Smallest distance from the body (its disks or polygon) to ``points`` ``(N, 2)`` [m] (``inf`` if none)."""
        points = np.asarray(points, dtype=float).reshape(-1, 2)
        if points.shape[0] == 0:
            return math.inf
        if self.name == "polygon":
            return float(polygon_distance(self.outline, points).min())
        gaps = np.hypot(points[:, None, 0] - self.centres[None, :, 0],
                        points[:, None, 1] - self.centres[None, :, 1]) - self.radii[None, :]
        return float(gaps.min())

    def barrier(self, points: np.ndarray, margin: float, uncertainty: np.ndarray | float = 0.0,
                lookahead: float = 0.0) -> float:
        """``H`` [m]: the smallest distance from the body (each disk's centre moved ``lookahead`` [m] ahead and
        its radius grown by it; or the polygon) to ``points`` ``(N, 2)``, less ``margin`` and each point's
        ``uncertainty`` [m] (``inf`` if no point)."""
        points = np.asarray(points, dtype=float).reshape(-1, 2)
        if points.shape[0] == 0:
            return math.inf
        uncertainty = np.broadcast_to(np.asarray(uncertainty, dtype=float), (points.shape[0],))
        if self.name == "polygon":
            return float((polygon_distance(self.outline, points) - margin - uncertainty).min())
        control = self.centres + np.array([lookahead, 0.0])
        distance = np.hypot(points[:, None, 0] - control[None, :, 0], points[:, None, 1] - control[None, :, 1])
        return float((distance - (self.radii[None, :] + lookahead + margin + uncertainty[:, None])).min())

    def outline_clearance(self, points: np.ndarray) -> float:
        """Smallest distance from the outline (footprint polygon, or the disk) to ``points`` [m]."""
        points = np.asarray(points, dtype=float).reshape(-1, 2)
        if points.shape[0] == 0:
            return math.inf
        if self.outline is None:
            return self.clearance(points)
        return float(polygon_distance(self.outline, points).min())

    def boundary(self) -> tuple[np.ndarray, np.ndarray]:
        """Samples of the outline and their outward unit normals, ``(S, 2)`` each [m]."""
        return _boundary(*self.key)

    def area_excess(self) -> float:
        """Area of the disks' union outside the outline, as a fraction of the outline's area."""
        if self.outline is None:
            return 0.0
        low = np.minimum(self.outline.min(axis=0), (self.centres - self.radii[:, None]).min(axis=0))
        high = np.maximum(self.outline.max(axis=0), (self.centres + self.radii[:, None]).max(axis=0))
        step = 0.002
        xs = np.arange(low[0], high[0], step) + 0.5 * step
        ys = np.arange(low[1], high[1], step) + 0.5 * step
        grid = np.stack(np.meshgrid(xs, ys), axis=-1).reshape(-1, 2)
        in_disks = np.any(np.hypot(grid[:, None, 0] - self.centres[None, :, 0],
                                   grid[:, None, 1] - self.centres[None, :, 1]) <= self.radii[None], axis=1)
        in_outline = polygon_distance(self.outline, grid) <= 0.0
        return float(np.count_nonzero(in_disks & ~in_outline)) / max(float(np.count_nonzero(in_outline)), 1.0)


@functools.lru_cache(maxsize=32)
def _boundary(outline_bytes: bytes, radius: float) -> tuple[np.ndarray, np.ndarray]:
    if not outline_bytes:
        angles = np.arange(0.0, 2.0 * math.pi, BOUNDARY_STEP)
        normals = np.column_stack((np.cos(angles), np.sin(angles)))
        points, normals = radius * normals, normals
    else:
        polygon = np.frombuffer(outline_bytes, dtype=float).reshape(-1, 2)
        pieces, piece_normals = [], []
        for a, b in zip(polygon, np.roll(polygon, -1, axis=0), strict=True):
            edge = b - a
            length = float(np.hypot(*edge))
            count = max(2, math.ceil(length / 0.01))
            t = (np.arange(count) + 0.5) / count
            pieces.append(a + t[:, None] * edge)
            piece_normals.append(np.tile(np.array([edge[1], -edge[0]]) / length, (count, 1)))
        points, normals = np.vstack(pieces), np.vstack(piece_normals)
    for array in (points, normals):
        array.flags.writeable = False
    return points, normals

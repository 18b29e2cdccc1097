"""A world as data: obstacles, a start pose and an optional goal, built into a simulator on demand.

Geometry is exact and analytic: :meth:`World.clearance` is the signed distance from the
robot's body disk to the nearest obstacle (negative inside), :meth:`World.scene` gives the
same outlines as a :class:`~safenav.synthetic.Scene` for exact ray casts, and
:func:`obstacle_mesh` the triangle mesh the PyBullet simulator (:mod:`safenav.sim_bullet`)
ray-casts against, while it takes :meth:`World.clearance` as its truth.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass
from types import SimpleNamespace
from typing import Any

import numpy as np

from safenav._checks import positive, vector
from safenav._kernels import plain
from safenav.errors import InvalidConfig
from safenav.geometry import Pose2D
from safenav.synthetic import Circle, Scene, Segment
from safenav.worlds.shapes import (
    Box,
    BoxSides,
    Cylinder,
    Obstacle,
    RayFan,
    Wall,
    box_array,
    box_distance,
    box_sides,
    placed_polygons,
    polygon_gaps,
    primitive,
)

__all__ = ["World", "obstacle_mesh"]


@dataclass(frozen=True)
class World:
    """Obstacles, a start pose and an optional goal: everything a simulator needs to build a scene.

    Attributes:
        name: a label (the tutorial name, or ``"random-<seed>"``).
        obstacles: boxes, cylinders and walls.
        start: initial pose of the robot base [m, m, rad].
        goal: goal position [m], for goal-reaching tasks.
        bounds: ``(xmin, ymin, xmax, ymax)`` of the region to draw [m]; by default the
            obstacles, start and goal with a 0.5 m margin.
        obstacle_height: height of every obstacle [m]; the lidar must scan below it.
    """

    name: str
    obstacles: tuple[Obstacle, ...]
    start: Pose2D = Pose2D()
    goal: tuple[float, float] | None = None
    bounds: tuple[float, float, float, float] | None = None
    obstacle_height: float = 0.5

    def __post_init__(self) -> None:
        if not isinstance(self.name, str):
            raise InvalidConfig(f"World.name must be a string, got {self.name!r}")
        obstacles = tuple(self.obstacles)
        for obstacle in obstacles:
            if not isinstance(obstacle, (Box, Cylinder, Wall)):
                raise InvalidConfig(f"World.obstacles must hold Box, Cylinder or Wall, got {obstacle!r}")
        object.__setattr__(self, "obstacles", obstacles)
        start = vector("World.start", self.start, 3, expected="a pose (x [m], y [m], yaw [rad])")
        object.__setattr__(self, "start", Pose2D(*start))
        if self.goal is not None:
            x, y = vector("World.goal", self.goal, 2, expected="a pair (x, y) of finite numbers [m]")
            object.__setattr__(self, "goal", (x, y))
        object.__setattr__(self, "obstacle_height", positive("World.obstacle_height", self.obstacle_height))
        if self.bounds is None:
            object.__setattr__(self, "bounds", self._default_bounds())
        else:
            xmin, ymin, xmax, ymax = vector("World.bounds", self.bounds, 4, expected="(xmin, ymin, xmax, ymax) [m]")
            if xmax <= xmin or ymax <= ymin:
                raise InvalidConfig(f"World.bounds must have xmax > xmin and ymax > ymin, got {self.bounds!r}")
            object.__setattr__(self, "bounds", (xmin, ymin, xmax, ymax))

    def _default_bounds(self, margin: float = 0.5) -> tuple[float, float, float, float]:
        points = [np.array([self.start[:2]])]
        if self.goal is not None:
            points.append(np.array([self.goal]))
        for obstacle in self.obstacles:
            shape = primitive(obstacle)
            if isinstance(shape, Cylinder):
                points.append(np.array(shape.center) + shape.radius * np.array([[1, 1], [-1, -1]]))
            else:
                points.append(shape.corners())
        stacked = np.vstack(points)
        low, high = stacked.min(axis=0) - margin, stacked.max(axis=0) + margin
        return (float(low[0]), float(low[1]), float(high[0]), float(high[1]))

    # ------------------------------------------------------------------ geometry

    @functools.cached_property
    def _boxes(self) -> np.ndarray:
        return box_array(primitive(o) for o in self.obstacles if not isinstance(o, Cylinder))

    @functools.cached_property
    def _box_sides(self) -> BoxSides:
        return box_sides(self._boxes)

    @functools.cached_property
    def _circles(self) -> np.ndarray:
        rows = [(*o.center, o.radius) for o in self.obstacles if isinstance(o, Cylinder)]
        return np.array(rows, dtype=float).reshape(-1, 3)

    def signed_distance(self, points: np.ndarray, compiled: SimpleNamespace | None = None) -> np.ndarray:
        """Signed distance from each of ``points`` ``(N, 2)`` to the nearest obstacle [m].

        Negative inside an obstacle; ``inf`` in a world without obstacles. ``compiled``: the compiled kernels
        (:data:`~safenav.worlds.shapes.COMPILED_GAPS`), or ``None``: numpy (the same values).
        """
        p = np.asarray(points, dtype=float).reshape(-1, 2)
        if compiled is not None:
            return compiled.signed_distance(plain(p), self._boxes, self._circles)
        best = np.full(p.shape[0], math.inf)
        if self._boxes.size:
            best = np.minimum(best, box_distance(p, self._boxes).min(axis=1))
        circles = self._circles
        if circles.size:
            distance = np.hypot(p[:, None, 0] - circles[None, :, 0], p[:, None, 1] - circles[None, :, 1])
            best = np.minimum(best, (distance - circles[None, :, 2]).min(axis=1))
        return best

    def clearance(self, pose: Pose2D | Sequence[float], radius: float, compiled: SimpleNamespace | None = None
                  ) -> float:
        """Exact signed clearance of the body disk to the nearest obstacle [m].

        Args:
            pose: the base pose, or just its position ``(x, y)`` [m].
            radius: radius of the body disk [m].
            compiled: the compiled kernels (:data:`~safenav.worlds.shapes.COMPILED_GAPS`), or ``None``: numpy
                (the same value).

        Returns:
            Distance from the disk to the nearest obstacle [m]: negative when the disk
            overlaps an obstacle (minus the depth), ``inf`` in a world without obstacles.
        """
        return float(self.signed_distance(np.array([[pose[0], pose[1]]], dtype=float), compiled)[0]) - radius

    def footprint_clearance(self, poses: np.ndarray, footprint: np.ndarray,
                            compiled: SimpleNamespace | None = None) -> np.ndarray:
        """Exact signed clearance [m] of a convex footprint at each of ``poses`` to the nearest obstacle.

        Args:
            poses: ``(K, 3)`` base poses ``(x, y, yaw)`` [m, m, rad].
            footprint: ``(V, 2)`` the convex body polygon in the base frame [m], either orientation.
            compiled: the compiled kernels (:data:`~safenav.worlds.shapes.COMPILED_GAPS`), or ``None``: numpy
                (the same values).

        Returns:
            ``(K,)`` distances from the polygon to the nearest obstacle [m]: negative when it overlaps one
            (minus the penetration depth), ``inf`` in a world without obstacles.
        """
        return polygon_gaps(placed_polygons(poses, footprint), self._box_sides, self._circles, compiled)

    def ray_reach(self, pose: Pose2D, rays: RayFan, compiled: SimpleNamespace, slack: float = 0.01) -> np.ndarray:
        """How far [m] each ray of a base at ``pose`` must reach to meet the first obstacle it meets, plus ``slack``.

        Args:
            pose: the base pose [m, m, rad].
            rays: the lidars' rays in the base frame (:class:`~safenav.worlds.shapes.RayFan`).
            compiled: the compiled kernels (:data:`~safenav.worlds.shapes.COMPILED_GAPS`).
            slack: added to each first meeting [m] (the cast a ray of that length makes must meet it).

        Returns:
            ``(R,)`` per ray the distance to the exact box or circle it first meets plus ``slack``, or its full
            length when that is shorter, when it meets nothing, or when its lidar sits inside an obstacle.
        """
        return compiled.ray_reach(float(pose.x), float(pose.y), float(pose.yaw), rays.mounts, rays.increments,
                                  rays.counts, rays.directions, rays.lengths, self._boxes, self._circles, float(slack))

    def scene(self) -> Scene:
        """The obstacle outlines as a :class:`~safenav.synthetic.Scene` for exact analytic ray casts.

        Boxes and walls become their four sides, cylinders their exact circles.
        """
        return self._scene

    @functools.cached_property
    def _scene(self) -> Scene:
        segments: list[Segment] = []
        circles: list[Circle] = []
        for obstacle in self.obstacles:
            shape = primitive(obstacle)
            if isinstance(shape, Cylinder):
                circles.append(Circle(shape.center, shape.radius))
            else:
                corners = [tuple(map(float, c)) for c in shape.corners()]
                segments.extend(Segment(corners[i], corners[(i + 1) % 4]) for i in range(4))
        return Scene(tuple(segments), tuple(circles))

    def replace(self, **changes: Any) -> World:
        """A copy with some fields changed (validated), as :func:`dataclasses.replace`.

        ``bounds`` is kept unless changed.
        """
        return dataclasses.replace(self, **changes)


def obstacle_mesh(world: World, *, height: float | None = None, tolerance: float = 0.001,
                  caps: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """The obstacles of ``world`` as one triangle mesh of vertical prisms.

    Args:
        world: the world.
        height: height of the prisms [m]; ``world.obstacle_height`` by default.
        tolerance: largest distance between a cylinder and its circumscribed polygon [m].
        caps: include the top and bottom faces (for drawing; horizontal rays never hit them).

    Returns:
        ``(vertices, indices)``: an ``(N, 3)`` float array [m] and an ``(M, 3)`` int array of
        triangles, counter-clockwise seen from outside.
    """
    top = world.obstacle_height if height is None else height
    vertices: list[np.ndarray] = []
    triangles: list[np.ndarray] = []
    offset = 0
    for obstacle in world.obstacles:
        outline = obstacle.polygon(tolerance)
        n = len(outline)
        vertices.append(np.column_stack((np.vstack((outline, outline)), np.repeat([0.0, top], n))))
        i = np.arange(n)
        j = (i + 1) % n
        sides = np.concatenate((np.column_stack((i, j, j + n)), np.column_stack((i, j + n, i + n))))
        faces = [sides]
        if caps:
            k = np.arange(1, n - 1)
            faces.append(np.column_stack((np.zeros(n - 2, dtype=int), k + 1, k)))
            faces.append(np.column_stack((np.full(n - 2, n), n + k, n + k + 1)))
        triangles.append(np.concatenate(faces) + offset)
        offset += 2 * n
    if not vertices:
        return np.empty((0, 3)), np.empty((0, 3), dtype=int)
    return np.concatenate(vertices), np.concatenate(triangles).astype(int)

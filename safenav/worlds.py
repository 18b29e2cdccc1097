"""Worlds as data: obstacles, a start pose and an optional goal, built into a simulator on demand.

A :class:`World` holds planar obstacles, each a vertical prism standing on the
floor:

* :class:`Box`: a rectangle of ``size`` around ``center``, turned by ``yaw``;
* :class:`Cylinder`: a disk of ``radius`` around ``center``;
* :class:`Wall`: a rectangle of ``thickness`` centred on the segment from
  ``start`` to ``end`` and squared off half a thickness past both ends, so walls
  that share an end point close the corner without a gap.

Geometry is exact and analytic: :meth:`World.clearance` is the signed distance
from the robot's body disk to the nearest obstacle (negative inside), and
:meth:`World.scene` gives the same outlines as a :class:`~safenav.synthetic.Scene`
for exact ray casts. The PyBullet simulator (:mod:`safenav.sim_bullet`) builds the
world into a triangle mesh and uses :meth:`World.clearance` as its truth.

Two sources of worlds:

* :func:`tutorial_world`: the worlds of the three classic tutorials,
  ``"stop_at_wall"`` (ROSbot), ``"obstacle_avoidance"`` (Puzzlebot) and
  ``"wall_follower"`` (m2wr); :data:`TUTORIAL_PRESETS` names the robot of each;
* :func:`random_world`: a seeded random arena with obstacles of mixed shapes,
  corridors and narrow passages, a collision-free start and a reachable goal.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import numbers
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any

import numpy as np
from scipy import ndimage

from safenav.errors import InvalidConfig, UnknownName
from safenav.geometry import Pose2D
from safenav.robot import RobotSpec
from safenav.synthetic import Circle, Scene, Segment

__all__ = [
    "TUTORIAL_PRESETS",
    "TUTORIAL_WORLDS",
    "Box",
    "Cylinder",
    "Obstacle",
    "Wall",
    "World",
    "gap",
    "random_world",
    "reachable",
    "tutorial_world",
]

TUTORIAL_WORLDS = ("stop_at_wall", "obstacle_avoidance", "wall_follower")
"""Names of the tutorial worlds, in the order of the presets ``rosbot``, ``puzzlebot``, ``m2wr``."""

TUTORIAL_PRESETS: Mapping[str, str] = MappingProxyType(
    {"stop_at_wall": "rosbot", "obstacle_avoidance": "puzzlebot", "wall_follower": "m2wr"}
)
"""The robot preset each tutorial world was made for."""

WALL_THICKNESS = 0.1
"""Thickness of the walls the world builders make [m]."""

START_CLEARANCE = 0.3
"""Body clearance that :func:`random_world` keeps free around the start and the goal [m]."""

GRID_RESOLUTION = 0.04
"""Cell size of the grid on which :func:`random_world` checks that the goal is reachable [m]."""


# ---------------------------------------------------------------------------------------------- validation


def _real(owner: str, name: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, numbers.Real) or not math.isfinite(value):
        raise InvalidConfig(f"{owner}.{name} must be a finite number, got {value!r}")
    return float(value)


def _positive(owner: str, name: str, value: Any) -> float:
    result = _real(owner, name, value)
    if result <= 0.0:
        raise InvalidConfig(f"{owner}.{name} must be > 0, got {value!r}")
    return result


def _pair(owner: str, name: str, value: Any) -> tuple[float, float]:
    if isinstance(value, (str, bytes)) or not isinstance(value, (Sequence, np.ndarray)) or len(value) != 2:
        raise InvalidConfig(f"{owner}.{name} must be a pair (x, y) of finite numbers [m], got {value!r}")
    return (_real(owner, f"{name}[0]", value[0]), _real(owner, f"{name}[1]", value[1]))


def _count(name: str, value: Any) -> int:
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < 0:
        raise InvalidConfig(f"random_world: {name} must be an integer >= 0, got {value!r}")
    return int(value)


# ---------------------------------------------------------------------------------------------- obstacles


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
        object.__setattr__(self, "center", _pair("Box", "center", self.center))
        size = _pair("Box", "size", self.size)
        if min(size) <= 0.0:
            raise InvalidConfig(f"Box.size must be two lengths > 0 [m], got {self.size!r}")
        object.__setattr__(self, "size", size)
        object.__setattr__(self, "yaw", _real("Box", "yaw", self.yaw))

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
        return _box_array((self,))

    def polygon(self, tolerance: float = 0.0) -> np.ndarray:
        """The outline as a counter-clockwise ``(4, 2)`` polygon [m] (exact; ``tolerance`` is unused)."""
        return self.corners().copy()

    def signed_distance(self, points: np.ndarray) -> np.ndarray:
        """Signed distance from each of ``points`` ``(N, 2)`` to the rectangle [m], negative inside."""
        return _box_distance(np.asarray(points, dtype=float).reshape(-1, 2), self._row)[:, 0]

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
        object.__setattr__(self, "center", _pair("Cylinder", "center", self.center))
        object.__setattr__(self, "radius", _positive("Cylinder", "radius", self.radius))

    def polygon(self, tolerance: float = 0.001) -> np.ndarray:
        """The circumscribed regular polygon that lies within ``tolerance`` of the circle, ``(n, 2)`` [m].

        The polygon contains the disk (its edges touch the circle at their midpoints) and
        its vertices lie ``radius * (1 / cos(pi / n) - 1) <= tolerance`` outside it, so a ray
        cast against the polygon reads at most ``tolerance`` short of the true circle and
        never long. ``n`` is the smallest count that meets the tolerance, between 12 and 256.

        Args:
            tolerance: largest distance between the polygon and the circle [m], > 0.
        """
        tolerance = _positive("Cylinder.polygon", "tolerance", tolerance)
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
        object.__setattr__(self, "start", _pair("Wall", "start", self.start))
        object.__setattr__(self, "end", _pair("Wall", "end", self.end))
        object.__setattr__(self, "thickness", _positive("Wall", "thickness", self.thickness))
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
"""Any obstacle a :class:`World` can hold."""


def _primitive(obstacle: Obstacle) -> Box | Cylinder:
    return obstacle.box if isinstance(obstacle, Wall) else obstacle


def _box_array(boxes: Iterable[Box]) -> np.ndarray:
    """Rows ``(cx, cy, hx, hy, cos yaw, sin yaw)`` of the boxes."""
    rows = [(*b.center, *b.half_size, math.cos(b.yaw), math.sin(b.yaw)) for b in boxes]
    return np.array(rows, dtype=float).reshape(-1, 6)


def _box_distance(points: np.ndarray, boxes: np.ndarray) -> np.ndarray:
    """Signed distance ``(N, M)`` from ``points`` ``(N, 2)`` to the boxes of :func:`_box_array` [m]."""
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
    a, b = _primitive(a), _primitive(b)
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


# ---------------------------------------------------------------------------------------------- world


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
        start = self.start
        if isinstance(start, (str, bytes)) or not isinstance(start, Sequence) or len(start) != 3:
            raise InvalidConfig(f"World.start must be a pose (x [m], y [m], yaw [rad]), got {start!r}")
        start = Pose2D(*(_real("World", f"start.{k}", v) for k, v in zip(Pose2D._fields, start, strict=True)))
        object.__setattr__(self, "start", start)
        if self.goal is not None:
            object.__setattr__(self, "goal", _pair("World", "goal", self.goal))
        object.__setattr__(self, "obstacle_height", _positive("World", "obstacle_height", self.obstacle_height))
        if self.bounds is None:
            object.__setattr__(self, "bounds", self._default_bounds())
        else:
            bounds = self.bounds
            if isinstance(bounds, (str, bytes)) or not isinstance(bounds, Sequence) or len(bounds) != 4:
                raise InvalidConfig(f"World.bounds must be (xmin, ymin, xmax, ymax) [m], got {bounds!r}")
            xmin, ymin, xmax, ymax = (_real("World", f"bounds[{i}]", v) for i, v in enumerate(bounds))
            if xmax <= xmin or ymax <= ymin:
                raise InvalidConfig(f"World.bounds must have xmax > xmin and ymax > ymin, got {bounds!r}")
            object.__setattr__(self, "bounds", (xmin, ymin, xmax, ymax))

    def _default_bounds(self, margin: float = 0.5) -> tuple[float, float, float, float]:
        points = [np.array([self.start[:2]])]
        if self.goal is not None:
            points.append(np.array([self.goal]))
        for obstacle in self.obstacles:
            primitive = _primitive(obstacle)
            if isinstance(primitive, Cylinder):
                points.append(np.array(primitive.center) + primitive.radius * np.array([[1, 1], [-1, -1]]))
            else:
                points.append(primitive.corners())
        stacked = np.vstack(points)
        low, high = stacked.min(axis=0) - margin, stacked.max(axis=0) + margin
        return (float(low[0]), float(low[1]), float(high[0]), float(high[1]))

    # ------------------------------------------------------------------ geometry

    @functools.cached_property
    def _boxes(self) -> np.ndarray:
        return _box_array(_primitive(o) for o in self.obstacles if not isinstance(o, Cylinder))

    @functools.cached_property
    def _circles(self) -> np.ndarray:
        rows = [(*o.center, o.radius) for o in self.obstacles if isinstance(o, Cylinder)]
        return np.array(rows, dtype=float).reshape(-1, 3)

    def signed_distance(self, points: np.ndarray) -> np.ndarray:
        """Signed distance from each of ``points`` ``(N, 2)`` to the nearest obstacle [m].

        Negative inside an obstacle; ``inf`` in a world without obstacles.
        """
        p = np.asarray(points, dtype=float).reshape(-1, 2)
        best = np.full(p.shape[0], math.inf)
        if self._boxes.size:
            best = np.minimum(best, _box_distance(p, self._boxes).min(axis=1))
        circles = self._circles
        if circles.size:
            distance = np.hypot(p[:, None, 0] - circles[None, :, 0], p[:, None, 1] - circles[None, :, 1])
            best = np.minimum(best, (distance - circles[None, :, 2]).min(axis=1))
        return best

    def clearance(self, pose: Pose2D | Sequence[float], radius: float) -> float:
        """Exact signed clearance of the body disk to the nearest obstacle [m].

        Args:
            pose: the base pose, or just its position ``(x, y)`` [m].
            radius: radius of the body disk [m].

        Returns:
            Distance from the disk to the nearest obstacle [m]: negative when the disk
            overlaps an obstacle (minus the depth), ``inf`` in a world without obstacles.
        """
        return float(self.signed_distance(np.array([[pose[0], pose[1]]]))[0]) - radius

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
            primitive = _primitive(obstacle)
            if isinstance(primitive, Cylinder):
                circles.append(Circle(primitive.center, primitive.radius))
            else:
                corners = [tuple(map(float, c)) for c in primitive.corners()]
                segments.extend(Segment(corners[i], corners[(i + 1) % 4]) for i in range(4))
        return Scene(tuple(segments), tuple(circles))

    def replace(self, **changes: Any) -> World:
        """A copy with some fields changed (validated), as :func:`dataclasses.replace`.

        ``bounds`` is kept unless changed.
        """
        return dataclasses.replace(self, **changes)


# ---------------------------------------------------------------------------------------------- tutorials


def _room(*corners: tuple[float, float], closed: bool = True) -> tuple[Wall, ...]:
    """Walls along a polyline through ``corners`` [m], closed back to the first corner by default."""
    points = list(corners) + ([corners[0]] if closed else [])
    return tuple(Wall(points[i], points[i + 1]) for i in range(len(points) - 1))


def tutorial_world(name: str) -> World:
    """The world of one of the three classic tutorials.

    * ``"stop_at_wall"`` (ROSbot): the robot at the origin faces +x; the near face of a
      4 m wide wall is 3 m ahead. Nothing else is in range, so side and rear beams read ``+inf``.
    * ``"obstacle_avoidance"`` (Puzzlebot): a walled 6 x 6 m arena, interior ``[-3, 3]^2``,
      with three boxes and three cylinders; the robot starts in a corner facing the middle.
    * ``"wall_follower"`` (m2wr): an L-shaped room (10 x 10 m with the 5 x 5 m top-right
      quarter cut away). Following the wall on its right, the robot turns left at the five
      inside corners and right round the outside corner at (5, 5), about 16 m along the
      wall from the start. It starts 0.8 m from the bottom wall, heading +x with that wall
      on its right.

    :data:`TUTORIAL_PRESETS` names the robot of each world.

    Raises:
        UnknownName: ``name`` is not a tutorial world (the message lists them).
    """
    if name == "stop_at_wall":
        face = 3.0
        wall = Wall((face + 0.5 * WALL_THICKNESS, -2.0), (face + 0.5 * WALL_THICKNESS, 2.0))
        return World("stop_at_wall", (wall,), start=Pose2D(0.0, 0.0, 0.0), bounds=(-1.0, -2.5, 3.6, 2.5))
    if name == "obstacle_avoidance":
        half = 3.0 + 0.5 * WALL_THICKNESS
        arena = _room((-half, -half), (half, -half), (half, half), (-half, half))
        obstacles = (
            Cylinder((0.0, 0.0), 0.35),
            Box((1.6, 1.1), (0.6, 0.4), yaw=0.4),
            Box((-1.3, 1.5), (0.5, 0.5)),
            Cylinder((1.3, -1.6), 0.25),
            Cylinder((-1.6, -0.2), 0.2),
            Box((0.3, 2.1), (1.0, 0.3)),
        )
        return World("obstacle_avoidance", arena + obstacles, start=Pose2D(-2.2, -2.2, math.pi / 4),
                     bounds=(-3.4, -3.4, 3.4, 3.4))
    if name == "wall_follower":
        room = _room((0.0, 0.0), (10.0, 0.0), (10.0, 5.0), (5.0, 5.0), (5.0, 10.0), (0.0, 10.0))
        return World("wall_follower", room, start=Pose2D(2.0, 0.8, 0.0), bounds=(-0.6, -0.6, 10.6, 10.6))
    raise UnknownName("tutorial world", name, TUTORIAL_WORLDS)


# ---------------------------------------------------------------------------------------------- random


class _Placer:
    """Accepts obstacles one by one if they keep a gap to everything placed so far."""

    def __init__(self, min_gap: float) -> None:
        self.min_gap = min_gap
        self.obstacles: list[Obstacle] = []
        self._primitives: list[Box | Cylinder] = []
        self._reach: list[tuple[float, float, float]] = []   # centre and circumscribed radius

    def fits(self, candidate: Obstacle) -> bool:
        primitive = _primitive(candidate)
        cx, cy = primitive.center
        reach = primitive.radius
        for other, (ox, oy, oreach) in zip(self._primitives, self._reach, strict=True):
            if math.hypot(cx - ox, cy - oy) - reach - oreach >= self.min_gap:
                continue
            if gap(primitive, other) < self.min_gap:
                return False
        return True

    def add(self, *obstacles: Obstacle) -> None:
        for obstacle in obstacles:
            primitive = _primitive(obstacle)
            self.obstacles.append(obstacle)
            self._primitives.append(primitive)
            self._reach.append((*primitive.center, primitive.radius))


def random_world(
    seed: int,
    robot: RobotSpec,
    *,
    n_obstacles: int = 30,
    size: tuple[float, float] = (10.0, 10.0),
    min_gap: float | None = None,
    corridors: int = 0,
    narrow_passages: int = 0,
    goal: bool = False,
    obstacle_size: tuple[float, float] = (0.2, 0.8),
    max_tries: int = 2000,
) -> World:
    """A seeded random arena: walls around, obstacles of mixed shapes, corridors and narrow passages.

    The arena's free interior is ``[-w/2, w/2] x [-h/2, h/2]`` for ``size = (w, h)``,
    closed by walls. The builder places, in this order, all from one
    ``np.random.default_rng(seed)`` so the same arguments give the same world:

    1. ``narrow_passages`` dividing walls across the longer side, evenly spaced (with
       jitter), each with one door ``2 * robot.radius + U(0.12, 0.3)`` m wide;
    2. ``corridors`` corridors: two parallel walls ``U(1.5, 3)`` m long (at most half the
       shorter side) with ``2 * robot.radius + U(0.25, 0.5)`` m between them, at a random
       position and heading;
    3. the start pose (random position and heading) with at least
       :data:`START_CLEARANCE` of body clearance, in the first strip when there are
       dividers; with ``goal=True`` the goal, as clear, at least half the shorter side away
       from the start (in the last strip when there are dividers);
    4. ``n_obstacles`` obstacles, each a box (sides ``U(*obstacle_size)``, random yaw) or a
       cylinder (diameter ``U(*obstacle_size)``) with equal odds, that keep the start and
       goal clear.

    Every obstacle keeps at least ``min_gap`` from every other obstacle and wall (the two
    walls of a corridor, and a divider where it meets the arena, excepted), so with the
    default ``min_gap`` the robot fits between any two obstacles. The obstacle density is
    ``n_obstacles / (w * h)``; ``obstacle_size`` sets how much of the floor they cover.
    With ``goal=True`` the goal is checked to be reachable by the body disk (a 4-connected
    path on a :data:`GRID_RESOLUTION` grid whose cells keep half a cell of clearance); a
    world that fails the check is drawn again from the same generator.

    Args:
        seed: seed of the generator [integer >= 0].
        robot: the robot the world is for (its radius sets gaps, doors and clearances).
        n_obstacles: number of free-standing obstacles.
        size: free interior ``(w, h)`` of the arena [m].
        min_gap: smallest free gap between two obstacles or an obstacle and a wall [m];
            default ``2 * robot.radius + 0.1``.
        corridors: number of corridors.
        narrow_passages: number of dividing walls, each with a narrow door.
        goal: whether to place a reachable goal.
        obstacle_size: smallest and largest obstacle extent (box side, cylinder diameter) [m].
        max_tries: random placements tried per item before giving up.

    Returns:
        The world, named ``"random-<seed>"``.

    Raises:
        InvalidConfig: an argument is out of range, or the items do not fit (the message
            says which and what to change).
    """
    if isinstance(seed, bool) or not isinstance(seed, numbers.Integral) or seed < 0:
        raise InvalidConfig(f"random_world: seed must be an integer >= 0, got {seed!r}")
    if not isinstance(robot, RobotSpec):
        raise InvalidConfig(f"random_world: robot must be a RobotSpec, got {robot!r}")
    n_obstacles = _count("n_obstacles", n_obstacles)
    corridors = _count("corridors", corridors)
    narrow_passages = _count("narrow_passages", narrow_passages)
    max_tries = _count("max_tries", max_tries) or 1
    width, height = _pair("random_world", "size", size)
    radius = robot.radius
    if min(width, height) < 4.0 * radius + 2.0 * START_CLEARANCE:
        raise InvalidConfig(f"random_world: size must be at least {4.0 * radius + 2.0 * START_CLEARANCE:.2f} m "
                            f"on each side for robot {robot.name!r}, got {size!r}")
    min_gap = 2.0 * radius + 0.1 if min_gap is None else _real("random_world", "min_gap", min_gap)
    if min_gap < 0.0:
        raise InvalidConfig(f"random_world: min_gap must be >= 0 [m], got {min_gap!r}")
    smallest, largest = _pair("random_world", "obstacle_size", obstacle_size)
    if not 0.0 < smallest <= largest:
        raise InvalidConfig(f"random_world: obstacle_size must be (smallest, largest) with 0 < smallest <= largest "
                            f"[m], got {obstacle_size!r}")
    if narrow_passages:
        strip = max(width, height) / (narrow_passages + 1)
        needed = 2.0 * max(min_gap, 2.0 * (radius + START_CLEARANCE)) + WALL_THICKNESS
        if strip < needed:
            raise InvalidConfig(f"random_world: {narrow_passages} narrow passages leave strips of {strip:.2f} m; "
                                f"expected at least {needed:.2f} m (fewer passages or a larger size)")
    rng = np.random.default_rng(int(seed))
    for _ in range(20):
        world = _draw_world(rng, int(seed), robot, n_obstacles, width, height, min_gap, corridors, narrow_passages,
                            goal, (smallest, largest), max_tries)
        if world.goal is None or reachable(world, radius, world.start, world.goal):
            return world
    raise InvalidConfig(f"random_world: no reachable goal in 20 worlds drawn with seed {seed}; "
                        f"min_gap={min_gap!r} may be too small for robot radius {radius!r}")


def _draw_world(rng: np.random.Generator, seed: int, robot: RobotSpec, n_obstacles: int, width: float,
                height: float, min_gap: float, corridors: int, narrow_passages: int, with_goal: bool,
                obstacle_size: tuple[float, float], max_tries: int) -> World:
    radius = robot.radius
    t = WALL_THICKNESS
    hx, hy = 0.5 * width, 0.5 * height
    placer = _Placer(min_gap)
    arena = _room((-hx - 0.5 * t, -hy - 0.5 * t), (hx + 0.5 * t, -hy - 0.5 * t),
                  (hx + 0.5 * t, hy + 0.5 * t), (-hx - 0.5 * t, hy + 0.5 * t))
    placer.add(*arena)

    # 1. Dividers across the longer side (x when width >= height), each with a narrow door.
    along_x = width >= height
    long_half, short_half = (hx, hy) if along_x else (hy, hx)
    strip = 2.0 * long_half / (narrow_passages + 1)

    def oriented(u: float, v: float) -> tuple[float, float]:
        return (u, v) if along_x else (v, u)

    dividers: list[float] = []
    for i in range(narrow_passages):
        u = -long_half + strip * (i + 1) + rng.uniform(-0.1, 0.1) * strip
        door = 2.0 * radius + rng.uniform(0.12, 0.3)
        limit = short_half - 0.5 * door - t
        v = 0.8 * rng.uniform(-limit, limit)
        low = Wall(oriented(u, -short_half), oriented(u, v - 0.5 * door - 0.5 * t))
        high = Wall(oriented(u, v + 0.5 * door + 0.5 * t), oriented(u, short_half))
        placer.add(low, high)
        dividers.append(u)

    # 2. Corridors: two parallel walls at a random place and heading.
    for i in range(corridors):
        for _ in range(max_tries):
            length = rng.uniform(1.5, 3.0) * min(1.0, min(width, height) / 6.0)
            inner = 2.0 * radius + rng.uniform(0.25, 0.5)
            yaw = rng.uniform(0.0, math.pi)
            cx, cy = rng.uniform(-hx, hx), rng.uniform(-hy, hy)
            c, s = math.cos(yaw), math.sin(yaw)
            offset = 0.5 * (inner + t)
            half_length = 0.5 * (length - t)
            pair = tuple(
                Wall((cx - c * half_length - s * side, cy - s * half_length + c * side),
                     (cx + c * half_length - s * side, cy + s * half_length + c * side))
                for side in (offset, -offset)
            )
            if all(placer.fits(w) for w in pair):
                placer.add(*pair)
                break
        else:
            raise InvalidConfig(f"random_world: could not place corridor {i + 1} of {corridors} in "
                                f"{width:g} x {height:g} m with min_gap={min_gap:g} m after {max_tries} tries")

    # 3. Start (and goal) with clearance, in the first (and last) strip when there are dividers.
    structure = World("structure", tuple(placer.obstacles))

    def free_point(what: str, low_u: float, high_u: float, away_from: tuple[float, float] | None) -> np.ndarray:
        margin = radius + START_CLEARANCE
        for _ in range(max_tries):
            point = np.array(oriented(rng.uniform(low_u + margin, high_u - margin),
                                      rng.uniform(-short_half + margin, short_half - margin)))
            if structure.clearance(point, radius) < START_CLEARANCE:
                continue
            if away_from is not None and math.dist(point, away_from) < 0.5 * min(width, height):
                continue
            return point
        raise InvalidConfig(f"random_world: no free {what} in {width:g} x {height:g} m after {max_tries} tries")

    first_strip = (-long_half, dividers[0] - 0.5 * t) if dividers else (-long_half, long_half)
    last_strip = (dividers[-1] + 0.5 * t, long_half) if dividers else (-long_half, long_half)
    start_xy = free_point("start", *first_strip, None)
    start = Pose2D(float(start_xy[0]), float(start_xy[1]), float(rng.uniform(-math.pi, math.pi)))
    goal_xy = free_point("goal", *last_strip, (start.x, start.y)) if with_goal else None
    keep_clear = [start_xy] + ([goal_xy] if goal_xy is not None else [])

    # 4. Free-standing obstacles of mixed shapes.
    smallest, largest = obstacle_size
    for i in range(n_obstacles):
        for _ in range(max_tries):
            center = (float(rng.uniform(-hx, hx)), float(rng.uniform(-hy, hy)))
            candidate: Obstacle
            if rng.random() < 0.5:
                candidate = Box(center, (float(rng.uniform(smallest, largest)), float(rng.uniform(smallest, largest))),
                                yaw=float(rng.uniform(0.0, math.pi)))
            else:
                candidate = Cylinder(center, 0.5 * float(rng.uniform(smallest, largest)))
            if any(candidate.signed_distance(np.array([p]))[0] < radius + START_CLEARANCE for p in keep_clear):
                continue
            if placer.fits(candidate):
                placer.add(candidate)
                break
        else:
            raise InvalidConfig(
                f"random_world: could not place obstacle {i + 1} of {n_obstacles} in {width:g} x {height:g} m with "
                f"min_gap={min_gap:g} m after {max_tries} tries; lower n_obstacles, obstacle_size or min_gap"
            )

    margin = 0.3
    bounds = (-hx - t - margin, -hy - t - margin, hx + t + margin, hy + t + margin)
    goal = None if goal_xy is None else (float(goal_xy[0]), float(goal_xy[1]))
    return World(f"random-{seed}", tuple(placer.obstacles), start=start, goal=goal, bounds=bounds)


def reachable(world: World, radius: float, start: Sequence[float], goal: Sequence[float]) -> bool:
    """Whether a disk of ``radius`` can move from ``start`` to ``goal`` without touching an obstacle.

    Conservative: cells of a :data:`GRID_RESOLUTION` grid over ``world.bounds`` are free
    when the disk at their centre keeps half a cell of clearance, and two 4-neighbour free
    cells are joined by a segment every point of which keeps clearance >= 0 (clearance is
    1-Lipschitz). A passage narrower than the disk plus about one cell may be missed.

    Args:
        world: the world.
        radius: radius of the disk [m].
        start: start position ``(x, y, ...)`` [m].
        goal: goal position ``(x, y)`` [m].
    """
    xmin, ymin, xmax, ymax = world.bounds
    xs = np.arange(xmin, xmax + GRID_RESOLUTION, GRID_RESOLUTION)
    ys = np.arange(ymin, ymax + GRID_RESOLUTION, GRID_RESOLUTION)
    free = np.empty((ys.size, xs.size), dtype=bool)
    for row, y in enumerate(ys):
        points = np.column_stack((xs, np.full(xs.size, y)))
        free[row] = world.signed_distance(points) - radius >= 0.5 * GRID_RESOLUTION
    labels, _ = ndimage.label(free)

    def cell(x: float, y: float) -> int:
        column = int(np.clip(round((x - xmin) / GRID_RESOLUTION), 0, xs.size - 1))
        row = int(np.clip(round((y - ymin) / GRID_RESOLUTION), 0, ys.size - 1))
        return int(labels[row, column])

    start_label, goal_label = cell(start[0], start[1]), cell(goal[0], goal[1])
    return start_label != 0 and start_label == goal_label

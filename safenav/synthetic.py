"""Synthetic scans of analytic 2D scenes, with no simulator.

A scene is a set of line segments and circles in a world frame. :func:`cast`
shoots rays exactly against them, and :func:`synthetic_scan` turns the result
into a :class:`~safenav.scan.LaserScan` of a robot's lidar at a given pose, with
REP-117 values: ``+inf`` when nothing is within ``range_max`` and ``-inf`` when
the first hit is closer than ``range_min``.

A real lidar turns: each beam is measured at its own time within the sweep (``time_increment``
apart, the stamp being the first beam's, as ``sensor_msgs/LaserScan`` defines it), from wherever
the robot is then. :func:`swept_scan` casts such a scan along a path; :func:`synthetic_scan` casts
every beam at once (``time_increment`` 0), as the simulators do.

Filter and policy tests use it to build exact inputs::

    from safenav import preset
    from safenav.synthetic import Scene, wall, synthetic_scan
    robot = preset("rosbot")
    scan = synthetic_scan(robot, Scene.of(wall(distance=0.3)))   # a wall 0.3 m ahead
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field

import numpy as np

from safenav.errors import InvalidConfig
from safenav.geometry import Pose2D
from safenav.robot import LidarSpec, RobotSpec
from safenav.scan import LaserScan

__all__ = ["Circle", "Scene", "Segment", "box", "cast", "swept_scan", "synthetic_scan", "wall"]


@dataclass(frozen=True)
class Segment:
    """A line segment from ``start`` to ``end`` [m]."""

    start: tuple[float, float]
    end: tuple[float, float]


@dataclass(frozen=True)
class Circle:
    """A disk of ``radius`` [m] around ``center`` [m]."""

    center: tuple[float, float]
    radius: float


@dataclass(frozen=True)
class Scene:
    """Segments and circles in the world frame."""

    segments: tuple[Segment, ...] = ()
    circles: tuple[Circle, ...] = ()
    _segment_array: np.ndarray = field(init=False, repr=False, compare=False)
    _circle_array: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        segments = np.array([[*s.start, *s.end] for s in self.segments], dtype=float).reshape(-1, 4)
        circles = np.array([[*c.center, c.radius] for c in self.circles], dtype=float).reshape(-1, 3)
        if not (np.all(np.isfinite(segments)) and np.all(np.isfinite(circles))):
            raise InvalidConfig("Scene coordinates must be finite")
        if np.any(circles[:, 2] <= 0):
            raise InvalidConfig(f"Scene circle radii must be > 0, got {circles[:, 2].tolist()}")
        object.__setattr__(self, "_segment_array", segments)
        object.__setattr__(self, "_circle_array", circles)

    @classmethod
    def of(cls, *items: Segment | Circle | Iterable[Segment | Circle]) -> Scene:
        """A scene from segments, circles, or iterables of them (such as :func:`box`)."""
        flat: list[Segment | Circle] = []
        for item in items:
            flat.extend([item] if isinstance(item, (Segment, Circle)) else item)
        return cls(tuple(x for x in flat if isinstance(x, Segment)), tuple(x for x in flat if isinstance(x, Circle)))

    def clearance(self, center: tuple[float, float], radius: float) -> float:
        """Distance from a disk of ``radius`` at ``center`` to the nearest item [m] (inf if empty).

        Negative when the disk overlaps an item. Segments have no inside, so a disk whose
        centre lies on the far side of a wall segment is measured to the segment, not as
        "inside"; :meth:`safenav.worlds.World.clearance` is the signed version for solid walls.
        """
        c = np.asarray(center, dtype=float)
        best = math.inf
        seg = self._segment_array
        if seg.size:
            a, b = seg[:, :2], seg[:, 2:]
            ab = b - a
            length2 = np.maximum(np.einsum("ij,ij->i", ab, ab), 1e-300)
            t = np.clip(np.einsum("ij,ij->i", c - a, ab) / length2, 0.0, 1.0)
            nearest = a + t[:, None] * ab
            best = min(best, float(np.min(np.hypot(*(nearest - c).T))))
        circ = self._circle_array
        if circ.size:
            best = min(best, float(np.min(np.hypot(*(circ[:, :2] - c).T) - circ[:, 2])))
        return best - radius


def wall(distance: float, direction: float = 0.0, length: float = 20.0) -> Segment:
    """A wall perpendicular to ``direction`` [rad], ``distance`` [m] from the origin, ``length`` [m] long."""
    cx, cy = distance * math.cos(direction), distance * math.sin(direction)
    tx, ty = -math.sin(direction) * 0.5 * length, math.cos(direction) * 0.5 * length
    return Segment((cx - tx, cy - ty), (cx + tx, cy + ty))


def box(center: tuple[float, float], size: tuple[float, float], yaw: float = 0.0) -> tuple[Segment, ...]:
    """The four sides of a rectangle of ``size`` [m] at ``center`` [m], rotated by ``yaw`` [rad]."""
    hx, hy = 0.5 * size[0], 0.5 * size[1]
    c, s = math.cos(yaw), math.sin(yaw)
    corners = [(center[0] + c * x - s * y, center[1] + s * x + c * y)
               for x, y in ((hx, hy), (-hx, hy), (-hx, -hy), (hx, -hy))]
    return tuple(Segment(corners[i], corners[(i + 1) % 4]) for i in range(4))


def cast(origin: tuple[float, float] | np.ndarray, angles: np.ndarray, scene: Scene) -> np.ndarray:
    """Distance along each ray from ``origin`` [m] at world ``angles`` [rad] to the first item (inf if none).

    ``origin``: one point for every ray, or ``(N, 2)`` one per ray.
    """
    angles = np.asarray(angles, dtype=float)
    d = np.column_stack((np.cos(angles), np.sin(angles)))
    o = np.asarray(origin, dtype=float)
    per_ray = o.ndim == 2
    best = np.full(angles.size, math.inf)
    seg = scene._segment_array
    if seg.size:
        # (rays or 1, segments) from each origin to each segment's start
        a = seg[None, :, :2] - (o[:, None, :] if per_ray else o[None, None, :])
        e = seg[:, 2:] - seg[:, :2]
        denom = d[:, None, 0] * e[None, :, 1] - d[:, None, 1] * e[None, :, 0]
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            t = (a[..., 0] * e[None, :, 1] - a[..., 1] * e[None, :, 0]) / denom
            u = (a[..., 0] * d[:, None, 1] - a[..., 1] * d[:, None, 0]) / denom
        hit = (np.abs(denom) > 1e-15) & (t >= 0.0) & (u >= 0.0) & (u <= 1.0)
        best = np.minimum(best, np.min(np.where(hit, t, math.inf), axis=1))
    circ = scene._circle_array
    if circ.size:
        if per_ray:
            oc = circ[None, :, :2] - o[:, None, :]                                       # (rays, circles, 2)
            proj = np.einsum("rj,rcj->rc", d, oc)
            disc = proj**2 - (np.einsum("rcj,rcj->rc", oc, oc) - circ[None, :, 2] ** 2)
        else:
            oc = circ[:, :2] - o
            proj = d @ oc.T
            disc = proj**2 - (np.einsum("ij,ij->i", oc, oc) - circ[:, 2] ** 2)[None, :]
        root = np.sqrt(np.maximum(disc, 0.0))
        near, far = proj - root, proj + root
        t = np.where(near >= 0.0, near, np.where(far >= 0.0, 0.0, math.inf))
        best = np.minimum(best, np.min(np.where(disc >= 0.0, t, math.inf), axis=1))
    return best


def synthetic_scan(
    robot: RobotSpec | LidarSpec,
    scene: Scene,
    pose: Pose2D = Pose2D(),
    *,
    noise_std: float = 0.0,
    rng: np.random.Generator | None = None,
    stamp: float | None = None,
) -> LaserScan:
    """The scan a robot's lidar sees in ``scene`` with the base at ``pose``.

    Args:
        robot: the robot (its lidar is used) or a lidar alone.
        scene: the world.
        pose: base pose in the scene frame [m, m, rad].
        noise_std: Gaussian range noise [m] added to hits; needs ``rng``.
        rng: random generator for the noise.
        stamp: acquisition time [s].
    """
    lidar = robot.lidar if isinstance(robot, RobotSpec) else robot
    template = lidar.scan()
    sensor = pose.compose(lidar.mount)
    ranges = cast((sensor.x, sensor.y), template.angles + sensor.yaw, scene)
    if noise_std > 0.0:
        if rng is None:
            raise InvalidConfig("synthetic_scan: noise_std > 0 needs rng=np.random.default_rng(seed)")
        finite = np.isfinite(ranges)
        ranges[finite] += rng.normal(0.0, noise_std, int(finite.sum()))
    return template.with_ranges(_rep117(ranges, lidar), stamp=stamp)


def _rep117(ranges: np.ndarray, lidar: LidarSpec) -> np.ndarray:
    """Exact distances as a lidar reports them: ``+inf`` beyond ``range_max``, ``-inf`` nearer than ``range_min``."""
    ranges[ranges > lidar.range_max] = math.inf
    ranges[ranges < lidar.range_min] = -math.inf
    return ranges


def swept_scan(robot: RobotSpec | LidarSpec, scene: Scene, pose_at: Callable[[float], Pose2D], stamp: float, *,
               sweep_time: float | None = None) -> LaserScan:
    """The scan a turning lidar takes while the base moves: beam ``i`` cast from the base pose at its own time.

    As ``sensor_msgs/LaserScan`` defines it, ``stamp`` is the time of the first beam and beam ``i`` is
    measured ``i * time_increment`` after it; here ``time_increment = sweep_time / n_beams`` (the lidar's
    ``scan_time`` by default: it turns once per scan), so the last beam is measured one increment before the
    sweep ends.

    Args:
        robot: the robot (its lidar is used) or a lidar alone.
        scene: the world.
        pose_at: the base pose in the scene frame at a time [s] -> [m, m, rad].
        stamp: time of the first beam [s].
        sweep_time: how long one turn of the lidar takes [s] (default: the lidar's ``scan_time``).
    """
    lidar = robot.lidar if isinstance(robot, RobotSpec) else robot
    sweep = lidar.scan_time if sweep_time is None else float(sweep_time)
    template = lidar.scan().replace(time_increment=sweep / lidar.n_beams, scan_time=sweep)
    sensors = np.array([tuple(pose_at(stamp + time).compose(lidar.mount)) for time in template.beam_times])
    ranges = cast(sensors[:, :2], template.angles + sensors[:, 2], scene)
    return template.with_ranges(_rep117(ranges, lidar), stamp=stamp)

"""The conventional baseline: stop and slowdown zones around the footprint, like ROS 2's collision monitor.

Many robots today guard their bases with Nav2's ``collision_monitor``: polygons fixed
around the footprint, checked against the latest scan points. If at least
``min_points`` points fall inside the *stop* polygon the command becomes ``(0, 0)``;
otherwise, if enough fall inside the *slowdown* polygon, the command is scaled by
``slowdown_ratio``. :class:`ZonesFilter` reproduces that behaviour so the benchmarks
can compare the barrier filters with what is deployed.

What it does not do, by design (these are the known weaknesses the benchmarks measure):
it does not look at the direction of motion (an obstacle behind a robot driving away
still stops it), it cannot steer, and a robot whose stop zone holds an obstacle stays
stopped until the obstacle moves, even when turning or backing away would be safe.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from safenav import _checks
from safenav.errors import InvalidConfig
from safenav.filters import kernels
from safenav.filters.base import FilterResult, FilterStatus, Reason, SafetyFilter, View
from safenav.filters.body import inside_polygon
from safenav.geometry import counter_clockwise
from safenav.robot import RobotSpec

__all__ = ["ZonesConfig", "ZonesFilter", "inflate_footprint"]


def inflate_footprint(robot: RobotSpec, distance: float, segments: int = 64, *, disk: bool = False) -> np.ndarray:
    """The robot's footprint (or body disk) grown by ``distance`` [m] on every side, as polygon vertices [m].

    A convex footprint becomes its Minkowski sum with a disk: each edge moved out along
    its normal, joined by arcs round the corners. Arcs are sampled with at most
    ``2 pi / segments`` between vertices and pushed out by ``1 / cos`` of half that step,
    so the polygon contains the exact shape. With ``disk=True``, or for a robot without a
    footprint, the body disk of radius ``robot.radius`` is grown instead.
    """
    step = 2.0 * math.pi / segments
    scale = 1.0 / math.cos(0.5 * step)
    if disk or robot.footprint is None:
        angles = np.arange(segments) * step
        return (robot.radius + distance) * scale * np.column_stack((np.cos(angles), np.sin(angles)))
    corners = counter_clockwise(robot.footprint)
    edges = np.roll(corners, -1, axis=0) - corners
    normals = np.column_stack((edges[:, 1], -edges[:, 0])) / np.hypot(edges[:, 0], edges[:, 1])[:, None]
    vertices = []
    for index, corner in enumerate(corners):
        start = math.atan2(normals[index - 1, 1], normals[index - 1, 0])
        sweep = (math.atan2(normals[index, 1], normals[index, 0]) - start) % (2.0 * math.pi)
        count = max(1, math.ceil(sweep / step))
        reach = distance / math.cos(0.5 * sweep / count)
        for angle in start + sweep * np.arange(count + 1) / count:
            vertices.append(corner + reach * np.array([math.cos(angle), math.sin(angle)]))
    return np.array(vertices)


@dataclass(frozen=True)
class ZonesConfig:
    """Settings of :class:`ZonesFilter`.

    Attributes:
        stop_distance: the stop polygon is the footprint grown by this much [m].
        slowdown_distance: the slowdown polygon is the footprint grown by this much [m].
        slowdown_ratio: factor applied to ``(v, omega)`` in the slowdown zone.
        min_points: points needed inside a polygon for it to act (Nav2's ``min_points``).
        scan_timeout: scans older than this stop the robot [s] (Nav2's ``source_timeout``).
        use_footprint: grow the footprint polygon instead of the body disk (the disk is the
            body the other filters and the simulator's truth use, so it is the default).
        deadlock_time: how long the commands may stall while the nominal asks to move before the
            result reports a deadlock [s].
        kernels: ``"auto"``, ``"numba"`` or ``"numpy"``: the compiled edges of what obstacles hide, as
            :attr:`CBFConfig.kernels <safenav.filters.CBFConfig>`.
    """

    stop_distance: float = 0.05
    slowdown_distance: float = 0.4
    slowdown_ratio: float = 0.3
    min_points: int = 3
    scan_timeout: float = 0.5
    use_footprint: bool = False
    deadlock_time: float = 1.5
    kernels: str = "auto"

    def __post_init__(self) -> None:
        name = "ZonesConfig."
        for field in ("stop_distance", "slowdown_distance"):
            _checks.number(name + field, getattr(self, field), low=0.0)
        _checks.number(name + "slowdown_ratio", self.slowdown_ratio, low=0.0, high=1.0)
        _checks.duration(name + "scan_timeout", self.scan_timeout, high=1e9)
        if self.slowdown_distance < self.stop_distance:
            raise InvalidConfig(f"ZonesConfig.slowdown_distance={self.slowdown_distance!r} must be >= "
                                f"stop_distance={self.stop_distance!r}")
        _checks.integer(name + "min_points", self.min_points, low=1)
        _checks.boolean(name + "use_footprint", self.use_footprint)
        _checks.positive(name + "deadlock_time", self.deadlock_time)
        _checks.choice("zones kernels", self.kernels, kernels.KERNELS)


class ZonesFilter(SafetyFilter):
    """Stop and slowdown polygons around the body, checked against the scan points.

    Points inside the stop polygon (at least ``min_points``) give ``(0, 0)``; else points
    inside the slowdown polygon scale the command by ``slowdown_ratio``; else the command
    passes unchanged. The result reports the zone in :attr:`FilterResult.message`
    (``"stop zone: ..."``, ``"slowdown zone: ..."``) with status ``OK``: this is the
    filter's normal action, not a failure. With ``velocity`` given the command is also
    clipped to what the acceleration limits allow within the period it is held (``dt``, or a
    late call's measured period: a real base cannot stop at once either).

    Args:
        robot: the robot.
        dt: control period [s].
        config: settings; keyword arguments override its fields.
    """

    name = "zones"

    def __init__(self, robot: RobotSpec, dt: float = 0.05, *, config: ZonesConfig | None = None, **overrides: Any):
        config = ZonesConfig(**{**(config.__dict__ if config else {}), **overrides})
        super().__init__(robot, dt, scan_timeout=config.scan_timeout, compensate_latency=False, memory_capacity=0,
                         deadlock_time=config.deadlock_time)
        self.config = config
        disk = not config.use_footprint
        self.stop_polygon = inflate_footprint(robot, config.stop_distance, disk=disk)
        self.slowdown_polygon = inflate_footprint(robot, config.slowdown_distance, disk=disk)
        self._ready(config.kernels)

    def _filter(self, u_nom: np.ndarray, view: View, velocity: np.ndarray | None, period: float) -> FilterResult:
        points = view.points[: view.n_current]   # like the collision monitor: the current scans only
        clearance = self.body.clearance(points)
        near = points[inside_polygon(self.slowdown_polygon, points, self._kernels)]
        in_stop = inside_polygon(self.stop_polygon, near, self._kernels)
        reason = None
        if int(in_stop.sum()) >= self.config.min_points:
            u = np.zeros(2)
            reason = Reason("zone", f"stop zone: {int(in_stop.sum())} points inside", _nearest(near[in_stop]))
        elif len(near) >= self.config.min_points:
            u = self.config.slowdown_ratio * u_nom
            reason = Reason("zone", f"slowdown zone: {len(near)} points inside", _nearest(near))
        else:
            u = u_nom
        limited = self.robot.clip(u, velocity, period if velocity is not None else None)
        if reason is None and not np.array_equal(limited, u_nom):
            reason = Reason("acceleration" if velocity is not None else "limits",
                            "clipped to the velocity and acceleration limits")
        return FilterResult(u=limited, u_nom=u_nom, status=FilterStatus.OK, reason=reason, clearance=clearance,
                            n_constraints=len(near), constraint_points=near)


def _nearest(points: np.ndarray) -> tuple[float, float] | None:
    if len(points) == 0:
        return None
    index = int(np.argmin(np.hypot(points[:, 0], points[:, 1])))
    return (float(points[index, 0]), float(points[index, 1]))

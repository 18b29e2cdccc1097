"""Dynamic worlds: obstacles that move on scripted or seeded paths, appear and disappear.

A :class:`MovingObstacle` is a disk or a box carried along a piecewise-linear path of timed
waypoints ``(t [s], x [m], y [m])``; it stands still before its first waypoint and after its
last, and exists only from ``appear`` until ``disappear``. A :class:`DynamicWorld` is a
:class:`~safenav.worlds.World` (its static obstacles) plus movers; its truth is exact at any
time: :meth:`DynamicWorld.clearance_at`. The simulator (:class:`~safenav.sim_bullet.BulletSim`)
moves the movers' PyBullet bodies before every scan and evaluates the truth clearance at every
physics step, so both the lidar and the metrics see them::

    from safenav.worlds import Cylinder
    from safenav.worlds.dynamic import DynamicWorld, MovingObstacle

    walker = MovingObstacle.constant_velocity(Cylinder((0.0, 0.0), 0.25), start=(3.0, -2.0),
                                              velocity=(0.0, 1.0), appear=1.0, disappear=6.0)
    world = DynamicWorld("crossing", obstacles=(), movers=(walker,))

The scripted encounters of a robot that drives along its start heading (:func:`crossing`,
:func:`head_on`, :func:`overtaking`, :func:`step_in`, :func:`pass_beside`) and the seeded
traffic of :func:`random_movers` build the movers; the same seed gives the same movers.

Nothing here is covered by the filters' guarantee, which assumes a static world
(``docs/safety.md``): dynamic worlds measure how fast it degrades.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from safenav._checks import choice, integer, number, pair, positive, vector
from safenav.errors import InvalidConfig
from safenav.geometry import Pose2D
from safenav.seeding import stream
from safenav.worlds.shapes import Box, Cylinder
from safenav.worlds.world import World

__all__ = ["ENCOUNTERS", "DynamicWorld", "MovingObstacle", "crossing", "head_on", "overtaking", "pass_beside",
           "patrols", "random_movers", "step_in"]

_FAR_FUTURE = 3600.0
"""End of the path of a constant-velocity mover that never disappears [s after it appears]."""

ENCOUNTERS = ("crossing", "head_on", "overtaking")
"""Kinds of seeded traffic :func:`random_movers` draws."""


@dataclass(frozen=True)
class MovingObstacle:
    """A disk or a box carried along a piecewise-linear timed path.

    Attributes:
        shape: the footprint; its ``center`` is the offset of the footprint from the path point
            [m] (usually ``(0, 0)``), a box keeps its ``yaw``.
        waypoints: ``(t [s], x [m], y [m])`` rows with strictly increasing times; the path point
            stays at the first waypoint before it and at the last after it.
        appear: the obstacle exists from this time on [s].
        disappear: ... until this time [s] (``inf``: never disappears).
    """

    shape: Cylinder | Box
    waypoints: tuple[tuple[float, float, float], ...]
    appear: float = 0.0
    disappear: float = math.inf

    def __post_init__(self) -> None:
        if not isinstance(self.shape, (Cylinder, Box)):
            raise InvalidConfig(f"MovingObstacle.shape must be a Cylinder or a Box, got {self.shape!r}")
        rows = tuple(vector(f"MovingObstacle.waypoints[{i}]", row, 3, expected="(t [s], x [m], y [m])")
                     for i, row in enumerate(self.waypoints))
        if not rows:
            raise InvalidConfig("MovingObstacle.waypoints must hold at least one (t, x, y) row, got none")
        times = [row[0] for row in rows]
        if any(later <= earlier for earlier, later in itertools.pairwise(times)):
            raise InvalidConfig(f"MovingObstacle.waypoints times must increase strictly, got {times!r}")
        object.__setattr__(self, "waypoints", rows)
        object.__setattr__(self, "appear", number("MovingObstacle.appear", self.appear))
        disappear = number("MovingObstacle.disappear", self.disappear, low=self.appear, low_open=True, finite=False)
        object.__setattr__(self, "disappear", disappear)

    @classmethod
    def constant_velocity(cls, shape: Cylinder | Box, start: Sequence[float], velocity: Sequence[float], *,
                          appear: float = 0.0, disappear: float = math.inf) -> MovingObstacle:
        """A mover at ``start`` [m] when it appears, at a constant ``velocity`` [m/s] until it disappears."""
        x, y = pair("MovingObstacle start", start)
        vx, vy = pair("MovingObstacle velocity", velocity)
        end = disappear if math.isfinite(disappear) else appear + _FAR_FUTURE
        duration = end - appear
        return cls(shape, ((appear, x, y), (end, x + vx * duration, y + vy * duration)), appear, disappear)

    def present(self, time: float) -> bool:
        """Whether the obstacle exists at ``time`` [s]."""
        return self.appear <= time < self.disappear

    def position(self, time: float) -> tuple[float, float]:
        """The path point at ``time`` [s] (where the footprint's offset is measured from) [m]."""
        table = self._table
        return (float(np.interp(time, table[:, 0], table[:, 1])), float(np.interp(time, table[:, 0], table[:, 2])))

    def velocity(self, time: float) -> tuple[float, float]:
        """Velocity of the path point at ``time`` [m/s] (the segment's after a waypoint; 0 outside the path)."""
        table = self._table
        index = int(np.searchsorted(table[:, 0], time, side="right"))
        if index == 0 or index == len(table):
            return (0.0, 0.0)
        (t0, x0, y0), (t1, x1, y1) = table[index - 1], table[index]
        return (float((x1 - x0) / (t1 - t0)), float((y1 - y0) / (t1 - t0)))

    @property
    def max_speed(self) -> float:
        """The fastest segment of the path [m/s]."""
        table = self._table
        if len(table) < 2:
            return 0.0
        return float(np.max(np.hypot(*np.diff(table[:, 1:], axis=0).T) / np.diff(table[:, 0])))

    @property
    def _table(self) -> np.ndarray:
        return np.array(self.waypoints, dtype=float)

    def shape_at(self, time: float) -> Cylinder | Box | None:
        """The footprint where it is at ``time`` [s]; ``None`` while the obstacle does not exist."""
        if not self.present(time):
            return None
        x, y = self.position(time)
        return dataclasses.replace(self.shape, center=(x + self.shape.center[0], y + self.shape.center[1]))


@dataclass(frozen=True)
class DynamicWorld(World):
    """A world with moving obstacles besides its static ones.

    Attributes:
        movers: the moving obstacles (the static ones are ``obstacles``).
    """

    movers: tuple[MovingObstacle, ...] = ()

    def __post_init__(self) -> None:
        super().__post_init__()
        movers = tuple(self.movers)
        for mover in movers:
            if not isinstance(mover, MovingObstacle):
                raise InvalidConfig(f"DynamicWorld.movers must hold MovingObstacle, got {mover!r}")
        object.__setattr__(self, "movers", movers)

    def obstacles_at(self, time: float) -> tuple[Box | Cylinder, ...]:
        """The movers that exist at ``time`` [s], where they are (the static obstacles not included)."""
        shapes = (mover.shape_at(time) for mover in self.movers)
        return tuple(shape for shape in shapes if shape is not None)

    def signed_distance_at(self, points: np.ndarray, time: float) -> np.ndarray:
        """Signed distance from each of ``points`` ``(N, 2)`` to the nearest obstacle at ``time`` [m, s]."""
        best = self.signed_distance(points)
        for shape in self.obstacles_at(time):
            best = np.minimum(best, shape.signed_distance(points))
        return best

    def clearance_at(self, pose: Pose2D | Sequence[float], radius: float, time: float) -> float:
        """Exact signed clearance of the body disk at ``time`` [s], static obstacles and movers [m]."""
        return float(self.signed_distance_at(np.array([[pose[0], pose[1]]]), time)[0]) - radius

    def footprint_clearance_at(self, poses: np.ndarray, footprint: np.ndarray, time: float) -> np.ndarray:
        """Exact signed clearance [m] of a convex footprint at ``poses`` ``(K, 3)`` at ``time`` [s], static
        obstacles and movers (:meth:`World.footprint_clearance`)."""
        return self.snapshot(time).footprint_clearance(poses, footprint)

    def snapshot(self, time: float) -> World:
        """The world frozen at ``time`` [s]: a static :class:`World` with the movers where they are."""
        return World(f"{self.name}@{time:g}s", (*self.obstacles, *self.obstacles_at(time)), self.start, self.goal,
                     self.bounds, self.obstacle_height)


# ---------------------------------------------------------------------------------------- scripted encounters


def _along(start: Pose2D, forward: float, left: float) -> tuple[float, float]:
    """The point ``forward`` ahead and ``left`` to the left of ``start`` [m]."""
    c, s = math.cos(start.yaw), math.sin(start.yaw)
    return (start.x + forward * c - left * s, start.y + forward * s + left * c)


def _heading(start: Pose2D, forward: float, left: float) -> tuple[float, float]:
    """A velocity ``forward`` along and ``left`` across the heading of ``start`` [m/s]."""
    c, s = math.cos(start.yaw), math.sin(start.yaw)
    return (forward * c - left * s, forward * s + left * c)


def crossing(start: Pose2D, *, distance: float, speed: float, radius: float = 0.25, time: float = 0.0,
             offset: float = 4.0, from_left: bool = True) -> MovingObstacle:
    """A disk that crosses the line ahead of ``start`` at right angles.

    Args:
        start: the robot's start pose; its heading is "ahead".
        distance: where the disk crosses the line, ahead of ``start`` [m].
        speed: the disk's speed [m/s].
        radius: the disk's radius [m].
        time: when the disk's centre is on the line [s].
        offset: the disk appears this far to the side of the line and disappears as far on the other [m].
        from_left: it comes from the robot's left (else from its right).
    """
    speed, offset = positive("crossing speed", speed), positive("crossing offset", offset)
    side = 1.0 if from_left else -1.0
    travel = offset / speed
    return MovingObstacle.constant_velocity(Cylinder((0.0, 0.0), radius), _along(start, distance, side * offset),
                                            _heading(start, 0.0, -side * speed), appear=time - travel,
                                            disappear=time + travel)


def head_on(start: Pose2D, *, distance: float, speed: float, radius: float = 0.25, lateral: float = 0.0,
            appear: float = 0.0) -> MovingObstacle:
    """A disk that appears ``distance`` ahead [m], ``lateral`` left [m], and walks to ``start`` at ``speed`` [m/s]."""
    return MovingObstacle.constant_velocity(Cylinder((0.0, 0.0), radius), _along(start, distance, lateral),
                                            _heading(start, -positive("head_on speed", speed), 0.0), appear=appear)


def overtaking(start: Pose2D, *, distance: float, speed: float, radius: float = 0.25, lateral: float = 0.0,
               appear: float = 0.0) -> MovingObstacle:
    """A disk that appears ``distance`` behind ``start`` [m] and walks along its heading at ``speed`` [m/s]."""
    return MovingObstacle.constant_velocity(Cylinder((0.0, 0.0), radius), _along(start, -distance, lateral),
                                            _heading(start, positive("overtaking speed", speed), 0.0), appear=appear)


def step_in(start: Pose2D, *, distance: float, enter: float, stay: float, speed: float = 1.0,
            radius: float = 0.25, side_distance: float = 1.5, from_left: bool = True) -> MovingObstacle:
    """A disk that steps sideways onto the line ahead of ``start``, stands there, and steps back out.

    The collision monitor's rosbag test in miniature: the disk walks at ``speed`` [m/s] from
    ``side_distance`` [m] beside the line to the point ``distance`` [m] ahead, arrives at
    ``enter`` [s], stays ``stay`` [s], and walks back the way it came.
    """
    speed = positive("step_in speed", speed)
    stay = positive("step_in stay", stay)
    side = 1.0 if from_left else -1.0
    walk = positive("step_in side_distance", side_distance) / speed
    beside, on_line = _along(start, distance, side * side_distance), _along(start, distance, 0.0)
    waypoints = ((enter - walk, *beside), (enter, *on_line), (enter + stay, *on_line), (enter + stay + walk, *beside))
    return MovingObstacle(Cylinder((0.0, 0.0), radius), waypoints, appear=enter - walk,
                          disappear=enter + stay + walk)


def pass_beside(start: Pose2D, *, distance: float, lateral: float, speed: float, radius: float = 0.25,
                appear: float = 0.0, length: float = 8.0) -> MovingObstacle:
    """A disk that walks towards ``start`` along a line ``lateral`` [m] to its left (negative: right).

    It appears ``distance`` ahead [m] and disappears after walking ``length`` [m] at ``speed`` [m/s]:
    it passes beside the robot's path without entering it when ``|lateral|`` exceeds its radius
    plus the robot's.
    """
    speed = positive("pass_beside speed", speed)
    return MovingObstacle.constant_velocity(Cylinder((0.0, 0.0), radius), _along(start, distance, lateral),
                                            _heading(start, -speed, 0.0), appear=appear,
                                            disappear=appear + positive("pass_beside length", length) / speed)


def random_movers(seed: int, count: int, *, start: Pose2D, speed: tuple[float, float] = (0.3, 1.5),
                  radius: float = 0.25, kinds: Sequence[str] = ENCOUNTERS,
                  window: tuple[float, float] = (1.0, 12.0), reach: tuple[float, float] = (1.5, 5.0),
                  lateral: float = 0.6) -> tuple[MovingObstacle, ...]:
    """Seeded traffic around a robot that starts at ``start``: ``count`` encounters of the given kinds.

    Each mover's kind, speed, place and time are drawn from a child of the ``world`` stream of
    ``seed`` (:mod:`safenav.seeding`), so the same arguments give the same movers, and the static
    world drawn from the same seed is not disturbed.

    Args:
        seed: the episode's seed.
        count: how many movers.
        start: the robot's start pose.
        speed: range of their speeds [m/s].
        radius: their radius [m].
        kinds: which encounters (:data:`ENCOUNTERS`).
        window: range of the times at which they are on the robot's line or appear [s].
        reach: range of the distances ahead (crossing, head-on) or behind (overtaking) [m].
        lateral: largest sideways offset of head-on and overtaking walkers [m].
    """
    count = integer("random_movers count", count, low=0)
    low_speed, high_speed = pair("random_movers speed", speed)
    if not 0.0 < low_speed <= high_speed:
        raise InvalidConfig(f"random_movers speed must be (low, high) with 0 < low <= high [m/s], got {speed!r}")
    kinds = tuple(choice("encounter", kind, ENCOUNTERS) for kind in kinds)
    if not kinds:
        raise InvalidConfig(f"random_movers kinds must name at least one of {', '.join(ENCOUNTERS)}, got none")
    rng = np.random.default_rng(stream(seed, "world").spawn(2)[1])
    movers = []
    for _ in range(count):
        kind = kinds[int(rng.integers(len(kinds)))]
        walker_speed = float(rng.uniform(low_speed, high_speed))
        when = float(rng.uniform(*window))
        how_far = float(rng.uniform(*reach))
        side = float(rng.uniform(-lateral, lateral))
        if kind == "crossing":
            movers.append(crossing(start, distance=how_far, speed=walker_speed, radius=radius, time=when,
                                   from_left=bool(rng.integers(2))))
        elif kind == "head_on":
            movers.append(head_on(start, distance=how_far + walker_speed * when, speed=walker_speed, radius=radius,
                                  lateral=side, appear=0.0))
        else:
            movers.append(overtaking(start, distance=how_far, speed=walker_speed, radius=radius, lateral=side,
                                     appear=when))
    return tuple(movers)


def patrols(seed: int, count: int, *, bounds: tuple[float, float, float, float], speed: float,
            duration: float, radius: float = 0.2, keep_clear: tuple[float, float, float] | None = None,
            ) -> tuple[MovingObstacle, ...]:
    """Seeded walkers that pace back and forth between two random points of ``bounds``, all at ``speed``.

    The traffic of an arena rather than of one encounter: each walker turns at its two points
    (drawn uniformly inside ``bounds`` shrunk by ``radius``, at least 1 m apart) and starts at a
    random point of its beat, so the density stays the same over the episode. The walkers pass
    through the static obstacles (they are ghosts to them, not to the robot). Drawn from a child
    of the ``world`` stream of ``seed`` (another child than :func:`random_movers`'), so the static
    world drawn from the same seed is not disturbed and the same arguments give the same walkers.

    Args:
        seed: the episode's seed.
        count: how many walkers.
        bounds: ``(xmin, ymin, xmax, ymax)`` of the region they walk in [m].
        speed: their speed [m/s].
        duration: how long their beats are written out [s] (they stand still afterwards).
        radius: their radius [m].
        keep_clear: ``(x, y, distance)``: at time 0 no walker is within ``distance`` of ``(x, y)``
            [m] (the robot's start); drawn again until none is.
    """
    count = integer("patrols count", count, low=0)
    speed, duration, radius = (positive(f"patrols {name}", value) for name, value in
                               (("speed", speed), ("duration", duration), ("radius", radius)))
    xmin, ymin, xmax, ymax = vector("patrols bounds", bounds, 4, expected="(xmin, ymin, xmax, ymax) [m]")
    low, high = np.array([xmin + radius, ymin + radius]), np.array([xmax - radius, ymax - radius])
    if np.any(high - low < 1.0):
        raise InvalidConfig(f"patrols bounds {bounds!r} leave less than 1 m to walk in once shrunk by the "
                            f"radius {radius!r}; expected a larger region")
    rng = np.random.default_rng(stream(seed, "world").spawn(3)[2])
    walkers = []
    for _ in range(count):
        for _attempt in range(1000):
            a, b = rng.uniform(low, high), rng.uniform(low, high)
            beat = float(np.hypot(*(b - a)))
            phase = float(rng.uniform(0.0, 2.0 * beat)) if beat >= 1.0 else 0.0
            if beat < 1.0:
                continue
            first = a + (b - a) * min(phase, 2 * beat - phase) / beat
            if keep_clear is None or math.hypot(first[0] - keep_clear[0], first[1] - keep_clear[1]) \
                    >= keep_clear[2] + radius:
                break
        else:
            raise InvalidConfig(f"patrols could not keep {keep_clear!r} clear in {bounds!r}")
        walkers.append(MovingObstacle(Cylinder((0.0, 0.0), radius), _beat(a, b, phase, beat, speed, duration)))
    return tuple(walkers)


def _beat(a: np.ndarray, b: np.ndarray, phase: float, beat: float, speed: float,
          duration: float) -> tuple[tuple[float, float, float], ...]:
    """Waypoints of a walk back and forth between ``a`` and ``b``, ``phase`` [m] along the round trip at time 0."""
    leg = beat / speed
    # position at time 0, and the first turn ahead
    if phase < beat:
        here, targets, first_leg = a + (b - a) * phase / beat, [b, a], (beat - phase) / speed
    else:
        here, targets, first_leg = b + (a - b) * (phase - beat) / beat, [a, b], (2 * beat - phase) / speed
    waypoints = [(0.0, float(here[0]), float(here[1]))]
    moment, turn = first_leg, 0
    while True:
        point = targets[turn % 2]
        waypoints.append((moment, float(point[0]), float(point[1])))
        if moment >= duration:
            return tuple(waypoints)
        moment += leg
        turn += 1

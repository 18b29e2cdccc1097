"""Robot descriptions: body, velocity and acceleration limits, lidar, and the three tutorial presets.

A :class:`RobotSpec` is everything a filter, a policy and the simulator need to
know about a differential-drive base. :func:`preset` returns the three robots of
the classic ROS tutorials (DESIGN.md section 3):

=============  ===================  =========================================  ==========
preset         tutorial             lidar                                      mount yaw
=============  ===================  =========================================  ==========
``rosbot``     stop at a wall       720 beams over -pi..pi, 0.15-12 m          pi
``puzzlebot``  obstacle avoidance   360 beams over 0..2pi, 0.15-12 m           0
``m2wr``       wall follower        720 beams over -pi/2..pi/2, 0.10-30 m      0
=============  ===================  =========================================  ==========

Commands are ``(v, omega)``: linear velocity along base x [m/s] and yaw rate
[rad/s], as ``geometry_msgs/Twist`` ``linear.x`` and ``angular.z``.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import numbers
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from safenav.errors import InvalidCommand, InvalidCommandType, InvalidConfig, UnknownName
from safenav.geometry import Pose2D
from safenav.scan import LaserScan

__all__ = ["PRESET_NAMES", "Command", "LidarSpec", "RobotSpec", "as_command", "preset"]

PRESET_NAMES = ("rosbot", "puzzlebot", "m2wr")


class Command(NamedTuple):
    """A velocity command: ``v`` along base x [m/s], ``omega`` yaw rate [rad/s]."""

    v: float
    omega: float


def as_command(u: Any, name: str = "u") -> np.ndarray:
    """``u`` as a float array of shape ``(2,)``; the values may still be non-finite.

    Raises:
        InvalidCommandType: ``u`` is not a pair of real numbers (``None``, strings, objects).
        InvalidCommand: ``u`` has the wrong shape.
    """
    if u is None or isinstance(u, (str, bytes)):
        raise InvalidCommandType(f"{name} must be a pair (v [m/s], omega [rad/s]) of real numbers, got {u!r}")
    try:
        array = np.asarray(u)
    except (TypeError, ValueError):
        raise InvalidCommandType(f"{name} must be a pair (v [m/s], omega [rad/s]) of real numbers, got {u!r}") from None
    if array.dtype.kind not in "fiu":
        raise InvalidCommandType(f"{name} must be a pair (v [m/s], omega [rad/s]) of real numbers, got {u!r}")
    if array.shape != (2,):
        raise InvalidCommand(f"{name} must have shape (2,) as (v [m/s], omega [rad/s]), got shape {array.shape}")
    return array.astype(float)


def _read_only(array: np.ndarray) -> np.ndarray:
    array.flags.writeable = False
    return array


def _positive(owner: str, name: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, numbers.Real) or not math.isfinite(value) or value <= 0:
        raise InvalidConfig(f"{owner}.{name} must be a finite number > 0, got {value!r}")
    return float(value)


@dataclass(frozen=True)
class LidarSpec:
    """A 2D lidar: beam layout, range limits and where it sits on the base.

    Attributes:
        n_beams: number of beams per scan.
        angle_min: angle of beam 0 in the laser frame [rad].
        angle_max: angle of the last beam in the laser frame [rad].
        range_min: smallest reported range [m].
        range_max: largest reported range [m].
        mount: pose of the laser frame in the base frame [m, m, rad].
        scan_time: time between scans [s].
        noise_std: standard deviation of the range noise of the tutorial's sensor model [m].
        height: height of the scan plane above the ground [m].
    """

    n_beams: int
    angle_min: float
    angle_max: float
    range_min: float
    range_max: float
    mount: Pose2D = Pose2D()
    scan_time: float = 0.1
    noise_std: float = 0.0
    height: float = 0.2

    def __post_init__(self) -> None:
        if isinstance(self.n_beams, bool) or not isinstance(self.n_beams, numbers.Integral) or self.n_beams < 1:
            raise InvalidConfig(f"LidarSpec.n_beams must be an integer >= 1, got {self.n_beams!r}")
        object.__setattr__(self, "mount", Pose2D(*self.mount))
        # The template scan validates angles, range limits and the mount.
        self.scan()

    @property
    def angle_increment(self) -> float:
        """Angle between beams [rad]."""
        if self.n_beams == 1:
            return 2.0 * math.pi
        return (self.angle_max - self.angle_min) / (self.n_beams - 1)

    def scan(self, ranges: Any = None, *, stamp: float | None = None) -> LaserScan:
        """A :class:`~safenav.scan.LaserScan` of this lidar.

        Args:
            ranges: the readings [m]; ``None`` gives an all-``+inf`` scan (nothing in range).
            stamp: acquisition time [s].
        """
        if ranges is None:
            ranges = np.full(self.n_beams, math.inf)
        return LaserScan(
            angle_min=self.angle_min,
            angle_max=self.angle_max,
            angle_increment=self.angle_increment,
            time_increment=self.scan_time / self.n_beams,
            scan_time=self.scan_time,
            range_min=self.range_min,
            range_max=self.range_max,
            ranges=ranges,
            mount=self.mount,
            stamp=stamp,
        )


@dataclass(frozen=True)
class RobotSpec:
    """A differential-drive robot: body, limits and lidar.

    The body is the disk of :attr:`radius` around the base origin (the
    circumscribed disk of :attr:`footprint` when one is given); the filters
    guarantee clearance for that disk.

    Attributes:
        name: preset name or a user label.
        radius: radius of the body disk around the base origin [m].
        v_max: largest forward velocity [m/s].
        v_min: largest reverse velocity, as a value <= 0 [m/s].
        omega_max: largest yaw rate magnitude [rad/s].
        a_max: largest linear acceleration magnitude [m/s^2].
        alpha_max: largest angular acceleration magnitude [rad/s^2].
        lidar: the 2D lidar.
        footprint: optional body polygon in the base frame [m], inside the disk.
        height: body height [m], for drawing and simulation.
        source: where the numbers come from.
    """

    name: str
    radius: float
    v_max: float
    v_min: float
    omega_max: float
    a_max: float
    alpha_max: float
    lidar: LidarSpec
    footprint: tuple[tuple[float, float], ...] | None = None
    height: float = 0.2
    source: str = ""

    def __post_init__(self) -> None:
        owner = "RobotSpec"
        for name in ("radius", "v_max", "omega_max", "a_max", "alpha_max", "height"):
            object.__setattr__(self, name, _positive(owner, name, getattr(self, name)))
        v_min = self.v_min
        if isinstance(v_min, bool) or not isinstance(v_min, numbers.Real) or not math.isfinite(v_min) or v_min > 0:
            raise InvalidConfig(f"{owner}.v_min must be a finite number <= 0 (reverse speed limit), got {v_min!r}")
        object.__setattr__(self, "v_min", float(v_min))
        if not isinstance(self.lidar, LidarSpec):
            raise InvalidConfig(f"RobotSpec.lidar must be a LidarSpec, got {self.lidar!r}")
        if self.footprint is not None:
            polygon = np.asarray(self.footprint, dtype=float)
            if polygon.ndim != 2 or polygon.shape[1] != 2 or polygon.shape[0] < 3:
                raise InvalidConfig(f"RobotSpec.footprint must be >= 3 (x, y) vertices, got {self.footprint!r}")
            farthest = float(np.max(np.hypot(polygon[:, 0], polygon[:, 1])))
            if farthest > self.radius + 1e-9:
                raise InvalidConfig(
                    f"RobotSpec.footprint reaches {farthest:.4f} m from the base origin; "
                    f"expected inside radius={self.radius!r}"
                )
            object.__setattr__(self, "footprint", tuple((float(x), float(y)) for x, y in polygon))

    @functools.cached_property
    def lower(self) -> np.ndarray:
        """Lower velocity limits ``(v_min, -omega_max)`` [m/s, rad/s] (read-only)."""
        return _read_only(np.array([self.v_min, -self.omega_max]))

    @functools.cached_property
    def upper(self) -> np.ndarray:
        """Upper velocity limits ``(v_max, omega_max)`` [m/s, rad/s] (read-only)."""
        return _read_only(np.array([self.v_max, self.omega_max]))

    @functools.cached_property
    def _accel_step(self) -> np.ndarray:
        return _read_only(np.array([self.a_max, self.alpha_max]))

    def velocity_bounds(self, velocity: Sequence[float] | np.ndarray | None = None,
                        dt: float | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Box of commands reachable within one period.

        Args:
            velocity: current ``(v, omega)`` [m/s, rad/s]; ``None`` gives the velocity limits alone.
            dt: period [s] over which the acceleration limits apply.

        Returns:
            ``(lower, upper)`` arrays [m/s, rad/s]: the velocity limits intersected with
            ``velocity +- (a_max, alpha_max) * dt``. The box is never empty and always inside
            the limits: from a current velocity beyond a limit (an odometry glitch, a push),
            the only command left is that limit, which the base approaches as fast as it can.
        """
        lower, upper = self.lower, self.upper
        if velocity is None or dt is None:
            return lower, upper
        current = np.asarray(velocity, dtype=float)
        step = self._accel_step * dt
        new_lower = np.clip(current - step, lower, upper)
        new_upper = np.clip(current + step, lower, upper)
        return np.minimum(new_lower, new_upper), np.maximum(new_lower, new_upper)

    def clip(self, u: Any, velocity: Sequence[float] | np.ndarray | None = None, dt: float | None = None) -> np.ndarray:
        """``u`` clipped to :meth:`velocity_bounds` [m/s, rad/s]."""
        lower, upper = self.velocity_bounds(velocity, dt)
        return np.clip(as_command(u), lower, upper)

    def brake(self, velocity: Sequence[float] | np.ndarray | None = None, dt: float | None = None) -> np.ndarray:
        """The command nearest a stop that the acceleration limits allow within ``dt`` [m/s, rad/s]."""
        lower, upper = self.velocity_bounds(velocity, dt)
        return np.clip(np.zeros(2), lower, upper)

    def scan(self, ranges: Any = None, *, stamp: float | None = None) -> LaserScan:
        """A scan of this robot's lidar (see :meth:`LidarSpec.scan`); all ``+inf`` by default."""
        return self.lidar.scan(ranges, stamp=stamp)

    def replace(self, **changes: Any) -> RobotSpec:
        """A copy with some fields changed (validated)."""
        return dataclasses.replace(self, **changes)


def preset(name: str) -> RobotSpec:
    """One of the tutorial robots: ``"rosbot"``, ``"puzzlebot"`` or ``"m2wr"``.

    Raises:
        UnknownName: ``name`` is not a preset (the message lists them).
    """
    if name == "rosbot":
        # Husarion ROSbot 2: 200 x 235 mm chassis, up to 1.0 m/s; RPLIDAR A2/A3 on top,
        # mounted backwards (yaw pi), so beam 0 at angle_min = -pi looks forward.
        half_length, half_width = 0.100, 0.1175
        return RobotSpec(
            name="rosbot",
            radius=round(math.hypot(half_length, half_width) + 0.0005, 3),
            v_max=1.0, v_min=-1.0, omega_max=3.0, a_max=1.5, alpha_max=6.0,
            lidar=LidarSpec(n_beams=720, angle_min=-math.pi, angle_max=math.pi, range_min=0.15, range_max=12.0,
                            mount=Pose2D(0.0, 0.0, math.pi), scan_time=0.1, height=0.22),
            footprint=((half_length, half_width), (-half_length, half_width),
                       (-half_length, -half_width), (half_length, -half_width)),
            height=0.22,
            source="Husarion ROSbot 2 (200 x 235 x 220 mm, 1.0 m/s); tutorial 'stop at a wall'",
        )
    if name == "puzzlebot":
        # Manchester Robotics Puzzlebot: about 0.19 m across; RPLIDAR A1 over 0..2pi, beam 0 forward.
        return RobotSpec(
            name="puzzlebot",
            radius=0.100,
            v_max=0.4, v_min=-0.4, omega_max=2.0, a_max=0.8, alpha_max=4.0,
            lidar=LidarSpec(n_beams=360, angle_min=0.0, angle_max=2.0 * math.pi, range_min=0.15, range_max=12.0,
                            mount=Pose2D(0.0, 0.0, 0.0), scan_time=0.1, height=0.15),
            height=0.15,
            source="Manchester Robotics Puzzlebot (about 0.19 m across); tutorial 'simple obstacle avoidance'",
        )
    if name == "m2wr":
        # The Construct's two-wheeled robot: 0.5 x 0.3 m chassis, 180-degree lidar at the front
        # (x = 0.15 m), 720 samples over -pi/2..pi/2, 0.10-30 m with 1 cm Gaussian noise in Gazebo.
        half_length, half_width = 0.25, 0.15
        return RobotSpec(
            name="m2wr",
            radius=round(math.hypot(half_length, half_width) + 0.0005, 3),
            v_max=1.0, v_min=-0.5, omega_max=2.0, a_max=1.0, alpha_max=3.0,
            lidar=LidarSpec(n_beams=720, angle_min=-0.5 * math.pi, angle_max=0.5 * math.pi, range_min=0.10,
                            range_max=30.0, mount=Pose2D(0.15, 0.0, 0.0), scan_time=0.05, noise_std=0.01,
                            height=0.1),
            footprint=((half_length, half_width), (-half_length, half_width),
                       (-half_length, -half_width), (half_length, -half_width)),
            height=0.1,
            source="m2wr of 'Exploring ROS with a 2 wheeled robot' (0.5 x 0.3 m chassis); tutorial 'wall follower'",
        )
    raise UnknownName("robot preset", name, PRESET_NAMES)

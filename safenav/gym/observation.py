"""What the agent observes: the lidar in bounded sectors, the goal in polar coordinates, the velocity.

Observations are a ``gymnasium.spaces.Dict`` (``gymnasium.wrappers.FlattenObservation`` turns it
into one flat ``Box`` for an MLP, in the key order below):

==================  =========================  ============================================================
key                 space                      meaning
==================  =========================  ============================================================
``"lidar"``         ``Box(0, 1, (n,))``        nearest reading per base-frame sector, as a fraction of
                                               ``lidar_range`` (table below)
``"lidar_known"``   ``MultiBinary(n)``         1 where the sector holds at least one informative beam
``"goal"``          ``Box((0, -pi), (d, pi))`` goal distance [m] (clipped to ``d = max_goal_distance``)
                                               and bearing [rad] in the base frame; goal tasks only
``"velocity"``      ``Box(lower, upper)``      measured ``(v [m/s], omega [rad/s])``, clipped to the
                                               robot's velocity limits
==================  =========================  ============================================================

Sector ``k`` of ``n`` is centred on the base-frame direction ``k * 2*pi/n`` (REP-103: sector 0
looks straight ahead, ``n/4`` to the left, ``n/2`` behind) and spans ``2*pi/n``. Beams are
assigned to sectors by their direction through the lidar's mount pose, never by index, so the
ROSbot's backwards lidar and the m2wr's 180-degree lidar give the same layout. Each sector holds
the smallest of its beams' values, REP-117 readings mapped as:

==============================================  =======================================================
reading                                         value
==============================================  =======================================================
finite, in ``[range_min, range_max]``           ``min(range, lidar_range) / lidar_range``
``+inf`` (no return within ``range_max``)       ``min(range_max, lidar_range) / lidar_range`` (1.0 for
                                                every preset: free up to the horizon)
``-inf`` (object closer than ``range_min``)     0.0 (an object at the sensor)
``NaN``, finite outside the range limits        ignored (no information)
a sector with no informative beam (outside      0.0, with ``lidar_known = 0``: unknown is never free
the field of view, or only ignored readings)
==============================================  =======================================================

The ranges are measured from the lidar, as in the scan.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from safenav._checks import integer, positive
from safenav.geometry import TWO_PI, Pose2D, wrap_angle
from safenav.robot import RobotSpec
from safenav.scan import LaserScan

__all__ = ["ObservationConfig", "encode_lidar", "observation_space"]


@dataclass(frozen=True)
class ObservationConfig:
    """How scans, goals and velocities become observations; validated on construction.

    Attributes:
        sectors: number of lidar sectors around the base [integer >= 4].
        lidar_range: the horizon of the lidar encoding [m]: farther readings read 1.0.
        max_goal_distance: goal distances are clipped to this [m].
    """

    sectors: int = 36
    lidar_range: float = 4.0
    max_goal_distance: float = 20.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "sectors", integer("ObservationConfig.sectors", self.sectors, low=4))
        object.__setattr__(self, "lidar_range", positive("ObservationConfig.lidar_range", self.lidar_range))
        object.__setattr__(self, "max_goal_distance",
                           positive("ObservationConfig.max_goal_distance", self.max_goal_distance))


def observation_space(config: ObservationConfig, robot: RobotSpec, *, goal: bool) -> Any:
    """The ``Dict`` space of the module docstring for ``robot`` (with the ``"goal"`` key when ``goal``)."""
    from gymnasium import spaces

    n = config.sectors
    items: dict[str, Any] = {
        "lidar": spaces.Box(0.0, 1.0, (n,), dtype=np.float32),
        "lidar_known": spaces.MultiBinary(n),
    }
    if goal:
        items["goal"] = spaces.Box(np.array([0.0, -math.pi], dtype=np.float32),
                                   np.array([config.max_goal_distance, math.pi], dtype=np.float32), dtype=np.float32)
    items["velocity"] = spaces.Box(robot.lower.astype(np.float32), robot.upper.astype(np.float32), dtype=np.float32)
    return spaces.Dict(items)


@functools.lru_cache(maxsize=32)
def _sector_of_beams(angle_min: float, angle_increment: float, n_beams: int, mount_yaw: float,
                     sectors: int) -> np.ndarray:
    """Sector index of every beam of a scan layout (read-only)."""
    base = angle_min + angle_increment * np.arange(n_beams) + mount_yaw
    index = np.rint(np.mod(base, TWO_PI) / (TWO_PI / sectors)).astype(np.intp) % sectors
    index.flags.writeable = False
    return index


def encode_lidar(scan: LaserScan, config: ObservationConfig) -> tuple[np.ndarray, np.ndarray]:
    """The ``"lidar"`` and ``"lidar_known"`` entries for ``scan`` (see the module docstring).

    Returns:
        ``(lidar, known)``: a float32 array in ``[0, 1]`` and an int8 array of 0/1, one per sector.
    """
    n = config.sectors
    horizon = config.lidar_range
    ranges = scan.ranges
    values = np.where(ranges == -math.inf, 0.0, np.minimum(ranges, min(scan.range_max, horizon)))
    informative = (ranges == -math.inf) | (ranges == math.inf) | ((ranges >= scan.range_min) &
                                                                 (ranges <= scan.range_max))
    sector = _sector_of_beams(scan.angle_min, scan.angle_increment, scan.n_beams, scan.mount.yaw, n)
    nearest = np.full(n, math.inf)
    np.minimum.at(nearest, sector[informative], values[informative])
    known = np.isfinite(nearest)
    lidar = np.where(known, np.minimum(nearest, horizon) / horizon, 0.0).astype(np.float32)
    return lidar, known.astype(np.int8)


def goal_polar(pose: Pose2D, goal: tuple[float, float]) -> tuple[float, float]:
    """Distance [m] and base-frame bearing [rad, in ``[-pi, pi)``] of ``goal`` seen from ``pose``."""
    dx, dy = goal[0] - pose.x, goal[1] - pose.y
    return math.hypot(dx, dy), float(wrap_angle(math.atan2(dy, dx) - pose.yaw))


def encode_goal(pose: Pose2D, goal: tuple[float, float], config: ObservationConfig) -> np.ndarray:
    """The ``"goal"`` entry: ``(distance clipped to max_goal_distance [m], bearing [rad])`` as float32."""
    distance, bearing = goal_polar(pose, goal)
    return np.array([min(distance, config.max_goal_distance), bearing], dtype=np.float32)


def encode_velocity(velocity: np.ndarray, robot: RobotSpec) -> np.ndarray:
    """The ``"velocity"`` entry: the measured velocity clipped to the robot's limits, float32."""
    return np.clip(velocity, robot.lower, robot.upper).astype(np.float32)

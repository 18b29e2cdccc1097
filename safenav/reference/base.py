"""What every nominal policy shares.

A nominal policy maps the latest :class:`~safenav.scan.LaserScan` (and, for
goal-seeking policies, the robot's pose) to a command ``(v [m/s], omega [rad/s])``.
It knows nothing about safety filters. It finds directions by angle through the
scan's mount pose, never by a fixed beam index, so it works with any lidar
convention.

Besides the :class:`Policy` base, this module holds the one rule every reference
policy uses to compare a direction of the scan with a distance threshold
(:func:`check_sector`, :func:`check_beam`), so that invalid readings and unseen
directions are treated the same way everywhere (REP-117). The
:class:`Proximity` of a direction is

* ``NEAR`` when a beam reads ``-inf`` (an object closer than ``range_min``), or the
  nearest hit is below the threshold;
* ``AT_THRESHOLD`` or ``CLEAR`` when the nearest hit is at or beyond the threshold;
* ``CLEAR`` when every informative beam reads ``+inf`` (nothing within ``range_max``)
  and ``range_max >= threshold``, ``UNKNOWN`` when ``range_max`` falls short of it;
* ``UNKNOWN`` when no beam is informative (``NaN``, finite values outside
  ``[range_min, range_max]``, or the direction outside the field of view), and when
  part of a sector lies outside the field of view with nothing near in the rest.

Invalid beams among informative ones are ignored, as the tutorials ignore them;
a direction with *no* informative beam is never read as clear.
"""

from __future__ import annotations

import abc
import enum
import math
from dataclasses import dataclass
from typing import Any

from safenav._checks import vector
from safenav.errors import InvalidConfig, InvalidScanType
from safenav.geometry import Pose2D
from safenav.robot import Command, RobotSpec
from safenav.scan import LaserScan, Reading, SectorState

__all__ = ["Policy", "Proximity", "RangeCheck", "TutorialController", "check_beam", "check_sector"]

_COVERAGE_TOL = 1e-9


class Policy(abc.ABC):
    """A nominal policy: ``policy(scan, pose) -> Command``.

    Subclasses implement :meth:`__call__` and, when they keep state, :meth:`reset`
    and :attr:`state`.
    """

    @abc.abstractmethod
    def __call__(self, scan: LaserScan, pose: Pose2D | None = None) -> Command:
        """The nominal command for this scan.

        Args:
            scan: the latest scan, in the robot's current base frame.
            pose: the robot's pose in the world (odometry) [m, m, rad]; only goal-seeking
                policies need it.
        """

    def reset(self, seed: int | None = None) -> None:  # noqa: B027 - optional hook for stateful policies
        """Forget internal state before a new episode; ``seed`` reseeds random policies."""

    @property
    def state(self) -> str:
        """Name of the internal state, for logging (e.g. the wall follower's ``"follow the wall"``)."""
        return ""


class TutorialController(Policy):
    """A tutorial's controller: each scan decides a state and a command, clipped to an optional robot.

    Subclasses implement :meth:`_decide` (the tutorial's rule, which also updates the state they
    report); this class checks the scan and applies the robot's velocity limits, so every tutorial
    controller treats a non-scan and the limits the same way.

    Attributes:
        robot: when given, commands are clipped to its velocity limits.
    """

    robot: RobotSpec | None

    def __call__(self, scan: LaserScan, pose: Pose2D | None = None) -> Command:
        """The command the tutorial's rule gives for this scan (see the class), within the robot's limits.

        Args:
            scan: the latest scan.
            pose: unused: the tutorials steer by the scan alone.

        Raises:
            InvalidScanType: ``scan`` is not a :class:`~safenav.scan.LaserScan`.
        """
        return limited(self._decide(require_scan(type(self).__name__, scan)), self.robot)

    @abc.abstractmethod
    def _decide(self, scan: LaserScan) -> Command:
        """The tutorial's command for ``scan``, before the robot's limits; updates the state."""


class Proximity(enum.Enum):
    """How a direction of the scan compares with a distance threshold."""

    NEAR = "near"
    """Something is closer than the threshold (or closer than ``range_min``)."""
    AT_THRESHOLD = "at threshold"
    """The nearest reading equals the threshold exactly (the tutorials' strict comparisons differ here)."""
    CLEAR = "clear"
    """Every informative reading is beyond the threshold and the whole direction is seen."""
    UNKNOWN = "unknown"
    """No informative reading, or part of the direction unseen with nothing near in the rest."""


@dataclass(frozen=True)
class RangeCheck:
    """The nearest reading in a direction and how it compares with a threshold.

    Attributes:
        distance: nearest informative range [m], measured from the laser: the hit's range,
            ``range_min`` for a ``-inf`` reading, ``inf`` when every informative beam saw
            nothing within ``range_max``, ``nan`` without an informative beam (for raw
            index reads, the raw value).
        proximity: see :class:`Proximity`.
    """

    distance: float
    proximity: Proximity


def _judge(distance: float, too_close: bool, informative: bool, fully_seen: bool, range_max: float,
           threshold: float) -> Proximity:
    """The :class:`Proximity` of a direction from its nearest reading (see the module docstring)."""
    if too_close:
        return Proximity.NEAR
    if not informative:
        return Proximity.UNKNOWN
    if distance < threshold:
        return Proximity.NEAR
    if not fully_seen:
        return Proximity.UNKNOWN
    if math.isinf(distance):  # only +inf: free up to range_max, unknown beyond it
        return Proximity.CLEAR if range_max >= threshold else Proximity.UNKNOWN
    return Proximity.AT_THRESHOLD if distance == threshold else Proximity.CLEAR


def check_sector(scan: LaserScan, lo: float, hi: float, threshold: float) -> RangeCheck:
    """Compare the nearest reading of a base-frame sector with ``threshold``.

    Args:
        scan: the scan.
        lo: start of the sector in the base frame [rad].
        hi: end of the sector, counter-clockwise from ``lo`` [rad].
        threshold: distance from the laser [m].

    Returns:
        The sector's nearest reading and its :class:`Proximity`, following the rule of the module docstring.
    """
    sector = scan.sector(lo, hi)
    return RangeCheck(sector.min_range, _judge(
        sector.min_range,
        too_close=sector.n_too_close > 0,
        informative=sector.state is not SectorState.UNKNOWN,
        fully_seen=sector.coverage >= 1.0 - _COVERAGE_TOL,
        range_max=scan.range_max,
        threshold=threshold,
    ))


def check_beam(scan: LaserScan, direction: float, threshold: float) -> RangeCheck:
    """Compare the single beam nearest a base-frame direction with ``threshold``.

    Args:
        scan: the scan.
        direction: direction in the base frame [rad].
        threshold: distance from the laser [m].

    Returns:
        The beam's reading (``nan`` when invalid or outside the field of view) and its
        :class:`Proximity`, following the rule of the module docstring.
    """
    index = scan.beam_index(direction)
    if index is None:
        return RangeCheck(math.nan, Proximity.UNKNOWN)
    reading = Reading(int(scan.readings[index]))
    distance = {
        Reading.HIT: float(scan.ranges[index]),
        Reading.NO_RETURN: math.inf,
        Reading.TOO_CLOSE: scan.range_min,
        Reading.INVALID: math.nan,
    }[reading]
    return RangeCheck(distance, _judge(
        distance,
        too_close=reading is Reading.TOO_CLOSE,
        informative=reading is not Reading.INVALID,
        fully_seen=True,
        range_max=scan.range_max,
        threshold=threshold,
    ))


# ---------------------------------------------------------------------- helpers for the policies


def require_scan(owner: str, scan: Any) -> LaserScan:
    """``scan`` itself, or :class:`~safenav.errors.InvalidScanType` naming ``owner``."""
    if not isinstance(scan, LaserScan):
        raise InvalidScanType(
            f"{owner} needs a safenav LaserScan, got {type(scan).__name__}; "
            "convert a ROS message with LaserScan.from_msg(msg, mount=robot.lidar.mount)"
        )
    return scan


def command_pair(owner: str, name: str, value: Any) -> Command:
    """``value`` as a finite :class:`~safenav.robot.Command`, or :class:`~safenav.errors.InvalidConfig`."""
    return Command(*vector(f"{owner}.{name}", value, 2, expected="a pair (v [m/s], omega [rad/s])"))


def robot_spec(name: str, robot: Any) -> RobotSpec:
    """``robot`` if it is a :class:`~safenav.robot.RobotSpec`, else :class:`~safenav.errors.InvalidConfig`."""
    if not isinstance(robot, RobotSpec):
        raise InvalidConfig(f"{name} must be a RobotSpec (e.g. safenav.preset('rosbot')), got {robot!r}")
    return robot


def optional_robot(owner: str, robot: Any) -> RobotSpec | None:
    """``robot`` when it is ``None`` or a :class:`~safenav.robot.RobotSpec`, else :class:`InvalidConfig`."""
    if robot is not None and not isinstance(robot, RobotSpec):
        raise InvalidConfig(f"{owner}.robot must be a RobotSpec (e.g. safenav.preset('rosbot')) or None, got {robot!r}")
    return robot


def limited(command: Command, robot: RobotSpec | None) -> Command:
    """``command`` clipped to the robot's velocity limits (unchanged without a robot), as Python floats."""
    if robot is None:
        return Command(float(command.v), float(command.omega))
    v, omega = robot.clip(command)
    return Command(float(v), float(omega))

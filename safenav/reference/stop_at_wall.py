"""Tutorial 1 (Husarion ROSbot 2, "stop at a wall"): drive forward until the wall ahead is within 1 m."""

from __future__ import annotations

import math
from typing import Any

from safenav._checks import angle, optional_integer, positive
from safenav.errors import InvalidConfig, InvalidScan
from safenav.reference.base import (
    Proximity,
    RangeCheck,
    TutorialController,
    check_beam,
    check_sector,
    optional_robot,
)
from safenav.robot import Command, RobotSpec
from safenav.scan import LaserScan

__all__ = ["StopAtWall"]

TUTORIAL_SPEED = 0.5
"""The tutorial's forward speed [m/s]."""
TUTORIAL_THRESHOLD = 1.0
"""The tutorial's stopping distance [m]."""
TUTORIAL_FRONT_INDEX = 360
"""The beam the tutorial reads as "front"; on the ROSbot it looks backward."""

STATES = ("stop", "go")
"""The state names, for logging."""


class StopAtWall(TutorialController):
    """Drive straight ahead while the front reading is beyond a threshold; stop otherwise.

    Reproduces tutorial 1 (Husarion ROSbot 2, "stop at a wall"): the node publishes
    ``linear.x = 0.5`` while the front reading is ``> 1.0`` m and ``0`` otherwise, never
    turning. The comparison is the tutorial's strict ``>``: a front reading of exactly the
    threshold stops the robot.

    The tutorial reads ``msg.ranges[360]`` as the front, but the ROSbot's RPLIDAR spans
    -pi..pi and is mounted backwards (yaw pi), so beam 360 looks *backward* and beam 0
    forward: the tutorial robot drives into the wall ahead as long as nothing is behind it.
    :meth:`tutorial_bug` (or ``front_index=360``) reproduces that bug on purpose, reading the
    raw value of that beam exactly as the tutorial did, so that benchmarks can show a safety
    filter saving the buggy controller.

    Deliberate differences of the default (fixed) policy:

    * The front is found by angle through the scan's mount pose (the beam nearest base-frame
      direction 0, or the nearest reading in a cone of ``front_half_width``), so it works on
      any lidar convention.
    * Readings follow REP-117: ``+inf`` (nothing within ``range_max``)
      goes when ``range_max >= threshold``, ``-inf`` (object closer than ``range_min``) stops,
      and a front with no informative reading (``NaN``, a finite value outside
      ``[range_min, range_max]``, or a front outside the field of view) stops: the robot does
      not drive into the unknown. The tutorial compares raw values, so it would drive on a
      spurious finite reading above ``range_max``.

    In raw-index mode (``front_index`` given) the raw value is compared with ``>`` exactly as
    the tutorial's Python did: ``NaN`` stops, ``+inf`` goes, ``-inf`` stops, and finite
    values outside the sensor's range are taken at face value.

    Attributes:
        speed: forward speed while the front is clear [m/s].
        threshold: stop when the front reading is at or below this distance from the laser [m].
        front_half_width: half-width of the front cone [rad]; 0 reads the single beam nearest
            straight ahead, as the tutorial reads a single beam.
        front_index: raw beam index read as "front" (the tutorial's bug), or ``None`` to find
            the front by angle.
        robot: when given, commands are clipped to its velocity limits (the tutorial's numbers
            are within the ROSbot's limits, so nothing is clipped there).
    """

    def __init__(
        self,
        *,
        speed: float = TUTORIAL_SPEED,
        threshold: float = TUTORIAL_THRESHOLD,
        front_half_width: float = 0.0,
        front_index: int | None = None,
        robot: RobotSpec | None = None,
    ) -> None:
        """Configure the policy.

        Args:
            speed: forward speed while the front is clear [m/s], > 0.
            threshold: stopping distance from the laser [m], > 0.
            front_half_width: half-width of the front cone [rad], in ``[0, pi/2]``; 0 reads one beam.
            front_index: raw beam index to read as "front" (reproduces the tutorial's bug), or
                ``None`` (default) to find the front by angle.
            robot: optional robot whose velocity limits clip the commands.

        Raises:
            InvalidConfig: a value is out of range (the message names it), or both
                ``front_index`` and a non-zero ``front_half_width`` are given.
        """
        owner = type(self).__name__
        self.speed = positive(f"{owner}.speed", speed)
        self.threshold = positive(f"{owner}.threshold", threshold)
        self.front_half_width = angle(f"{owner}.front_half_width", front_half_width, high=0.5 * math.pi,
                                      allow_zero=True)
        self.front_index = optional_integer(f"{owner}.front_index", front_index, low=0)
        if front_index is not None and self.front_half_width > 0.0:
            raise InvalidConfig(
                f"{owner}: front_index={front_index!r} reads one raw beam; front_half_width must be 0, "
                f"got {front_half_width!r}"
            )
        self.robot = optional_robot(owner, robot)
        self._state = STATES[0]
        self._front: RangeCheck | None = None

    @classmethod
    def tutorial_bug(cls, **kwargs: Any) -> StopAtWall:
        """The tutorial exactly as published, bug included: it reads raw beam 360 as "front".

        On the ROSbot (lidar mounted backwards) beam 360 looks backward, so the robot keeps
        driving toward a wall ahead. Other arguments are as for the constructor.
        """
        return cls(front_index=TUTORIAL_FRONT_INDEX, **kwargs)

    @property
    def buggy(self) -> bool:
        """True when the front is a raw beam index (the tutorial's bug) rather than found by angle."""
        return self.front_index is not None

    @property
    def state(self) -> str:
        """``"go"`` or ``"stop"`` (``"stop"`` before the first scan)."""
        return self._state

    @property
    def front(self) -> RangeCheck | None:
        """The last front reading [m] and its comparison with the threshold (``None`` before the first scan)."""
        return self._front

    def reset(self, seed: int | None = None) -> None:
        """Back to ``"stop"`` with no front reading; ``seed`` is unused (the policy is deterministic)."""
        self._state = STATES[0]
        self._front = None

    def _decide(self, scan: LaserScan) -> Command:
        """``(speed, 0)`` while the front reading is beyond the threshold, else ``(0, 0)``.

        Raises:
            InvalidScan: in raw-index mode, the scan has no beam ``front_index`` (the tutorial
                would fail with an ``IndexError``).
        """
        front = self._read_front(scan)
        self._front = front
        go = front.proximity is Proximity.CLEAR
        self._state = STATES[int(go)]
        return Command(self.speed if go else 0.0, 0.0)

    def _read_front(self, scan: LaserScan) -> RangeCheck:
        if self.front_index is not None:
            if self.front_index >= scan.n_beams:
                raise InvalidScan(
                    f"StopAtWall reads raw beam front_index={self.front_index} but the scan has "
                    f"{scan.n_beams} beams (indices 0..{scan.n_beams - 1})"
                )
            raw = float(scan.ranges[self.front_index])
            if raw > self.threshold:
                proximity = Proximity.CLEAR
            elif raw == self.threshold:
                proximity = Proximity.AT_THRESHOLD
            elif raw < self.threshold:
                proximity = Proximity.NEAR
            else:  # NaN: every comparison is false, so the tutorial publishes 0
                proximity = Proximity.UNKNOWN
            return RangeCheck(raw, proximity)
        if self.front_half_width > 0.0:
            return check_sector(scan, -self.front_half_width, self.front_half_width, self.threshold)
        return check_beam(scan, 0.0, self.threshold)

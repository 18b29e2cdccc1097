"""Tutorial 2 (Puzzlebot, "simple obstacle avoidance"): turn in place while something is close ahead."""

from __future__ import annotations

import math

from safenav._checks import angle, positive
from safenav.reference.base import (
    Proximity,
    RangeCheck,
    TutorialController,
    check_sector,
    command_pair,
    optional_robot,
)
from safenav.robot import Command, RobotSpec
from safenav.scan import LaserScan

__all__ = ["ObstacleAvoidance"]

TUTORIAL_THRESHOLD = 0.5
"""Distance under which a reading in the cone counts as an obstacle [m]."""
TUTORIAL_HALF_ANGLE = math.radians(15.0)
"""Half-width of the cone ahead [rad] (+-15 degrees)."""
TUTORIAL_CRUISE = (0.2, 0.3)
"""Command while the cone is clear: forward while turning [m/s, rad/s]."""
TUTORIAL_TURN = (0.0, 0.5)
"""Command while something is close ahead: turn in place [m/s, rad/s]."""

STATES = ("drive", "turn in place")
"""The state names, for logging."""


class ObstacleAvoidance(TutorialController):
    """Drive forward while turning gently; turn in place while anything is close ahead.

    Reproduces tutorial 2 (Manchester Robotics Puzzlebot, "simple obstacle avoidance"):
    if any valid reading within +-15 degrees of the front is closer than 0.5 m, publish
    ``(0, 0.5)`` (turn in place), else ``(0.2, 0.3)``. The comparison is the tutorial's
    strict ``<``: a nearest reading of exactly 0.5 m counts as clear.

    Deliberate differences:

    * The cone is found by angle through the scan's mount pose (``scan.sector``), not by
      index ranges, so the wrap-around of the Puzzlebot's 0..2pi scan (the cone spans both ends of
      the ranges array, beams 345..359 and 0..14) and any other lidar convention are handled the same way.
    * Readings follow REP-117: a ``-inf`` reading (object closer than
      ``range_min``) turns; finite values outside ``[range_min, range_max]`` are discarded
      as the sensor's spec says (the tutorial would turn on a spurious reading below
      ``range_min``); ``NaN`` readings are ignored as the tutorial ignores invalid ones.
    * A cone with no informative reading, or partly outside the field of view with nothing
      near in the rest, is *unknown* and the robot turns in place: unseen is never clear.

    Attributes:
        threshold: distance from the laser under which a reading is an obstacle [m].
        half_angle: half-width of the cone ahead [rad].
        cruise: command while the cone is clear ``(v [m/s], omega [rad/s])``.
        turn: command while the cone is blocked or unknown ``(v [m/s], omega [rad/s])``.
        robot: when given, commands are clipped to its velocity limits (the tutorial's numbers
            are within the Puzzlebot's limits, so nothing is clipped there).
    """

    def __init__(
        self,
        *,
        threshold: float = TUTORIAL_THRESHOLD,
        half_angle: float = TUTORIAL_HALF_ANGLE,
        cruise: tuple[float, float] = TUTORIAL_CRUISE,
        turn: tuple[float, float] = TUTORIAL_TURN,
        robot: RobotSpec | None = None,
    ) -> None:
        """Configure the policy.

        Args:
            threshold: obstacle distance [m], > 0.
            half_angle: half-width of the cone ahead [rad], in ``(0, pi]``.
            cruise: command while clear ``(v [m/s], omega [rad/s])``, finite.
            turn: command while blocked ``(v [m/s], omega [rad/s])``, finite.
            robot: optional robot whose velocity limits clip the commands.

        Raises:
            InvalidConfig: a value is out of range (the message names it).
        """
        owner = type(self).__name__
        self.threshold = positive(f"{owner}.threshold", threshold)
        self.half_angle = angle(f"{owner}.half_angle", half_angle, high=math.pi)
        self.cruise = command_pair(owner, "cruise", cruise)
        self.turn = command_pair(owner, "turn", turn)
        self.robot = optional_robot(owner, robot)
        self._state = STATES[0]
        self._cone: RangeCheck | None = None

    @property
    def state(self) -> str:
        """``"drive"`` or ``"turn in place"`` (``"drive"`` before the first scan)."""
        return self._state

    @property
    def cone(self) -> RangeCheck | None:
        """The last nearest reading in the cone [m] and its comparison (``None`` before the first scan)."""
        return self._cone

    def reset(self, seed: int | None = None) -> None:
        """Back to ``"drive"`` with no cone reading; ``seed`` is unused (the policy is deterministic)."""
        self._state = STATES[0]
        self._cone = None

    def _decide(self, scan: LaserScan) -> Command:
        """:attr:`turn` when the cone ahead is blocked or unknown, else :attr:`cruise`."""
        cone = check_sector(scan, -self.half_angle, self.half_angle, self.threshold)
        self._cone = cone
        blocked = cone.proximity in (Proximity.NEAR, Proximity.UNKNOWN)
        self._state = STATES[int(blocked)]
        return self.turn if blocked else self.cruise

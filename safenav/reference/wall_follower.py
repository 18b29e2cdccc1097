"""Tutorial 3 (The Construct's m2wr, "Exploring ROS with a 2 wheeled robot"): follow a wall on the right."""

from __future__ import annotations

import math
from collections.abc import Mapping
from types import MappingProxyType

from safenav._checks import angle, positive
from safenav.errors import InvalidConfig
from safenav.geometry import TWO_PI
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

__all__ = ["WallFollower"]

TUTORIAL_THRESHOLD = 1.5
"""The tutorial's ``d``: a region closer than this is "near" [m]."""
TUTORIAL_CLAMP = 10.0
"""The tutorial clamps every region's minimum to this value [m]."""
TUTORIAL_SPAN = math.pi
"""Angular span of the five regions, centred straight ahead [rad] (the m2wr's 180-degree lidar)."""
TUTORIAL_FIND_WALL = (0.2, -0.3)
"""Command of state 0, "find the wall": forward while turning right [m/s, rad/s]."""
TUTORIAL_TURN_LEFT = (0.0, 0.3)
"""Command of state 1, "turn left": turn in place [m/s, rad/s]."""
TUTORIAL_FOLLOW_WALL = (0.5, 0.0)
"""Command of state 2, "follow the wall": straight ahead [m/s, rad/s]."""

STATES = ("find the wall", "turn left", "follow the wall")
"""The tutorial's three states, by its state number 0, 1, 2."""
REGIONS = ("right", "fright", "front", "fleft", "left")
"""The tutorial's five regions, clockwise-most first (its index order on the m2wr)."""

CASES: Mapping[tuple[bool, bool, bool], tuple[int, int]] = MappingProxyType({
    # (front near, fleft near, fright near): (tutorial case, state)
    (False, False, False): (1, 0),
    (True, False, False): (2, 1),
    (False, False, True): (3, 2),
    (False, True, False): (4, 0),
    (True, False, True): (5, 1),
    (True, True, False): (6, 1),
    (True, True, True): (7, 1),
    (False, True, True): (8, 0),
})
"""The tutorial's eight cases: which of front, fleft, fright are near -> (case number, state number)."""

CASE_DESCRIPTIONS = (
    "unknown case",
    "case 1 - nothing",
    "case 2 - front",
    "case 3 - fright",
    "case 4 - fleft",
    "case 5 - front and fright",
    "case 6 - front and fleft",
    "case 7 - front and fleft and fright",
    "case 8 - fleft and fright",
)
"""The tutorial's log strings, by case number (0 is its ``else`` branch)."""


class WallFollower(TutorialController):
    """Find a wall, turn left at corners, and follow the wall on the robot's right.

    Reproduces tutorial 3 (The Construct, "Exploring ROS with a 2 wheeled robot", m2wr with
    a 720-beam lidar over -pi/2..pi/2). The tutorial splits the scan into five regions
    (right, fright, front, fleft, left), each the minimum range clamped to 10 m, and with
    ``d = 1.5`` m maps which of front, fleft and fright are nearer than ``d`` to a state:

    ====  =============================  =====================
    case  near (``< d``)                 state
    ====  =============================  =====================
    1     nothing                        0 find the wall
    2     front                          1 turn left
    3     fright                         2 follow the wall
    4     fleft                          0 find the wall
    5     front and fright               1 turn left
    6     front and fleft                1 turn left
    7     front, fleft and fright        1 turn left
    8     fleft and fright               0 find the wall
    ====  =============================  =====================

    with the commands find the wall ``(0.2, -0.3)``, turn left ``(0, 0.3)`` and follow the
    wall ``(0.5, 0)``. The right and left regions are computed (see :attr:`regions`) but, as in
    the tutorial, unused. The tutorial's comparisons are strict on both sides (``< d`` and
    ``> d``), so when a region reads exactly ``d`` no case matches, its ``else`` branch logs
    "unknown case" and the state does not change; this policy does the same (:attr:`case` is
    0). The state starts at 0, "find the wall".

    Deliberate differences:

    * The regions are defined by base-frame angle, through the scan's mount pose: five equal
      slices of ``span`` (default pi, so the tutorial's 36-degree slices from -90 to +90
      degrees) centred straight ahead, rather than the index ranges ``[0:143]``, ``[144:287]``,
      ... of the m2wr's scan (which also skip the boundary beams 143, 287, 431, 575 and
      714..719). Any lidar that covers the slices works, whatever its field of view,
      ``angle_min`` or mount yaw. A beam exactly on a boundary belongs to both slices.
    * Readings follow REP-117: ``+inf`` is free up to ``range_max``
      (clamped to 10 m as in the tutorial); ``-inf`` is near; ``NaN`` and finite values outside
      ``[range_min, range_max]`` are ignored. A region with no informative beam, or partly
      outside the field of view with nothing near in the rest, is *unknown* and counts as near
      (conservative: an unknown front makes the robot turn in place, never drive into it); its
      :attr:`regions` value is ``nan``. The tutorial's Python ``min`` over ``NaN`` values gives
      order-dependent results instead.

    Attributes:
        threshold: the tutorial's ``d`` [m].
        clamp: every region's minimum is clamped to this value [m], > ``threshold``.
        span: angular span of the five regions, centred straight ahead [rad].
        commands: the command of each state, by state number ``(v [m/s], omega [rad/s])``.
        robot: when given, commands are clipped to its velocity limits (the tutorial's numbers
            are within the m2wr's limits, so nothing is clipped there).
    """

    def __init__(
        self,
        *,
        threshold: float = TUTORIAL_THRESHOLD,
        clamp: float = TUTORIAL_CLAMP,
        span: float = TUTORIAL_SPAN,
        find_wall: tuple[float, float] = TUTORIAL_FIND_WALL,
        turn_left: tuple[float, float] = TUTORIAL_TURN_LEFT,
        follow_wall: tuple[float, float] = TUTORIAL_FOLLOW_WALL,
        robot: RobotSpec | None = None,
    ) -> None:
        """Configure the policy.

        Args:
            threshold: the tutorial's ``d`` [m], > 0.
            clamp: clamp of each region's minimum [m], > ``threshold``.
            span: angular span of the five regions [rad], in ``(0, 2*pi]``.
            find_wall: command of state 0 ``(v [m/s], omega [rad/s])``.
            turn_left: command of state 1 ``(v [m/s], omega [rad/s])``.
            follow_wall: command of state 2 ``(v [m/s], omega [rad/s])``.
            robot: optional robot whose velocity limits clip the commands.

        Raises:
            InvalidConfig: a value is out of range (the message names it).
        """
        owner = type(self).__name__
        self.threshold = positive(f"{owner}.threshold", threshold)
        self.clamp = positive(f"{owner}.clamp", clamp)
        if self.clamp <= self.threshold:
            raise InvalidConfig(
                f"{owner}.clamp must be > threshold={self.threshold!r} (else every region reads near), got {clamp!r}"
            )
        self.span = angle(f"{owner}.span", span, high=TWO_PI)
        self.commands = (
            command_pair(owner, "find_wall", find_wall),
            command_pair(owner, "turn_left", turn_left),
            command_pair(owner, "follow_wall", follow_wall),
        )
        self.robot = optional_robot(owner, robot)
        width = self.span / len(REGIONS)
        start = -0.5 * self.span
        self._sectors = MappingProxyType({
            name: (start + k * width, start + (k + 1) * width) for k, name in enumerate(REGIONS)
        })
        self._state_id = 0
        self._case: int | None = None
        self._checks: Mapping[str, RangeCheck] = MappingProxyType({})

    @property
    def sectors(self) -> Mapping[str, tuple[float, float]]:
        """Each region's base-frame sector ``(lo, hi)`` [rad], counter-clockwise from ``lo``."""
        return self._sectors

    @property
    def state(self) -> str:
        """The tutorial's state name: ``"find the wall"``, ``"turn left"`` or ``"follow the wall"``."""
        return STATES[self._state_id]

    @property
    def state_id(self) -> int:
        """The tutorial's state number: 0 find the wall, 1 turn left, 2 follow the wall."""
        return self._state_id

    @property
    def case(self) -> int | None:
        """The tutorial's case of the last scan, 1..8, or 0 for its "unknown case" (``None`` before any scan)."""
        return self._case

    @property
    def case_description(self) -> str:
        """The tutorial's log string for :attr:`case` (empty before any scan)."""
        return "" if self._case is None else CASE_DESCRIPTIONS[self._case]

    @property
    def checks(self) -> Mapping[str, RangeCheck]:
        """Each region's nearest reading [m] and its comparison with the threshold (empty before any scan)."""
        return self._checks

    @property
    def regions(self) -> Mapping[str, float]:
        """The tutorial's ``regions``: each region's minimum range clamped to :attr:`clamp` [m], ``nan`` if unknown."""
        return MappingProxyType({name: min(check.distance, self.clamp) if check.proximity is not Proximity.UNKNOWN
                                 else math.nan for name, check in self._checks.items()})

    def reset(self, seed: int | None = None) -> None:
        """Back to state 0, "find the wall", with no regions; ``seed`` is unused (the policy is deterministic)."""
        self._state_id = 0
        self._case = None
        self._checks = MappingProxyType({})

    def _decide(self, scan: LaserScan) -> Command:
        """The command of the state the tutorial's case analysis gives for this scan."""
        checks = MappingProxyType({
            name: check_sector(scan, lo, hi, self.threshold) for name, (lo, hi) in self._sectors.items()
        })
        self._checks = checks
        used = (checks["front"], checks["fleft"], checks["fright"])
        if any(check.proximity is Proximity.AT_THRESHOLD for check in used):
            self._case = 0  # the tutorial's "unknown case": the state is left as it was
        else:
            near = tuple(check.proximity in (Proximity.NEAR, Proximity.UNKNOWN) for check in used)
            self._case, self._state_id = CASES[near]
        return self.commands[self._state_id]

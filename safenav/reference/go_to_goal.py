"""Go to a goal point, ignoring obstacles: the standard nominal that a safety filter must make safe."""

from __future__ import annotations

import math
from collections.abc import Sequence

from safenav._checks import angle, positive, vector
from safenav.errors import InvalidConfig
from safenav.geometry import Pose2D, wrap_angle
from safenav.reference.base import Policy, limited, require_scan, robot_spec
from safenav.robot import Command, RobotSpec
from safenav.scan import LaserScan

__all__ = ["GoToGoal"]

STATES = ("idle", "turn", "drive", "reached")
"""The state names, for logging."""


class GoToGoal(Policy):
    """Turn toward a goal point and drive to it, blind to obstacles on purpose.

    Not a tutorial controller: the standard go-to-goal nominal of the safety-filter
    literature, which drives straight through anything in the way so that the filter has
    to make it safe. It uses the pose (odometry) and never looks at the scan.

    The control law, with ``e`` the heading error to the goal wrapped into ``[-pi, pi)``
    and ``rho`` the distance to it:

    * ``rho <= stop_radius``: ``(0, 0)``, state ``"reached"``;
    * ``|e| > turn_in_place_angle``: ``(0, omega)``, state ``"turn"``;
    * otherwise ``(min(speed, distance_gain * rho) * cos(e), omega)``, state ``"drive"``,

    with ``omega = clip(heading_gain * e, -omega_max, omega_max)``, and the command clipped to
    the robot's velocity limits. It never reverses.

    Attributes:
        robot: the robot whose limits bound the commands.
        speed: cruise speed [m/s], at most ``robot.v_max``.
        heading_gain: proportional gain on the heading error [1/s].
        distance_gain: proportional gain on the distance, which slows the approach [1/s].
        turn_in_place_angle: heading error above which the robot turns in place [rad].
        stop_radius: distance to the goal within which the robot stops [m].
    """

    def __init__(
        self,
        robot: RobotSpec,
        goal: Sequence[float],
        *,
        speed: float | None = None,
        heading_gain: float = 2.0,
        distance_gain: float = 1.0,
        turn_in_place_angle: float = math.pi / 4,
        stop_radius: float = 0.1,
    ) -> None:
        """Configure the policy.

        Args:
            robot: the robot (its velocity limits bound the commands).
            goal: goal point ``(x, y)`` in the world (odometry) frame [m].
            speed: cruise speed [m/s] in ``(0, robot.v_max]``; ``None`` uses ``robot.v_max``.
            heading_gain: proportional gain on the heading error [1/s], > 0.
            distance_gain: proportional gain on the distance [1/s], > 0.
            turn_in_place_angle: heading error above which the robot turns in place [rad],
                in ``(0, pi/2]``.
            stop_radius: stop within this distance of the goal [m], > 0.

        Raises:
            InvalidConfig: a value is out of range (the message names it).
        """
        owner = type(self).__name__
        self.robot = robot_spec(f"{owner}.robot", robot)
        self.speed = robot.v_max if speed is None else positive(f"{owner}.speed", speed)
        if self.speed > robot.v_max:
            raise InvalidConfig(f"{owner}.speed must be at most robot.v_max={robot.v_max!r} m/s, got {speed!r}")
        self.heading_gain = positive(f"{owner}.heading_gain", heading_gain)
        self.distance_gain = positive(f"{owner}.distance_gain", distance_gain)
        self.turn_in_place_angle = angle(f"{owner}.turn_in_place_angle", turn_in_place_angle, high=0.5 * math.pi)
        self.stop_radius = positive(f"{owner}.stop_radius", stop_radius)
        self._goal = vector(f"{owner}.goal", goal, 2)
        self._state = STATES[0]
        self._distance = math.nan
        self._heading_error = math.nan

    @property
    def goal(self) -> tuple[float, float]:
        """Goal point ``(x, y)`` in the world frame [m]; assigning a new one validates it and resets the state."""
        x, y = self._goal
        return x, y

    @goal.setter
    def goal(self, goal: Sequence[float]) -> None:
        self._goal = vector(f"{type(self).__name__}.goal", goal, 2)
        self.reset()

    @property
    def state(self) -> str:
        """``"idle"`` (before the first call), ``"turn"``, ``"drive"`` or ``"reached"``."""
        return self._state

    @property
    def reached(self) -> bool:
        """True when the last pose was within :attr:`stop_radius` of the goal."""
        return self._state == "reached"

    @property
    def distance(self) -> float:
        """Distance from the last pose to the goal [m] (``nan`` before the first call)."""
        return self._distance

    @property
    def heading_error(self) -> float:
        """Bearing of the goal relative to the last heading [rad] (``nan`` before the first call)."""
        return self._heading_error

    def reset(self, seed: int | None = None) -> None:
        """Back to ``"idle"``, keeping the goal; ``seed`` is unused (the policy is deterministic)."""
        self._state = STATES[0]
        self._distance = math.nan
        self._heading_error = math.nan

    def __call__(self, scan: LaserScan, pose: Pose2D | None = None) -> Command:
        """The command toward the goal from ``pose``.

        Args:
            scan: the latest scan (checked, then ignored: this policy is blind to obstacles).
            pose: the robot's pose in the goal's frame ``(x [m], y [m], yaw [rad])``; required.

        Raises:
            InvalidScanType: ``scan`` is not a :class:`~safenav.scan.LaserScan`.
            InvalidConfig: ``pose`` is missing or not three finite numbers.
        """
        owner = type(self).__name__
        require_scan(owner, scan)
        if pose is None:
            raise InvalidConfig(f"{owner} needs the robot's pose (x [m], y [m], yaw [rad]): call policy(scan, pose)")
        x, y, yaw = vector(f"{owner}.pose", pose, 3)
        dx, dy = self._goal[0] - x, self._goal[1] - y
        self._distance = math.hypot(dx, dy)
        self._heading_error = float(wrap_angle(math.atan2(dy, dx) - yaw))
        if self._distance <= self.stop_radius:
            self._state = "reached"
            return Command(0.0, 0.0)
        error = self._heading_error
        omega = self.heading_gain * error  # clipped to +-omega_max by limited()
        if abs(error) > self.turn_in_place_angle:
            self._state = "turn"
            return limited(Command(0.0, omega), self.robot)
        self._state = "drive"
        v = min(self.speed, self.distance_gain * self._distance) * math.cos(error)
        return limited(Command(v, omega), self.robot)

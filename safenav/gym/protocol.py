"""The small protocol an environment implements so that :class:`~safenav.gym.SafetyShield` can guard it.

A safety filter needs what a real robot's filter sees: the latest lidar scan, the measured
velocity and the current time. An environment (or any wrapper in its stack) exposes them
through one method::

    class MyEnv(gymnasium.Env):
        robot = preset("puzzlebot")     # body, limits and lidar         (needed for filter="cbf")
        control_dt = 0.05               # how long each action is held [s] (needed for filter="cbf")

        def safety_observation(self) -> SafetyObservation:
            return SafetyObservation(scan=self._scan, velocity=self._velocity, pose=self._odometry, time=self._time)

The contract, for the shield to keep its guarantee (docs/safety.md):

* ``safety_observation()`` describes the state in which the *next* action will be executed:
  call it after ``reset()`` and after every ``step()``; it is read before each action.
* ``scan`` is a :class:`~safenav.scan.LaserScan` whose ``mount`` is the lidar's pose on the
  base (REP-117 readings; :meth:`LaserScan.from_msg <safenav.scan.LaserScan.from_msg>`
  converts ROS messages).
* ``velocity`` is the measured ``(v [m/s], omega [rad/s])``, or ``None`` when unknown (the
  filter then cannot account for the acceleration limits).
* ``pose`` is the odometry pose ``(x [m], y [m], yaw [rad])`` in any fixed frame, or ``None``;
  with it, the points the filter remembers (beside and behind a lidar that does not see all
  round) are carried exactly, else by ``velocity``.
* ``time`` is the current time [s] on the clock of ``scan.stamp``, or ``None``; with both, the
  filter brakes on a stale scan.
* The action space is a ``Box`` of shape ``(2,)``: ``(v [m/s], omega [rad/s])`` held for
  ``control_dt``, containing the stop command ``(0, 0)``.

safenav's own environments (:class:`~safenav.gym.SafeNavEnv`) implement it.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Protocol, runtime_checkable

import numpy as np

from safenav._checks import number
from safenav.errors import InvalidConfig, InvalidScanType
from safenav.geometry import Pose2D
from safenav.robot import as_command
from safenav.scan import LaserScan

__all__ = ["SafetyObservable", "SafetyObservation"]


@dataclass(frozen=True, eq=False)
class SafetyObservation:
    """What a safety filter needs to know before the next action.

    Attributes:
        scan: the latest scan, in the robot's current base frame.
        velocity: measured ``(v [m/s], omega [rad/s])`` (read-only), or ``None`` when unknown.
        pose: odometry pose ``(x [m], y [m], yaw [rad])`` in any fixed frame, or ``None``.
        time: current time [s] on the clock of ``scan.stamp``, or ``None``.

    Raises:
        InvalidScanType: ``scan`` is not a :class:`~safenav.scan.LaserScan`.
        InvalidCommand: ``velocity`` is not a pair of numbers.
        InvalidConfig: ``pose`` is not three finite numbers, or ``time`` not a finite number.
    """

    scan: LaserScan
    velocity: np.ndarray | None = None
    pose: Pose2D | None = None
    time: float | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.scan, LaserScan):
            raise InvalidScanType(f"SafetyObservation.scan must be a safenav LaserScan (LaserScan.from_msg converts "
                                  f"ROS messages), got {type(self.scan).__name__}")
        if self.velocity is not None:
            velocity = as_command(self.velocity, "SafetyObservation.velocity")
            velocity.flags.writeable = False
            object.__setattr__(self, "velocity", velocity)
        if self.pose is not None:
            object.__setattr__(self, "pose", Pose2D(*pose_triple("SafetyObservation.pose", self.pose)))
        if self.time is not None:
            object.__setattr__(self, "time", number("SafetyObservation.time", self.time))


@runtime_checkable
class SafetyObservable(Protocol):
    """An environment a :class:`~safenav.gym.SafetyShield` can guard (see the module docstring).

    ``robot`` (a :class:`~safenav.robot.RobotSpec`) and ``control_dt`` [s] are needed only when
    the shield builds its filter by name; with a filter instance, ``safety_observation()`` is
    enough.
    """

    def safety_observation(self) -> SafetyObservation:
        """The scan, measured velocity and time in which the next action will be executed."""
        ...


def pose_triple(name: str, value: Any) -> tuple[float, float, float]:
    """``value`` as ``(x, y, yaw)`` finite floats, or :class:`~safenav.errors.InvalidConfig` naming ``name``."""
    if isinstance(value, (str, bytes)) or not isinstance(value, Sequence) or len(value) != 3:
        raise InvalidConfig(f"{name} must be a pose (x [m], y [m], yaw [rad]), got {value!r}")
    return tuple(number(f"{name}[{index}]", item) for index, item in enumerate(value))


def describe(env: Any) -> str:
    """A short name of ``env`` for error messages."""
    spec = getattr(env, "spec", None)
    return f"{type(env).__name__}" + (f" ({spec.id})" if spec is not None and getattr(spec, "id", None) else "")

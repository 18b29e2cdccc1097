"""What every safety filter shares: the result type, the status codes and the input checks.

A safety filter takes a nominal command ``u_nom = (v, omega)``, the latest
:class:`~safenav.scan.LaserScan` and optionally the current velocity and the
scan's age, and returns a frozen :class:`FilterResult`: the command to send and
what the filter did. It never reads simulator truth, never returns NaN, and
never raises inside the control loop for an input it can still act on: it
brakes and says why in :attr:`FilterResult.status`. It raises only for
structural mistakes (a ``u_nom`` of the wrong shape, something that is not a
scan), as :class:`~safenav.errors.InvalidCommand` or
:class:`~safenav.errors.InvalidScanType`.

Subclasses implement :meth:`SafetyFilter._filter`; :meth:`SafetyFilter.filter`
wraps it with the checks every filter needs (stale scan, non-finite nominal,
blind scan, a non-finite answer).
"""

from __future__ import annotations

import abc
import enum
import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from safenav.errors import InvalidConfig, InvalidScanType
from safenav.geometry import Pose2D, unicycle_step
from safenav.robot import RobotSpec, as_command
from safenav.scan import LaserScan

__all__ = ["BRAKING_STATUSES", "FilterResult", "FilterStatus", "SafetyFilter", "check_period"]


class FilterStatus(enum.Enum):
    """What the filter did with the nominal command."""

    OK = "ok"
    """Every constraint holds for the returned command (``u_nom`` itself when it was already safe)."""
    RECOVERING = "recovering"
    """The robot is already inside the margin of some obstacle (a barrier is negative, e.g.
    after noise or a push); the command satisfies the barrier condition, which moves it back out."""
    SLACK = "slack"
    """The constraints could not all hold (the robot is already too close, or cannot brake in
    time); the command violates them as little as possible, moving away from the obstacles."""
    FALLBACK = "fallback"
    """The optimiser failed or its answer failed verification; the robot brakes (the MPC filter
    follows its last verified plan, which ends stopped)."""
    NO_DATA = "no_data"
    """The scan holds no informative beam; the robot brakes."""
    STALE = "stale"
    """The scan is older than the timeout; the robot brakes."""
    BAD_INPUT = "bad_input"
    """The nominal command or the measured velocity is not finite; the robot brakes."""


BRAKING_STATUSES = frozenset({FilterStatus.FALLBACK, FilterStatus.NO_DATA, FilterStatus.STALE,
                              FilterStatus.BAD_INPUT})
"""Statuses in which the filter ignores ``u_nom`` and brakes."""


def _frozen(array: Any, shape: tuple[int, ...] | None = None) -> np.ndarray:
    """A read-only float copy of ``array`` (arrays already read-only float are kept)."""
    if isinstance(array, np.ndarray) and not array.flags.writeable and array.dtype == np.float64:
        result = array
    else:
        result = np.array(array, dtype=float)
        result.flags.writeable = False
    return result if shape is None or result.shape == shape else result.reshape(shape)


@dataclass(frozen=True, eq=False)
class FilterResult:
    """The filtered command and what the filter did to get it.

    Attributes:
        u: the command to send, ``(v [m/s], omega [rad/s])``; always finite and within the limits.
        u_nom: the nominal command as given (may be non-finite when ``status`` is ``BAD_INPUT``).
        status: see :class:`FilterStatus`.
        message: why the filter braked or relaxed a constraint; empty when ``status`` is ``OK``.
        min_barrier: smallest barrier value at the current state [m] (``inf`` without constraints).
        clearance: distance from the base origin to the nearest obstacle point minus the body
            radius [m] (``inf`` when no point is seen); negative means inside the body disk.
        n_constraints: number of obstacle constraints the optimiser saw (after reduction).
        constraint_points: ``(n, 2)`` obstacle points behind those constraints, base frame [m].
        active: indices into ``constraint_points`` of the constraints that hold with equality.
        slack: largest constraint relaxation [m] (0 unless ``status`` is ``SLACK``).
        solver: name of the back-end that produced ``u`` (empty when no optimisation ran).
        solve_time: time spent in the optimiser [s].
        filter_time: time spent in the whole call [s].
        plan: the predicted trajectory, ``(N + 1, 5)`` rows of ``(x, y, yaw, v, omega)`` in the
            current base frame, for predictive filters; ``None`` otherwise.
    """

    u: np.ndarray
    u_nom: np.ndarray
    status: FilterStatus
    message: str = ""
    min_barrier: float = math.inf
    clearance: float = math.inf
    n_constraints: int = 0
    constraint_points: np.ndarray = field(default_factory=lambda: _frozen(np.empty((0, 2))))
    active: tuple[int, ...] = ()
    slack: float = 0.0
    solver: str = ""
    solve_time: float = 0.0
    filter_time: float = 0.0
    plan: np.ndarray | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "u", _frozen(self.u, (2,)))
        object.__setattr__(self, "u_nom", _frozen(self.u_nom, (2,)))
        object.__setattr__(self, "constraint_points", _frozen(self.constraint_points, (-1, 2)))
        object.__setattr__(self, "active", tuple(map(int, self.active)))
        if self.plan is not None:
            object.__setattr__(self, "plan", _frozen(self.plan))

    @property
    def braked(self) -> bool:
        """True when the filter ignored ``u_nom`` and braked (see :data:`BRAKING_STATUSES`)."""
        return self.status in BRAKING_STATUSES

    @property
    def modified(self) -> bool:
        """True when ``u`` differs from ``u_nom``."""
        return not np.array_equal(self.u, self.u_nom)

    @property
    def intervention(self) -> float:
        """Euclidean size of the change ``||u - u_nom||`` in ``(m/s, rad/s)`` (``inf`` if ``u_nom`` is not finite)."""
        difference = self.u - self.u_nom
        return float(np.hypot(*difference)) if np.all(np.isfinite(difference)) else math.inf


def check_period(name: str, value: Any) -> float:
    """A positive, finite duration [s], or :class:`~safenav.errors.InvalidConfig` naming it."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)):
        raise InvalidConfig(f"{name} must be a duration in seconds, got {value!r}")
    if not math.isfinite(value) or value <= 0:
        raise InvalidConfig(f"{name} must be a finite duration > 0 [s], got {value!r}")
    return float(value)


class SafetyFilter(abc.ABC):
    """Base of the safety filters: input checks, the stale-scan watchdog, braking.

    Args:
        robot: the robot whose body and limits the filter protects.
        dt: control period [s]: how long each returned command is held.
        scan_timeout: largest scan age [s] the filter acts on; older scans make it brake.
        compensate_latency: move a scan of known age into the current base frame using the
            measured velocity before filtering.
    """

    name = "filter"

    def __init__(self, robot: RobotSpec, dt: float, *, scan_timeout: float = 0.5,
                 compensate_latency: bool = True) -> None:
        if not isinstance(robot, RobotSpec):
            raise InvalidConfig(f"robot must be a RobotSpec (see safenav.robot.preset), got {robot!r}")
        if not isinstance(compensate_latency, bool):
            raise InvalidConfig(f"compensate_latency must be True or False, got {compensate_latency!r}")
        self.robot = robot
        self.dt = check_period("dt", dt)
        self.scan_timeout = check_period("scan_timeout", scan_timeout)
        self.compensate_latency = compensate_latency

    def reset(self) -> None:  # noqa: B027 - an optional hook: stateless filters need nothing
        """Forget warm-start state (call between episodes)."""

    def __call__(self, u_nom: Any, scan: LaserScan, **kwargs: Any) -> FilterResult:
        return self.filter(u_nom, scan, **kwargs)

    def filter(
        self,
        u_nom: Any,
        scan: LaserScan,
        *,
        velocity: Any = None,
        scan_age: float | None = None,
        now: float | None = None,
    ) -> FilterResult:
        """Filter one nominal command.

        Args:
            u_nom: nominal command ``(v [m/s], omega [rad/s])``.
            scan: the latest scan, in the robot's current base frame.
            velocity: current ``(v [m/s], omega [rad/s])``; when given, the returned command is
                reachable within one period under the acceleration limits.
            scan_age: how old the scan is [s]; past ``scan_timeout`` the filter brakes. With
                ``velocity`` given (and ``compensate_latency``), the scan is first moved into the
                current base frame by the motion since it was taken (:meth:`current_frame`).
            now: the current time [s]; with ``scan.stamp`` it gives the age when ``scan_age`` is ``None``.

        Returns:
            The command to send and what the filter did.

        Raises:
            InvalidCommand: ``u_nom`` or ``velocity`` is not a pair of numbers.
            InvalidScanType: ``scan`` is not a :class:`~safenav.scan.LaserScan`.
        """
        start = time.perf_counter()
        result = self._screened(u_nom, scan, velocity, scan_age, now)
        object.__setattr__(result, "filter_time", time.perf_counter() - start)
        return result

    def _screened(self, u_nom: Any, scan: LaserScan, velocity: Any, scan_age: float | None,
                  now: float | None) -> FilterResult:
        """The checks every filter needs around :meth:`_filter` (see :meth:`filter`)."""
        nominal = as_command(u_nom, "u_nom")
        if not isinstance(scan, LaserScan):
            raise InvalidScanType(
                f"scan must be a safenav LaserScan (use LaserScan.from_msg for ROS messages), got {type(scan).__name__}"
            )
        current = None
        if velocity is not None:
            current = as_command(velocity, "velocity")
            if not np.all(np.isfinite(current)):
                return self._brake(nominal, None, FilterStatus.BAD_INPUT,
                                   f"velocity is not finite: {current.tolist()}")
        if scan_age is None and now is not None and scan.stamp is not None:
            scan_age = float(now) - scan.stamp
        if scan_age is not None and not scan_age <= self.scan_timeout:  # also catches NaN
            return self._brake(nominal, current, FilterStatus.STALE,
                               f"scan is {scan_age:.3f} s old; timeout {self.scan_timeout:.3f} s")
        if not (math.isfinite(nominal[0]) and math.isfinite(nominal[1])):
            return self._brake(nominal, current, FilterStatus.BAD_INPUT,
                               f"u_nom is not finite: {nominal.tolist()}")
        if scan.n_informative == 0:
            return self._brake(nominal, current, FilterStatus.NO_DATA,
                               f"none of the {scan.n_beams} beams is informative (all NaN or out of range)")
        if self.compensate_latency and current is not None and scan_age is not None and scan_age > 0.0:
            scan = self.current_frame(scan, current, scan_age)
        result = self._filter(nominal, scan, current)
        if not (math.isfinite(result.u[0]) and math.isfinite(result.u[1])):
            return self._brake(nominal, current, FilterStatus.FALLBACK,
                               f"filter produced a non-finite command {result.u.tolist()}")
        return result

    @staticmethod
    def current_frame(scan: LaserScan, velocity: np.ndarray, scan_age: float) -> LaserScan:
        """The scan re-expressed in the current base frame, ``scan_age`` [s] after it was taken.

        Assumes the base held ``velocity`` ``(v [m/s], omega [rad/s])`` since then (the world
        is static): the base has moved by the exact arc ``unicycle_step(0, v, omega, age)``,
        so the laser now sits at the inverse of that motion composed with its mount. Only
        the mount pose changes; the readings are untouched.
        """
        moved = unicycle_step(Pose2D(), float(velocity[0]), float(velocity[1]), scan_age)
        return scan.replace(mount=moved.inverse().compose(scan.mount))

    def _brake(self, nominal: np.ndarray, velocity: np.ndarray | None, status: FilterStatus, message: str,
                **details: Any) -> FilterResult:
        """A result that brakes as hard as the acceleration limits allow (from ``velocity`` when known)."""
        u = self.robot.brake(velocity, self.dt if velocity is not None else None)
        return FilterResult(u=u, u_nom=nominal, status=status, message=message, **details)

    @abc.abstractmethod
    def _filter(self, u_nom: np.ndarray, scan: LaserScan, velocity: np.ndarray | None) -> FilterResult:
        """Filter a finite ``u_nom`` with an informative, fresh ``scan``."""

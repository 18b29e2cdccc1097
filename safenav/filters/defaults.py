"""Every setting the filters derive from the robot, computed in one place.

Configs (:class:`~safenav.filters.cbf.CBFConfig`, :class:`~safenav.filters.mpc.MPCConfig`)
leave robot-dependent settings at ``None``; ``config.resolve(robot, dt)`` fills them in with
the functions below, so the resolved config shows the values a filter actually uses.
"""

from __future__ import annotations

import math

from safenav.robot import RobotSpec

__all__ = [
    "BUDGET_FRACTION",
    "SAFETY_DISTANCE",
    "STEERING_PREFERENCE",
    "default_gamma",
    "default_margin",
    "default_weights",
    "lag_fraction",
    "noise_allowance",
    "reaction_time",
]

SAFETY_DISTANCE = 0.02
"""The part of the default margin that is a plain safety distance [m]."""

BUDGET_FRACTION = 0.5
"""Default compute budget of one filter call, as a share of the period ``dt``."""

STEERING_PREFERENCE = 0.2
"""Cost of a yaw-rate change relative to a speed change, both as fractions of their limits:
0.2 makes steering five times cheaper than braking, which measured more progress (the wall
follower twice as far, more goals reached) at the same clearance."""


def default_margin(robot: RobotSpec) -> float:
    """The filters' default clearance margin for ``robot`` [m].

    ``0.02 m + 2 noise_std + 1 m x angle_increment``: a safety distance, twice the lidar's
    range noise, and the widest object that can hide between two beams 1 m away (the widest
    increment of the robot's lidars).
    """
    lidars = getattr(robot, "lidars", (robot.lidar,))
    noise = max(lidar.noise_std for lidar in lidars)
    increment = max(lidar.angle_increment for lidar in lidars)
    return SAFETY_DISTANCE + 2.0 * noise + 1.0 * increment


def noise_allowance(robot: RobotSpec, margin: float) -> float:
    """The range-noise part of ``margin`` [m]: ``2 noise_std`` of the noisiest lidar, at most half the margin.

    The braking rows keep the base able to stop before the margin less this allowance: a
    reading that noise puts just inside the margin then does not forbid every approach.
    """
    lidars = getattr(robot, "lidars", (robot.lidar,))
    return min(2.0 * max(lidar.noise_std for lidar in lidars), 0.5 * margin)


def default_gamma(robot: RobotSpec, dt: float) -> float:
    """``min(1, a_max dt / v_max)``: a head-on exponential approach at full speed brakes at ``a_max`` at most."""
    return min(1.0, robot.a_max * dt / robot.v_max)


def default_weights(robot: RobotSpec) -> tuple[float, float]:
    """Cost weights on ``(v, omega)`` deviations: ``(1 / v_max^2, STEERING_PREFERENCE / omega_max^2)``."""
    return (1.0 / robot.v_max**2, STEERING_PREFERENCE / robot.omega_max**2)


def lag_fraction(dt: float, time_constant: float) -> float:
    """Largest share of a period's displacement still due to the period's start velocity.

    Over a period the mean velocity is ``u + b (w0 - u)``. A base that reaches the command
    within the period (at once, linearly, or at its acceleration limit) has ``b <= 1/2``; a
    first-order lag of time constant ``tau`` has ``b = (tau / dt)(1 - exp(-dt / tau))``.

    Args:
        dt: the period [s].
        time_constant: the base's first-order lag time constant [s]; 0 for a base that
            reaches each command within the period.
    """
    if time_constant <= 0.0:
        return 0.5
    ratio = time_constant / dt
    return max(0.5, ratio * (1.0 - math.exp(-1.0 / ratio)))


def reaction_time(dt: float, time_constant: float) -> float:
    """Time before a braking command takes full effect [s]: one period, plus the lag's time constant."""
    return dt + max(time_constant, 0.0)

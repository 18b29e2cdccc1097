"""The MPC's model of the base and of a plan: prediction, checks, braking plans.

A plan is ``N`` commands ``u_0..u_{N-1}``, each held for one period ``dt``. The base's
velocity ``w`` follows the commands as a first-order lag of time constant ``tau``
(:class:`BaseModel`); ``tau = 0`` is a base that reaches each command within the period
(the velocity then ramps from ``w_k`` to ``u_k``). Over period ``k`` the base moves along
the exact arc of the mean velocity ``u_k + beta (w_k - u_k)`` and ends the period at
``w_{k+1} = u_k + rho (w_k - u_k)``, with ``rho = exp(-dt / tau)`` and
``beta = (tau / dt)(1 - rho)`` (``rho = 0``, ``beta = 1/2`` for ``tau = 0``).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from scipy.signal import lfilter

from safenav.filters.perception import Frontier
from safenav.geometry import Pose2D, unicycle_rollout

__all__ = ["BaseModel", "MPCProblem", "PlanCheck", "distances", "row_values"]

#: Smallest radius the clearance rows are scaled by [m] (a point at the base origin has radius 0).
MIN_ROW_SCALE = 1e-3


class BaseModel(NamedTuple):
    """How the base's velocity follows the commands (see the module docstring)."""

    dt: float
    """The period [s]."""
    time_constant: float
    """First-order lag ``tau`` [s]; 0 for a base that reaches each command within the period."""

    @property
    def rho(self) -> float:
        """Share of the velocity error left at the end of a period."""
        return 0.0 if self.time_constant <= 0.0 else math.exp(-self.dt / self.time_constant)

    @property
    def beta(self) -> float:
        """Share of the period's displacement due to the start velocity's error."""
        return 0.5 if self.time_constant <= 0.0 else self.time_constant / self.dt * (1.0 - self.rho)

    @property
    def tracking(self) -> float:
        """Largest ``|u_k - w_k|`` in units of one period's command change (``1 / (1 - rho)``)."""
        return 1.0 / (1.0 - self.rho)

    def velocities(self, commands: np.ndarray, velocity: np.ndarray) -> np.ndarray:
        """The velocities ``w_0..w_N`` ``(N + 1, 2)`` when ``commands`` ``(N, 2)`` follow ``velocity``."""
        commands = np.asarray(commands, dtype=float).reshape(-1, 2)
        start = np.asarray(velocity, dtype=float).reshape(1, 2)
        rho = self.rho
        if rho == 0.0:
            return np.vstack((start, commands))
        # w_{k+1} = rho w_k + (1 - rho) u_k, a first-order filter of the commands.
        after = lfilter([1.0 - rho], [1.0, -rho], commands, axis=0, zi=rho * start)[0]
        return np.vstack((start, after))

    def rollout(self, commands: np.ndarray, velocity: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Poses ``(N + 1, 3)`` and velocities ``(N + 1, 2)`` of a plan from the base origin."""
        commands = np.asarray(commands, dtype=float).reshape(-1, 2)
        velocities = self.velocities(commands, velocity)
        means = commands + self.beta * (velocities[:-1] - commands)
        return unicycle_rollout(Pose2D(), means, self.dt), velocities

    def coast(self, pose: np.ndarray, velocity: np.ndarray) -> np.ndarray:
        """Where a lagging base still drifts after its last command (zero): ``tau v`` along the heading [m]."""
        drift = self.time_constant * velocity[0]
        return np.array([pose[0] + drift * math.cos(pose[2]), pose[1] + drift * math.sin(pose[2])])


class MPCProblem(NamedTuple):
    """What one call of the filter optimises over, in the current base frame."""

    u_nom: np.ndarray
    """The nominal command ``(v [m/s], omega [rad/s])``."""
    velocity: np.ndarray
    """The velocity the plan starts from (measured, or the last command) [m/s, rad/s]."""
    points: np.ndarray
    """``(M, 2)`` every obstacle point a plan could come near, base frame [m]."""
    radii: np.ndarray
    """``(M,)`` distance the planner keeps every knot from each point [m]."""
    guaranteed: np.ndarray
    """``(M,)`` distance a verified plan keeps every knot from each point [m]."""
    lower: np.ndarray
    """``(N, 2)`` lower bounds on the commands (limits, reachability, field of view, stop at the end)."""
    upper: np.ndarray
    """``(N, 2)`` upper bounds on the commands."""
    hold: int
    """The first ``hold`` commands are equal (the call period is ``hold`` periods long)."""
    frontier: Frontier
    """The part of the outline facing unknown space."""
    min_barrier: float
    """Smallest ``||o|| - (R + margin)`` over every point, at the current pose [m]."""
    clearance: float
    """Distance from the body to the nearest point [m]."""


class PlanCheck(NamedTuple):
    """How far a plan is from satisfying a :class:`MPCProblem`."""

    limits: float
    """Largest violation of a command bound, an acceleration row or the hold [m/s or rad/s] (<= 0 if none)."""
    clearance: float
    """Smallest ``||p_k - o|| - guaranteed(o)`` over the knots and every point [m] (``inf`` without points)."""
    planned: float
    """Smallest ``||p_k - o|| - radii(o)`` [m]: negative means the plan uses some of the buffer."""
    distances: np.ndarray
    """``(M,)`` the smallest knot distance ``||p_k - o||`` per point [m]."""
    poses: np.ndarray
    """``(N + 1, 3)`` the predicted poses ``(x, y, yaw)``, starting at the origin."""
    velocities: np.ndarray
    """``(N + 1, 2)`` the predicted velocities."""


def distances(knots: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Per point, the smallest distance to any of ``knots`` [m]."""
    if points.shape[0] == 0:
        return np.empty(0)
    dx = knots[:, 0:1] - points[:, 0]
    dy = knots[:, 1:2] - points[:, 1]
    return np.sqrt(np.min(dx * dx + dy * dy, axis=0))


def row_values(distance: np.ndarray, radii: np.ndarray) -> np.ndarray:
    """The clearance rows as the NLP writes them, ``(d^2 - r^2) / (2 r)`` (about ``d - r``) [m]."""
    return (distance * distance - radii * radii) * (0.5 / np.maximum(radii, MIN_ROW_SCALE))

"""The MPC's model of the base and of a plan: layout, prediction, checks, braking plans.

A plan is ``P`` commands ``u_0..u_{P-1}``, one per control period ``dt``, covering the
horizon (given in seconds). The optimiser does not choose every command: it chooses the
commands ``U_j`` of ``n <= P`` *knots* (:class:`PlanLayout`): with a short ``dt`` the
commands between knots are linearly interpolated (move blocking, which keeps the full
braking authority: a change of at most ``a_max dt`` per period between knots ``k`` periods
apart is ``|U_{j+1} - U_j| <= k a_max dt``); when calls come late, every command is held
for the call period (blocks of equal commands). Clearance is still required at the end of
*every* period, so the argument that covers the motion between two clearance knots
(:class:`~safenav.filters.mpc.MPCSafetyFilter`) is the one-period argument whatever the
number of knots.

The base's velocity ``w`` follows the commands as a first-order lag of time constant
``tau`` (:class:`BaseModel`); ``tau = 0`` is a base that reaches each command within the
period (the velocity then ramps from ``w_k`` to ``u_k``). Over period ``k`` the base moves
along the exact arc of the mean velocity ``u_k + beta (w_k - u_k)`` and ends the period at
``w_{k+1} = u_k + rho (w_k - u_k)``, with ``rho = exp(-dt / tau)`` and
``beta = (tau / dt)(1 - rho)`` (``rho = 0``, ``beta = 1/2`` for ``tau = 0``).

When calls come late, a command is held for the call period ``T = m dt`` and may differ from the
velocity at its start by what the acceleration limits allow in ``T``; a base that reaches each
command within the period (``tau = 0``) then reaches it by the end of ``T``, not of the block's first
``dt``. The model ramps it over the whole block: at the end of the block's ``j``-th period
(``j = 1..m``) the velocity is ``w + (j / m) (U - w)``, from the velocity ``w`` the block starts at
(:func:`block_ramp`). That is exactly a base ramping linearly over the call period (at its limits
when the change is the largest they allow), and no velocity between ``w`` and ``U`` strays from it
by more than half the change times ``T`` (the actuator error's bound). A lag's model is the same
whatever the call period.

The body is one disk or several (:class:`~safenav.filters.body.BodyModel`); a disk whose
centre sits at ``c`` in the base frame is at ``p_k + R(yaw_k) c`` at knot ``k``.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from safenav.filters.perception import Frontier
from safenav.geometry import Pose2D, unicycle_rollout

__all__ = ["FINE_KNOTS", "BaseModel", "MPCProblem", "PlanCheck", "PlanLayout", "disk_centres", "distances",
           "row_values"]

#: Smallest radius the clearance rows are scaled by [m] (a point at the base origin has radius 0).
MIN_ROW_SCALE = 1e-3
#: With move blocking, the first knots stay one period apart (the near future keeps its resolution).
FINE_KNOTS = 5


def _read_only(array: np.ndarray) -> np.ndarray:
    array.flags.writeable = False
    return array


@dataclass(frozen=True, eq=False)
class PlanLayout:
    """Which commands of a plan the optimiser chooses, and how the others follow.

    Two kinds, by the call period (``hold``, in periods ``dt``, see :meth:`of`):

    * ``hold = 1`` (calls every ``dt``): every period is a knot when ``periods <= max_commands``;
      else the first :data:`FINE_KNOTS` periods, then knots spread evenly to the last period,
      with the commands in between *linearly interpolated* (move blocking that keeps the full
      braking authority: a knot-to-knot change of ``k`` periods may be ``k (a_max, alpha_max) dt``).
    * ``hold >= 2`` (late calls: each command is held for ``hold`` periods): *blocks* of
      ``hold`` equal commands, one knot per block; consecutive blocks differ by at most what the
      acceleration limits allow in ``hold`` periods.

    Attributes:
        periods: ``P``, the commands of a plan (one per period).
        max_commands: the most knots of a ``hold = 1`` layout.
        hold: periods each command is held (1: a new command every period).
        knots: ``(n,)`` the first period of each knot's command (``k_0 = 0``).
        interpolation: ``(P, n)`` the matrix ``B`` with ``u = B U``.
        changes: ``(n - 1,)`` periods of acceleration each knot-to-knot change may use.
        period_changes: ``(P - 1,)`` periods of acceleration each period-to-period change may use.
    """

    periods: int
    max_commands: int
    hold: int
    knots: np.ndarray
    interpolation: np.ndarray
    changes: np.ndarray
    period_changes: np.ndarray

    @classmethod
    def of(cls, periods: int, max_commands: int, hold: int = 1) -> PlanLayout:
        """The layout of a plan of ``periods`` commands, each held ``hold`` periods (see the class docstring)."""
        return _layout(int(periods), int(max_commands), int(hold))

    @property
    def n_knots(self) -> int:
        return int(self.knots.size)

    @property
    def identity(self) -> bool:
        """Whether every period's command is chosen (``B`` is the identity)."""
        return self.n_knots == self.periods

    @property
    def interpolated(self) -> bool:
        """Whether some commands are interpolated between knots (a ``hold = 1`` layout with blocking)."""
        return self.hold == 1 and not self.identity

    def expand(self, knot_commands: np.ndarray) -> np.ndarray:
        """The commands of every period ``(P, 2)`` from the knots' commands ``(n, 2)``."""
        knot_commands = np.asarray(knot_commands, dtype=float).reshape(-1, 2)
        return knot_commands.copy() if self.identity else self.interpolation @ knot_commands

    def sample(self, commands: np.ndarray) -> np.ndarray:
        """The knots' commands ``(n, 2)`` of a plan given per period ``(P, 2)``."""
        return np.asarray(commands, dtype=float).reshape(-1, 2)[self.knots].copy()

    def knot_bounds(self, lower: np.ndarray, upper: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Bounds ``(n, 2)`` on the knots' commands from the bounds of every period ``(P, 2)``.

        A block's command must satisfy the bounds of every period of its block; an interpolated
        layout's knots their own period's (the periods in between get rows of their own where
        the interpolation does not imply them).
        """
        if self.hold == 1:
            return self.sample(lower), self.sample(upper)
        return (np.maximum.reduceat(lower, self.knots, axis=0), np.minimum.reduceat(upper, self.knots, axis=0))


@functools.lru_cache(maxsize=64)
def block_ramp(periods: int, hold: int) -> tuple[np.ndarray, np.ndarray]:
    """``(R (P, P), r (P,))``: the velocities at the end of each of ``periods`` periods are ``R u + r w_0`` when each
    block of ``hold`` commands ``u`` is reached linearly over the block from the velocity it starts at (``w_0``
    for the first block, the previous block's command after it); the identity and zero for ``hold = 1``. Applied
    to every period's command, so a plan whose commands change within a block (none the filter makes) ramps from
    the command before the block too."""
    ramp, start = np.zeros((periods, periods)), np.zeros(periods)
    for k in range(periods):
        block, share = divmod(k, hold)
        share = (share + 1) / hold
        ramp[k, k] = share
        if block == 0:
            start[k] = 1.0 - share
        else:
            ramp[k, block * hold - 1] += 1.0 - share
    for array in (ramp, start):
        array.flags.writeable = False
    return ramp, start


@functools.lru_cache(maxsize=64)
def _layout(periods: int, max_commands: int, hold: int) -> PlanLayout:
    if hold > 1:
        knots = np.arange(0, periods, hold)
        interpolation = np.zeros((periods, knots.size))
        interpolation[np.arange(periods), np.arange(periods) // hold] = 1.0
        changes = np.full(knots.size - 1, float(hold))
        period_changes = np.where(np.arange(1, periods) % hold == 0, float(hold), 0.0)
    else:
        if periods <= max_commands:
            knots = np.arange(periods)
        else:
            fine = min(FINE_KNOTS, max_commands - 1)
            coarse = np.rint(np.linspace(fine - 1, periods - 1, max_commands - fine + 1)).astype(int)[1:]
            knots = np.unique(np.concatenate((np.arange(fine), coarse)))
        interpolation = np.zeros((periods, knots.size))
        for j in range(knots.size - 1):
            start, stop = knots[j], knots[j + 1]
            share = (np.arange(start, stop) - start) / (stop - start)
            interpolation[start:stop, j] = 1.0 - share
            interpolation[start:stop, j + 1] = share
        interpolation[-1, -1] = 1.0
        changes = np.diff(knots).astype(float)
        period_changes = np.ones(periods - 1)
    return PlanLayout(periods, max_commands, hold, *(_read_only(array) for array in (
        knots, interpolation, changes, period_changes)))


def lag_filter() -> Callable[..., tuple[np.ndarray, np.ndarray]]:
    """``scipy.signal.lfilter``, imported when first asked: scipy.signal is 1.2 s of a process's start that only a
    lagging base's model uses. :class:`~safenav.filters.mpc.MPCSafetyFilter` asks for it when it is built with a
    lag, so that no control call pays the import."""
    from scipy.signal import lfilter

    return lfilter


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

    def ramps(self, hold: int) -> bool:
        """Whether commands held in blocks of ``hold`` periods are ramped over each block (:func:`block_ramp`): a late
        call's blocks (``hold > 1``) of a base without a lag."""
        return hold > 1 and self.rho == 0.0

    def reached(self, commands: np.ndarray, velocity: np.ndarray, hold: int = 1) -> np.ndarray:
        """``(N, 2)``: for ``tau = 0``, the velocity the base has at the end of each period when ``commands`` ``(N, 2)``
        are held in blocks of ``hold`` periods from ``velocity`` (each block ramped over its length,
        :func:`block_ramp`); the commands themselves for ``hold = 1`` and for a lag (the model's commands)."""
        commands = np.asarray(commands, dtype=float).reshape(-1, 2)
        if not self.ramps(hold):
            return commands
        ramp, start = block_ramp(commands.shape[0], int(hold))
        return ramp @ commands + start[:, None] * np.asarray(velocity, dtype=float).reshape(1, 2)

    def velocities(self, commands: np.ndarray, velocity: np.ndarray, hold: int = 1) -> np.ndarray:
        """The velocities ``w_0..w_N`` ``(N + 1, 2)`` when ``commands`` ``(N, 2)``, held in blocks of ``hold`` periods,
        follow ``velocity``."""
        commands = np.asarray(commands, dtype=float).reshape(-1, 2)
        start = np.asarray(velocity, dtype=float).reshape(1, 2)
        rho = self.rho
        if rho == 0.0:
            return np.vstack((start, self.reached(commands, velocity, hold)))
        # w_{k+1} = rho w_k + (1 - rho) u_k, a first-order filter of the commands.
        after = lag_filter()([1.0 - rho], [1.0, -rho], commands, axis=0, zi=rho * start)[0]
        return np.vstack((start, after))

    def rollout(self, commands: np.ndarray, velocity: np.ndarray, hold: int = 1) -> tuple[np.ndarray, np.ndarray]:
        """Poses ``(N + 1, 3)`` and velocities ``(N + 1, 2)`` of a plan from the base origin, its commands held in
        blocks of ``hold`` periods."""
        commands = np.asarray(commands, dtype=float).reshape(-1, 2)
        velocities = self.velocities(commands, velocity, hold)
        # Without a lag the base ramps within each period to the velocity it reaches at its end.
        ends = velocities[1:] if self.rho == 0.0 else commands
        means = ends + self.beta * (velocities[:-1] - ends)
        return unicycle_rollout(Pose2D(), means, self.dt), velocities

    def coast(self, pose: np.ndarray, velocity: np.ndarray) -> np.ndarray:
        """The pose a lagging base still drifts to after its last command (zero): ``tau v`` along the heading."""
        drift = self.time_constant * velocity[0]
        return np.array([pose[0] + drift * math.cos(pose[2]), pose[1] + drift * math.sin(pose[2]), pose[2]])

    def knot_poses(self, commands: np.ndarray, velocity: np.ndarray, hold: int = 1
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The poses a plan's clearance is checked at ``(K, 3)``: the end of every period and, for a
        lag, where the base drifts to; with the rollout's poses ``(N + 1, 3)`` and velocities (commands held in
        blocks of ``hold`` periods)."""
        poses, velocities = self.rollout(commands, velocity, hold)
        knots = poses[1:]
        if self.time_constant > 0.0:
            knots = np.vstack((knots, self.coast(poses[-1], velocities[-1])))
        return knots, poses, velocities


def disk_centres(poses: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """Where disks centred at ``offsets`` ``(D, 2)`` (base frame) are at ``poses`` ``(K, 3)``: ``(K, D, 2)``."""
    if not np.any(offsets):
        return np.repeat(poses[:, None, :2], offsets.shape[0], axis=1)
    cos, sin = np.cos(poses[:, 2])[:, None], np.sin(poses[:, 2])[:, None]
    x = poses[:, 0:1] + cos * offsets[None, :, 0] - sin * offsets[None, :, 1]
    y = poses[:, 1:2] + sin * offsets[None, :, 0] + cos * offsets[None, :, 1]
    return np.stack((x, y), axis=-1)


class MPCProblem(NamedTuple):
    """What one call of the filter optimises over, in the current base frame.

    Radii are per point and per body disk (one column for the disk model).
    """

    u_nom: np.ndarray
    """The nominal command ``(v [m/s], omega [rad/s])``."""
    velocity: np.ndarray
    """The velocity the plan starts from (measured, or the last command) [m/s, rad/s]."""
    points: np.ndarray
    """``(M, 2)`` every obstacle point a plan could come near, base frame [m]."""
    uncertainty: np.ndarray
    """``(M,)`` each point's position uncertainty (odometry, for remembered points; else 0) [m]."""
    radii: np.ndarray
    """``(M, D)`` distance the planner aims to keep each disk centre from each point at every knot [m]."""
    guaranteed: np.ndarray
    """``(M, D)`` distance a verified plan keeps each disk centre from each point at every knot [m]
    (``-inf`` in the column of the look-ahead's control disk, which is never verified)."""
    floor: np.ndarray
    """``(M, D)`` the nearest the planner may come by using the soft part of the buffer [m]: the
    guaranteed radius, the buffer's actuator part and the growth of the point's uncertainty at the
    next carry (never nearer than the point is now)."""
    lower: np.ndarray
    """``(P, 2)`` lower bounds on the commands (limits, reachability, field of view, stop at the end)."""
    upper: np.ndarray
    """``(P, 2)`` upper bounds on the commands."""
    layout: PlanLayout
    """Which commands are chosen; ``layout.hold`` periods per command (the call period)."""
    frontier: Frontier
    """The part of the outline facing unknown space."""
    min_barrier: float
    """Smallest ``||c_d - o|| - (rho_d + margin) - e_o`` over every disk and point, at the current pose [m]."""
    clearance: float
    """Distance from the body to the nearest point [m]."""

    @property
    def hold(self) -> int:
        """Periods each command is held (the call period in periods)."""
        return self.layout.hold


class PlanCheck(NamedTuple):
    """How far a plan is from satisfying a :class:`MPCProblem`."""

    limits: float
    """Largest violation of a command bound, an acceleration row or the hold [m/s or rad/s] (<= 0 if none)."""
    clearance: float
    """Smallest ``||c - o|| - guaranteed(o)`` over the knots, the disks and every point [m] (``inf`` without points)."""
    planned: float
    """Smallest ``||c - o|| - radii(o)`` [m]: negative means the plan uses some of the buffer."""
    distances: np.ndarray
    """``(M, D)`` the smallest knot distance from each disk centre to each point [m]."""
    poses: np.ndarray
    """``(N + 1, 3)`` the predicted poses ``(x, y, yaw)``, starting at the origin."""
    velocities: np.ndarray
    """``(N + 1, 2)`` the predicted velocities."""


def distances(centres: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Per point and disk, the smallest distance from the disk's centres ``(K, D, 2)`` to the point: ``(M, D)`` [m]."""
    if points.shape[0] == 0:
        return np.empty((0, centres.shape[1]))
    squared = centres[:, :, 0, None] - np.ascontiguousarray(points[:, 0])     # (K, D, M), in place from here
    squared *= squared
    dy = centres[:, :, 1, None] - np.ascontiguousarray(points[:, 1])
    dy *= dy
    squared += dy
    return np.sqrt(squared.min(axis=0)).T


def row_values(distance: np.ndarray, radii: np.ndarray) -> np.ndarray:
    """The clearance rows as the optimiser writes them, ``(d^2 - r^2) / (2 r)`` (about ``d - r``) [m]."""
    return (distance * distance - radii * radii) * (0.5 / np.maximum(radii, MIN_ROW_SCALE))

"""Control-barrier-function QP safety filter built from lidar points."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np
import qpsolvers

from safenav.errors import InvalidConfig
from safenav.filters.base import FilterResult, FilterStatus, SafetyFilter
from safenav.filters.qp import QPBackend, QPData, make_backend
from safenav.filters.reduction import (
    BlockedMotion,
    blocked_motion,
    body_clearance,
    default_margin,
    nearest_per_bin,
    obstacle_beams,
)
from safenav.robot import RobotSpec
from safenav.scan import LaserScan

__all__ = ["CBFConfig", "CBFSafetyFilter"]

#: Tolerance of the filter's own check of a QP answer against every row [m/s]
#: (rows are barrier decrements per period divided by dt: 1e-6 m/s is 5e-8 m per 50 ms).
VERIFY_TOLERANCE = 1e-6
#: Regularisation of the auxiliary variables |v|, |omega| (keeps the Hessian positive definite).
AUX_REGULARISATION = 1e-9
#: Linear cost on the slack variable [s/m] (with slack_weight: an exact penalty in practice).
SLACK_LINEAR_WEIGHT = 1e3
#: Default look-ahead distance [m] (measured: steering authority vs 2 l of conservatism head-on).
DEFAULT_LOOKAHEAD = 0.1
#: Default cost of a yaw-rate change relative to a speed change, both as fractions of their
#: limits: 0.2 makes steering five times cheaper than braking, which measured more progress
#: (wall follower twice as far, goals reached) at the same clearance.
STEERING_PREFERENCE = 0.2
MAX_GENERATION_ROUNDS = 8
"""Rounds of constraint generation before the QP takes every candidate row."""
#: Upper limit on the rows a QP takes at once (one solve, no generation rounds); a back-end may
#: ask for fewer (:attr:`~safenav.filters.qp.QPBackend.direct_rows`).
DIRECT_ROWS = 512


def _check_fraction(name: str, value: float, low: float, high: float) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not low <= value <= high:
        raise InvalidConfig(f"CBFConfig.{name} must be a number in [{low}, {high}], got {value!r}")
    return float(value)


@dataclass(frozen=True)
class CBFConfig:
    """Settings of :class:`CBFSafetyFilter`; ``None`` means "derive from the robot" (see there).

    Attributes:
        gamma: decay of the discrete-time barrier condition, in (0, 1].
        margin: clearance kept between the body disk and every obstacle point [m].
        lookahead: distance of the look-ahead point ahead of the base origin [m]; 0 gives
            the centre-distance barrier, which constrains ``v`` only.
        solver: QP back-end name (``"daqp"``, ``"quadprog"``, ``"osqp"``, any qpsolvers solver).
        weights: cost weights on the ``(v, omega)`` deviations [s^2/m^2, s^2/rad^2];
            default ``(1 / v_max^2, 0.2 / omega_max^2)``.
        far_gamma: largest fraction of its own barrier any point may lose per period, in
            (0, 1]; default 1 (only the minimum condition). ``far_gamma = gamma`` gives the
            classic point-wise condition ``h(o, x+) >= (1 - gamma) h(o, x)``.
        max_gap: widest run of invalid beams bridged by its neighbours [rad]; wider runs are unknown.
        side_tolerance: unknown directions this close to exactly sideways do not block motion [rad].
        n_bins: angular bins of the initial working set (nearest point per bin).
        slack_weight: quadratic cost on the relaxation of the rows (in m/s) when no command
            satisfies them all; with the linear cost of 1e3 it acts as an exact penalty [s^2/m^2].
        scan_timeout: scans older than this make the filter brake [s].
        compensate_latency: move a scan of known age into the current base frame first
            (see :meth:`SafetyFilter.current_frame`).
    """

    gamma: float | None = None
    far_gamma: float | None = None
    margin: float | None = None
    lookahead: float | None = None
    solver: str = "daqp"
    weights: tuple[float, float] | None = None
    max_gap: float = math.radians(5.0)
    side_tolerance: float = math.radians(5.0)
    n_bins: int = 36
    slack_weight: float = 1e4
    scan_timeout: float = 0.5
    compensate_latency: bool = True

    def __post_init__(self) -> None:
        if self.gamma is not None:
            _check_fraction("gamma", self.gamma, 1e-6, 1.0)
        if self.far_gamma is not None:
            _check_fraction("far_gamma", self.far_gamma, 1e-6, 1.0)
        if self.margin is not None:
            _check_fraction("margin", self.margin, 0.0, 10.0)
        if self.lookahead is not None:
            _check_fraction("lookahead", self.lookahead, 0.0, 10.0)
        if not isinstance(self.solver, str):
            raise InvalidConfig(f"CBFConfig.solver must be a solver name, got {self.solver!r}")
        if self.weights is not None and (len(self.weights) != 2 or not all(
                isinstance(w, (int, float)) and math.isfinite(w) and w > 0 for w in self.weights)):
            raise InvalidConfig(f"CBFConfig.weights must be two positive numbers (v, omega), got {self.weights!r}")
        _check_fraction("max_gap", self.max_gap, 0.0, 2 * math.pi)
        _check_fraction("side_tolerance", self.side_tolerance, 0.0, 0.5 * math.pi)
        if isinstance(self.n_bins, bool) or not isinstance(self.n_bins, int) or self.n_bins < 1:
            raise InvalidConfig(f"CBFConfig.n_bins must be an integer >= 1, got {self.n_bins!r}")
        _check_fraction("slack_weight", self.slack_weight, 1.0, 1e12)
        _check_fraction("scan_timeout", self.scan_timeout, 1e-6, 1e9)


class _Constraints(NamedTuple):
    """The barrier rows ``G z <= rhs`` over ``z = (v, omega, t_v, t_omega)`` and their provenance."""

    G: np.ndarray            # (k, 4)
    rhs: np.ndarray          # (k,)
    point: np.ndarray        # (k,) index of the obstacle point behind each row; -1 for field-of-view rows
    points: np.ndarray       # (N, 2) obstacle points, base frame [m]
    barrier: np.ndarray      # (N,) barrier value of each point [m]
    lower: np.ndarray        # (4,) bounds on z
    upper: np.ndarray        # (4,)
    blocked: BlockedMotion
    velocity: np.ndarray | None


#: |v| <= t_v and |omega| <= t_omega as rows over z = (v, omega, t_v, t_omega).
_ABS_ROWS = np.array([[1.0, 0.0, -1.0, 0.0], [-1.0, 0.0, -1.0, 0.0], [0.0, 1.0, 0.0, -1.0], [0.0, -1.0, 0.0, -1.0]])
_ABS_RHS = np.zeros(4)


class CBFSafetyFilter(SafetyFilter):
    """Minimal change of ``(v, omega)`` that keeps the body disk clear of every lidar point.

    **Barrier.** For each obstacle point ``o`` of the scan (base frame, taken as static
    over one period) and the look-ahead point ``p = c + l (cos yaw, sin yaw)``::

        h(o) = ||p - o|| - (R + l + margin),        H = min over o of h(o)

    ``H >= 0`` implies ``||c - o|| >= R + margin`` for every point: the body disk of radius
    ``R`` keeps ``margin`` of clearance (the look-ahead barrier is conservative by up to
    ``2 l`` when facing an obstacle). Unlike the centre distance, ``p`` moves with both
    ``v`` and ``omega``, so the filter can steer as well as brake; ``lookahead=0`` gives
    the centre-distance barrier, which constrains ``v`` only.

    **Discrete-time condition.** With the command held for one period ``dt`` the filter
    enforces ``H(x+) >= (1 - gamma) H(x)``, that is ``h(o, x+) >= (1 - gamma) H(x)`` for
    every point: one row per point. This is the condition on the safe set itself
    (the minimum), not on each point's own barrier, so a wall alongside does not slow
    the robot just because its points ahead come closer at a shallow angle. Each row is
    the linearisation of ``h`` (a lower bound, since ``||.||`` is convex) at the exact
    displacement, whose error against the straight-line model ``dt (v, l omega)`` is
    bounded by ``kappa dt (|v| + l |omega|)`` with ``kappa = omega_max dt / 2`` (the arc).
    That bound enters the row through auxiliary variables ``t_v >= |v|``,
    ``t_omega >= |omega|``, so the condition holds for the true unicycle motion, with no
    accumulation between steps.

    **Acceleration limits** (when the current ``velocity`` is given). The command must be
    reachable within one period; every row is imposed both on the command and on the mean
    of current and commanded velocity, which bounds the displacement of a base that ramps
    to the command at its acceleration limit; and the approach speed towards each point is
    capped so that the base can still stop before it, ``s dt + s^2 / (2 a_max) <= h(o)``
    (one period of reaction, then braking). Without that cap the relief of the minimum
    condition would let a turn bring a far point into the path faster than the base can
    brake. When the base is already too fast to stop, the rows cannot all hold: see below.

    **Defaults derived from the robot.** ``gamma = min(1, a_max dt / v_max)``: a head-on
    approach at full speed then needs at most the acceleration limit to brake.
    ``margin = 0.02 m + 2 noise_std + 1 m x angle_increment``: a safety distance, the
    lidar's range noise, and the widest object that can hide between two beams 1 m away.
    ``lookahead = 0.1 m``. Cost weights ``(1 / v_max^2, 0.2 / omega_max^2)``: steering is
    preferred to braking, which keeps the robot moving round obstacles (BENCHMARKS.md).

    **Field of view.** Unknown directions (outside the field of view, or runs of invalid
    beams wider than ``max_gap``) are never free: an unknown direction within
    ``90 deg - side_tolerance`` of the heading forbids ``v > 0``; of the rear, ``v < 0``.

    **Guarantee.** If the world is static, every obstacle wider than the beam gap at
    1 m is seen by a beam whose reading is within ``2 noise_std`` of the truth, the
    base executes each command for ``dt`` (instantly, or ramping at no more than its
    acceleration limits when ``velocity`` is given), and the body starts with ``H >= 0``,
    then ``H`` stays ``>= 0``, so the body disk keeps ``margin`` of clearance from every
    point seen. Returned commands always respect the
    velocity (and acceleration) limits. The body region the lidar cannot see (e.g.
    behind a front-mounted 180-degree lidar) is covered only by forbidding motion
    towards it.

    **Readings closer than range_min** (``-inf``) put their point where the beam leaves
    the body disk: the object may be touching, so the robot counts as inside its margin and
    backs away until the lidar can measure the gap again. (A lidar whose ``range_min``
    exceeds ``R + margin`` from the body cannot see the margin itself; with this rule the
    robot keeps out of that blind ring instead.)

    **When it cannot hold.** If no command satisfies every row (the robot is already
    inside the margin, or moving too fast to stop before an obstacle or an unseen
    direction), a slack variable relaxes the barrier rows with a heavy penalty: the
    command violates them as little as possible, which moves the robot away, and the
    status is ``SLACK``. A robot already inside the margin whose command does satisfy the
    condition (it moves back out) gets status ``RECOVERING``. Every QP answer is checked
    against every row of every point in reach (not only the reduced set) to ``1e-6`` m/s
    (``5e-8`` m per 50 ms period); a failed solve or check brakes with status ``FALLBACK``.

    **Minimal intervention.** When ``u_nom`` satisfies every row and limit, it is
    returned unchanged (bit for bit) and no QP is solved. Otherwise the QP minimises the
    weighted distance to ``u_nom`` clipped to the velocity limits.

    **Point reduction.** Rows that cannot be active for any reachable command are
    dropped (exact). The QP starts from the nearest point per angular bin around ``p``
    and adds any violated row until none is (constraint generation), so the answer is
    that of the QP with every point.

    Args:
        robot: the robot to protect.
        dt: control period [s].
        config: settings; keyword arguments override its fields.
    """

    name = "cbf"

    def __init__(self, robot: RobotSpec, dt: float = 0.05, *, config: CBFConfig | None = None, **overrides: Any):
        config = CBFConfig(**{**(config.__dict__ if config else {}), **overrides})
        super().__init__(robot, dt, scan_timeout=config.scan_timeout, compensate_latency=config.compensate_latency)
        self.config = config
        self.gamma = config.gamma if config.gamma is not None else min(1.0, robot.a_max * self.dt / robot.v_max)
        self.far_gamma = max(self.gamma, config.far_gamma if config.far_gamma is not None else 1.0)
        self.margin = config.margin if config.margin is not None else default_margin(robot)
        self.lookahead = config.lookahead if config.lookahead is not None else DEFAULT_LOOKAHEAD
        self.kappa = 0.5 * robot.omega_max * self.dt
        weights = config.weights or (1.0 / robot.v_max**2, STEERING_PREFERENCE / robot.omega_max**2)
        self._P = np.diag([weights[0], weights[1], AUX_REGULARISATION, AUX_REGULARISATION])
        self.backend: QPBackend = make_backend(config.solver)

    def __repr__(self) -> str:
        return (f"CBFSafetyFilter(robot={self.robot.name!r}, dt={self.dt}, gamma={self.gamma:.4f}, "
                f"margin={self.margin:.4f}, lookahead={self.lookahead:.4f}, solver={self.backend.name!r})")

    # ------------------------------------------------------------------ constraints

    def _relevant_points(self, scan: LaserScan, lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
        """Obstacle points [m] whose row some reachable command could violate, plus the nearest ones.

        A point's row allows its barrier to drop to ``(1 - gamma) H``, ``H`` the smallest
        barrier; in one period the barrier of any point drops by at most
        ``D = dt (V + l Omega)(1 + kappa)`` at the largest reachable speeds. With ``o`` the
        distance from the laser to the look-ahead point, a beam of range ``rho`` has a
        barrier of at least ``rho - o - r`` and ``H <= rho_min + o - r``, so beams longer than
        ``(1 - gamma)(rho_min + o - r) + D + o + r`` can never be violated and are skipped
        before any trigonometry. The beams nearest the base origin and the look-ahead point
        are always kept, so the reported clearance and minimum barrier are exact.
        """
        index, ranges = obstacle_beams(scan, self.robot.radius)
        if index.size == 0:
            return np.empty((0, 2))
        ell = self.lookahead
        mount = scan.mount
        offset = max(math.hypot(mount.x, mount.y), math.hypot(mount.x - ell, mount.y))
        speed = max(abs(lower[0]), abs(upper[0])) + ell * max(abs(lower[1]), abs(upper[1]))
        drop = self.dt * speed * (1.0 + self.kappa)
        radius = self.robot.radius + ell + self.margin
        nearest = float(ranges.min())
        cut = max((1.0 - self.gamma) * (nearest + offset - radius) + drop + offset + radius, nearest + 2.0 * offset)
        keep = ranges <= cut
        return scan.beam_points(index[keep], ranges[keep])

    def _constraints(self, scan: LaserScan, velocity: np.ndarray | None) -> _Constraints:
        robot, dt, ell = self.robot, self.dt, self.lookahead
        lower, upper = robot.velocity_bounds(velocity, dt if velocity is not None else None)
        points = self._relevant_points(scan, lower, upper)
        dx = ell - points[:, 0]
        dy = -points[:, 1]
        distance = np.hypot(dx, dy)
        degenerate = distance < 1e-9
        if degenerate.any():  # a point exactly at p: push it back along -x
            dx, dy, distance = dx.copy(), dy.copy(), distance.copy()
            dx[degenerate], dy[degenerate], distance[degenerate] = 1.0, 0.0, 1.0
        nx, ny = dx / distance, dy / distance
        barrier = np.where(degenerate, 0.0, distance) - (robot.radius + ell + self.margin)
        # Rows are divided by dt (units of m/s) for the solvers' sake.
        count = len(points)
        rows = np.empty((count, 4))
        rows[:, 0], rows[:, 1], rows[:, 2], rows[:, 3] = -nx, -ell * ny, self.kappa, self.kappa * ell
        smallest = float(barrier.min()) if count else math.inf
        # h(o, x+) >= (1 - gamma) H(x); with far_gamma < 1 also h(o, x+) >= (1 - far_gamma) h(o, x)
        # for points outside the margin (inside it, the minimum condition is the recovery rule).
        rhs = barrier - (1.0 - self.gamma) * smallest
        if self.far_gamma < 1.0:
            rhs = np.where(barrier > 0.0, np.minimum(rhs, self.far_gamma * barrier), rhs)
        rhs /= dt
        point = np.arange(count)
        fov_rows: list[list[float]] = []
        fov_rhs: list[float] = []
        blocked = blocked_motion(scan, self.config.max_gap, self.config.side_tolerance)
        if blocked.forward:
            fov_rows.append([1.0, 0.0, 0.0, 0.0])
            fov_rhs.append(0.0)
        if blocked.backward:
            fov_rows.append([-1.0, 0.0, 0.0, 0.0])
            fov_rhs.append(0.0)
        if fov_rows:
            rows = np.vstack((rows, fov_rows))
            rhs = np.concatenate((rhs, fov_rhs))
            point = np.concatenate((point, np.full(len(fov_rhs), -1)))
        G = rows
        t_low = np.abs(velocity) if velocity is not None else np.zeros(2)
        t_high = np.maximum(np.maximum(np.abs(lower), np.abs(upper)), t_low)
        if velocity is not None:
            # Braking: the approach speed towards each point (the row's left side, in m/s) must
            # let the base stop within that point's barrier after one period of reaction,
            # v dt + v^2 / (2 a) <= h, at the acceleration limit a.
            point_rows = point >= 0
            accel = robot.a_max
            reach = np.maximum(barrier, 0.0)
            braking = np.sqrt((accel * dt) ** 2 + 2.0 * accel * reach) - accel * dt
            rhs[point_rows] = np.minimum(rhs[point_rows], braking[point[point_rows]])
            # The heading keeps turning while the base brakes: a point within the angle it can
            # still sweep, Delta = (|omega| + alpha dt)(|v| / a + dt), caps the speed along the
            # heading as if the base already faced it (forward for points ahead, reverse behind).
            sweep = (abs(velocity[1]) + robot.alpha_max * dt) * (abs(velocity[0]) / accel + dt)
            bearing = np.arctan2(points[:, 1], points[:, 0])
            cone_rows, cone_rhs, cone_point = [], [], []
            for sign, off_axis in ((1.0, np.abs(bearing)), (-1.0, math.pi - np.abs(bearing))):
                effective = np.maximum(off_axis - sweep, 0.0)
                inside = np.flatnonzero(effective < 0.5 * math.pi - 1e-6)
                block = np.zeros((inside.size, 4))
                block[:, 0] = sign * np.cos(effective[inside])
                block[:, 2], block[:, 3] = self.kappa, self.kappa * ell
                cone_rows.append(block)
                cone_rhs.append(braking[inside])
                cone_point.append(inside)
            G = np.vstack((G, *cone_rows))
            rhs = np.concatenate((rhs, *cone_rhs))
            point = np.concatenate((point, *cone_point))
            # The base ramps from velocity to the command: bound the mean velocity too.
            mean_rows = G.copy()
            mean_rows[:, :2] *= 0.5
            mean_rhs = rhs - 0.5 * (G[:, :2] @ velocity)
            G = np.vstack((G, mean_rows))
            rhs = np.concatenate((rhs, mean_rhs))
            point = np.concatenate((point, point))
        return _Constraints(G, rhs, point, points, barrier, np.concatenate((lower, t_low)),
                            np.concatenate((upper, t_high)), blocked, velocity)

    @staticmethod
    def _lifted(u: np.ndarray, constraints: _Constraints) -> np.ndarray:
        """``z = (v, omega, t_v, t_omega)`` with the smallest auxiliaries ``u`` allows."""
        t = np.abs(u)
        if constraints.velocity is not None:
            t = np.maximum(t, np.abs(constraints.velocity))
        return np.concatenate((u, t))

    def _problem(self, u_nom: np.ndarray, G: np.ndarray, rhs: np.ndarray, constraints: _Constraints,
                 slack: bool = False) -> QPData:
        P = self._P
        # A nominal beyond the velocity limits is first clipped to them (it keeps the QP well scaled).
        target = np.clip(u_nom, self.robot.lower, self.robot.upper)
        q = np.concatenate((-P[:2, :2] @ target, (0.0, 0.0)))
        lower, upper = constraints.lower, constraints.upper
        abs_rows = _ABS_ROWS
        if slack:
            P = np.diag([*np.diag(P), self.config.slack_weight])
            q = np.append(q, SLACK_LINEAR_WEIGHT)
            G = np.column_stack((G, -np.ones(len(G))))
            abs_rows = np.column_stack((abs_rows, np.zeros(4)))
            lower, upper = np.append(lower, 0.0), np.append(upper, np.inf)
        return QPData(P, q, np.vstack((abs_rows, G)), np.concatenate((_ABS_RHS, rhs)), lower, upper)

    def _prune(self, constraints: _Constraints) -> np.ndarray:
        """Mask of the rows that some reachable command could make active (the others never are)."""
        G = constraints.G
        worst = np.maximum(G * constraints.lower, G * constraints.upper).sum(axis=1)
        return worst > constraints.rhs

    def build_qp(self, u_nom: Any, scan: LaserScan, velocity: Any = None, *, reduce: bool = True
                 ) -> qpsolvers.Problem:
        """The QP the filter solves, for inspection, over ``z = (v, omega, t_v, t_omega)``.

        Rows 0-3 of ``G`` are ``|v| <= t_v`` and ``|omega| <= t_omega``; the rest are barrier
        and field-of-view rows. With ``reduce=True`` the rows no reachable command can make
        active are dropped (the answer is the same); with ``reduce=False`` every point gives a row.
        """
        u_nom = np.asarray(u_nom, dtype=float)
        constraints = self._constraints(scan, None if velocity is None else np.asarray(velocity, dtype=float))
        keep = self._prune(constraints) if reduce else np.ones(len(constraints.rhs), dtype=bool)
        return self._problem(u_nom, constraints.G[keep], constraints.rhs[keep], constraints).problem()

    # ------------------------------------------------------------------ filtering

    def _filter(self, u_nom: np.ndarray, scan: LaserScan, velocity: np.ndarray | None) -> FilterResult:
        constraints = self._constraints(scan, velocity)
        points, barrier = constraints.points, constraints.barrier
        min_barrier = float(barrier.min()) if len(barrier) else math.inf
        clearance = body_clearance(points, self.robot.radius)
        G, rhs = constraints.G, constraints.rhs
        details: dict[str, Any] = dict(min_barrier=min_barrier, clearance=clearance)

        lower, upper = constraints.lower, constraints.upper
        v, omega = u_nom
        if (lower[0] <= v <= upper[0] and lower[1] <= omega <= upper[1]
                and (G @ self._lifted(u_nom, constraints) <= rhs).all()):
            return FilterResult(u=u_nom, u_nom=u_nom, status=FilterStatus.OK, **details)

        direct_rows = min(self.backend.direct_rows, DIRECT_ROWS)
        if len(rhs) <= direct_rows:
            # Few enough rows for one solve: skip the pruning (it would not pay for itself).
            candidate = np.arange(len(rhs))
            cand_G, cand_rhs, cand_point = G, rhs, constraints.point
        else:
            candidate = np.flatnonzero(self._prune(constraints))
            cand_G, cand_rhs, cand_point = G[candidate], rhs[candidate], constraints.point[candidate]
        if candidate.size <= direct_rows:
            working = np.ones(candidate.size, dtype=bool)
        else:
            # Initial working set: every field-of-view row and the tightest row per angular bin around p.
            point_rows = np.flatnonzero(cand_point >= 0)
            chosen = nearest_per_bin(points[cand_point[point_rows]], cand_rhs[point_rows], (self.lookahead, 0.0),
                                     self.config.n_bins)
            working = cand_point < 0
            working[point_rows[chosen]] = True
        initial = working.copy()
        z, working, solve_time, _ = self._solve_generating(u_nom, cand_G, cand_rhs, working, constraints)
        slack = 0.0
        status = FilterStatus.OK
        message = ""
        if z is None:
            # No command satisfies every row: relax them all by one heavily penalised slack.
            z, working, more_time, solver_status = self._solve_generating(u_nom, cand_G, cand_rhs, initial,
                                                                           constraints, slack=True)
            solve_time += more_time
            if z is None:
                return self._brake(u_nom, constraints.velocity, FilterStatus.FALLBACK,
                                   f"QP solver {self.backend.name} failed ({solver_status}) even with slack",
                                   solver=self.backend.name, solve_time=solve_time, **details)
            z, slack = z[:4], max(float(z[4]), 0.0)
            if slack > VERIFY_TOLERANCE:
                status = FilterStatus.SLACK
                message = self._slack_reason(constraints, min_barrier, slack * self.dt)
        if status is FilterStatus.OK and min_barrier < 0.0:
            status = FilterStatus.RECOVERING
            message = f"inside the margin of the nearest obstacle (barrier {min_barrier:.3f} m); moving back out"

        u = np.clip(z[:2], constraints.lower[:2], constraints.upper[:2])
        residual = G @ self._lifted(u, constraints) - rhs - slack
        if not np.all(residual <= VERIFY_TOLERANCE):
            worst = int(np.argmax(residual))
            return self._brake(u_nom, constraints.velocity, FilterStatus.FALLBACK,
                               f"QP answer from {self.backend.name} violates row {worst} by {residual[worst]:.3g} m/s",
                               solver=self.backend.name, solve_time=solve_time, **details)
        rows_used = candidate[working]
        row_points = constraints.point[rows_used]
        used = np.zeros(len(points) + 1, dtype=bool)  # the extra slot absorbs field-of-view rows (-1)
        used[row_points] = True
        active = np.zeros(len(points) + 1, dtype=bool)
        active[row_points[np.abs(residual[rows_used]) <= 1e-6]] = True
        used, active = used[:-1], active[:-1]
        return FilterResult(
            u=u, u_nom=u_nom, status=status, message=message, n_constraints=int(working.sum()),
            constraint_points=points[used], active=np.flatnonzero(active[used]),
            slack=slack * self.dt if status is FilterStatus.SLACK else 0.0, solver=self.backend.name,
            solve_time=solve_time, **details,
        )

    def _solve_generating(self, u_nom: np.ndarray, G: np.ndarray, rhs: np.ndarray, working: np.ndarray,
                          constraints: _Constraints, slack: bool = False
                          ) -> tuple[np.ndarray | None, np.ndarray, float, str]:
        """Solve over the rows in ``working``, adding violated rows until none is (constraint generation).

        Returns the solution (``None`` on failure), the final working set, the solve time [s]
        and the solver's last status word. The answer equals that of the QP with all rows.
        """
        working = working.copy()
        solve_time = 0.0
        outcome = None
        for round_index in range(MAX_GENERATION_ROUNDS + 1):
            if round_index == MAX_GENERATION_ROUNDS:
                working[:] = True
            outcome = self.backend.solve(self._problem(u_nom, G[working], rhs[working], constraints, slack=slack))
            solve_time += outcome.solve_time
            z = outcome.x
            if z is None:
                return None, working, solve_time, outcome.status
            lhs = G @ z[:4] - (z[4] if slack else 0.0)
            violated = (lhs > rhs + 0.1 * VERIFY_TOLERANCE) & ~working
            if not violated.any():
                return z, working, solve_time, outcome.status
            working |= violated
        return None, working, solve_time, "constraint generation did not settle"

    def _slack_reason(self, constraints: _Constraints, min_barrier: float, slack: float) -> str:
        """Why no command satisfied every row; ``slack`` is the relaxation per period [m]."""
        if min_barrier < 0.0:
            return (f"already inside the margin (barrier {min_barrier:.3f} m); constraints relaxed by "
                    f"{slack:.4f} m, moving away")
        if constraints.blocked.forward or constraints.blocked.backward:
            return f"cannot stop before moving towards an unseen direction; constraints relaxed by {slack:.4f} m"
        return f"cannot brake in time under the acceleration limits; constraints relaxed by {slack:.4f} m"

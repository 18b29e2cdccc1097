"""Predictive (MPC) safety filter: a plan over a short horizon that is safe all the way to a stop.

A velocity-level barrier assumes the base can stop at once; a real base cannot. This
filter plans ``N`` commands ahead under the acceleration limits, keeps the body disk
clear of every lidar point at every step, and ends the plan stopped, so "stay stopped"
is always a safe continuation and the problem stays feasible from one period to the
next. The nonlinear program is built once in casadi (single shooting over the commands;
obstacle points, radii and bounds are parameters) and solved by ``sqpmethod`` with the
DAQP QP solver and a Gauss-Newton Hessian, which measured fastest (see :class:`MPCConfig`).
"""

from __future__ import annotations

import functools
import math
import time
from dataclasses import dataclass
from typing import Any, NamedTuple

import casadi
import numpy as np

from safenav.errors import InvalidConfig, UnknownName
from safenav.filters.base import FilterResult, FilterStatus, SafetyFilter
from safenav.filters.cbf import STEERING_PREFERENCE
from safenav.filters.reduction import (
    BlockedMotion,
    blocked_motion,
    default_margin,
    nearest_per_bin,
    obstacle_points,
    unknown_arcs,
)
from safenav.geometry import TWO_PI, Pose2D, unicycle_rollout, unicycle_step
from safenav.robot import RobotSpec
from safenav.scan import LaserScan

__all__ = [
    "CasadiBackend",
    "MPCConfig",
    "MPCProblem",
    "MPCSafetyFilter",
    "PlanCheck",
    "SolveOutcome",
    "available_mpc_solvers",
]

#: Horizon used unless the robot needs more steps to stop from its velocity limits.
DEFAULT_HORIZON = 20
#: Tolerance of the filter's own check of a plan's clearance against every point [m].
VERIFY_TOLERANCE = 1e-6
#: Tolerance of the check of a plan against the velocity, acceleration and terminal bounds [m/s, rad/s]
#: (an SQP stopped at its iteration limit can miss a linear row by ~1e-7; the first command is
#: clipped into its bounds exactly).
BOUND_TOLERANCE = 1e-6
#: After the last swap of missed points, an answer that misses its own rows by at most this much
#: is accepted, with its true slack reported [m]; a larger miss counts as a failed solve.
SETTLE_TOLERANCE = 1e-3
#: Distance of the parameter slots the reduction leaves unused from the robot [m].
FAR_AWAY = 1e6
#: Smallest radius the clearance rows are scaled by [m] (a point at the base origin has radius 0).
MIN_ROW_SCALE = 1e-3
#: QP solvers casadi's ``sqpmethod`` can use here, in order of preference.
CONIC_PLUGINS = ("daqp", "qrqp", "osqp", "qpoases", "hpipm", "proxqp", "highs")
HESSIANS = ("gauss-newton", "exact")


def available_mpc_solvers() -> list[str]:
    """Solver names :class:`MPCConfig` accepts on this machine (casadi QP plugins, and ``"ipopt"``)."""
    names = [name for name in CONIC_PLUGINS if casadi.has_conic(name)]
    if casadi.has_nlpsol("ipopt"):
        names.append("ipopt")
    return names


def _check_number(name: str, value: Any, low: float, high: float) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not low <= value <= high:
        raise InvalidConfig(f"MPCConfig.{name} must be a number in [{low}, {high}], got {value!r}")
    return float(value)


def _check_integer(name: str, value: Any, low: int, high: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
        raise InvalidConfig(f"MPCConfig.{name} must be an integer in [{low}, {high}], got {value!r}")
    return value


@dataclass(frozen=True)
class MPCConfig:
    """Settings of :class:`MPCSafetyFilter`; ``None`` means "derive from the robot" (see there).

    Attributes:
        horizon: number of planned commands ``N``; default ``max(20, steps to stop from the
            velocity limits + 1)``.
        margin: clearance kept between the body disk and every obstacle point [m].
        buffer: extra distance the plan keeps beyond the guaranteed radius [m], so that a base
            that ramps differently from the model, or range noise between scans, does not make
            the next problem need slack; default ``e_act + 2 noise_std`` (see :class:`MPCSafetyFilter`).
        n_points: obstacle-point slots ``K`` of the optimiser (each gives one row per step);
            the plan is checked against every point in reach, and missed points are swapped in.
        solver: ``"daqp"`` (default) or another casadi QP plugin for ``sqpmethod``
            (``"qrqp"``, ``"osqp"``, ``"qpoases"``, ...), or ``"ipopt"``.
        hessian: ``"gauss-newton"`` (the cost's own: constant, positive definite) or ``"exact"``
            (the Lagrangian's, made convex by eigenvalue clipping; with ipopt, exact versus
            limited-memory).
        weights: cost weights on the deviation of the first command from ``u_nom``
            [s^2/m^2, s^2/rad^2]; default ``(1 / v_max^2, 0.2 / omega_max^2)`` as the CBF filter.
        regularisation: weight of the later commands' magnitudes relative to ``weights``
            (keeps the plan unique, prefers braking early, and speeds up the Gauss-Newton SQP).
        slack_weight: linear and quadratic cost of the relaxation of the clearance rows [1/m, 1/m^2].
        max_iter: SQP iterations per solve.
        max_rounds: solves with missed points swapped into the slots before the call counts as failed.
        max_gap: widest run of invalid beams bridged by its neighbours [rad]; wider runs are unknown.
        side_tolerance: unknown directions this close to exactly sideways do not block motion [rad].
        memory: how long a point seen earlier stays an obstacle while its direction is unknown to
            the current scan (e.g. beside the body behind a 180-degree lidar) [s]; 0 forgets at once.
        scan_timeout: scans older than this make the filter brake [s].
        compensate_latency: move a scan of known age into the current base frame first
            (see :meth:`SafetyFilter.current_frame`).
    """

    horizon: int | None = None
    margin: float | None = None
    buffer: float | None = None
    n_points: int = 32
    solver: str = "daqp"
    hessian: str = "gauss-newton"
    weights: tuple[float, float] | None = None
    regularisation: float = 1e-2
    slack_weight: float = 1e4
    max_iter: int = 30
    max_rounds: int = 4
    max_gap: float = math.radians(5.0)
    side_tolerance: float = math.radians(5.0)
    memory: float = 2.0
    scan_timeout: float = 0.5
    compensate_latency: bool = True

    def __post_init__(self) -> None:
        if self.horizon is not None:
            _check_integer("horizon", self.horizon, 2, 400)
        if self.margin is not None:
            _check_number("margin", self.margin, 0.0, 10.0)
        if self.buffer is not None:
            _check_number("buffer", self.buffer, 0.0, 1.0)
        _check_integer("n_points", self.n_points, 1, 2000)
        if self.solver not in available_mpc_solvers():
            raise UnknownName("MPC solver", self.solver, available_mpc_solvers(),
                              hint="casadi QP plugins for sqpmethod, or ipopt")
        if self.hessian not in HESSIANS:
            raise UnknownName("MPC Hessian", self.hessian, HESSIANS)
        if self.weights is not None and (
                not isinstance(self.weights, (tuple, list)) or len(self.weights) != 2 or not all(
                    isinstance(w, (int, float)) and not isinstance(w, bool) and math.isfinite(w) and w > 0
                    for w in self.weights)):
            raise InvalidConfig(f"MPCConfig.weights must be two positive numbers (v, omega), got {self.weights!r}")
        _check_number("regularisation", self.regularisation, 1e-9, 1.0)
        _check_number("slack_weight", self.slack_weight, 1.0, 1e9)
        _check_integer("max_iter", self.max_iter, 1, 10000)
        _check_integer("max_rounds", self.max_rounds, 1, 100)
        _check_number("max_gap", self.max_gap, 0.0, 2 * math.pi)
        _check_number("side_tolerance", self.side_tolerance, 0.0, 0.5 * math.pi)
        _check_number("memory", self.memory, 0.0, 60.0)
        _check_number("scan_timeout", self.scan_timeout, 1e-6, 1e9)
        if not isinstance(self.compensate_latency, bool):
            raise InvalidConfig(f"MPCConfig.compensate_latency must be True or False, got {self.compensate_latency!r}")


class MPCProblem(NamedTuple):
    """What one call of the filter optimises over, in the current base frame.

    Commands ``u_k``, ``k = 0..N-1``, are held for one period each; the base ramps from
    ``u_{k-1}`` (``u_{-1}`` = :attr:`velocity`) to ``u_k`` during period ``k``, modelled as
    the exact arc of the mean velocity. Knot ``k`` (``1..N``) is the pose after period ``k-1``.
    """

    u_nom: np.ndarray
    """The nominal command ``(v [m/s], omega [rad/s])``."""
    velocity: np.ndarray
    """The velocity the plan starts from (measured, or the last command) [m/s, rad/s]."""
    points: np.ndarray
    """``(M, 2)`` every obstacle point a plan could come near, base frame [m]."""
    radii: np.ndarray
    """``(M,)`` distance the planner keeps every knot from each point [m]: ``min(r_eff + buffer, ||o||)``."""
    guaranteed: np.ndarray
    """``(M,)`` distance a verified plan keeps every knot from each point [m]: ``min(r_eff, ||o||)``."""
    lower: np.ndarray
    """``(N, 2)`` lower bounds on the commands (limits, reachability, field of view, stop at the end)."""
    upper: np.ndarray
    """``(N, 2)`` upper bounds on the commands."""
    blocked: BlockedMotion
    """Motion directions the scan does not see."""
    min_barrier: float
    """Smallest ``||o|| - (R + margin)`` over every point of the scan, at the current pose [m]."""
    clearance: float
    """Distance from the base origin to the nearest point minus the body radius [m]."""


class PlanCheck(NamedTuple):
    """How far a plan is from satisfying a :class:`MPCProblem`."""

    limits: float
    """Largest violation of a command bound or of an acceleration row [m/s or rad/s] (<= 0 if none)."""
    clearance: float
    """Smallest ``||p_k - o|| - guaranteed(o)`` over knots ``1..N`` and every point [m] (``inf`` without
    points): negative means the plan needs that much slack."""
    planned: float
    """Smallest ``||p_k - o|| - radii(o)`` [m]: negative means the plan uses some of the buffer."""
    distances: np.ndarray
    """``(M,)`` the smallest knot distance ``||p_k - o||`` per point [m]."""
    poses: np.ndarray
    """``(N + 1, 3)`` the predicted poses ``(x, y, yaw)``, starting at the origin."""


class SolveOutcome(NamedTuple):
    """What a back-end returned for one NLP."""

    x: np.ndarray | None
    """The decision vector ``(u_0, ..., u_{N-1}, slack)``, or ``None`` when the solver raised."""
    status: str
    """The solver's own status word."""
    iterations: int
    """SQP (or interior-point) iterations."""
    solve_time: float
    """Wall time of the solve [s]."""


class _Solved(NamedTuple):
    """A verified plan (``commands`` is ``None`` on failure), the slots used, the time and why it failed."""

    commands: np.ndarray | None
    check: PlanCheck | None
    used: np.ndarray
    solve_time: float
    message: str


def _sinc(x: casadi.SX) -> casadi.SX:
    """sin(x)/x as its Taylor polynomial to x^10 (error below 2e-10 for |x| <= 1, smooth at 0)."""
    x2 = x * x
    return 1 - x2 / 6 * (1 - x2 / 20 * (1 - x2 / 42 * (1 - x2 / 72 * (1 - x2 / 110))))


def _row_values(distances: np.ndarray, radii: np.ndarray) -> np.ndarray:
    """The clearance rows as the NLP writes them, ``(d^2 - r^2) / (2 r)`` (about ``d - r``) [m]."""
    return (distances * distances - radii * radii) * (0.5 / np.maximum(radii, MIN_ROW_SCALE))


class _NLPKey(NamedTuple):
    horizon: int
    n_points: int
    dt: float
    weights: tuple[float, float]
    regularisation: float
    slack_weight: float
    solver: str
    hessian: str
    max_iter: int


@functools.lru_cache(maxsize=32)
def _build_nlp(key: _NLPKey) -> casadi.Function:
    """The casadi solver for one problem shape; built once and shared by filters with the same key.

    Decision vector ``x = (u_0, ..., u_{N-1}, s)``; parameters ``p = (velocity, u_nom,
    points (K x 2, row-major), radii (K))``; constraints ``g`` = the ``2 (N - 1)``
    acceleration rows ``u_k - u_{k-1}``, then ``K N`` clearance rows, knot-major,
    ``(||p_k - o_j||^2 - r_j^2) / (2 r_j) + s >= 0`` (about ``||p_k - o_j|| - r_j + s`` [m]).
    """
    horizon, n_points, dt = key.horizon, key.n_points, key.dt
    commands = casadi.SX.sym("u", 2, horizon)
    slack = casadi.SX.sym("s")
    velocity = casadi.SX.sym("velocity", 2)
    nominal = casadi.SX.sym("u_nom", 2)
    points = casadi.SX.sym("points", 2, n_points)
    radii = casadi.SX.sym("radii", n_points)
    parameters = casadi.vertcat(velocity, nominal, casadi.vec(points), radii)
    w_v, w_omega = key.weights
    cost = w_v * (commands[0, 0] - nominal[0]) ** 2 + w_omega * (commands[1, 0] - nominal[1]) ** 2
    cost += key.regularisation * (w_v * casadi.sumsqr(commands[0, 1:]) + w_omega * casadi.sumsqr(commands[1, 1:]))
    cost += key.slack_weight * (slack + slack**2)
    scale = 0.5 / casadi.fmax(radii, MIN_ROW_SCALE)
    acceleration_rows = []
    clearance_rows = []
    x = y = yaw = 0.0
    previous = velocity
    for k in range(horizon):
        command = commands[:, k]
        if k > 0:
            acceleration_rows.append(command - previous)
        mean = 0.5 * (previous + command)
        half_turn = 0.5 * dt * mean[1]
        chord = dt * mean[0] * _sinc(half_turn)
        heading = yaw + half_turn
        x, y, yaw = x + chord * casadi.cos(heading), y + chord * casadi.sin(heading), yaw + 2.0 * half_turn
        dx = x - points[0, :].T
        dy = y - points[1, :].T
        clearance_rows.append((dx * dx + dy * dy - radii * radii) * scale + slack)
        previous = command
    nlp = {"x": casadi.vertcat(casadi.vec(commands), slack), "p": parameters, "f": cost,
           "g": casadi.vertcat(*acceleration_rows, *clearance_rows)}
    if key.solver == "ipopt":
        options: dict[str, Any] = {"print_time": False, "ipopt.print_level": 0, "ipopt.sb": "yes",
                                   "ipopt.max_iter": key.max_iter, "ipopt.tol": 1e-9,
                                   "ipopt.constr_viol_tol": 1e-9, "error_on_fail": False}
        if key.hessian == "gauss-newton":
            options["ipopt.hessian_approximation"] = "limited-memory"
        return casadi.nlpsol("mpc_filter", "ipopt", nlp, options)
    qp_options: dict[str, Any] = {"print_time": False, "error_on_fail": False}
    if key.solver == "daqp":
        qp_options["daqp"] = {"primal_tol": 1e-10, "iter_limit": 2000}
    elif key.solver == "qrqp":
        qp_options.update(print_iter=False, print_header=False, print_info=False, max_iter=2000)
    elif key.solver == "osqp":
        qp_options["osqp"] = {"verbose": False, "eps_abs": 1e-10, "eps_rel": 1e-10, "max_iter": 20000,
                              "polishing": True}
    elif key.solver == "qpoases":
        qp_options.update(printLevel="none", sparse=True)
    # Full SQP steps (no line search) and a dual tolerance of 1e-6 measured fastest with the same
    # answers; every answer is verified by the filter anyway.
    options = {"qpsol": key.solver, "qpsol_options": qp_options, "print_time": False, "print_header": False,
               "print_iteration": False, "print_status": False, "max_iter": key.max_iter, "tol_pr": 1e-10,
               "tol_du": 1e-6, "min_step_size": 1e-14, "max_iter_ls": 0, "error_on_fail": False}
    if key.hessian == "gauss-newton":
        decision = nlp["x"]
        lam_f = casadi.SX.sym("lam_f")
        lam_g = casadi.SX.sym("lam_g", nlp["g"].shape[0])
        hessian = casadi.triu(casadi.hessian(cost, decision)[0]) * lam_f
        options["hess_lag"] = casadi.Function("gauss_newton", [decision, parameters, lam_f, lam_g], [hessian],
                                              ["x", "p", "lam_f", "lam_g"], ["hess_gamma_x_x"])
    else:
        options["convexify_strategy"] = "eigen-clip"
    return casadi.nlpsol("mpc_filter", "sqpmethod", nlp, options)


class CasadiBackend:
    """The NLP of one problem shape, built once; each call only passes new parameters and bounds.

    Args:
        key: the problem shape and solver settings.
    """

    def __init__(self, key: _NLPKey) -> None:
        self.key = key
        self.name = "ipopt" if key.solver == "ipopt" else f"sqpmethod+{key.solver}"
        self._solver = _build_nlp(key)

    def solve(self, x0: np.ndarray, parameters: np.ndarray, lbx: np.ndarray, ubx: np.ndarray,
              lbg: np.ndarray, ubg: np.ndarray) -> SolveOutcome:
        """Solve from ``x0``; ``x`` is ``None`` only when casadi raised (the caller verifies any answer)."""
        start = time.perf_counter()
        try:
            result = self._solver(x0=x0, p=parameters, lbx=lbx, ubx=ubx, lbg=lbg, ubg=ubg)
        except RuntimeError as error:  # casadi raises RuntimeError for evaluation errors
            return SolveOutcome(None, f"error: {error}", 0, time.perf_counter() - start)
        elapsed = time.perf_counter() - start
        try:
            stats = self._solver.stats()
        except RuntimeError:  # some plugins leave no statistics behind after a failure
            stats = {}
        return SolveOutcome(np.asarray(result["x"], dtype=float).ravel(), str(stats.get("return_status", "unknown")),
                            int(stats.get("iter_count", 0)), elapsed)


class MPCSafetyFilter(SafetyFilter):
    """Minimal change of the first command such that a plan that ends stopped stays clear of every lidar point.

    **Plan.** ``N`` commands ``u_0..u_{N-1}`` held for ``dt`` each, starting from the
    current velocity ``u_{-1}``: the measured ``velocity``, or, when ``velocity`` is ``None``,
    the last command this filter returned (zero after :meth:`reset`; the filter then
    assumes the base reached it). Each command is reachable from the previous one within
    one period (``|u_k - u_{k-1}| <= (a_max, alpha_max) dt``), respects the velocity limits,
    and ``u_{N-1} = 0``: the plan ends stopped. During period ``k`` the base is modelled as
    moving along the exact arc of the mean velocity ``(u_{k-1} + u_k) / 2``: the
    displacement of a base that ramps linearly to each command.

    **Constraints.** At every knot ``p_k`` (``k = 1..N``) and for every obstacle point
    ``o`` of the scan (base frame, the world taken as static)::

        ||p_k - o|| >= min(r_eff, ||o||)
        r_eff = max(sqrt((R + margin + e_arc + e_act)^2 + (L / 2)^2),  range_min + |mount|)

    with ``L = max(v_max, -v_min) dt`` the longest chord of one period,
    ``e_arc = (L / 2) sin(omega_max dt / 2)`` the farthest a one-period arc strays from its
    chord, and ``e_act = dt^2 (a_max + L alpha_max) / 2`` the farthest the true position
    strays from the model's within a period when the velocity stays between the previous
    and the new command. If both knots of a period are ``>= r_eff`` from ``o``, the whole
    chord is ``>= sqrt(r_eff^2 - L^2/4)`` from it, so the body disk keeps ``margin`` of
    clearance *between* the knots too. The second term keeps the plan out of the ring the
    lidar cannot measure (readings closer than ``range_min`` are ``-inf``).
    A point already nearer than ``r_eff`` (noise, a push) may not be approached further
    (recovery). The planner aims for ``r_eff + buffer`` (default ``buffer = e_act + 2
    noise_std``), so a base that ramps differently from the model, or the range noise of
    the next scan, does not make the next problem need slack; verification and status use
    ``r_eff``.
    ``margin = 0.02 m + 2 noise_std + 1 m x angle_increment``, as the CBF filter.

    **Field of view.** As the CBF filter: an unknown direction within ``90 deg -
    side_tolerance`` of the heading forbids ``v > 0`` over the whole horizon (of the rear,
    ``v < 0``). A base already moving that way brakes at its limit (status ``SLACK``).

    **Cost.** ``w_v (v_0 - v_nom)^2 + w_omega (omega_0 - omega_nom)^2`` plus
    ``regularisation`` times the same weights on the later commands, plus a slack ``s``
    that relaxes every clearance row, with a heavy linear and quadratic cost (an exact
    penalty: ``s = 0`` whenever a plan satisfies every row).

    **Minimal intervention (fast path).** The candidate "``u_nom`` clipped to the reachable
    box, then brake at the acceleration limits to a stop" is checked against every bound
    and every point in reach; when it passes, its first command is returned (``u_nom``
    itself, bit for bit, when ``u_nom`` is reachable) and nothing is solved.

    **Solve.** Otherwise the NLP (built once; single shooting over the commands, ``K``
    point slots as parameters, unused slots far away) is solved by casadi's ``sqpmethod``
    with the configured QP solver, warm-started from the previous plan shifted by one
    step. The slots hold the nearest point per angular bin around the base (key: clearance
    to the warm start and to the fast-path candidate). **Every answer is checked
    numerically** against every bound, every acceleration row and *every* point in reach
    (not only the ``K`` slots); points the plan violates are swapped into the slots and
    the NLP is solved again (up to ``max_rounds`` solves), so binning cannot let the disk
    cut between two sampled points unnoticed. (If the last solve still misses a point by
    less than 1 mm, it is kept and its true slack reported; by more, the call falls back.)

    **Guarantee.** If the world is static, every obstacle wider than the beam gap at 1 m is
    seen by a beam whose reading is within ``2 noise_std`` of the truth, and during each
    period the base's velocity stays componentwise between the velocity the period starts
    with and the returned command (any base that reaches each command within the period
    without overshoot, or applies it at once), then, with status ``OK`` or ``RECOVERING``,
    throughout the executed period the body disk keeps ``margin`` of clearance from every
    point seen at least ``r_eff`` away when the period starts, and the base origin comes no
    closer than ``sqrt(||o||^2 - L^2/4) - e_arc - e_act`` to a point already nearer (only
    after noise or a push; ``RECOVERING`` when nearer than ``R + margin``); with ``SLACK``
    the knots come up to ``slack`` closer than that. Returned commands always respect the velocity and
    acceleration limits. **Recursive feasibility:** if the base moves exactly as modelled
    and no point is nearer than ``r_eff + buffer``, the previous plan shifted by one step
    (then stay stopped) satisfies every constraint of the next problem, so a plan without
    slack always exists; a base that ramps differently moves up to ``e_act`` (and
    ``dt^2 alpha_max / 2`` in heading) away from the prediction per period, and noise moves
    the points, which the buffer absorbs (in practice; beyond it the status says
    ``SLACK``). Not covered: obstacles the lidar has not seen (covered only by forbidding
    motion towards unseen directions), moving obstacles, points newly revealed by occlusion.

    **Memory.** A point seen earlier stays an obstacle for ``memory`` seconds while the
    current scan says nothing about its direction (e.g. beside the body behind a
    front-mounted 180-degree lidar), moved into the current frame by the motion the last
    plan predicted (the filter assumes one call per period). A direction the scan sees
    again replaces what was remembered there.

    **When it cannot hold.** No plan without slack (already inside the radius, or too fast
    to stop before a point or an unseen direction): the plan violates the rows as little as
    possible (status ``SLACK``, ``slack`` the largest violation [m]). A base too fast to stop
    within the horizon at all (a measured velocity beyond what ``N`` steps can brake) brakes
    at its limits, status ``SLACK``, ``slack`` the distance still needed. Solver failure, or an
    answer that fails verification: the filter executes the next command of the last
    verified plan, which ends stopped (status ``FALLBACK``); without one it brakes at the
    acceleration limits.

    **Result fields.** ``min_barrier`` is ``min ||o|| - (R + margin)`` at the current pose
    (as the CBF filter's, negative inside the margin); ``clearance`` the nearest point minus
    ``R``; ``n_constraints`` the clearance rows the optimiser saw (points x ``N``; 0 on the
    fast path); ``constraint_points`` those points; ``active`` the ones whose planning row
    holds with equality (to ``1e-6`` m); ``slack`` the largest violation of ``r_eff`` [m];
    ``plan`` the ``(N + 1, 5)`` predicted ``(x, y, yaw, v, omega)``.

    Args:
        robot: the robot to protect.
        dt: control period [s].
        config: settings; keyword arguments override its fields (e.g. ``horizon=30``).

    Raises:
        InvalidConfig: a setting is out of range, or ``omega_max dt > 2`` (too coarse a period).
        UnknownName: the solver or Hessian is not known (the message lists the known ones).
    """

    name = "mpc"

    def __init__(self, robot: RobotSpec, dt: float = 0.05, *, config: MPCConfig | None = None, **overrides: Any):
        config = MPCConfig(**{**(config.__dict__ if config else {}), **overrides})
        super().__init__(robot, dt, scan_timeout=config.scan_timeout, compensate_latency=config.compensate_latency)
        self.config = config
        dt = self.dt
        if robot.omega_max * dt > 2.0:
            raise InvalidConfig(f"omega_max * dt = {robot.omega_max * dt:.3g} rad per period is too coarse for the "
                                f"MPC filter's arc model; expected <= 2 (a shorter dt)")
        lidar = robot.lidar
        self.margin = config.margin if config.margin is not None else default_margin(robot)
        self._step = np.array([robot.a_max, robot.alpha_max]) * dt
        self.speed = max(robot.v_max, -robot.v_min)
        stop_steps = math.ceil(max(self.speed / self._step[0], robot.omega_max / self._step[1]) - 1e-9)
        self.horizon = config.horizon if config.horizon is not None else max(DEFAULT_HORIZON, stop_steps + 1)
        chord = self.speed * dt
        self.arc_error = 0.5 * chord * math.sin(0.5 * min(robot.omega_max * dt, 0.5 * math.pi))
        self.actuator_error = 0.5 * dt * dt * (robot.a_max + chord * robot.alpha_max)
        blind = lidar.range_min + math.hypot(lidar.mount.x, lidar.mount.y)
        self.inflated_radius = max(math.hypot(robot.radius + self.margin + self.arc_error + self.actuator_error,
                                              0.5 * chord), blind)
        self.buffer = (config.buffer if config.buffer is not None
                       else self.actuator_error + 2.0 * lidar.noise_std)
        weights = config.weights or (1.0 / robot.v_max**2, STEERING_PREFERENCE / robot.omega_max**2)
        self.weights = (float(weights[0]), float(weights[1]))
        self.n_points = config.n_points
        self.backend = CasadiBackend(_NLPKey(self.horizon, self.n_points, dt, self.weights, config.regularisation,
                                             config.slack_weight, config.solver, config.hessian, config.max_iter))
        clearance_rows = self.n_points * self.horizon
        self._lbg = np.concatenate((-np.tile(self._step, self.horizon - 1), np.zeros(clearance_rows)))
        self._ubg = np.concatenate((np.tile(self._step, self.horizon - 1), np.full(clearance_rows, np.inf)))
        self._commands: np.ndarray | None = None
        self._last_command = np.zeros(2)
        # Points of earlier scans (previous call's frame) and their ages [s], the predicted motion
        # since then, the memory moved into the current frame, and what this call will remember.
        self._memory = (np.empty((0, 2)), np.empty(0))
        self._motion: Pose2D | None = None
        self._recalled = (np.empty((0, 2)), np.empty(0))
        self._pending: tuple[np.ndarray, np.ndarray] | None = None
        self._memory_range = self._reach(np.array([self.speed, 0.0])) + self.inflated_radius + self.buffer

    def __repr__(self) -> str:
        return (f"MPCSafetyFilter(robot={self.robot.name!r}, dt={self.dt}, horizon={self.horizon}, "
                f"n_points={self.n_points}, margin={self.margin:.4f}, inflated_radius={self.inflated_radius:.4f}, "
                f"buffer={self.buffer:.4f}, solver={self.backend.name!r})")

    def reset(self) -> None:
        """Forget the stored plan (warm start and fallback) and the remembered points; take the base as stopped."""
        self._commands = None
        self._last_command = np.zeros(2)
        self._memory = self._recalled = (np.empty((0, 2)), np.empty(0))
        self._motion = None
        self._pending = None

    def filter(self, u_nom: Any, scan: LaserScan, *, velocity: Any = None, scan_age: float | None = None,
               now: float | None = None) -> FilterResult:
        """Filter one nominal command (see :meth:`SafetyFilter.filter`).

        Without ``velocity``, the plan starts from the last command this filter returned (zero
        after :meth:`reset`), so the returned commands form a sequence the base can follow
        under its acceleration limits.
        """
        start = self._last_command
        self._recalled = self._recall()
        self._pending = None
        result = super().filter(u_nom, scan, velocity=velocity, scan_age=scan_age, now=now)
        if velocity is not None:   # a valid pair by now (the base class checked it)
            measured = np.asarray(velocity, dtype=float).reshape(2)
            if np.all(np.isfinite(measured)):
                start = measured
        self._last_command = np.array(result.u, dtype=float)
        self._memory = self._pending if self._pending is not None else self._recalled
        if result.plan is not None:
            self._motion = Pose2D(*result.plan[1, :3])
        else:
            mean = 0.5 * (start + result.u)
            self._motion = unicycle_step(Pose2D(), float(mean[0]), float(mean[1]), self.dt)
        return result

    # ------------------------------------------------------------------ memory of unseen points

    def _recall(self) -> tuple[np.ndarray, np.ndarray]:
        """The remembered points moved into the current frame by the predicted motion, and their ages.

        The filter assumes one call per period and a base that moved as its last plan predicted.
        """
        points, ages = self._memory
        if points.shape[0] == 0 or self._motion is None:
            return np.empty((0, 2)), np.empty(0)
        points = self._motion.to_local(points)
        ages = ages + self.dt
        keep = (ages <= self.config.memory + 1e-9) & (np.hypot(points[:, 0], points[:, 1]) <= self._memory_range)
        return points[keep], ages[keep]

    def _unseen(self, scan: LaserScan, points: np.ndarray) -> np.ndarray:
        """Mask of ``points`` whose direction from the laser the scan says nothing about."""
        arcs = unknown_arcs(scan, self.config.max_gap)
        if not arcs or points.shape[0] == 0:
            return np.zeros(points.shape[0], dtype=bool)
        bearing = np.arctan2(points[:, 1] - scan.mount.y, points[:, 0] - scan.mount.x)
        unseen = np.zeros(points.shape[0], dtype=bool)
        for start, width in arcs:
            unseen |= (bearing - start) % TWO_PI <= width
        return unseen

    # ------------------------------------------------------------------ problem

    def _reach(self, velocity: np.ndarray) -> float:
        """Upper bound on the path length of any plan from ``velocity`` [m]."""
        k = np.arange(self.horizon)
        step = self._step[0]
        start = abs(float(velocity[0]))
        speeds = np.minimum(np.minimum(self.speed, start + (k + 1) * step), (self.horizon - 1 - k) * step)
        speeds = np.maximum(speeds, np.maximum(start - (k + 1) * step, 0.0))
        previous = np.concatenate(([start], speeds[:-1]))
        return float(0.5 * self.dt * np.sum(previous + speeds))

    def _bounds(self, velocity: np.ndarray, blocked: BlockedMotion) -> tuple[np.ndarray, np.ndarray]:
        """Per-step command bounds ``(N, 2)``: limits, reachability, field of view, stopped at the end."""
        robot = self.robot
        change = np.arange(1, self.horizon + 1)[:, None] * self._step
        reach_low, reach_high = velocity - change, velocity + change
        # Later steps: the limits, widened only to let a base outside them brake at its limit.
        lower = np.minimum(robot.lower, reach_high)
        upper = np.maximum(robot.upper, reach_low)
        lower[0], upper[0] = robot.velocity_bounds(velocity, self.dt)
        if blocked.forward:
            upper[:, 0] = np.minimum(upper[:, 0], np.maximum(0.0, reach_low[:, 0]))
        if blocked.backward:
            lower[:, 0] = np.maximum(lower[:, 0], np.minimum(0.0, reach_high[:, 0]))
        # Stopped at the end; a base too fast to stop within the horizon brakes at its limit instead.
        lower[-1] = np.minimum(0.0, reach_high[-1])
        upper[-1] = np.maximum(0.0, reach_low[-1])
        return lower, upper

    def build_problem(self, u_nom: Any, scan: LaserScan, velocity: Any = None) -> MPCProblem:
        """The data of one call, for inspection: points in reach, their radii, the command bounds.

        Args:
            u_nom: nominal command ``(v [m/s], omega [rad/s])``.
            scan: the scan, in the current base frame.
            velocity: the velocity the plan starts from; ``None`` takes the last returned command.
        """
        nominal = np.asarray(u_nom, dtype=float).reshape(2)
        start = self._last_command if velocity is None else np.asarray(velocity, dtype=float).reshape(2)
        return self._problem(nominal, scan, start)

    def _problem(self, u_nom: np.ndarray, scan: LaserScan, velocity: np.ndarray) -> MPCProblem:
        robot = self.robot
        points = obstacle_points(scan, robot.radius)
        distance = np.hypot(points[:, 0], points[:, 1])
        if self.config.memory > 0.0:
            # Remembered points stay obstacles while their direction is unknown to this scan.
            recalled, ages = self._recalled
            unseen = self._unseen(scan, recalled)
            recalled, ages = recalled[unseen], ages[unseen]
            near = distance <= self._memory_range
            self._pending = (np.vstack((points[near], recalled)), np.concatenate((np.zeros(int(near.sum())), ages)))
            points = np.vstack((points, recalled))
            distance = np.concatenate((distance, np.hypot(recalled[:, 0], recalled[:, 1])))
        if distance.size:
            nearest = float(distance.min())
            min_barrier, clearance = nearest - (robot.radius + self.margin), nearest - robot.radius
        else:
            min_barrier = clearance = math.inf
        planned = self.inflated_radius + self.buffer
        keep = distance <= self._reach(velocity) + planned
        points, distance = points[keep], distance[keep]
        blocked = blocked_motion(scan, self.config.max_gap, self.config.side_tolerance)
        lower, upper = self._bounds(velocity, blocked)
        return MPCProblem(u_nom, velocity.copy(), points, np.minimum(planned, distance),
                          np.minimum(self.inflated_radius, distance), lower, upper, blocked, min_barrier, clearance)

    # ------------------------------------------------------------------ plans

    def predict(self, commands: np.ndarray, velocity: np.ndarray) -> np.ndarray:
        """Poses ``(N + 1, 3)`` the model predicts for ``commands`` ``(N, 2)`` from ``velocity``, in the base frame."""
        commands = np.asarray(commands, dtype=float).reshape(-1, 2)
        previous = np.vstack((np.asarray(velocity, dtype=float).reshape(1, 2), commands[:-1]))
        return unicycle_rollout(Pose2D(), 0.5 * (previous + commands), self.dt)

    def check_plan(self, problem: MPCProblem, commands: np.ndarray) -> PlanCheck:
        """How far ``commands`` ``(N, 2)`` are from satisfying every constraint of ``problem``."""
        commands = np.asarray(commands, dtype=float).reshape(self.horizon, 2)
        limits = max(float(np.max(problem.lower - commands)), float(np.max(commands - problem.upper)))
        if self.horizon > 1:
            limits = max(limits, float(np.max(np.abs(np.diff(commands, axis=0)) - self._step)))
        poses = self.predict(commands, problem.velocity)
        distances = self._distances(poses[1:, :2], problem.points)
        if distances.size == 0:
            return PlanCheck(limits, math.inf, math.inf, distances, poses)
        return PlanCheck(limits, float(np.min(distances - problem.guaranteed)),
                         float(np.min(distances - problem.radii)), distances, poses)

    @staticmethod
    def _distances(knots: np.ndarray, points: np.ndarray) -> np.ndarray:
        """Per point, the smallest distance to any of ``knots`` [m]."""
        if points.shape[0] == 0:
            return np.empty(0)
        dx = knots[:, 0:1] - points[:, 0]
        dy = knots[:, 1:2] - points[:, 1]
        return np.sqrt(np.min(dx * dx + dy * dy, axis=0))

    def _braking(self, first: np.ndarray) -> np.ndarray:
        """``first``, then every command nearer zero by the acceleration limit until stopped: ``(N, 2)``."""
        steps = np.arange(self.horizon)[:, None] * self._step
        return np.sign(first) * np.maximum(np.abs(first) - steps, 0.0)

    @staticmethod
    def _plan_array(poses: np.ndarray, commands: np.ndarray, velocity: np.ndarray) -> np.ndarray:
        return np.column_stack((poses, np.vstack((velocity.reshape(1, 2), commands))))

    # ------------------------------------------------------------------ filtering

    def _filter(self, u_nom: np.ndarray, scan: LaserScan, velocity: np.ndarray | None) -> FilterResult:
        start = self._last_command if velocity is None else velocity
        problem = self._problem(u_nom, scan, start)
        details: dict[str, Any] = dict(min_barrier=problem.min_barrier, clearance=problem.clearance)
        shifted = None
        if self._commands is not None:
            shifted = np.vstack((self._commands[1:], np.zeros((1, 2))))
        self._commands = None

        # Fast path: u_nom (clipped to the reachable box), then brake at the limits.
        first = np.clip(u_nom, problem.lower[0], problem.upper[0])
        candidate = self._braking(first)
        check = self.check_plan(problem, candidate)
        if check.limits <= BOUND_TOLERANCE and check.planned >= 0.0:
            self._commands = candidate
            return self._result(problem, candidate, check, details, used=np.empty(0, dtype=np.intp),
                                solve_time=0.0, solver="")

        warm = np.clip(shifted if shifted is not None else candidate, problem.lower, problem.upper)
        outcome = self._solve(problem, warm, candidate)
        if outcome.commands is None or outcome.check is None:
            return self._fallback(problem, shifted, outcome.message, outcome.solve_time, details)
        self._commands = outcome.commands
        return self._result(problem, outcome.commands, outcome.check, details, used=outcome.used,
                            solve_time=outcome.solve_time, solver=self.backend.name)

    def _result(self, problem: MPCProblem, commands: np.ndarray, check: PlanCheck, details: dict[str, Any], *,
                used: np.ndarray, solve_time: float, solver: str) -> FilterResult:
        """The result for a verified plan: status from its slack, the field of view and the margin."""
        status, message = FilterStatus.OK, ""
        slack = max(0.0, -check.clearance)
        means = 0.5 * (np.vstack((problem.velocity.reshape(1, 2), commands[:-1])) + commands)
        into_unknown = 0.0
        if problem.blocked.forward:
            into_unknown += self.dt * float(np.sum(np.maximum(means[:, 0], 0.0)))
        if problem.blocked.backward:
            into_unknown += self.dt * float(np.sum(np.maximum(-means[:, 0], 0.0)))
        if commands[-1, 0] != 0.0 or commands[-1, 1] != 0.0:
            # Too fast to stop within the horizon: the relaxation is the distance still to go.
            status = FilterStatus.SLACK
            slack = max(slack, 0.5 * commands[-1, 0] ** 2 / self.robot.a_max)
            message = (f"cannot stop within the horizon of {self.horizon} steps from velocity "
                       f"{problem.velocity.tolist()}; braking at the limits")
        elif slack > VERIFY_TOLERANCE:
            status = FilterStatus.SLACK
            if problem.min_barrier < 0.0:
                message = (f"already inside the margin (barrier {problem.min_barrier:.3f} m); plan relaxed by "
                           f"{slack:.4f} m, moving away")
            else:
                message = f"cannot brake in time under the acceleration limits; plan relaxed by {slack:.4f} m"
        elif into_unknown > VERIFY_TOLERANCE:
            status = FilterStatus.SLACK
            slack = into_unknown
            message = (f"cannot stop before moving towards an unseen direction; braking at the limit, "
                       f"{into_unknown:.4f} m towards it")
        elif problem.min_barrier < 0.0:
            status = FilterStatus.RECOVERING
            message = (f"inside the margin of the nearest obstacle (barrier {problem.min_barrier:.3f} m); "
                       f"the plan comes no closer")
        margins = check.distances[used] - problem.radii[used]
        active = np.flatnonzero(margins <= VERIFY_TOLERANCE + max(0.0, -check.planned))
        return FilterResult(
            u=commands[0], u_nom=problem.u_nom, status=status, message=message,
            n_constraints=int(used.size) * self.horizon, constraint_points=problem.points[used], active=active,
            slack=slack if status is FilterStatus.SLACK else 0.0, solver=solver, solve_time=solve_time,
            plan=self._plan_array(check.poses, commands, problem.velocity), **details,
        )

    def _select(self, problem: MPCProblem, references: list[np.ndarray]) -> np.ndarray:
        """Indices of at most ``K`` points: nearest per angular bin by clearance to the reference knots."""
        count = problem.points.shape[0]
        if count <= self.n_points:
            return np.arange(count)
        knots = np.vstack([poses[1:, :2] for poses in references])
        keys = self._distances(knots, problem.points) - problem.radii
        chosen = nearest_per_bin(problem.points, keys, (0.0, 0.0), self.n_points)
        if chosen.size < self.n_points:
            rest = np.setdiff1d(np.arange(count), chosen, assume_unique=True)
            order = np.argsort(keys[rest], kind="stable")[: self.n_points - chosen.size]
            chosen = np.concatenate((chosen, rest[order]))
        return chosen

    def _solve(self, problem: MPCProblem, warm: np.ndarray, candidate: np.ndarray) -> _Solved:
        """Solve the NLP; swap points the answer violates into the slots and solve again.

        An answer is accepted when, for every point in reach, each knot keeps either the
        guaranteed radius or the distance the solver's own slack allows in its row.
        """
        horizon, n_points = self.horizon, self.n_points
        used = self._select(problem, [self.predict(warm, problem.velocity),
                                      self.predict(candidate, problem.velocity)])
        lbx = np.append(problem.lower.ravel(), 0.0)
        ubx = np.append(problem.upper.ravel(), np.inf)
        head = np.concatenate((problem.velocity, problem.u_nom))
        commands = warm
        solve_time = 0.0
        # Smallest row value each point has had in any answer so far: a point that was ever near a
        # violation keeps its slot, so the working set grows monotonically until the slots run out.
        priority = np.full(problem.points.shape[0], np.inf)
        for round_index in range(self.config.max_rounds):
            slots = np.full((n_points, 2), FAR_AWAY)
            radii = np.full(n_points, self.inflated_radius)
            slots[: used.size] = problem.points[used]
            radii[: used.size] = problem.radii[used]
            start_slack = 0.0
            if used.size:
                knots = self.predict(commands, problem.velocity)[1:, :2]
                rows = _row_values(self._distances(knots, problem.points[used]), problem.radii[used])
                start_slack = max(0.0, -float(rows.min()))
            outcome = self.backend.solve(np.append(commands.ravel(), start_slack),
                                         np.concatenate((head, slots.ravel(), radii)), lbx, ubx, self._lbg, self._ubg)
            solve_time += outcome.solve_time
            x = outcome.x
            if x is None or x.shape != (2 * horizon + 1,) or not np.all(np.isfinite(x)):
                return _Solved(None, None, used, solve_time, f"solver {self.backend.name} failed ({outcome.status})")
            commands = self._repair(x[:-1].reshape(horizon, 2), problem)
            check = self.check_plan(problem, commands)
            if check.limits > BOUND_TOLERANCE:
                return _Solved(None, None, used, solve_time,
                               f"answer of {self.backend.name} ({outcome.status}) violates the velocity or "
                               f"acceleration bounds by {check.limits:.3g}")
            rows = _row_values(check.distances, problem.radii)
            shortfall = np.maximum(rows + max(0.0, float(x[-1])), check.distances - problem.guaranteed)
            violated = np.flatnonzero(shortfall < -VERIFY_TOLERANCE)
            if violated.size == 0:
                return _Solved(commands, check, used, solve_time, "")
            missed = np.setdiff1d(violated, used, assume_unique=True)
            worst = int(violated[np.argmin(shortfall[violated])])
            if missed.size == 0:
                return _Solved(None, None, used, solve_time,
                               f"answer of {self.backend.name} ({outcome.status}) violates the clearance of "
                               f"point {worst} by {-shortfall[worst]:.3g} m")
            if round_index == self.config.max_rounds - 1:
                if -shortfall[worst] <= SETTLE_TOLERANCE:   # accepted; its true slack is reported
                    return _Solved(commands, check, used, solve_time, "")
                break
            # Swap the missed points in, in place of the points that have stayed farthest from violation.
            priority = np.minimum(priority, rows)
            pool = np.union1d(used, missed)
            order = np.argsort(priority[pool], kind="stable")
            used = pool[order[:n_points]]
        return _Solved(None, None, used, solve_time,
                       f"point reduction did not settle in {self.config.max_rounds} solves")

    def _repair(self, commands: np.ndarray, problem: MPCProblem) -> np.ndarray:
        """``commands`` moved into their bounds and acceleration rows (an SQP stopped at its iteration
        limit can miss a linear row by ~1e-6); the result is verified like any answer."""
        repaired = np.clip(commands, problem.lower, problem.upper)
        for k in range(1, self.horizon):
            repaired[k] = np.clip(np.clip(repaired[k], repaired[k - 1] - self._step, repaired[k - 1] + self._step),
                                  problem.lower[k], problem.upper[k])
        return repaired

    def _fallback(self, problem: MPCProblem, shifted: np.ndarray | None, reason: str, solve_time: float,
                  details: dict[str, Any]) -> FilterResult:
        """Next command of the last verified plan (which ends stopped), or braking at the limits without one."""
        if shifted is not None:
            commands = shifted.copy()
            commands[0] = np.clip(commands[0], problem.lower[0], problem.upper[0])
            message = f"{reason}; following the last verified plan"
            self._commands = commands
        else:
            commands = self._braking(self.robot.brake(problem.velocity, self.dt))
            message = f"{reason}; no verified plan, braking at the acceleration limits"
        poses = self.predict(commands, problem.velocity)
        return FilterResult(u=commands[0], u_nom=problem.u_nom, status=FilterStatus.FALLBACK, message=message,
                            solver=self.backend.name, solve_time=solve_time,
                            plan=self._plan_array(poses, commands, problem.velocity), **details)

    def _brake(self, nominal: np.ndarray, velocity: np.ndarray | None, status: FilterStatus, message: str,
               **details: Any) -> FilterResult:
        """Brake at the limits from ``velocity`` (the last command when unknown); the stored plan is dropped."""
        self._commands = None
        current = self._last_command if velocity is None else velocity
        return super()._brake(nominal, current, status, message, **details)

"""Predictive (MPC) safety filter: a plan over a short horizon that is safe all the way to a stop."""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np

from safenav import _checks
from safenav.errors import InvalidConfig
from safenav.filters.base import FilterResult, FilterStatus, Reason, SafetyFilter, View, as_scans
from safenav.filters.body import BodyModel
from safenav.filters.mpc.config import DEFAULT_HORIZON, MPCConfig
from safenav.filters.mpc.nlp import CasadiBackend, NLPKey
from safenav.filters.mpc.plan import BaseModel, MPCProblem, PlanCheck, distances, row_values
from safenav.filters.perception import Frontier, nearest_per_bin
from safenav.robot import RobotSpec
from safenav.scan import LaserScan

__all__ = ["MPCSafetyFilter"]

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


class _Solved(NamedTuple):
    """A verified plan (``commands`` is ``None`` on failure), the slots used, the time and why it failed."""

    commands: np.ndarray | None
    check: PlanCheck | None
    used: np.ndarray
    solve_time: float
    message: str


class MPCSafetyFilter(SafetyFilter):
    """Minimal change of the first command such that a plan that ends stopped stays clear of every lidar point.

    **Plan.** ``N`` commands ``u_0..u_{N-1}`` held for ``dt`` each, starting from the
    velocity ``w_0``: the measured ``velocity``, or, when ``velocity`` is ``None``, the last
    command this filter returned (zero after :meth:`reset`; the filter then assumes the base
    reached it). Each command is at most ``(a_max, alpha_max) dt`` from the previous one (the
    first from ``w_0``, or from the last command for a lagging base), respects the velocity
    limits, and ``u_{N-1} = 0``: the plan ends stopped. The base's velocity follows the
    commands as the model of :class:`~safenav.filters.mpc.plan.BaseModel`: within the period
    for ``time_constant = 0`` (the base ramps from ``w_k`` to ``u_k``), or as a first-order
    lag of that time constant, in which case the plan also keeps clear the point where the
    base still drifts after its last command.

    **Constraints.** At every knot ``p_k`` and for every obstacle point ``o`` of the scans or
    the memory (base frame, the world taken as static)::

        ||p_k - o|| >= min(r_eff + e_o, ||o||)
        r_eff = max(sqrt((R + margin + e_arc + e_act)^2 + (L / 2)^2),  range_min + |mount|)

    with ``L = max(v_max, -v_min) dt`` the longest chord of one period, ``e_arc = (L / 2)
    sin(omega_max dt / 2)`` the farthest a one-period arc strays from its chord, ``e_act`` the
    farthest the true position strays from the model's within a period when the velocity
    stays between the period's start velocity and the command (``dt^2 (a_max + L alpha_max)``
    times ``max(beta, 1 - beta) / (1 - rho)`` of the model; 1/2 without lag), and ``e_o`` a
    remembered point's odometry uncertainty. If both knots of a period are ``>= r_eff`` from
    ``o``, the whole chord is ``>= sqrt(r_eff^2 - L^2/4)`` from it, so the body disk keeps
    ``margin`` between the knots too. A point already nearer than ``r_eff`` (noise, a push)
    may not be approached further (recovery). The planner aims for ``r_eff + buffer``
    (default ``buffer = e_act + 2 noise_std``) so that the shifted previous plan stays
    feasible; verification and status use ``r_eff``.

    **Unknown region and memory.** As the CBF filter (:mod:`safenav.filters.perception`):
    outline samples facing a gap or a side no lidar sees forbid translating towards them over
    the whole horizon; points that leave every field of view are remembered while within
    reach and not contradicted, carried by odometry.

    **Cost.** ``w_v (v_0 - v_nom)^2 + w_omega (omega_0 - omega_nom)^2`` plus
    ``regularisation`` times the same weights on the later commands, plus a slack ``s`` that
    relaxes every clearance row, with a heavy linear and quadratic cost.

    **Minimal intervention (fast path).** The candidate "``u_nom`` clipped to the reachable
    box, then brake at the acceleration limits to a stop" is checked against every bound and
    every point in reach; when it passes, its first command is returned (``u_nom`` itself,
    bit for bit, when ``u_nom`` is reachable) and nothing is solved.

    **Solve.** Otherwise the NLP (built once; ``K`` point slots as parameters) is solved by
    casadi's ``sqpmethod``, warm-started from the previous plan shifted by one step. **Every
    answer is checked numerically** against every bound, every acceleration row and *every*
    point in reach; points the plan violates are swapped into the slots and the NLP is solved
    again (up to ``max_rounds`` solves).

    **Late calls.** With ``now`` given, a call ``m`` periods after the previous one plans every
    command held for ``m`` periods (blocks of ``m`` equal commands, each block within what the
    acceleration limits allow in ``m`` periods of the previous one, ``e_act`` grown to the block's
    length) and reports ``LATE``.

    **Guarantee.** If the world is static, every obstacle wider than the beam gap at 1 m is
    seen within ``2 noise_std`` before the body comes within ``margin`` of it (see the CBF
    filter and ``docs/safety.md`` for the blind region), the base holds each command for at
    most the period and its velocity over each period stays between the period's start
    velocity and the command with the model's end-of-period velocity (any base that reaches
    each command within the period for ``time_constant = 0``; a first-order lag of at most
    ``time_constant`` otherwise), then, with status ``OK``, ``LATE`` or ``RECOVERING``,
    throughout the executed period the body disk keeps ``margin`` from every point seen or
    remembered at least ``r_eff`` away, and the plan it follows can be continued to a stop
    without coming nearer. Returned commands always respect the velocity and acceleration
    limits. **Recursive feasibility:** if the base moves exactly as modelled and no point is
    nearer than ``r_eff + buffer``, the previous plan shifted by one step satisfies every
    constraint of the next problem. The filter checks the base against its model at every
    call with ``velocity`` and warns (:attr:`FilterResult.warnings`) when the base lags more
    than the model allows.

    **When it cannot hold.** No plan without slack: the plan violates the rows as little as
    possible (status ``SLACK``). No plan that keeps the hard bounds (a base too fast to stop
    within the horizon, or moving towards space that has just become unknown): it brakes at
    its limits (status ``BRAKING``). Solver failure, or an answer that fails verification:
    the filter executes the next command of the last verified plan, which ends stopped
    (status ``FALLBACK``); without one it brakes at the acceleration limits.

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
        base_config = MPCConfig(**{**(config.__dict__ if config else {}), **overrides})
        dt = _checks.duration("dt", dt, high=1.0)
        self.config = cfg = base_config.resolve(robot, dt)
        if robot.omega_max * dt > 2.0:
            raise InvalidConfig(f"omega_max * dt = {robot.omega_max * dt:.3g} rad per period is too coarse for the "
                                f"MPC filter's arc model; expected <= 2 (a shorter dt)")
        self.margin = float(cfg.margin)
        super().__init__(robot, dt, body=BodyModel.disk(robot), scan_timeout=cfg.scan_timeout,
                         compensate_latency=cfg.compensate_latency, max_gap=cfg.max_gap,
                         side_tolerance=cfg.side_tolerance, memory_range=cfg.memory_range,
                         memory_capacity=cfg.memory_capacity, time_constant=cfg.time_constant,
                         deadlock_time=cfg.deadlock_time)
        dt = self.dt
        lidar = robot.lidar
        self.model = BaseModel(dt, cfg.time_constant)
        self._step = np.array([robot.a_max, robot.alpha_max]) * dt
        self.speed = max(robot.v_max, -robot.v_min)
        stop_steps = math.ceil(max(self.speed / self._step[0], robot.omega_max / self._step[1]) - 1e-9)
        self.horizon = cfg.horizon if cfg.horizon is not None else max(DEFAULT_HORIZON, stop_steps + 1)
        chord = self.speed * dt
        self.arc_error = 0.5 * chord * math.sin(0.5 * min(robot.omega_max * dt, 0.5 * math.pi))
        self._spread = max(self.model.beta, 1.0 - self.model.beta) * self.model.tracking
        self.actuator_error = self._actuator_error(1)
        self._blind = lidar.range_min + math.hypot(lidar.mount.x, lidar.mount.y)
        self.inflated_radius = self._inflated_radius(1)
        self._buffer_setting = cfg.buffer
        self.buffer = cfg.buffer if cfg.buffer is not None else self.actuator_error + 2.0 * lidar.noise_std
        self.weights = (float(cfg.weights[0]), float(cfg.weights[1]))
        self.n_points = cfg.n_points
        self.backend = CasadiBackend(NLPKey(self.horizon, self.n_points, dt, cfg.time_constant, self.weights,
                                            cfg.regularisation, cfg.slack_weight, cfg.solver, cfg.hessian,
                                            cfg.max_iter))
        knots = self.horizon + (1 if cfg.time_constant > 0.0 else 0)
        self._lbg = np.concatenate((-np.tile(self._step, self.horizon - 1), np.zeros(self.n_points * knots)))
        self._ubg = np.concatenate((np.tile(self._step, self.horizon - 1), np.full(self.n_points * knots, np.inf)))
        self._commands: np.ndarray | None = None

    def _actuator_error(self, hold: int) -> float:
        """Farthest the true position strays from the model's over a block of ``hold`` periods in which one
        command is held (the velocity between the block's start velocity and the command) [m]."""
        robot, held = self.robot, hold * self.dt
        return self._spread * held * held * (robot.a_max + self.speed * self.dt * robot.alpha_max)

    def _inflated_radius(self, hold: int) -> float:
        """``r_eff`` when commands are held ``hold`` periods (see the class docstring) [m]."""
        chord = self.speed * self.dt
        radius = self.robot.radius + self.margin + self.arc_error + self._actuator_error(hold)
        return max(math.hypot(radius, 0.5 * chord), self._blind)

    def _step_bounds(self, hold: int) -> np.ndarray:
        """``(N - 1, 2)`` largest change between consecutive commands: within a block of ``hold`` equal
        commands none, between blocks what the acceleration limits allow in ``hold`` periods."""
        k = np.arange(1, self.horizon)
        return np.where((k % hold == 0)[:, None], hold * self._step, 0.0)

    def __repr__(self) -> str:
        return (f"MPCSafetyFilter(robot={self.robot.name!r}, dt={self.dt}, horizon={self.horizon}, "
                f"n_points={self.n_points}, margin={self.margin:.4f}, inflated_radius={self.inflated_radius:.4f}, "
                f"buffer={self.buffer:.4f}, time_constant={self.model.time_constant}, solver={self.backend.name!r})")

    # ------------------------------------------------------------------ hooks

    def _on_reset(self) -> None:
        self._commands = None

    def _on_brake(self) -> None:
        self._commands = None

    def _braking_start(self, velocity: np.ndarray | None) -> np.ndarray:
        # Without a measurement the commands stay a sequence the base can follow: brake from the last one.
        return velocity if velocity is not None else self._last_command

    # ------------------------------------------------------------------ problem

    def _reach(self, velocity: np.ndarray) -> float:
        """Upper bound on the path length of any plan from ``velocity`` [m] (and the lag's drift)."""
        k = np.arange(self.horizon)
        step = self._step[0]
        start = max(abs(float(velocity[0])), abs(float(self._last_command[0])))
        speeds = np.minimum(np.minimum(self.speed, start + (k + 1) * step), (self.horizon - 1 - k) * step)
        speeds = np.maximum(speeds, np.maximum(start - (k + 1) * step, 0.0))
        previous = np.concatenate(([start], speeds[:-1]))
        return float(0.5 * self.dt * np.sum(np.maximum(previous, speeds) + speeds)) + \
            self.model.time_constant * max(start, self.speed)

    def _bounds(self, velocity: np.ndarray, frontier: Frontier, hold: int = 1) -> tuple[np.ndarray, np.ndarray]:
        """Per-step command bounds ``(N, 2)``: limits, reachability, unknown space, stopped at the end.

        Commands come in blocks of ``hold`` equal ones (one call period); each block may differ from the
        previous one by what the acceleration limits allow in ``hold`` periods.
        """
        robot = self.robot
        # A lagging base is commanded a sequence that slews at the acceleration limits; its velocity follows.
        origin = velocity if self.model.time_constant <= 0.0 else self._last_command
        blocks = np.arange(self.horizon) // hold + 1
        change = blocks[:, None] * hold * self._step
        reach_low, reach_high = origin - change, origin + change
        # Later steps: the limits, widened only to let a base outside them brake at its limit.
        lower = np.minimum(robot.lower, reach_high)
        upper = np.maximum(robot.upper, reach_low)
        lower[0], upper[0] = robot.velocity_bounds(origin, self.dt * hold)
        if frontier.blocks_forward:
            upper[:, 0] = np.minimum(upper[:, 0], np.maximum(0.0, reach_low[:, 0]))
        if frontier.blocks_backward:
            lower[:, 0] = np.maximum(lower[:, 0], np.minimum(0.0, reach_high[:, 0]))
        # Stopped at the end; a base too fast to stop within the horizon brakes at its limit instead.
        lower[-1] = np.minimum(0.0, reach_high[-1])
        upper[-1] = np.maximum(0.0, reach_low[-1])
        return lower, upper

    def build_problem(self, u_nom: Any, scan: LaserScan | Any, velocity: Any = None) -> MPCProblem:
        """The data of one call, for inspection: points in reach, their radii, the command bounds.

        Args:
            u_nom: nominal command ``(v [m/s], omega [rad/s])``.
            scan: the scan (or scans), in the current base frame.
            velocity: the velocity the plan starts from; ``None`` takes the last returned command.
        """
        nominal = np.asarray(u_nom, dtype=float).reshape(2)
        start = self._last_command if velocity is None else np.asarray(velocity, dtype=float).reshape(2)
        return self._problem(nominal, self._observe(self._match(as_scans(scan))), start, 1)

    def _problem(self, u_nom: np.ndarray, view: View, velocity: np.ndarray, hold: int) -> MPCProblem:
        robot = self.robot
        points, uncertainty = view.points, view.uncertainty
        distance = np.hypot(points[:, 0], points[:, 1])
        if distance.size:
            nearest = float(np.min(distance - uncertainty))
            min_barrier = nearest - (robot.radius + self.margin)
        else:
            min_barrier = math.inf
        clearance = self.body.clearance(points)
        inflated = self._inflated_radius(hold)
        buffer = self.buffer if self._buffer_setting is not None or hold == 1 else \
            self._actuator_error(hold) + 2.0 * robot.lidar.noise_std
        planned = inflated + buffer + uncertainty
        keep = distance <= self._reach(velocity) + planned
        points, distance, uncertainty, planned = points[keep], distance[keep], uncertainty[keep], planned[keep]
        lower, upper = self._bounds(velocity, view.frontier, hold)
        return MPCProblem(u_nom, velocity.copy(), points, np.minimum(planned, distance),
                          np.minimum(inflated + uncertainty, distance), lower, upper, hold,
                          view.frontier, min_barrier, clearance)

    # ------------------------------------------------------------------ plans

    def predict(self, commands: np.ndarray, velocity: np.ndarray) -> np.ndarray:
        """Poses ``(N + 1, 3)`` the model predicts for ``commands`` ``(N, 2)`` from ``velocity``, in the base frame."""
        return self.model.rollout(commands, velocity)[0]

    def _knots(self, poses: np.ndarray, velocities: np.ndarray) -> np.ndarray:
        """The points a plan's clearance is checked at: knots ``1..N`` and, for a lag, where it drifts to."""
        knots = poses[1:, :2]
        if self.model.time_constant > 0.0:
            knots = np.vstack((knots, self.model.coast(poses[-1], velocities[-1])))
        return knots

    def check_plan(self, problem: MPCProblem, commands: np.ndarray) -> PlanCheck:
        """How far ``commands`` ``(N, 2)`` are from satisfying every constraint of ``problem``."""
        commands = np.asarray(commands, dtype=float).reshape(self.horizon, 2)
        limits = max(float(np.max(problem.lower - commands)), float(np.max(commands - problem.upper)))
        if self.horizon > 1:
            limits = max(limits, float(np.max(np.abs(np.diff(commands, axis=0)) - self._step_bounds(problem.hold))))
        poses, velocities = self.model.rollout(commands, problem.velocity)
        gaps = distances(self._knots(poses, velocities), problem.points)
        if gaps.size == 0:
            return PlanCheck(limits, math.inf, math.inf, gaps, poses, velocities)
        return PlanCheck(limits, float(np.min(gaps - problem.guaranteed)), float(np.min(gaps - problem.radii)),
                         gaps, poses, velocities)

    def _braking(self, first: np.ndarray, hold: int = 1) -> np.ndarray:
        """``first``, then every block of ``hold`` commands nearer zero by the acceleration limit: ``(N, 2)``."""
        steps = (np.arange(self.horizon) // hold)[:, None] * hold * self._step
        return np.sign(first) * np.maximum(np.abs(first) - steps, 0.0)

    @staticmethod
    def _plan_array(poses: np.ndarray, commands: np.ndarray, velocity: np.ndarray) -> np.ndarray:
        return np.column_stack((poses, np.vstack((velocity.reshape(1, 2), commands))))

    # ------------------------------------------------------------------ filtering

    def _filter(self, u_nom: np.ndarray, view: View, velocity: np.ndarray | None, period: float) -> FilterResult:
        start = self._last_command if velocity is None else velocity
        hold = min(self.horizon - 1, max(1, math.ceil(period / self.dt - 1e-6)))
        problem = self._problem(u_nom, view, start, hold)
        details: dict[str, Any] = dict(min_barrier=problem.min_barrier, clearance=problem.clearance)
        shifted = None
        if self._commands is not None:
            shift = min(hold, self.horizon)
            shifted = np.vstack((self._commands[shift:], np.zeros((shift, 2))))
        self._commands = None
        frontier = view.frontier
        if (frontier.blocks_forward and problem.lower[0, 0] > 0.0) or (
                frontier.blocks_backward and problem.upper[0, 0] < 0.0):
            return self._brake(u_nom, velocity, FilterStatus.BRAKING, "unknown",
                               "cannot stop before moving towards unknown space within the acceleration limits; "
                               "braking at the limits", **details)

        # Fast path: u_nom (clipped to the reachable box), held, then brake at the limits.
        first = np.clip(u_nom, problem.lower[0], problem.upper[0])
        candidate = self._braking(first, hold)
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
        """The result for a verified plan: status from its slack and the margin, and why it differs from u_nom."""
        status, reason = FilterStatus.OK, None
        slack = max(0.0, -check.clearance)
        margins = check.distances - problem.radii
        nearest = int(np.argmin(margins)) if margins.size else -1
        point = None if nearest < 0 else (float(problem.points[nearest, 0]), float(problem.points[nearest, 1]))
        if slack > VERIFY_TOLERANCE:
            status = FilterStatus.SLACK
            if problem.min_barrier < 0.0:
                reason = Reason("plan", f"already inside the margin (barrier {problem.min_barrier:.3f} m); plan "
                                        f"relaxed by {slack:.4f} m, moving away", point)
            else:
                reason = Reason("plan", f"cannot brake in time under the acceleration limits; plan relaxed by "
                                        f"{slack:.4f} m", point)
        elif problem.min_barrier < 0.0:
            status = FilterStatus.RECOVERING
            reason = Reason("plan", f"inside the margin of the nearest obstacle (barrier {problem.min_barrier:.3f} "
                                    f"m); the plan comes no closer", point)
        elif not np.array_equal(commands[0], problem.u_nom):
            reason = self._why(problem, commands, check, point)
        active = np.flatnonzero(margins[used] <= VERIFY_TOLERANCE + max(0.0, -check.planned))
        return FilterResult(
            u=commands[0], u_nom=problem.u_nom, status=status, reason=reason,
            n_constraints=int(used.size) * self.horizon, constraint_points=problem.points[used], active=active,
            slack=slack if status is FilterStatus.SLACK else 0.0, solver=solver, solve_time=solve_time,
            plan=self._plan_array(check.poses, commands, problem.velocity), **details,
        )

    def _why(self, problem: MPCProblem, commands: np.ndarray, check: PlanCheck,
             point: tuple[float, float] | None) -> Reason:
        """Why the first command differs from ``u_nom`` when the plan is feasible."""
        robot = self.robot
        u_nom = problem.u_nom
        if np.any(u_nom < robot.lower) or np.any(u_nom > robot.upper):
            limited = np.clip(u_nom, robot.lower, robot.upper)
            if np.array_equal(limited, commands[0]):
                return Reason("limits",
                              f"clipped to the velocity limits {robot.lower.tolist()}..{robot.upper.tolist()}")
        reachable = np.clip(u_nom, problem.lower[0], problem.upper[0])
        if np.array_equal(reachable, commands[0]):
            if problem.frontier.blocks_forward or problem.frontier.blocks_backward:
                return Reason("blind", "does not translate towards unknown space")
            return Reason("acceleration", f"not reachable within one period from {problem.velocity.tolist()}")
        return Reason("plan", "a plan that ends stopped keeps the clearance only with this first command", point)

    def _select(self, problem: MPCProblem, references: list[np.ndarray]) -> np.ndarray:
        """Indices of at most ``K`` points: nearest per angular bin by clearance to the reference knots."""
        count = problem.points.shape[0]
        if count <= self.n_points:
            return np.arange(count)
        knots = np.vstack([poses[1:, :2] for poses in references])
        keys = distances(knots, problem.points) - problem.radii
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
        lbg, ubg = self._lbg, self._ubg
        if problem.hold > 1:   # blocks of `hold` equal commands, one per call period
            steps = self._step_bounds(problem.hold).ravel()
            lbg, ubg = lbg.copy(), ubg.copy()
            lbg[: steps.size], ubg[: steps.size] = -steps, steps
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
                poses, velocities = self.model.rollout(commands, problem.velocity)
                rows = row_values(distances(self._knots(poses, velocities), problem.points[used]),
                                  problem.radii[used])
                start_slack = max(0.0, -float(rows.min()))
            outcome = self.backend.solve(np.append(commands.ravel(), start_slack),
                                         np.concatenate((head, slots.ravel(), radii)), lbx, ubx, lbg, ubg)
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
            rows = row_values(check.distances, problem.radii)
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
        """``commands`` moved into their bounds, acceleration rows and hold (an SQP stopped at its
        iteration limit can miss a linear row by ~1e-6); the result is verified like any answer."""
        repaired = np.clip(commands, problem.lower, problem.upper)
        steps = self._step_bounds(problem.hold)
        for k in range(1, self.horizon):
            repaired[k] = np.clip(np.clip(repaired[k], repaired[k - 1] - steps[k - 1], repaired[k - 1] + steps[k - 1]),
                                  problem.lower[k], problem.upper[k])
        return repaired

    def _fallback(self, problem: MPCProblem, shifted: np.ndarray | None, detail: str, solve_time: float,
                  details: dict[str, Any]) -> FilterResult:
        """Next command of the last verified plan (which ends stopped), or braking at the limits without one."""
        if shifted is not None:
            commands = shifted.copy()
            commands[0] = np.clip(commands[0], problem.lower[0], problem.upper[0])
            detail = f"{detail}; following the last verified plan"
            self._commands = commands
        else:
            commands = self._braking(self.robot.brake(problem.velocity, self.dt))
            detail = f"{detail}; no verified plan, braking at the acceleration limits"
        poses = self.predict(commands, problem.velocity)
        return FilterResult(u=commands[0], u_nom=problem.u_nom, status=FilterStatus.FALLBACK,
                            reason=Reason("solver", detail), solver=self.backend.name, solve_time=solve_time,
                            plan=self._plan_array(poses, commands, problem.velocity), **details)

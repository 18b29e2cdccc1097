"""Predictive (MPC) safety filter: a plan over a horizon in seconds that is safe all the way to a stop.

Longer than most modules because the filter's docstring states its guarantee in full and the call
owns the plan's life cycle (fast path, solve, verification, repair, deadline, late-call blocks); the
NLP, the SQP, the plan layout and the configuration are the package's other modules.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import time
from collections.abc import Callable, Sequence
from typing import Any, NamedTuple

import numpy as np

from safenav import _checks
from safenav.errors import InvalidConfig
from safenav.filters.base import FilterResult, FilterStatus, Reason, SafetyFilter, View, _frozen, _replace, as_scans
from safenav.filters.body import BodyModel
from safenav.filters.cbf import CBFSafetyFilter
from safenav.filters.kernels import plain
from safenav.filters.mpc.config import MPCConfig
from safenav.filters.mpc.nlp import CasadiNLP, NLPKey, PlanModel
from safenav.filters.mpc.plan import (
    BaseModel,
    MPCProblem,
    PlanCheck,
    PlanLayout,
    disk_centres,
    distances,
    lag_filter,
    row_values,
)
from safenav.filters.mpc.sqp import DirectSQP, PlanCost, PlanNLP, PlanSolver
from safenav.filters.perception import Frontier, nearest_per_bin
from safenav.filters.qp import DirectDAQP, make_backend
from safenav.robot import RobotSpec
from safenav.scan import LaserScan

__all__ = ["MPCSafetyFilter"]

#: Tolerance of the filter's own check of a plan's clearance against every point [m].
VERIFY_TOLERANCE = 1e-6
#: Tolerance of the check of a plan against the velocity, acceleration and terminal bounds [m/s, rad/s]
#: (an SQP stopped at its iteration limit can miss a linear row by ~1e-7; the first command is
#: clipped into its bounds exactly).
BOUND_TOLERANCE = 1e-6
#: Acceleration rows an answer meets to this [m/s, rad/s] are left as they are by the repair.
REPAIR_TOLERANCE = 1e-9
#: After the last swap of missed points, an answer that misses its own rows by at most this much
#: is accepted, with its true slack reported [m]; a larger miss counts as a failed solve.
SETTLE_TOLERANCE = 1e-3
#: An answer whose one slack relaxes the rows by more than this [m] is solved again with a slack per point
#: (:meth:`MPCSafetyFilter._split_slack`): with less, the rows of the points it could keep clear give way by
#: at most this much (a robot held by its remembered points' growing uncertainty needs tenths of a millimetre).
SPLIT_SLACK = 0.005


class _Ramps(NamedTuple):
    """The command changes the acceleration limits allow when commands are held ``hold`` periods."""

    reach: np.ndarray
    """``(P, 2)`` from the start velocity to the end of each period's block [m/s, rad/s]."""
    braking: np.ndarray
    """``(P, 2)`` from the first command to each period's, braking in blocks [m/s, rad/s]."""
    steps: np.ndarray
    """``(P - 1, 2)`` between consecutive periods (zero within a block) [m/s, rad/s]."""


class _Solved(NamedTuple):
    """A verified plan (``commands`` is ``None`` on failure), the slots used, the time and why it failed."""

    commands: np.ndarray | None
    check: PlanCheck | None
    used: np.ndarray
    solve_time: float
    message: str
    abandoned: bool = False
    held: bool = False
    taken: str = ""
    """Which plan at hand was taken instead of the solver's answer, and why (``""``: the answer)."""


def _least_slack(solved: _Solved, others: list[tuple[str, np.ndarray, PlanCheck]]) -> _Solved:
    """``solved``, or the plan of ``others`` that needs the least slack when it needs less than ``solved``
    (:meth:`MPCSafetyFilter._plans_at_hand`): slack lets the plan come nearer a point than its radius, so of the
    verified plans at hand the filter takes the one that comes least far inside any point's."""
    best = max(others, key=lambda other: other[2].clearance, default=None)
    if solved.check is None or best is None or best[2].clearance <= solved.check.clearance:
        return solved
    needed = -solved.check.clearance
    return solved._replace(commands=best[1], check=best[2],
                           taken=f"{best[0]} taken: the solver's answer needed {needed:.4f} m of slack")


class MPCSafetyFilter(SafetyFilter):
    """Minimal change of the command such that a plan that ends stopped keeps the body clear of every lidar point.

    **Plan.** A horizon of ``horizon_time`` seconds: ``P = ceil(horizon_time / dt)`` commands
    ``u_0..u_{P-1}``, one per period, starting from the velocity ``w_0``: the measured
    ``velocity``, or, when ``velocity`` is ``None``, the last command this filter returned
    (zero after :meth:`reset`; the filter then assumes the base reached it). Each command is at
    most ``(a_max, alpha_max) dt`` from the previous one (the first from ``w_0``, or from the
    last command for a lagging base), respects the velocity limits, and ``u_{P-1} = 0``: the
    plan ends stopped. The optimiser chooses at most ``max_commands`` of them (the control
    knots, :class:`~safenav.filters.mpc.plan.PlanLayout`); the others are interpolated
    linearly, which keeps the full braking authority, so a short ``dt`` lengthens the plan in
    periods but not in variables. The base's velocity follows the commands as the model of
    :class:`~safenav.filters.mpc.plan.BaseModel`: within the period for ``time_constant = 0``
    (the base ramps from ``w_k`` to ``u_k``), or as a first-order lag of that time constant,
    in which case the plan also keeps clear the point where the base still drifts after its
    last command.

    **Body.** One disk of radius ``R`` at the base origin (``body="disk"``), or ``n_disks``
    disks of radius ``rho`` centred at ``c_d`` along the body (``body="cover"``,
    :meth:`~safenav.filters.body.BodyModel.cover`), whose union contains the footprint.

    **Constraints.** At the end ``k`` of every period, for every disk ``d`` with centre
    ``c_kd = p_k + R(yaw_k) c_d`` and every obstacle point ``o`` of the scans or the memory
    (base frame, the world taken as static)::

        ||c_kd - o|| >= min(r_d + e_o, ||c_d - o||)
        r_d = sqrt((rho_d + margin + e_arc_d + e_act_d)^2 + (L_d / 2)^2)

    with ``L_d = (max(v_max, -v_min) + |c_d| omega_max) dt`` the longest path of the disk's
    centre in one period, ``e_arc_d = (L_d / 2) sin(omega_max dt / 2)`` the farthest the
    centre's arc in one period (a rigid motion at constant twist moves every point of the
    body on an arc turning by ``omega dt``) strays from its chord, ``e_act_d = T^2 (a_max +
    (v_max T + |c_d|) alpha_max)`` times ``max(beta, 1 - beta) / (1 - rho)`` of the model (1/2
    without lag) the farthest the true centre strays from the model's while a command is held
    for ``T`` (``dt``, or the call period of a late call) when the velocity stays between the
    start velocity and the command (a speed error and a heading error, the latter acting on
    the distance travelled and on the disk's offset), and ``e_o`` a remembered point's
    odometry uncertainty. If both ends of a period
    are ``>= r_d`` from ``o``, the whole chord is ``>= sqrt(r_d^2 - L_d^2 / 4)`` from it, so
    the disk keeps ``margin`` between the knots too, and with it the footprint the disks
    cover. The disk nearest the lidar also keeps ``r_d >= range_min + |mount - c_d|``, so the
    lidar can always measure a point the plan keeps out. A point already nearer than ``r_d``
    (noise, a push) may not be approached further (recovery). The planner aims beyond ``r_d``
    by the buffer (default ``e_act + 2 noise_std``) plus the growth of the point's
    uncertainty at the next carry by measured velocity (``T^2 (a_max + ||o|| alpha_max) / 2``),
    so that the shifted previous plan stays feasible. The actuator part and that growth are
    kept; the rest (the range noise) a plan may use at a cost (``buffer_cost``: all of it costs
    as much as braking the first command from full speed to a stop), to pass a door just
    wider than the body (:attr:`MPCProblem.floor`); never ``r_d``, which verification and the
    status use.

    **Unknown region and memory.** As the CBF filter (:mod:`safenav.filters.perception`):
    outline samples facing a gap forbid translating towards them over the whole horizon, and
    facing a side no lidar sees beyond the speed that keeps the plan's whole path within the
    space earlier scans saw free that side (:meth:`seen_travel`; 0 until they did); points
    that leave every field of view are remembered while within reach and not contradicted,
    carried by odometry.

    **Cost: the nominal's intent along the plan.** The nominal clipped to the velocity limits
    is held along the plan: ``sum_k c_k [w_v (v_k - v_nom)^2 + w_omega (omega_k -
    omega_nom)^2]`` with ``c_0 = 1`` and ``c_k = tracking / (P - 1)``, plus the buffer and the
    slack costs (:mod:`safenav.filters.mpc.sqp`). A plan that brakes in front of an obstacle
    pays for every later period it is slower than the nominal; one that steers round it pays
    only the (five times cheaper) turn: the filter steers where it can. With
    ``reference="cbf"`` the plan tracks the answer of :attr:`reference` (a CBF filter with the
    same margin and body, called first) instead of the nominal: it brakes when the CBF does, in
    front of a person stepping in, rather than as late as its plan allows. Only the target
    moves; constraints, verification and fallbacks are unchanged, and the result keeps the
    nominal as ``u_nom``.

    **Look-ahead (opt-in, ``lookahead``).** With the body's disk about the base origin a turn
    changes no clearance, so in front of an obstacle straight ahead the plan that stops is the
    optimum of the tracking cost and the robot stands there while the nominal points at it. A
    control disk of the (foremost) body disk's radius ``lookahead`` ahead of it moves sideways in
    a turn, as a barrier filter's look-ahead point does: planned like the body's disks (radius,
    buffer, "no nearer than now"), it makes the plan brake earlier head-on and turn to go round.
    It is never verified and never part of the status or ``min_barrier``: the guarantee below is
    the body's. It ignores remembered points (a walker that left the field of view would pin it)
    and is dropped while :attr:`~safenav.filters.base.SafetyFilter.passage` is set.

    **Minimal intervention (fast path).** The candidate "``u_nom`` clipped to the reachable
    box, then brake at the acceleration limits to a stop" is checked against every bound and
    every point in reach; when it passes, its first command is returned (``u_nom`` itself,
    bit for bit, when ``u_nom`` is reachable) and nothing is solved.

    **Solve.** Otherwise the NLP is solved by sequential quadratic programming
    (:class:`~safenav.filters.mpc.sqp.DirectSQP`): casadi gives the model and its exact
    derivatives (one Function per shape, built once), each step's QP goes to DAQP directly
    through the same back-end interface as the CBF's (:mod:`safenav.filters.qp`), warm-started
    from the previous plan (shifted by one period, its final braking left aligned with the
    end of the horizon) and from the previous QP's active set. ``solver="sqpmethod"`` solves the
    same NLP with casadi's ``sqpmethod`` instead (the reference, three to ten times slower).
    **Every answer is checked numerically** against every bound, every acceleration row and
    *every* point in reach at every period's end; points the plan violates are swapped into the
    ``K`` slots and the NLP is solved again (up to ``max_rounds`` solves). An answer that needs
    slack gives way to the previous plan shifted by one period when that plan, checked the
    same way, needs none.

    **Holding a stop.** Held in front of an obstacle, the tracking plan would take each
    millimetre of room in its first period and reverse in the next (a linear command
    alternating about zero for as long as the obstacle stays). A solved plan whose first two
    linear commands have opposite signs, when the base can stop in one period, gives way to a
    zero first linear command followed by the plan's (its turn kept), verified like any answer:
    the robot stands still or turns on the spot, and moves again as soon as a plan makes
    progress without reversing (``hold_stop``). The feasible set is unchanged.

    **Deadline.** A call has a compute budget (``budget``, default ``BUDGET_FRACTION = 0.5``
    of ``dt``), counted from the call's start: the perception, the reference's call, the solve,
    the verification and the result all spend it. The SQP checks the clock before every step
    (an iteration, or another round of rows for its QP) and begins one only if it can end, as
    long as the longest step of the recent calls (at most, and until one has been timed, a quarter
    of the budget) or of this call, before the budget less a reserve for the verification and the
    result (as long as the longest the recent calls' took, at most, and until timed, a quarter;
    :mod:`~safenav.filters.deadline`). When it cannot, the solve is abandoned (the next call
    starts afresh, on time) and the filter follows the next command of its last verified plan,
    which ends stopped (status ``FALLBACK``, reason ``deadline``); without one it brakes at the
    acceleration limits. That plan was verified against the points seen then: checked against
    this call's, when it comes nearer a point than its guaranteed radius (a wall seen since) and
    braking at the limits keeps more clearance, the filter brakes instead and says so. A call
    ends within its budget unless what comes before the solve (the perception, the reference's
    call, the fast path's check) already takes it, a step takes longer than that estimate
    (longer than every step of the recent calls and of this call, or than a quarter of the
    budget), or the verification and result longer than the reserve (a new filter's first solving
    calls included); only the solve is cut short (with ``reference="cbf"`` the reference's call is
    not: sharing the budget with it was tried and sent more calls past the budget, BENCHMARKS.md).

    **Late calls.** With ``now`` given, a call ``m`` periods after the previous one plans every
    command held for ``m`` periods (blocks of ``m`` equal commands, each block within what the
    acceleration limits allow in ``m`` periods of the previous one, ``e_act`` grown to the
    block's length ``T = m dt``) and reports ``LATE``. Without a lag the model ramps the velocity
    to each block's command over the whole block, as a base that reaches each command within the
    call period does (:func:`~safenav.filters.mpc.plan.block_ramp`); it is then exact for a base
    ramping linearly over the call period, and ``e_act`` bounds every base of the guarantee.

    **Guarantee.** If the world is static, every obstacle at least :attr:`smallest_obstacle` wide is
    seen within ``2 noise_std`` before the body comes within ``margin`` of it (see the CBF
    filter and ``docs/safety.md`` for the blind region), the base holds each command for at
    most the period and its velocity over each period stays between the period's start
    velocity and the command with the model's end-of-period velocity (any base that reaches
    each command within the period for ``time_constant = 0``; a first-order lag of at most
    ``time_constant`` otherwise), then, with status ``OK``, ``LATE`` or ``RECOVERING``,
    throughout the executed period every body disk, hence the footprint they cover, keeps
    ``margin`` from every point seen or remembered at least ``r_d`` away, and the plan it
    follows can be continued to a stop without coming nearer. Returned commands always respect
    the velocity and acceleration limits. **Recursive feasibility:** if the base moves
    exactly as modelled and no point is nearer than the planned radius, the previous plan
    shifted by one period passes every check of the next problem, and the filter takes it
    when its optimiser's answer needs slack (with move blocking the shifted plan need not be
    one the optimiser can represent).
    The filter checks the base against its model at every call with ``velocity`` and warns
    (:attr:`FilterResult.warnings`) when the base lags more than the model allows.

    **When it cannot hold.** No plan without slack: the plan violates the rows as little as
    possible (status ``SLACK``), each point with a slack of its own when one would relax them
    all by more than :data:`SPLIT_SLACK` (direct SQP): a point it cannot keep clear relaxes the
    rows of those it can by that much at most. The call after such an answer solves with a slack
    per point at once (the point stays; one slack first, then one per point, is twice the work
    within the compute budget), and with one slack when that finds no verified answer. No plan that keeps the hard
    bounds (a base too fast to stop within the horizon, or moving towards space that has just
    become unknown): it brakes at its limits (status ``BRAKING``). Solver failure, an answer
    that fails verification, or the deadline: the filter executes the next command of the last
    verified plan, which ends stopped (status ``FALLBACK``); without one it brakes at the
    acceleration limits.

    Args:
        robot: the robot to protect.
        dt: control period [s].
        config: settings; keyword arguments override its fields (e.g. ``horizon_time=1.5``).
        clock: the clock the compute budget is measured with [s] (default ``time.perf_counter``;
            tests inject a simulated one).

    Raises:
        InvalidConfig: a setting is out of range, or ``omega_max dt > 2`` (too coarse a period).
        UnknownName: the solver or Hessian is not known (the message lists the known ones).
    """

    name = "mpc"

    def __init__(self, robot: RobotSpec, dt: float = 0.05, *, config: MPCConfig | None = None,
                 clock: Callable[[], float] | None = None, **overrides: Any):
        base_config = MPCConfig(**{**(config.__dict__ if config else {}), **overrides})
        dt = _checks.duration("dt", dt, high=1.0)
        self.config = cfg = base_config.resolve(robot, dt)
        if robot.omega_max * dt > 2.0:
            raise InvalidConfig(f"omega_max * dt = {robot.omega_max * dt:.3g} rad per period is too coarse for the "
                                f"MPC filter's arc model; expected <= 2 (a shorter dt)")
        self.margin = float(cfg.margin)
        body = BodyModel.cover(robot, cfg.n_disks) if cfg.body == "cover" else BodyModel.disk(robot)
        narrow_body = None if cfg.narrow_body is None else BodyModel.cover(robot, cfg.n_disks)
        super().__init__(robot, dt, body=body, other_bodies=() if narrow_body is None else (narrow_body,),
                         scan_timeout=cfg.scan_timeout,
                         compensate_latency=cfg.compensate_latency, max_gap=cfg.max_gap,
                         side_tolerance=cfg.side_tolerance, memory_range=cfg.memory_range,
                         memory_capacity=cfg.memory_capacity, time_constant=cfg.time_constant,
                         deadlock_time=cfg.deadlock_time, min_obstacle_width=cfg.min_obstacle_width,
                         budget=cfg.budget, clock=clock)
        dt = self.dt
        self.model = BaseModel(dt, cfg.time_constant)
        if self.model.rho > 0.0:
            lag_filter()     # imported now, not in the first control call
        self._step = np.array([robot.a_max, robot.alpha_max]) * dt
        self.speed = max(robot.v_max, -robot.v_min)
        periods = max(2, math.ceil(float(cfg.horizon_time) / dt - 1e-9))
        self.layout = PlanLayout.of(periods, cfg.max_commands)
        self._layouts: dict[int, PlanLayout] = {1: self.layout}
        self._ramps: dict[tuple[int, int, int], _Ramps] = {}
        # The reach's speed profile: accelerating from the start, braking to the end [m/s].
        self._speed_ramps = (np.arange(1, periods + 1) * self._step[0], np.arange(periods - 1, -1, -1) * self._step[0])
        # The body's disks, then (with a look-ahead) the control disk ahead of the foremost one.
        self.n_body = self.body.n_disks
        centres, radii = np.array(self.body.centres, dtype=float), np.array(self.body.radii, dtype=float)
        self.lookahead = float(cfg.lookahead)
        if self.lookahead > 0.0:
            front = int(np.argmax(centres[:, 0]))
            centres = np.vstack((centres, centres[front] + (self.lookahead, 0.0)))
            radii = np.append(radii, radii[front])
        self.offsets = centres
        self._disk_radii = radii
        self._inflations: dict[int, tuple[np.ndarray, np.ndarray, float, float]] = {}
        self.inflated_radii, self.actuator_errors, self.buffer, self.soft_buffer = self._inflation(1)
        self.weights = (float(cfg.weights[0]), float(cfg.weights[1]))
        # Using the whole soft buffer costs buffer_cost times the first command braking from full speed to a stop.
        buffer_weight = float(cfg.buffer_cost) * self.weights[0] * self.speed**2 / max(self.soft_buffer, 0.01) ** 2
        self.cost = PlanCost(self.weights, float(cfg.tracking), buffer_weight, float(cfg.slack_weight))
        self.n_points = cfg.n_points
        self.backend: PlanSolver = self._make_solver()
        self._ready(cfg.kernels)
        if isinstance(self.backend, DirectSQP):
            self.backend.kernels = self._kernels
            if isinstance(self.backend.qp, DirectDAQP):
                self.backend.qp.kernels = self._kernels
        self._commands: np.ndarray | None = None
        # Whether the last solved answer needed more than SPLIT_SLACK: the next call solves with a slack per point
        # at once (the wall it could not keep clear is still there).
        self._splitting = False
        #: The filter whose answer the plan tracks (``reference="cbf"``), else ``None``.
        self.reference: CBFSafetyFilter | None = None
        if cfg.reference == "cbf":
            self.reference = CBFSafetyFilter(
                robot, dt, margin=self.margin, body="disk" if cfg.body == "disk" else "cover", n_disks=cfg.n_disks,
                time_constant=cfg.time_constant, max_gap=cfg.max_gap, side_tolerance=cfg.side_tolerance,
                scan_timeout=cfg.scan_timeout, compensate_latency=cfg.compensate_latency,
                memory_range=cfg.memory_range, memory_capacity=cfg.memory_capacity, deadlock_time=cfg.deadlock_time,
                kernels=cfg.kernels, clock=clock, budget=math.inf)
        self._referenced: FilterResult | None = None    # the reference's answer of this call
        #: The planner of the narrow body (the same filter for the cover of the footprint; its memory and clock
        #: are this filter's), used while :attr:`narrow` asks for it, else ``None``.
        self.narrow_planner: MPCSafetyFilter | None = None
        if narrow_body is not None:
            self.narrow_planner = MPCSafetyFilter(robot, dt, config=dataclasses.replace(
                base_config, body="cover", narrow_body=None, reference="nominal", memory_capacity=0), clock=clock)
            self.narrow_planner._budget = self._budget      # one call, one budget
        self._in_narrow = False     # whether the last answer's plan was the narrow planner's

    def _inflation(self, hold: int) -> tuple[np.ndarray, np.ndarray, float, float]:
        """Each disk's guaranteed radius ``r_d``, actuator error ``e_act_d``, the buffer and the part of
        it the plan may use, when every command is held ``hold`` periods (see the class docstring) [m].

        The buffer's actuator part keeps the shifted plan feasible when the base strays from the
        model as far as A4 allows: it is kept. The rest (twice the range noise by default) is
        for noise between scans: a plan may use it, at a cost, where it cannot move otherwise.
        """
        cached = self._inflations.get(hold)
        if cached is not None:
            return cached
        robot, dt = self.robot, self.dt
        lever = np.hypot(self.offsets[:, 0], self.offsets[:, 1])
        chord = (self.speed + lever * robot.omega_max) * dt
        spread = max(self.model.beta, 1.0 - self.model.beta) * self.model.tracking
        held = hold * dt
        arc = 0.5 * chord * math.sin(0.5 * min(robot.omega_max * dt, 0.5 * math.pi))
        actuator = spread * held * held * (robot.a_max + (self.speed * held + lever) * robot.alpha_max)
        radii = np.hypot(self._disk_radii + self.margin + arc + actuator, 0.5 * chord)
        lidar = robot.lidar
        body = self.offsets[:self.n_body]
        to_lidar = np.hypot(lidar.mount.x - body[:, 0], lidar.mount.y - body[:, 1])
        nearest = int(np.argmin(to_lidar))
        radii[nearest] = max(radii[nearest], lidar.range_min + to_lidar[nearest])
        setting = self.config.buffer
        kept = float(np.max(actuator))
        buffer = float(setting) if setting is not None else kept + 2.0 * lidar.noise_std
        soft = max(0.0, buffer - kept)
        for array in (radii, actuator):
            array.flags.writeable = False
        if hold == 1:
            arc.flags.writeable = False
            self.arc_errors = arc
        self._inflations[hold] = (radii, actuator, buffer, soft)
        return radii, actuator, buffer, soft

    def _ramps_for(self, layout: PlanLayout) -> _Ramps:
        """The :class:`_Ramps` of a layout (cached per layout shape: one per call period seen)."""
        key = (layout.periods, layout.max_commands, layout.hold)
        ramps = self._ramps.get(key)
        if ramps is None:
            hold = layout.hold
            blocks = np.arange(layout.periods) // hold
            ramps = _Ramps((blocks + 1)[:, None] * hold * self._step, blocks[:, None] * hold * self._step,
                           layout.period_changes[:, None] * self._step)
            for array in ramps:
                array.flags.writeable = False
            self._ramps[key] = ramps
        return ramps

    def _layout_for(self, hold: int) -> PlanLayout:
        """The layout of a plan whose commands are held ``hold`` periods (cached per filter)."""
        layout = self._layouts.get(hold)
        if layout is None:
            layout = self._layouts[hold] = PlanLayout.of(self.horizon, self.layout.max_commands, hold)
        return layout

    def _make_solver(self) -> PlanSolver:
        cfg = self.config
        if cfg.solver == "ipopt" or cfg.solver.startswith("sqpmethod"):
            offsets = tuple((float(x), float(y)) for x, y in self.offsets)
            return CasadiNLP(NLPKey(self.layout.periods, self.layout.max_commands, 1, self.n_points, offsets,
                                    self.dt, cfg.time_constant, self.cost, cfg.solver, cfg.hessian, cfg.max_iter))
        solver = DirectSQP(PlanModel(self.layout.periods, self.model), self.offsets, self.cost,
                           make_backend(cfg.solver), cfg.max_iter)
        solver.prepare(self.layout)     # its model is built now, not in the first call that solves
        return solver

    @property
    def horizon(self) -> int:
        """Commands of a plan (one per period)."""
        return self.layout.periods

    @property
    def inflated_radius(self) -> float:
        """The largest of :attr:`inflated_radii` [m] (the only one for the disk model)."""
        return float(np.max(self.inflated_radii))

    @property
    def arc_error(self) -> float:
        """The largest of :attr:`arc_errors` [m]."""
        return float(np.max(self.arc_errors))

    @property
    def actuator_error(self) -> float:
        """The largest of :attr:`actuator_errors` [m]."""
        return float(np.max(self.actuator_errors))

    def __repr__(self) -> str:
        return (f"MPCSafetyFilter(robot={self.robot.name!r}, dt={self.dt}, horizon={self.horizon}, "
                f"knots={self.layout.n_knots}, body={self.body.name!r}, n_points={self.n_points}, "
                f"margin={self.margin:.4f}, inflated_radius={self.inflated_radius:.4f}, buffer={self.buffer:.4f}, "
                f"time_constant={self.model.time_constant}, budget={self.budget:.4g}, "
                f"solver={self.backend.name!r}, reference={self.config.reference!r})")

    # ------------------------------------------------------------------ hooks

    def _on_reset(self) -> None:
        self._commands = None
        self._splitting = False
        self._in_narrow = False
        if self.narrow_planner is not None:
            self.narrow_planner.reset()
        if self.reference is not None:
            self.reference.reset()

    @property
    def narrow_half_width(self) -> float:
        """The narrow body's half-width plus the margin [m] (the cover of the footprint), when there is one."""
        if self.narrow_planner is None:
            return self.corridor_half_width
        return min(self.corridor_half_width, self.narrow_planner.corridor_half_width)

    @property
    def narrowed(self) -> bool:
        return self._in_narrow

    @property
    def plan_body(self) -> BodyModel:
        """The body model of the last answer's plan: :attr:`body`, or the narrow body's in a narrow gap."""
        return self.narrow_planner.body if self._in_narrow and self.narrow_planner is not None else self.body

    def filter(self, u_nom: Any, scan: LaserScan | Sequence[LaserScan], *, velocity: Any = None,
               pose: Any = None, scan_age: Any = None, now: float | None = None) -> FilterResult:
        """Filter one nominal command (see :meth:`SafetyFilter.filter`; same arguments).

        With ``reference="cbf"`` the reference CBF filters ``u_nom`` first (with the same
        arguments and :attr:`passage`) and the plan tracks its answer; the result keeps
        ``u_nom``, and its time and compute budget include the reference's call.
        """
        start = time.perf_counter()
        self._budget.begin()    # the budget covers the whole call, the reference's too (the template then keeps it)
        try:
            if self.reference is not None:
                self.reference.passage = self.passage
                self.reference.narrow = self.narrow and self.narrow_planner is not None
                self._referenced = self.reference.filter(u_nom, scan, velocity=velocity, pose=pose,
                                                         scan_age=scan_age, now=now)
            result = super().filter(u_nom, scan, velocity=velocity, pose=pose, scan_age=scan_age, now=now)
        finally:
            self._referenced = None
            self._budget.end()
        object.__setattr__(result, "filter_time", time.perf_counter() - start)
        return result

    def _on_brake(self) -> None:
        self._commands = None
        if self.narrow_planner is not None:
            self.narrow_planner._commands = None

    def _braking_start(self, velocity: np.ndarray | None) -> np.ndarray:
        # Without a measurement the commands stay a sequence the base can follow: brake from the last one.
        return self.command_origin(velocity) if velocity is not None else self._last_command

    # ------------------------------------------------------------------ problem

    def _reach(self, velocity: np.ndarray) -> float:
        """Upper bound on the path length of any plan from ``velocity`` [m] (and the lag's drift)."""
        rising, falling = self._speed_ramps     # (k + 1) a_max dt and (P - 1 - k) a_max dt
        start = max(abs(float(velocity[0])), abs(float(self._last_command[0])))
        speeds = np.minimum(np.minimum(self.speed, start + rising), falling)
        speeds = np.maximum(speeds, np.maximum(start - rising, 0.0))
        previous = np.concatenate(([start], speeds[:-1]))
        return float(0.5 * self.dt * np.sum(np.maximum(previous, speeds) + speeds)) + \
            self.model.time_constant * max(start, self.speed)

    def _blind_cap(self, u_nom: np.ndarray, velocity: np.ndarray, view: View, hold: int, periods: int) -> float:
        """Largest speed [m/s] of every period's command, either way, in a plan that translates towards a side no
        lidar sees: the plan's whole path, the first ``hold`` periods at up to the current speed (and the
        lag's drift) and ``periods`` more at this speed, stays within the space earlier scans saw free that side
        (:meth:`seen_travel`), so that every pose of the plan (forward ones too: a plan that went forward and
        then back would leave the ball the free space was checked in) keeps the body there. Zero (no such
        translation) unless ``u_nom`` asks to move that way and the first period's box reaches it."""
        frontier = view.frontier
        if not ((frontier.backward and u_nom[0] < 0.0) or (frontier.forward and u_nom[0] > 0.0)):
            return 0.0
        lower, upper = self.robot.velocity_bounds(self.command_origin(velocity), self.dt * hold)
        if not ((frontier.backward and lower[0] < 0.0) or (frontier.forward and upper[0] > 0.0)):
            return 0.0
        travel = self.seen_travel(view)
        if travel <= 0.0:
            return 0.0
        start = max(abs(float(velocity[0])), abs(float(self._last_command[0])))
        left = travel - start * (hold * self.dt + self.model.time_constant)
        return max(left, 0.0) / (periods * self.dt)

    def _bounds(self, velocity: np.ndarray, frontier: Frontier, hold: int = 1, cap: float = 0.0
                ) -> tuple[np.ndarray, np.ndarray]:
        """Per-period command bounds ``(P, 2)``: limits, reachability, unknown space, stopped at the end.

        With late calls commands come in blocks of ``hold`` equal ones (one call period); each block
        may differ from the previous one by what the acceleration limits allow in ``hold`` periods.
        """
        robot = self.robot
        # A lagging base is commanded a sequence that slews at the acceleration limits; its velocity follows.
        origin = self.command_origin(velocity)
        change = self._ramps_for(self._layout_for(hold)).reach
        reach_low, reach_high = origin - change, origin + change
        # Later steps: the limits, widened only to let a base outside them brake at its limit.
        lower = np.minimum(robot.lower, reach_high)
        upper = np.maximum(robot.upper, reach_low)
        lower[0], upper[0] = robot.velocity_bounds(origin, self.dt * hold)
        # Towards a side no lidar sees at most at ``cap``, and then at most at ``cap`` either way: the plan's whole
        # path stays within what earlier scans saw free there (never behind invalid beams).
        if cap > 0.0 and (frontier.forward or frontier.backward):
            upper[:, 0] = np.minimum(upper[:, 0], np.maximum(0.0 if frontier.gap_forward else cap, reach_low[:, 0]))
            lower[:, 0] = np.maximum(lower[:, 0], np.minimum(-0.0 if frontier.gap_backward else -cap,
                                                             reach_high[:, 0]))
        else:
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
        body = self.body
        points, uncertainty = view.points, view.uncertainty
        offsets = self.offsets
        inflated, _, buffer, soft = self._inflation(hold)
        if points.shape[0]:
            now = np.hypot(points[:, None, 0] - offsets[None, :, 0], points[:, None, 1] - offsets[None, :, 1])
            barriers = now[:, :self.n_body] - uncertainty[:, None] - (body.radii + self.margin)[None, :]
            min_barrier = float(np.min(barriers))
            # BodyModel.clearance of every point, from the same distances (the body's disks are the first offsets)
            clearance = float(np.min(now[:, :self.n_body] - body.radii[None, :]))
            reach = self._reach(velocity) + float(np.max(np.hypot(offsets[:, 0], offsets[:, 1]) + inflated))
            ranges = np.hypot(points[:, 0], points[:, 1])
            keep = ranges <= reach + buffer + uncertainty
            # Which of the kept points are remembered (only the look-ahead's control disk needs to know).
            remembered = np.flatnonzero(keep) >= view.n_current + view.n_horizon if self.lookahead > 0.0 else None
            points, uncertainty, now, ranges = points[keep], uncertainty[keep], now[keep], ranges[keep]
        else:
            now = np.empty((0, offsets.shape[0]))
            ranges = np.empty(0)
            remembered = np.empty(0, dtype=bool)
            min_barrier = clearance = math.inf
        guaranteed = inflated[None, :] + uncertainty[:, None]
        # The planner also keeps the growth of a point's uncertainty at the next carry by the measured
        # velocity (A5's trapezoid: half the period times the velocity change, at most the acceleration
        # limits), so that the shifted plan stays feasible once a point has left the field of view.
        held = hold * self.dt
        drift = 0.5 * held * held * (self.robot.a_max + ranges * self.robot.alpha_max)
        floor = np.minimum(guaranteed + (buffer - soft) + drift[:, None], now)
        planned = np.minimum(floor + soft, now)
        guaranteed = np.minimum(guaranteed, now)
        if self.lookahead > 0.0:
            # The control disk is planned like the body (it brakes and steers the plan early) but never
            # verified: the guarantee is the body's. It ignores remembered points, and every point in a passage.
            guaranteed[:, self.n_body:] = -np.inf
            ignored = slice(None) if self.passage else remembered
            planned[ignored, self.n_body:] = floor[ignored, self.n_body:] = 0.0
        lower, upper = self._bounds(velocity, view.frontier, hold,
                                    self._blind_cap(u_nom, velocity, view, hold, len(self._speed_ramps[0])))
        return MPCProblem(u_nom, velocity.copy(), points, uncertainty, planned, guaranteed, floor, lower, upper,
                          self._layout_for(hold), view.frontier, min_barrier, clearance)

    # ------------------------------------------------------------------ plans

    def predict(self, commands: np.ndarray, velocity: np.ndarray, hold: int = 1) -> np.ndarray:
        """Poses ``(P + 1, 3)`` the model predicts for ``commands`` ``(P, 2)`` held in blocks of ``hold`` periods (a
        call ``hold`` periods late) from ``velocity``, in the base frame."""
        return self.model.rollout(commands, velocity, hold)[0]

    def knot_centres(self, commands: np.ndarray, velocity: np.ndarray, hold: int = 1) -> np.ndarray:
        """Where each body disk's centre is at every clearance knot of a plan: ``(K, D, 2)`` [m]."""
        return disk_centres(self.model.knot_poses(commands, velocity, hold)[0], self.offsets)

    def check_plan(self, problem: MPCProblem, commands: np.ndarray) -> PlanCheck:
        """How far ``commands`` ``(P, 2)`` are from satisfying every constraint of ``problem``."""
        commands = np.asarray(commands, dtype=float).reshape(self.horizon, 2)
        steps = self._ramps_for(problem.layout).steps
        if not np.isfinite(commands).all():    # fails every test a plan has to pass
            unknown = np.full((problem.points.shape[0], self.offsets.shape[0]), np.nan)
            return PlanCheck(math.inf, -math.inf, -math.inf, unknown, np.full((self.horizon + 1, 3), np.nan),
                             np.full((self.horizon + 1, 2), np.nan))
        if self._kernels is not None:
            model = self.model
            return PlanCheck(*self._kernels.plan_check(
                plain(commands), plain(model.reached(commands, problem.velocity, problem.hold)),
                plain(problem.velocity), model.rho, model.beta, model.dt, model.time_constant,
                plain(self.offsets), plain(problem.points), plain(problem.guaranteed), plain(problem.radii),
                plain(problem.lower), plain(problem.upper), plain(steps)))
        limits = float(np.max(np.maximum(problem.lower - commands, commands - problem.upper)))
        limits = max(limits, float(np.max(np.abs(commands[1:] - commands[:-1]) - steps)))
        knots, poses, velocities = self.model.knot_poses(commands, problem.velocity, problem.hold)
        gaps = distances(disk_centres(knots, self.offsets), problem.points)
        if gaps.size == 0:
            return PlanCheck(limits, math.inf, math.inf, gaps, poses, velocities)
        return PlanCheck(limits, float(np.min(gaps - problem.guaranteed)), float(np.min(gaps - problem.radii)),
                         gaps, poses, velocities)

    def plan_cost(self, problem: MPCProblem, commands: np.ndarray) -> float:
        """The cost of ``commands`` ``(P, 2)`` without the slacks (what the optimiser trades off)."""
        target = np.clip(problem.u_nom, self.robot.lower, self.robot.upper)
        deviation = (np.asarray(commands, dtype=float).reshape(self.horizon, 2) - target) ** 2 @ np.array(self.weights)
        return float(self.cost.period_weights(self.horizon) @ deviation)

    def _realigned(self, shifted: np.ndarray, previous: np.ndarray) -> np.ndarray:
        """A warm start from the last plan: shifted in time, except its final braking, which stays put.

        The optimum tracks the nominal as long as it can still stop by the end of the horizon,
        so from one call to the next its final braking (where each command is as far from zero
        as stopping at the end allows) stays aligned with the end of the horizon, not with time;
        the plain shifted plan would stop one period early (one more SQP iteration).
        """
        warm = shifted.copy()
        stopping = (self.horizon - 1 - np.arange(self.horizon))[:, None] * self._step
        on_profile = np.abs(previous) >= stopping - 1e-9
        for axis in range(2):
            outside = np.flatnonzero(~on_profile[:, axis])
            tail = outside[-1] + 1 if outside.size else 0
            warm[tail:, axis] = previous[tail:, axis]
        return warm

    def _braking(self, first: np.ndarray, hold: int = 1) -> np.ndarray:
        """``first``, then every block of ``hold`` commands nearer zero by the acceleration limit: ``(P, 2)``."""
        steps = self._ramps_for(self._layout_for(hold)).braking
        return np.sign(first) * np.maximum(np.abs(first) - steps, 0.0)

    @staticmethod
    def _plan_array(poses: np.ndarray, commands: np.ndarray, velocity: np.ndarray) -> np.ndarray:
        plan = np.empty((poses.shape[0], 5))
        plan[:, :3] = poses
        plan[0, 3:] = velocity
        plan[1:, 3:] = commands
        return plan

    # ------------------------------------------------------------------ filtering

    def _filter(self, u_nom: np.ndarray, view: View, velocity: np.ndarray | None, period: float) -> FilterResult:
        referenced = self._referenced
        if referenced is None:
            return self._plan_for(u_nom, view, velocity, period)
        return self._tracked(self._plan_for(np.array(referenced.u, dtype=float), view, velocity, period), u_nom,
                             referenced)

    def _tracked(self, result: FilterResult, u_nom: np.ndarray, referenced: FilterResult) -> FilterResult:
        """``result`` of the plan that tracked the reference's answer, told against ``u_nom``."""
        reason = result.reason
        if reason is None and not np.array_equal(result.u, u_nom):
            # The plan took the reference's answer: the reference says why it differs from u_nom.
            told, status = referenced.reason, referenced.status
            source = f"the {self.config.reference} reference" + (
                "" if status is FilterStatus.OK else f" ({status.value})")
            reason = (Reason("reference", f"{source}'s answer") if told is None
                      else Reason(told.family, f"{source}: {told.detail}", told.point))
            message = str(reason) + (f"; {result.message}" if result.message else "")
            return _replace(result, u_nom=_frozen(u_nom, (2,)), reason=reason, message=message)
        return _replace(result, u_nom=_frozen(u_nom, (2,)))

    def _plan_for(self, u_nom: np.ndarray, view: View, velocity: np.ndarray | None, period: float) -> FilterResult:
        """The verified plan that tracks ``u_nom``, of the body or (in a narrow gap) of the narrow body.

        Either planner is taken up afresh (no stored plan of its own, which would be stale) only when
        its body's barrier over the call's points is not negative and its answer has status
        ``OK``/``LATE``; else the current one answers. Both share the call's compute budget.
        """
        narrow = self.narrow_planner
        if narrow is None:
            return self._planned(u_nom, view, velocity, period)
        if self.narrow != self._in_narrow:
            body = narrow.body if self.narrow else self.body
            if body.barrier(view.points, self.margin, view.uncertainty) >= 0.0:
                planner = self._planner(self.narrow)
                planner._commands, planner._splitting = None, False
                result = planner._planned(u_nom, view, velocity, period)
                if result.status in (FilterStatus.OK, FilterStatus.LATE):
                    self._in_narrow = self.narrow
                    return self._noted(result)
        return self._noted(self._planner(self._in_narrow)._planned(u_nom, view, velocity, period))

    def _planner(self, narrow: bool) -> MPCSafetyFilter:
        """This filter, or its narrow planner with this call's state (the last command, the flags; the
        budget is shared)."""
        planner = self.narrow_planner if narrow and self.narrow_planner is not None else self
        if planner is not self:
            planner._last_command, planner._called = self._last_command, self._called
            planner.passage = self.passage
        return planner

    def _noted(self, result: FilterResult) -> FilterResult:
        """``result`` with its reason saying when the narrow body's plan made it."""
        if not self._in_narrow or result.reason is None:
            return result
        reason = result.reason
        reason = Reason(reason.family, f"{reason.detail}; {self.plan_body.name} body (a narrow gap)", reason.point)
        return _replace(result, reason=reason, message=str(reason))

    def _planned(self, u_nom: np.ndarray, view: View, velocity: np.ndarray | None, period: float) -> FilterResult:
        """The verified plan of this filter's body that tracks ``u_nom`` (the nominal, or the reference's answer)."""
        start = self._last_command if velocity is None else velocity
        hold = min(self.horizon - 1, max(1, math.ceil(period / self.dt - 1e-6)))
        problem = self._problem(u_nom, view, start, hold)
        details: dict[str, Any] = dict(min_barrier=problem.min_barrier, clearance=problem.clearance)
        shifted = None
        if self._commands is not None:
            shift = min(hold, self.horizon)
            shifted = np.vstack((self._commands[shift:], np.zeros((shift, 2))))
            previous = self._commands
        self._commands = None
        frontier = view.frontier
        cap = self._blind_cap(u_nom, start, view, hold, len(problem.lower))
        if (frontier.blocks_forward and problem.lower[0, 0] > (0.0 if frontier.gap_forward else cap)) or (
                frontier.blocks_backward and problem.upper[0, 0] < (0.0 if frontier.gap_backward else -cap)):
            return self._brake(u_nom, velocity, FilterStatus.BRAKING, "unknown",
                               "cannot stop before moving towards unknown space within the acceleration limits; "
                               "braking at the limits", period=period, **details)

        # Fast path: u_nom (clipped to the reachable box), held, then brake at the limits.
        first = np.clip(u_nom, problem.lower[0], problem.upper[0])
        candidate = self._braking(first, hold)
        check = self.check_plan(problem, candidate)
        if check.limits <= BOUND_TOLERANCE and check.planned >= 0.0:
            self._commands, self._splitting = candidate, False
            return self._result(problem, candidate, check, details, used=np.empty(0, dtype=np.intp),
                                solve_time=0.0, solver="")
        warm = np.clip(candidate if shifted is None else self._realigned(shifted, previous), problem.lower,
                       problem.upper)
        split = self._splitting and isinstance(self.backend, DirectSQP)
        outcome = self._solve(problem, warm, candidate, check, split=split)
        if split and outcome.commands is None and not outcome.abandoned:
            # No verified answer with a slack per point: one slack for every row, as in any other call.
            retried = self._solve(problem, warm, candidate, check)
            outcome = retried._replace(solve_time=outcome.solve_time + retried.solve_time)
            split = False
        if outcome.abandoned:
            spent = self._budget.spent()
            return self._fallback(problem, shifted, "deadline",
                                  f"no verified plan within the compute budget of {1e3 * self.budget:.3g} ms "
                                  f"({1e3 * spent:.3g} ms spent; the solve was abandoned)", outcome.solve_time,
                                  details)
        if outcome.commands is None or outcome.check is None:
            return self._fallback(problem, shifted, "solver", outcome.message, outcome.solve_time, details)
        others: list[tuple[str, np.ndarray, PlanCheck]] = []
        if outcome.check.clearance < -VERIFY_TOLERANCE:
            others = self._plans_at_hand(problem, shifted)
            outcome = _least_slack(outcome, others)
        if outcome.check.clearance < -SPLIT_SLACK and not split:
            outcome = _least_slack(self._split_slack(problem, outcome, candidate), others)
        outcome = self._hold(problem, outcome)
        self._commands = outcome.commands
        self._splitting = outcome.check.clearance < -SPLIT_SLACK
        return self._result(problem, outcome.commands, outcome.check, details, used=outcome.used,
                            solve_time=outcome.solve_time, solver=self.backend.name, held=outcome.held,
                            taken=outcome.taken)

    def _hold(self, problem: MPCProblem, solved: _Solved) -> _Solved:
        """No linear command that the plan itself reverses in the next period, when the base can stop now.

        Held in front of an obstacle, the plan that tracks the nominal takes whatever room it
        has in its first period and reverses in the next, which makes room again (the base
        reaches a command sooner than the modelled ramp): the linear command alternates about
        zero while the obstacle stays, also while the plan turns on the spot to find a way
        round. When the solved plan's first two linear commands have opposite signs and the
        linear velocity can reach zero in one period, the plan with a zero first linear
        command, then the solved plan's linear commands followed within the acceleration
        limits, and the solved yaw rates, is taken instead if it passes every check of the
        problem without using more of the buffer: it is verified like any answer, so the
        feasible set is unchanged. A plan that makes progress without reversing is kept.
        """
        commands, solved_check = solved.commands, solved.check
        if not self.config.hold_stop or commands is None or solved_check is None:
            return solved
        next_period = min(problem.hold, self.horizon - 1)
        stoppable = problem.lower[0, 0] <= 0.0 <= problem.upper[0, 0]
        if not stoppable or commands[0, 0] * commands[next_period, 0] >= 0.0:
            return solved
        held = commands.copy()
        held[:next_period, 0] = 0.0
        held = self._repair(held, problem)
        check = self.check_plan(problem, held)
        if (check.limits > BOUND_TOLERANCE or check.clearance < -VERIFY_TOLERANCE
                or check.planned < min(0.0, solved_check.planned) - VERIFY_TOLERANCE):
            return solved
        return solved._replace(commands=held, check=check, held=True)

    def _plans_at_hand(self, problem: MPCProblem, shifted: np.ndarray | None
                       ) -> list[tuple[str, np.ndarray, PlanCheck]]:
        """The plans besides the solver's answer that pass the checks of ``problem`` (the velocity and acceleration
        bounds; any slack), named, with their checks: the last plan shifted by the call's period (its first command
        moved into what the base can reach now), and braking at the acceleration limits from now.

        The NLP is not convex: its solver can end in a local optimum that needs more slack than these (with move
        blocking the shifted plan need not even be one it can represent), so an answer with slack proves
        neither that no plan needs less nor that none needs none.
        """
        plans = [] if shifted is None else [("the last plan", self._repair(shifted, problem))]
        plans.append(("braking at the limits", self._braking_now(problem)))
        checked = [(name, commands, self.check_plan(problem, commands)) for name, commands in plans]
        return [(name, commands, check) for name, commands, check in checked if check.limits <= BOUND_TOLERANCE]

    def _braking_now(self, problem: MPCProblem) -> np.ndarray:
        """Braking at the acceleration limits from now: the command nearest a stop within the box of the problem's
        first block (what the limits reach within the call's period, ``hold`` periods, from the command origin),
        held for the block, then each block nearer zero by the limits: ``(P, 2)``."""
        return self._braking(np.clip(0.0, problem.lower[0], problem.upper[0]), problem.hold)

    def _result(self, problem: MPCProblem, commands: np.ndarray, check: PlanCheck, details: dict[str, Any], *,
                used: np.ndarray, solve_time: float, solver: str, held: bool = False, taken: str = ""
                ) -> FilterResult:
        """The result for a verified plan: status from its slack and the margin, and why it differs from u_nom
        (``taken``: which plan at hand was taken instead of the solver's answer, and why)."""
        status, reason = FilterStatus.OK, None
        slack = max(0.0, -check.clearance)
        margins = (check.distances - problem.radii).min(axis=1) if check.distances.size else np.empty(0)
        nearest = int(np.argmin(margins)) if margins.size else -1
        point = None if nearest < 0 else (float(problem.points[nearest, 0]), float(problem.points[nearest, 1]))
        if slack > VERIFY_TOLERANCE:
            status = FilterStatus.SLACK
            if problem.min_barrier < 0.0:
                reason = Reason("plan", f"already inside the margin (barrier {problem.min_barrier:.3f} m); plan "
                                        f"relaxed by {slack:.4f} m, moving away" + (f" ({taken})" if taken else ""),
                                point)
            else:
                reason = Reason("plan", f"cannot brake in time under the acceleration limits; plan relaxed by "
                                        f"{slack:.4f} m" + (f" ({taken})" if taken else ""), point)
        elif problem.min_barrier < 0.0:
            status = FilterStatus.RECOVERING
            reason = Reason("plan", f"inside the margin of the nearest obstacle (barrier {problem.min_barrier:.3f} "
                                    f"m); the plan comes no closer", point)
        elif held:
            reason = Reason("plan", "held stopped: the plan would only reverse in the next period", point)
        elif taken:
            reason = Reason("plan", f"{taken}, this one none", point)
        elif not np.array_equal(commands[0], problem.u_nom):
            reason = self._why(problem, commands, check, point)
        active = np.flatnonzero(margins[used] <= VERIFY_TOLERANCE + max(0.0, -check.planned))
        n_knots = check.poses.shape[0] - 1 + (1 if self.model.time_constant > 0.0 else 0)
        return FilterResult(
            u=commands[0], u_nom=problem.u_nom, status=status, reason=reason,
            n_constraints=int(used.size) * n_knots * self.offsets.shape[0], constraint_points=problem.points[used],
            active=active, slack=slack if status is FilterStatus.SLACK else 0.0, solver=solver, solve_time=solve_time,
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

    def _select(self, problem: MPCProblem, references: list[np.ndarray],
                known: Sequence[np.ndarray] = ()) -> np.ndarray:
        """Indices of at most ``K`` points: nearest per angular bin by clearance to the reference plans.

        The bins halve until the slots are full, so the slots spread over every direction
        (a wall's points one slot every few degrees, not its nearest stretch twice over).
        ``known`` are :attr:`PlanCheck.distances` of further reference plans, already computed.
        """
        count = problem.points.shape[0]
        if count <= self.n_points:
            return np.arange(count)
        compiled = self._kernels
        if compiled is None:
            gaps = [distances(self.knot_centres(commands, problem.velocity, problem.hold), problem.points)
                    for commands in references]
        else:   # the compiled check's distances (the same to rounding; ``known`` come from it too)
            gaps = [self.check_plan(problem, commands).distances for commands in references]
        keys = np.min(functools.reduce(np.minimum, [*gaps, *known]) - problem.radii, axis=1)
        angles = np.arctan2(problem.points[:, 1], problem.points[:, 0])     # once for every halving of the bins
        chosen = nearest_per_bin(problem.points, keys, (0.0, 0.0), self.n_points, angles, compiled)
        bins = self.n_points
        free = np.ones(count, dtype=bool)
        while chosen.size < self.n_points and bins < 64 * self.n_points:
            bins *= 2
            free[chosen] = False
            rest = np.flatnonzero(free)
            more = rest[nearest_per_bin(problem.points[rest], keys[rest], (0.0, 0.0), bins, angles[rest], compiled)]
            chosen = np.concatenate((chosen, more[: self.n_points - chosen.size]))
        return chosen

    def _nlp(self, problem: MPCProblem, used: np.ndarray, start: np.ndarray, split: bool = False) -> PlanNLP:
        """The NLP of ``problem`` with the points ``used`` in the slots, starting from the plan ``start``
        (``split``: a slack of its own for each point)."""
        soft = self._inflation(problem.hold)[3]
        return PlanNLP(problem.velocity, np.clip(problem.u_nom, self.robot.lower, self.robot.upper),
                       problem.points[used], problem.radii[used], self._relief(problem)[used], problem.lower,
                       problem.upper, problem.layout, self._step, soft, problem.layout.sample(start),
                       np.arange(used.size) if split else None)

    def _split_slack(self, problem: MPCProblem, solved: _Solved, candidate: np.ndarray) -> _Solved:
        """An answer that needs slack, solved again with a slack of its own for each point.

        One slack relaxes every row alike: a plan that cannot keep one point (revealed late, too
        near to brake for) would then come as much nearer to every other point, which it could
        keep clear. With a slack per point (each at the cost of the one), only the rows that need
        relaxing are relaxed. Taken when verified (points outside the slots keep the guaranteed
        radius); only the direct SQP has slack per point.
        """
        if not isinstance(self.backend, DirectSQP) or solved.commands is None:
            return solved
        split = self._solve(problem, solved.commands, candidate, split=True)
        if split.commands is None or split.check is None:
            return solved._replace(solve_time=solved.solve_time + split.solve_time)
        return split._replace(solve_time=solved.solve_time + split.solve_time)

    def _relief(self, problem: MPCProblem) -> np.ndarray:
        """``(M, D)`` the share of the soft buffer each row may use: down to :attr:`MPCProblem.floor`."""
        soft = self._inflation(problem.hold)[3]
        if soft <= 0.0:
            return np.zeros_like(problem.radii)
        return np.clip((problem.radii - problem.floor) / soft, 0.0, 1.0)

    def _solve(self, problem: MPCProblem, warm: np.ndarray, candidate: np.ndarray,
               candidate_check: PlanCheck | None = None, split: bool = False) -> _Solved:
        """Solve the NLP; swap points the answer violates into the slots and solve again.

        An answer is accepted when, for every point in reach, each knot keeps either the
        guaranteed radius or the distance the solver's own slacks allow in its row (with
        ``split``, each point in a slot has a slack of its own, and the others none).
        ``candidate_check`` is the fast path's check of ``candidate``, when already made.
        """
        n_points = self.n_points
        if candidate_check is None:
            used = self._select(problem, [warm, candidate])
        else:
            used = self._select(problem, [warm], [candidate_check.distances])
        commands = warm
        solve_time = 0.0
        relief = self._relief(problem)
        # Smallest row value each point has had in any answer so far: a point that was ever near a
        # violation keeps its slot, so the working set grows monotonically until the slots run out.
        priority = np.full(problem.points.shape[0], np.inf)
        budget = self._budget
        for round_index in range(self.config.max_rounds):
            outcome = self.backend.solve(self._nlp(problem, used, commands, split), budget.solver_deadline(),
                                         self.clock, step=budget.step)
            budget.returned(outcome.longest_step)
            solve_time += outcome.solve_time
            if outcome.abandoned:
                return _Solved(None, None, used, solve_time, "deadline", abandoned=True)
            if outcome.knots is None or not np.all(np.isfinite(outcome.knots)):
                return _Solved(None, None, used, solve_time, f"solver {self.backend.name} failed ({outcome.status})")
            commands = self._repair(problem.layout.expand(outcome.knots), problem)
            check = self.check_plan(problem, commands)
            if check.limits > BOUND_TOLERANCE:
                return _Solved(None, None, used, solve_time,
                               f"answer of {self.backend.name} ({outcome.status}) violates the velocity or "
                               f"acceleration bounds by {check.limits:.3g}")
            rows = row_values(check.distances, problem.radii)
            if outcome.point_slacks is None:
                slacks: np.ndarray | float = max(0.0, outcome.slack)
            else:
                slacks = np.zeros((rows.shape[0], 1))
                slacks[used, 0] = np.maximum(outcome.point_slacks, 0.0)
            relaxed = rows + relief * max(0.0, outcome.buffer_slack) + slacks
            shortfall = np.min(np.maximum(relaxed, check.distances - problem.guaranteed), axis=1)
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
            priority = np.minimum(priority, np.min(rows, axis=1))
            pool = np.union1d(used, missed)
            order = np.argsort(priority[pool], kind="stable")
            used = pool[order[:n_points]]
        return _Solved(None, None, used, solve_time,
                       f"point reduction did not settle in {self.config.max_rounds} solves")

    def _repair(self, commands: np.ndarray, problem: MPCProblem) -> np.ndarray:
        """``commands`` moved into their bounds, acceleration rows and hold (an SQP stopped at its
        iteration limit can miss a linear row by ~1e-6); the result is verified like any answer."""
        repaired = np.clip(commands, problem.lower, problem.upper)
        steps = self._ramps_for(problem.layout).steps
        if np.all(np.abs(np.diff(repaired, axis=0)) <= steps + REPAIR_TOLERANCE):
            return repaired     # within the QP solver's accuracy: the check's tolerance is far larger
        for k in range(1, self.horizon):
            repaired[k] = np.clip(np.clip(repaired[k], repaired[k - 1] - steps[k - 1], repaired[k - 1] + steps[k - 1]),
                                  problem.lower[k], problem.upper[k])
        return repaired

    def _fallback(self, problem: MPCProblem, shifted: np.ndarray | None, family: str, detail: str,
                  solve_time: float, details: dict[str, Any]) -> FilterResult:
        """Next command of the last verified plan (which ends stopped), or braking at the limits without one.

        The last plan was verified against the points seen then. Checked against this call's (a wall
        that has come into view since), a plan that comes nearer a point than its guaranteed radius
        gives way to braking at the limits when that keeps more clearance.
        """
        if shifted is not None:
            commands = shifted.copy()
            commands[0] = np.clip(commands[0], problem.lower[0], problem.upper[0])
            action = "following the last verified plan"
            clearance = self.check_plan(problem, commands).clearance
            if clearance < -VERIFY_TOLERANCE:
                braking = self._braking_now(problem)
                if self.check_plan(problem, braking).clearance > clearance:
                    commands = braking
                    action = (f"the last verified plan comes {-clearance:.3f} m too near a point seen since: "
                              "braking at the acceleration limits")
            detail = f"{detail}; {action}"
            self._commands = commands
        else:
            commands = self._braking_now(problem)
            detail = f"{detail}; no verified plan, braking at the acceleration limits"
        poses = self.predict(commands, problem.velocity, problem.hold)
        return FilterResult(u=commands[0], u_nom=problem.u_nom, status=FilterStatus.FALLBACK,
                            reason=Reason(family, detail), solver=self.backend.name, solve_time=solve_time,
                            plan=self._plan_array(poses, commands, problem.velocity), **details)

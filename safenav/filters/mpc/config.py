"""Settings of the MPC filter, and the solvers it can use."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import casadi

from safenav import _checks
from safenav.errors import UnknownName
from safenav.filters.defaults import BUDGET_FRACTION, default_margin, default_weights
from safenav.filters.kernels import KERNELS
from safenav.filters.qp import available_solvers, solver_installed
from safenav.robot import RobotSpec

__all__ = [
    "BODIES",
    "BUDGET_FRACTION",
    "CONIC_PLUGINS",
    "DEFAULT_COMMANDS",
    "DEFAULT_HORIZON_TIME",
    "HESSIANS",
    "REFERENCES",
    "MPCConfig",
    "available_mpc_solvers",
]

#: Plan length [s] unless the robot needs longer to stop from its velocity limits.
DEFAULT_HORIZON_TIME = 1.0
#: Commands the optimiser chooses at most; a longer plan (a short ``dt``) interpolates between them.
DEFAULT_COMMANDS = 20
#: Default point slots of the direct SQP and of the casadi solvers.
DIRECT_POINTS, CASADI_POINTS = 64, 32
#: casadi QP plugins the reference ``sqpmethod`` can use here, in order of preference.
CONIC_PLUGINS = ("daqp", "qrqp", "osqp", "qpoases", "hpipm", "proxqp", "highs")
HESSIANS = ("gauss-newton", "exact")
BODIES = ("disk", "cover")
#: What a plan can track: the nominal command, or a CBF filter's answer to it.
REFERENCES = ("nominal", "cbf")


def available_mpc_solvers() -> list[str]:
    """Solver names :class:`MPCConfig` accepts on this machine.

    The QP back-ends of the direct SQP (:func:`safenav.filters.qp.available_solvers`, and
    ``"qpsolvers:<name>"``), the casadi reference ``"sqpmethod"`` / ``"sqpmethod:<plugin>"``,
    and ``"ipopt"``.
    """
    names = list(available_solvers())
    plugins = [name for name in CONIC_PLUGINS if casadi.has_conic(name)]
    if plugins:
        names += ["sqpmethod", *(f"sqpmethod:{plugin}" for plugin in plugins)]
    if casadi.has_nlpsol("ipopt"):
        names.append("ipopt")
    return names


def _is_known_solver(name: str) -> bool:
    return solver_installed(name) or name in available_mpc_solvers()


@dataclass(frozen=True)
class MPCConfig:
    """Settings of :class:`~safenav.filters.mpc.MPCSafetyFilter`; ``None`` means "derive from the robot".

    :meth:`resolve` fills every robot-derived default in.

    Attributes:
        horizon_time: length of a plan [s]; default ``max(1 s, time to stop from the velocity
            limits + dt)``. The plan has one command per period (``ceil(horizon_time / dt)``).
        max_commands: the most commands the optimiser chooses; a plan with more periods (a short
            ``dt``) interpolates linearly between them (move blocking). Clearance is still
            required at the end of every period.
        margin: clearance kept between the body and every obstacle point [m]; default as the CBF's.
        buffer: extra distance the plan aims to keep beyond the guaranteed radius [m], so that a
            base that moves differently from the model, or range noise between scans, does not
            make the next problem need slack; default ``e_act + 2 noise_std``. The plan may use
            it at a cost (a narrow door), never the guaranteed radius.
        buffer_cost: cost of using the whole buffer, relative to the cost of the first command
            braking from full speed to a stop (quadratic in the share used).
        body: ``"disk"`` (the circumscribed disk) or ``"cover"`` (``n_disks`` disks covering the
            footprint, :meth:`~safenav.filters.body.BodyModel.cover`).
        narrow_body: ``"cover"`` (default) or ``None``: while the filter's ``narrow`` flag is set (the
            escape, through a gap the disk does not fit) the plan is made and verified for the cover
            of the footprint, taken and left only with an answer of status ``OK``/``LATE`` (see
            :class:`~safenav.filters.mpc.MPCSafetyFilter`, "Narrow body"). None for a round robot or
            ``body="cover"``.
        n_disks: disks of the cover.
        lookahead: a control disk of the (foremost) body disk's radius this far ahead of it [m]
            (0: none). The plan keeps it clear like the body, but verification does not: it
            makes the plan brake earlier head-on and turn to go round what is ahead (turning
            moves it sideways), as a barrier filter's look-ahead point does; the guarantee stays
            the body's. It ignores remembered points, and is dropped while the filter's
            ``passage`` is set.
        n_points: the most obstacle points the optimiser sees at once (its slots; the nearest per
            angular bin); the plan is checked against every point in reach, and missed points are
            swapped in. Default: 64 for the direct SQP (it passes only the rows that can bind to
            each QP; 64 slots rarely need a swap, and cost less per iteration than every point in
            reach), 32 for the casadi solvers (each slot is a row per disk and knot of their NLP).
        solver: ``"daqp"`` (default: the direct SQP with DAQP), another QP back-end of the direct
            SQP (``"quadprog"``, ``"osqp"``, ``"qpsolvers:daqp"``, ...), ``"sqpmethod"`` (the
            reference: casadi's SQP; ``"sqpmethod:qpoases"`` picks its QP plugin), or ``"ipopt"``;
            case-insensitive.
        hessian: of the casadi solvers: ``"gauss-newton"`` (the cost's own, as the direct SQP)
            or ``"exact"``.
        weights: cost weights on the deviation of the first command from ``u_nom``
            [s^2/m^2, s^2/rad^2]; default ``(1 / v_max^2, 0.2 / omega_max^2)`` as the CBF filter.
        tracking: weight of the later commands' deviations from the nominal held along the plan,
            in all, relative to the first command's (0: only the first command counts).
        reference: what the plan tracks. ``"nominal"`` (default): the nominal command; a plan
            keeps its speed until it has to brake, so it stops late in front of an obstacle that
            steps into the path, and it plans round what a barrier filter would stop at.
            ``"cbf"``: the answer of a :class:`~safenav.filters.CBFSafetyFilter` with the same
            margin, body and base settings to the nominal (one CBF call per call, within the
            compute budget): the plan brakes as early as that filter, in front of a person
            stepping in as a stop zone would (ROS 2's collision-monitor thresholds), and steers
            as it does. Only the cost changes: the constraints, the verification of every
            answer against every point, and so the guarantee, are the MPC's own. The MPC inside
            the deadlock escape (``make_filter("mpc+escape", ...)``, the CLI, the ROS node, the
            Gymnasium shield) tracks ``"cbf"`` unless told otherwise
            (:data:`safenav.filters.ESCAPE_PRESETS`).
        slack_weight: linear and quadratic cost of the relaxation of the clearance rows [1/m, 1/m^2].
        max_iter: SQP iterations per solve.
        max_rounds: solves with missed points swapped into the slots before the call counts as failed.
        budget: compute budget of one call [s] (``math.inf``: none); default ``BUDGET_FRACTION * dt``.
            When a solve would end after it, the filter follows its last verified plan (status
            ``FALLBACK``, reason ``deadline``).
        max_gap: widest run of invalid beams bridged by its neighbours [rad]; wider runs are unknown.
        side_tolerance: unknown space this close to exactly sideways does not block motion [rad].
        time_constant: first-order lag of the base's velocity loop [s]: the plan models the
            base's velocity as following the commands with this lag (0: the base reaches each
            command within the period). Needs ``velocity`` at each call.
        memory_range: remembered points farther than this are forgotten [m] (default: reach + 1 m).
        memory_capacity: largest number of remembered points.
        hold_stop: a solved plan whose first two linear commands have opposite signs gives way
            to a zero first linear command (the rest of the plan followed within the
            acceleration limits, its turn kept) when the base can stop in one period and that
            plan passes every check: held in front of an obstacle the robot stands still or
            turns on the spot instead of a linear command alternating about zero.
        deadlock_time: how long the commands may stall while the nominal asks to move before the
            result reports a deadlock [s].
        scan_timeout: scans older than this make the filter brake [s].
        compensate_latency: move a scan of known age into the current base frame first.
        min_obstacle_width: the narrowest obstacle [m] the filter must see in time to brake clear of
            (``None``: whatever the lidars resolve where the robot must see an obstacle,
            :attr:`~safenav.filters.SafetyFilter.smallest_obstacle`). Thinner obstacles can hide
            between two beams until they are near; when this is smaller, the filter keeps able to stop
            within the range where a beam must hit one (it drives slower).
        kernels: ``"auto"``, ``"numba"`` or ``"numpy"``: the compiled perception kernels (and those of the
            ``reference="cbf"`` filter), as :attr:`CBFConfig.kernels <safenav.filters.CBFConfig>`.
    """

    horizon_time: float | None = None
    max_commands: int = DEFAULT_COMMANDS
    margin: float | None = None
    buffer: float | None = None
    buffer_cost: float = 1.0
    body: str = "disk"
    narrow_body: str | None = "cover"
    n_disks: int = 3
    lookahead: float = 0.0
    n_points: int | None = None
    solver: str = "daqp"
    hessian: str = "gauss-newton"
    weights: tuple[float, float] | None = None
    tracking: float = 1.0
    reference: str = "nominal"
    slack_weight: float = 1e4
    max_iter: int = 30
    max_rounds: int = 4
    budget: float | None = None
    max_gap: float = math.radians(5.0)
    side_tolerance: float = math.radians(5.0)
    time_constant: float = 0.0
    memory_range: float | None = None
    memory_capacity: int = 4000
    hold_stop: bool = True
    deadlock_time: float = 1.5
    scan_timeout: float = 0.5
    compensate_latency: bool = True
    min_obstacle_width: float | None = None
    kernels: str = "auto"

    def __post_init__(self) -> None:
        name = "MPCConfig."
        if self.horizon_time is not None:
            _checks.number(name + "horizon_time", self.horizon_time, low=0.0, high=10.0, low_open=True)
        _checks.integer(name + "max_commands", self.max_commands, low=2, high=400)
        if self.margin is not None:
            _checks.number(name + "margin", self.margin, low=0.0, high=10.0)
        if self.buffer is not None:
            _checks.number(name + "buffer", self.buffer, low=0.0, high=1.0)
        _checks.number(name + "buffer_cost", self.buffer_cost, low=0.0, high=1e9, low_open=True)
        _checks.choice("MPC body model", self.body, BODIES)
        if self.narrow_body is not None:
            _checks.choice("MPC narrow body model", self.narrow_body, BODIES[1:])
        _checks.integer(name + "n_disks", self.n_disks, low=1, high=16)
        _checks.number(name + "lookahead", self.lookahead, low=0.0, high=10.0)
        if self.n_points is not None:
            _checks.integer(name + "n_points", self.n_points, low=1, high=2000)
        if not isinstance(self.solver, str) or not _is_known_solver(self.solver.lower()):
            raise UnknownName("MPC solver", self.solver, available_mpc_solvers(),
                              hint="QP back-ends of the direct SQP, casadi's sqpmethod (the reference), or ipopt")
        _checks.choice("MPC Hessian", self.hessian, HESSIANS)
        if self.weights is not None:
            _checks.pair(name + "weights", self.weights, low=0.0, low_open=True)
        _checks.number(name + "tracking", self.tracking, low=0.0, high=1e3)
        _checks.choice("MPC reference", self.reference, REFERENCES)
        _checks.choice("MPC kernels", self.kernels, KERNELS)
        _checks.number(name + "slack_weight", self.slack_weight, low=1.0, high=1e9)
        _checks.integer(name + "max_iter", self.max_iter, low=1, high=10000)
        _checks.integer(name + "max_rounds", self.max_rounds, low=1, high=100)
        if self.budget is not None:
            _checks.number(name + "budget", self.budget, low=0.0, low_open=True, finite=False)
        _checks.number(name + "max_gap", self.max_gap, low=0.0, high=2 * math.pi)
        _checks.number(name + "side_tolerance", self.side_tolerance, low=0.0, high=0.5 * math.pi)
        _checks.number(name + "time_constant", self.time_constant, low=0.0, high=1.0)
        if self.memory_range is not None:
            _checks.positive(name + "memory_range", self.memory_range)
        _checks.integer(name + "memory_capacity", self.memory_capacity, low=0)
        _checks.boolean(name + "hold_stop", self.hold_stop)
        _checks.positive(name + "deadlock_time", self.deadlock_time)
        _checks.duration(name + "scan_timeout", self.scan_timeout, high=1e9)
        _checks.boolean(name + "compensate_latency", self.compensate_latency)
        if self.min_obstacle_width is not None:
            _checks.positive(name + "min_obstacle_width", self.min_obstacle_width)

    def resolve(self, robot: RobotSpec, dt: float) -> MPCConfig:
        """This config with the robot-derived defaults that do not need the plan model filled in.

        (``buffer`` depends on the plan model; the filter resolves it and exposes it as
        :attr:`~safenav.filters.mpc.MPCSafetyFilter.buffer`.)
        """
        stop_time = max(max(robot.v_max, -robot.v_min) / robot.a_max, robot.omega_max / robot.alpha_max)
        solver = self.solver.lower()
        casadi_solver = solver == "ipopt" or solver.startswith("sqpmethod")
        return dataclasses.replace(
            self,
            horizon_time=self.horizon_time if self.horizon_time is not None else max(DEFAULT_HORIZON_TIME,
                                                                                     stop_time + dt),
            margin=self.margin if self.margin is not None else default_margin(robot),
            weights=tuple(self.weights) if self.weights is not None else default_weights(robot),
            solver=solver,
            n_points=self.n_points if self.n_points is not None else CASADI_POINTS if casadi_solver else DIRECT_POINTS,
            budget=self.budget if self.budget is not None else BUDGET_FRACTION * dt,
            narrow_body=self.narrow_body if self.body == "disk" and robot.footprint is not None else None,
        )

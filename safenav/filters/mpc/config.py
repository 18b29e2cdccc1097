"""Settings of the MPC filter, and the solvers it can use."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import casadi

from safenav import _checks
from safenav.errors import UnknownName
from safenav.filters.defaults import default_margin, default_weights
from safenav.robot import RobotSpec

__all__ = ["CONIC_PLUGINS", "DEFAULT_HORIZON", "HESSIANS", "MPCConfig", "available_mpc_solvers"]

#: Horizon used unless the robot needs more steps to stop from its velocity limits.
DEFAULT_HORIZON = 20
#: QP solvers casadi's ``sqpmethod`` can use here, in order of preference.
CONIC_PLUGINS = ("daqp", "qrqp", "osqp", "qpoases", "hpipm", "proxqp", "highs")
HESSIANS = ("gauss-newton", "exact")


def available_mpc_solvers() -> list[str]:
    """Solver names :class:`MPCConfig` accepts on this machine (casadi QP plugins, and ``"ipopt"``)."""
    names = [name for name in CONIC_PLUGINS if casadi.has_conic(name)]
    if casadi.has_nlpsol("ipopt"):
        names.append("ipopt")
    return names


@dataclass(frozen=True)
class MPCConfig:
    """Settings of :class:`~safenav.filters.mpc.MPCSafetyFilter`; ``None`` means "derive from the robot".

    :meth:`resolve` fills every robot-derived default in.

    Attributes:
        horizon: number of planned commands ``N``; default ``max(20, steps to stop from the
            velocity limits + 1)``.
        margin: clearance kept between the body and every obstacle point [m]; default as the CBF's.
        buffer: extra distance the plan keeps beyond the guaranteed radius [m], so that a base
            that moves differently from the model, or range noise between scans, does not make
            the next problem need slack; default ``e_act + 2 noise_std``.
        n_points: obstacle-point slots ``K`` of the optimiser (each gives one row per step);
            the plan is checked against every point in reach, and missed points are swapped in.
        solver: ``"daqp"`` (default) or another casadi QP plugin for ``sqpmethod``
            (``"qrqp"``, ``"osqp"``, ``"qpoases"``, ...), or ``"ipopt"``; case-insensitive.
        hessian: ``"gauss-newton"`` (the cost's own: constant, positive definite) or ``"exact"``.
        weights: cost weights on the deviation of the first command from ``u_nom``
            [s^2/m^2, s^2/rad^2]; default ``(1 / v_max^2, 0.2 / omega_max^2)`` as the CBF filter.
        regularisation: weight of the later commands' magnitudes relative to ``weights``.
        slack_weight: linear and quadratic cost of the relaxation of the clearance rows [1/m, 1/m^2].
        max_iter: SQP iterations per solve.
        max_rounds: solves with missed points swapped into the slots before the call counts as failed.
        max_gap: widest run of invalid beams bridged by its neighbours [rad]; wider runs are unknown.
        side_tolerance: unknown space this close to exactly sideways does not block motion [rad].
        time_constant: first-order lag of the base's velocity loop [s]: the plan models the
            base's velocity as following the commands with this lag (0: the base reaches each
            command within the period). Needs ``velocity`` at each call.
        memory_range: remembered points farther than this are forgotten [m] (default: reach + 1 m).
        memory_capacity: largest number of remembered points.
        deadlock_time: how long the commands may stall while the nominal asks to move before the
            result reports a deadlock [s].
        scan_timeout: scans older than this make the filter brake [s].
        compensate_latency: move a scan of known age into the current base frame first.
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
    time_constant: float = 0.0
    memory_range: float | None = None
    memory_capacity: int = 4000
    deadlock_time: float = 1.5
    scan_timeout: float = 0.5
    compensate_latency: bool = True

    def __post_init__(self) -> None:
        name = "MPCConfig."
        if self.horizon is not None:
            _checks.integer(name + "horizon", self.horizon, low=2, high=400)
        if self.margin is not None:
            _checks.number(name + "margin", self.margin, low=0.0, high=10.0)
        if self.buffer is not None:
            _checks.number(name + "buffer", self.buffer, low=0.0, high=1.0)
        _checks.integer(name + "n_points", self.n_points, low=1, high=2000)
        solvers = available_mpc_solvers()
        if not isinstance(self.solver, str) or self.solver.lower() not in solvers:
            raise UnknownName("MPC solver", self.solver, solvers, hint="casadi QP plugins for sqpmethod, or ipopt")
        _checks.choice("MPC Hessian", self.hessian, HESSIANS)
        if self.weights is not None:
            _checks.pair(name + "weights", self.weights, low=0.0, low_open=True)
        _checks.number(name + "regularisation", self.regularisation, low=1e-9, high=1.0)
        _checks.number(name + "slack_weight", self.slack_weight, low=1.0, high=1e9)
        _checks.integer(name + "max_iter", self.max_iter, low=1, high=10000)
        _checks.integer(name + "max_rounds", self.max_rounds, low=1, high=100)
        _checks.number(name + "max_gap", self.max_gap, low=0.0, high=2 * math.pi)
        _checks.number(name + "side_tolerance", self.side_tolerance, low=0.0, high=0.5 * math.pi)
        _checks.number(name + "time_constant", self.time_constant, low=0.0, high=1.0)
        if self.memory_range is not None:
            _checks.positive(name + "memory_range", self.memory_range)
        _checks.integer(name + "memory_capacity", self.memory_capacity, low=0)
        _checks.positive(name + "deadlock_time", self.deadlock_time)
        _checks.duration(name + "scan_timeout", self.scan_timeout, high=1e9)
        _checks.boolean(name + "compensate_latency", self.compensate_latency)

    def resolve(self, robot: RobotSpec, dt: float) -> MPCConfig:
        """This config with the robot-derived defaults that do not need the plan model filled in.

        (``horizon`` and ``buffer`` depend on the plan model; the filter resolves them and
        exposes them as :attr:`~safenav.filters.mpc.MPCSafetyFilter.horizon` and ``buffer``.)
        """
        return dataclasses.replace(
            self,
            margin=self.margin if self.margin is not None else default_margin(robot),
            weights=tuple(self.weights) if self.weights is not None else default_weights(robot),
            solver=self.solver.lower(),
        )

"""The MPC filter's nonlinear program, built once in casadi per problem shape, and its solver.

Single shooting over the commands; obstacle points, radii and bounds are parameters, so one
built NLP serves every call. Solved by ``sqpmethod`` with the DAQP QP solver and a
Gauss-Newton Hessian, which measured fastest (see BENCHMARKS.md), or by any casadi QP plugin
or Ipopt.
"""

from __future__ import annotations

import functools
import time
from typing import Any, NamedTuple

import casadi
import numpy as np

from safenav.filters.mpc.plan import MIN_ROW_SCALE, BaseModel

__all__ = ["CasadiBackend", "NLPKey", "SolveOutcome", "build_nlp"]


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


def _sinc(x: casadi.SX) -> casadi.SX:
    """sin(x)/x as its Taylor polynomial to x^10 (error below 2e-10 for |x| <= 1, smooth at 0)."""
    x2 = x * x
    return 1 - x2 / 6 * (1 - x2 / 20 * (1 - x2 / 42 * (1 - x2 / 72 * (1 - x2 / 110))))



class NLPKey(NamedTuple):
    """The shape of one NLP and its solver settings (NLPs are built once per key and shared)."""

    horizon: int
    n_points: int
    dt: float
    time_constant: float
    weights: tuple[float, float]
    regularisation: float
    slack_weight: float
    solver: str
    hessian: str
    max_iter: int


@functools.lru_cache(maxsize=32)
def build_nlp(key: NLPKey) -> casadi.Function:
    """The casadi solver for one problem shape; built once and shared by filters with the same key.

    Decision vector ``x = (u_0, ..., u_{N-1}, s)``; parameters ``p = (velocity, u_nom,
    points (K x 2, row-major), radii (K))``; constraints ``g`` = the ``2 (N - 1)``
    acceleration rows ``u_k - u_{k-1}``, then ``K N`` clearance rows, knot-major,
    ``(||p_k - o_j||^2 - r_j^2) / (2 r_j) + s >= 0`` (about ``||p_k - o_j|| - r_j + s`` [m]),
    then, for a lagging base (``time_constant > 0``), ``K`` rows for the point where the base
    still drifts after the plan's last command (:meth:`BaseModel.coast`). The motion is the
    model of :class:`~safenav.filters.mpc.plan.BaseModel`.
    """
    model = BaseModel(key.dt, key.time_constant)
    rho, beta = model.rho, model.beta
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
    state = velocity
    previous = None

    def clearance(px: casadi.SX, py: casadi.SX) -> casadi.SX:
        dx = px - points[0, :].T
        dy = py - points[1, :].T
        return (dx * dx + dy * dy - radii * radii) * scale + slack

    for k in range(horizon):
        command = commands[:, k]
        if previous is not None:
            acceleration_rows.append(command - previous)
        mean = command + beta * (state - command)
        half_turn = 0.5 * dt * mean[1]
        chord = dt * mean[0] * _sinc(half_turn)
        heading = yaw + half_turn
        x, y, yaw = x + chord * casadi.cos(heading), y + chord * casadi.sin(heading), yaw + 2.0 * half_turn
        clearance_rows.append(clearance(x, y))
        state = command + rho * (state - command)
        previous = command
    if key.time_constant > 0.0:
        drift = key.time_constant * state[0]
        clearance_rows.append(clearance(x + drift * casadi.cos(yaw), y + drift * casadi.sin(yaw)))
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

    def __init__(self, key: NLPKey) -> None:
        self.key = key
        self.name = "ipopt" if key.solver == "ipopt" else f"sqpmethod+{key.solver}"
        self._solver = build_nlp(key)

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

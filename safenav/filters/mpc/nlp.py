"""The MPC's nonlinear program in casadi: the plan model with its derivatives, and the reference NLP.

Both solvers of the MPC filter optimise the same NLP (:class:`PlanNLP`, stated in
:mod:`safenav.filters.mpc.sqp`); this module holds what casadi builds for it, once per
problem shape:

* :class:`PlanModel`: a casadi ``Function`` from a plan's commands and the start velocity to
  the pose ``(x, y, yaw)`` at the end of every period (and where a lagging base drifts to
  after the plan) and its Jacobian with respect to the commands chosen: every period's, or a
  layout's knots' (``u = B U``, differentiated through ``B`` by casadi). Evaluated through
  casadi's buffer interface into arrays this object owns (no conversions per call). The direct
  SQP (:class:`~safenav.filters.mpc.sqp.DirectSQP`) calls it once per iteration: the model of
  its every-period layout's knots, built with the filter, and the every-period model for the
  blocks of late calls (summed per block), so a late call builds nothing.
* :class:`CasadiNLP`: the whole NLP handed to casadi's ``sqpmethod`` (with any of its QP
  plugins) or Ipopt: the reference the direct SQP is checked against
  (``tests/filters/test_mpc_replay.py``), selectable with ``solver="sqpmethod"``.
"""

from __future__ import annotations

import functools
import time
from typing import TYPE_CHECKING, Any, NamedTuple

import casadi
import numpy as np

from safenav.errors import InvalidConfig
from safenav.filters.mpc.plan import MIN_ROW_SCALE, BaseModel, PlanLayout, block_ramp

if TYPE_CHECKING:
    from safenav.filters.mpc.sqp import NLPOutcome, PlanCost, PlanNLP

__all__ = ["CasadiNLP", "NLPKey", "PlanModel", "build_nlp"]

#: Distance of the unused point slots of the reference NLP from the robot [m].
FAR_AWAY = 1e6


def _sinc(x: casadi.SX) -> casadi.SX:
    """sin(x)/x as its Taylor polynomial to x^10 (error below 2e-10 for |x| <= 1, smooth at 0)."""
    x2 = x * x
    return 1 - x2 / 6 * (1 - x2 / 20 * (1 - x2 / 42 * (1 - x2 / 72 * (1 - x2 / 110))))


def _knot_poses(model: BaseModel, commands: casadi.SX, velocity: casadi.SX) -> casadi.SX:
    """Symbolic ``(3, K)`` poses at the clearance knots of a plan of ``(2, P)`` commands.

    The base follows the commands as :class:`BaseModel` says, along the exact arc of each
    period's mean velocity; with a lag, the last pose is where it drifts to after the plan.
    """
    dt, rho, beta = model.dt, model.rho, model.beta
    x = y = yaw = 0.0
    state = velocity
    poses = []
    for k in range(commands.shape[1]):
        command = commands[:, k]
        mean = command + beta * (state - command)
        half_turn = 0.5 * dt * mean[1]
        chord = dt * mean[0] * _sinc(half_turn)
        heading = yaw + half_turn
        x, y, yaw = x + chord * casadi.cos(heading), y + chord * casadi.sin(heading), yaw + 2.0 * half_turn
        poses.append(casadi.vertcat(x, y, yaw))
        state = command + rho * (state - command)
    if model.time_constant > 0.0:
        drift = model.time_constant * state[0]
        poses.append(casadi.vertcat(x + drift * casadi.cos(yaw), y + drift * casadi.sin(yaw), yaw))
    return casadi.horzcat(*poses)


def _reached(model: BaseModel, commands: casadi.SX, velocity: casadi.SX, hold: int) -> casadi.SX:
    """``(2, P)``: what the model is evaluated at for ``commands`` held in blocks of ``hold`` periods: without a lag,
    the velocities the base reaches (:meth:`BaseModel.reached`); the commands otherwise."""
    if not model.ramps(hold):
        return commands
    ramp, start = block_ramp(commands.shape[1], hold)
    return casadi.mtimes(commands, casadi.DM(ramp.T)) + casadi.mtimes(velocity, casadi.DM(start).T)


@functools.lru_cache(maxsize=32)
def _model_function(periods: int, max_commands: int, hold: int, dt: float, time_constant: float) -> casadi.Function:
    layout = PlanLayout.of(periods, max_commands, hold)
    model = BaseModel(dt, time_constant)
    knots = casadi.SX.sym("U", 2, layout.n_knots)
    commands = knots if layout.identity else casadi.mtimes(knots, casadi.DM(layout.interpolation.T))
    velocity = casadi.SX.sym("velocity", 2)
    flat = casadi.vec(_knot_poses(model, _reached(model, commands, velocity, hold), velocity))
    jacobian = casadi.jacobian(flat, casadi.vec(knots))
    # The Jacobian's transpose, stored column-major: the Jacobian row-major (no transposition per call).
    return casadi.Function("plan_model", [casadi.vec(knots), velocity],
                           [casadi.densify(flat), casadi.densify(jacobian.T)], ["U", "velocity"],
                           ["poses", "jacobian_transposed"])


class PlanModel:
    """The knot poses of a plan and their Jacobian, from a casadi Function built once per shape.

    Args:
        periods: commands of a plan.
        model: how the base follows the commands.
        layout: whose knots' commands are the variables (``u = B U``, the derivatives taken through
            ``B``); ``None``: every period's command.
    """

    def __init__(self, periods: int, model: BaseModel, layout: PlanLayout | None = None) -> None:
        self.periods = int(periods)
        self.model = model
        self.layout = layout if layout is not None else PlanLayout.of(self.periods, self.periods)
        if self.layout.periods != self.periods:
            raise InvalidConfig(f"PlanModel: a layout of {self.layout.periods} periods for a plan of {self.periods} "
                                "periods; expected the same number")
        self.n_poses = self.periods + (1 if model.time_constant > 0.0 else 0)
        function = _model_function(self.periods, self.layout.max_commands, self.layout.hold, model.dt,
                                   model.time_constant)
        self._buffer, self._evaluate = function.buffer()
        n_vars = 2 * self.layout.n_knots
        self._commands = np.zeros(n_vars)
        self._velocity = np.zeros(2)
        self._poses = np.zeros(3 * self.n_poses)
        self._jacobian = np.zeros(3 * self.n_poses * n_vars)
        for index, array in enumerate((self._commands, self._velocity)):
            self._buffer.set_arg(index, memoryview(array))
        for index, array in enumerate((self._poses, self._jacobian)):
            self._buffer.set_res(index, memoryview(array))

    def __call__(self, commands: np.ndarray, velocity: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Poses ``(K, 3)`` at the clearance knots and their Jacobian ``(K, 3, 2n)`` with respect to
        the knots' commands ``(n, 2)`` (flattened knot by knot: ``v_0, omega_0, v_1, ...``)."""
        poses, jacobian = self.evaluate(commands, velocity)
        return poses.copy(), jacobian.copy()

    def evaluate(self, commands: np.ndarray, velocity: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """As calling the model, without copies: views of buffers that the next evaluation overwrites."""
        self._commands[:] = np.ravel(commands)
        self._velocity[:] = velocity
        self._evaluate()
        return self._poses.reshape(self.n_poses, 3), self._jacobian.reshape(self.n_poses, 3, self._commands.size)

    def __getstate__(self) -> dict[str, Any]:
        layout = self.layout
        return {"periods": self.periods, "model": self.model,
                "layout": (layout.periods, layout.max_commands, layout.hold)}

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__init__(state["periods"], state["model"], PlanLayout.of(*state["layout"]))  # type: ignore[misc]
class NLPKey(NamedTuple):
    """The shape of one reference NLP and its solver settings (built once per key and shared)."""

    periods: int
    max_commands: int
    hold: int
    n_points: int
    offsets: tuple[tuple[float, float], ...]
    dt: float
    time_constant: float
    cost: PlanCost
    solver: str
    hessian: str
    max_iter: int


@functools.lru_cache(maxsize=16)
def build_nlp(key: NLPKey) -> casadi.Function:
    """The casadi solver of the reference NLP for one problem shape.

    Decision vector ``x = (U, s_b, s_h)``: the control knots' commands, the buffer slack and
    the slack. Parameters ``p = (velocity, target, points (K x 2), radii (K x D), relief
    (K x D))``. Constraints ``g``: the ``2 (n - 1)`` changes between knots (acceleration, and
    the held commands: :func:`~safenav.filters.mpc.sqp.knot_changes`), the commands of the
    periods between knots (their bounds; the knots' own are bounds on ``x``), then ``K D``
    clearance rows per knot, knot-major, ``(||c - o||^2 - r^2) / (2 r) + relief s_b + s_h >= 0``
    (about ``||c - o|| - r``).
    """
    layout = PlanLayout.of(key.periods, key.max_commands, key.hold)
    model = BaseModel(key.dt, key.time_constant)
    n_knots, n_points = layout.n_knots, key.n_points
    offsets = np.asarray(key.offsets, dtype=float).reshape(-1, 2)
    n_disks = offsets.shape[0]
    knots = casadi.SX.sym("U", 2, n_knots)
    buffer_slack = casadi.SX.sym("s_b")
    slack = casadi.SX.sym("s_h")
    velocity = casadi.SX.sym("velocity", 2)
    target = casadi.SX.sym("target", 2)
    points = casadi.SX.sym("points", 2, n_points)
    radii = casadi.SX.sym("radii", n_points, n_disks)
    relief = casadi.SX.sym("relief", n_points, n_disks)
    parameters = casadi.vertcat(velocity, target, casadi.vec(points), casadi.vec(radii), casadi.vec(relief))
    commands = knots if layout.identity else casadi.mtimes(knots, casadi.DM(layout.interpolation.T))
    poses = _knot_poses(model, _reached(model, commands, velocity, layout.hold), velocity)
    cost_weights = key.cost.period_weights(layout.periods)
    w_v, w_omega = key.cost.weights
    cost = casadi.dot(cost_weights, w_v * (commands[0, :].T - target[0]) ** 2
                      + w_omega * (commands[1, :].T - target[1]) ** 2)
    cost += key.cost.buffer_weight * buffer_slack**2 + key.cost.slack_weight * (slack + slack**2)
    interpolated = _interpolated(layout).tolist()
    rows = [knots[:, 1:] - knots[:, :-1], commands[:, interpolated]]
    scale = 0.5 / casadi.fmax(radii, MIN_ROW_SCALE)
    for k in range(poses.shape[1]):
        x, y, yaw = poses[0, k], poses[1, k], poses[2, k]
        for d in range(n_disks):
            cx = x + casadi.cos(yaw) * offsets[d, 0] - casadi.sin(yaw) * offsets[d, 1]
            cy = y + casadi.sin(yaw) * offsets[d, 0] + casadi.cos(yaw) * offsets[d, 1]
            dx, dy = cx - points[0, :].T, cy - points[1, :].T
            rows.append((dx * dx + dy * dy - radii[:, d] ** 2) * scale[:, d] + relief[:, d] * buffer_slack + slack)
    nlp = {"x": casadi.vertcat(casadi.vec(knots), buffer_slack, slack), "p": parameters, "f": cost,
           "g": casadi.vertcat(*(casadi.vec(row) for row in rows))}
    if key.solver == "ipopt":
        options: dict[str, Any] = {"print_time": False, "ipopt.print_level": 0, "ipopt.sb": "yes",
                                   "ipopt.max_iter": key.max_iter, "ipopt.tol": 1e-10,
                                   "ipopt.constr_viol_tol": 1e-10, "error_on_fail": False}
        if key.hessian == "gauss-newton":
            options["ipopt.hessian_approximation"] = "limited-memory"
        return casadi.nlpsol("mpc_reference", "ipopt", nlp, options)
    plugin = key.solver.partition(":")[2] or "daqp"
    qp_options: dict[str, Any] = {"print_time": False, "error_on_fail": False}
    if plugin == "daqp":
        qp_options["daqp"] = {"primal_tol": 1e-10, "iter_limit": 2000}
    elif plugin == "qrqp":
        qp_options.update(print_iter=False, print_header=False, print_info=False, max_iter=2000)
    elif plugin == "osqp":
        qp_options["osqp"] = {"verbose": False, "eps_abs": 1e-10, "eps_rel": 1e-10, "max_iter": 20000,
                              "polishing": True}
    elif plugin == "qpoases":
        qp_options.update(printLevel="none", sparse=True)
    # Full steps (no line search), as the direct SQP; tight tolerances: this is the reference.
    options = {"qpsol": plugin, "qpsol_options": qp_options, "print_time": False, "print_header": False,
               "print_iteration": False, "print_status": False, "max_iter": key.max_iter, "tol_pr": 1e-10,
               "tol_du": 1e-9, "min_step_size": 1e-14, "max_iter_ls": 0, "error_on_fail": False}
    if key.hessian == "gauss-newton":
        decision = nlp["x"]
        lam_f = casadi.SX.sym("lam_f")
        lam_g = casadi.SX.sym("lam_g", nlp["g"].shape[0])
        hessian = casadi.hessian(cost, decision)[0] * lam_f
        options["hess_lag"] = casadi.Function("gauss_newton", [decision, parameters, lam_f, lam_g], [hessian],
                                              ["x", "p", "lam_f", "lam_g"], ["hess_gamma_x_x"])
    else:
        options["convexify_strategy"] = "eigen-clip"
    return casadi.nlpsol("mpc_reference", "sqpmethod", nlp, options)


def _interpolated(layout: PlanLayout) -> np.ndarray:
    """The periods whose commands an interpolated layout gives bound rows of their own."""
    return np.setdiff1d(np.arange(layout.periods), layout.knots) if layout.interpolated else np.empty(0, dtype=int)


class CasadiNLP:
    """The reference solver: the whole NLP in casadi's ``sqpmethod`` (any QP plugin) or Ipopt.

    Slower than :class:`~safenav.filters.mpc.sqp.DirectSQP` (casadi's QP interface costs
    about 0.9 ms per SQP iteration here) and not interruptible: the deadline is checked
    before the solve only. One NLP is built per layout, when first needed (a late call's
    layout costs a build). Kept to check the direct SQP against.

    Args:
        key: the problem shape and the solver settings (its ``hold`` is replaced by each layout's).
    """

    def __init__(self, key: NLPKey) -> None:
        self.key = key
        self.name = "ipopt" if key.solver == "ipopt" else f"sqpmethod+{key.solver.partition(':')[2] or 'daqp'}"
        build_nlp(key)

    def solve(self, nlp: PlanNLP, deadline: float = float("inf"), clock: Any = time.perf_counter,
              step: float = 0.0) -> NLPOutcome:
        """Solve ``nlp`` from its start, unless it would end after ``deadline`` lasting ``step`` [s]; ``knots``
        is ``None`` when casadi raised (the caller verifies). The whole solve is one step."""
        from safenav.filters.mpc.sqp import NLPOutcome, knot_changes

        start = clock()
        if start + step > deadline:
            return NLPOutcome(None, 0.0, 0.0, "deadline", 0, 0.0, abandoned=True)
        layout = nlp.layout
        key = self.key._replace(hold=layout.hold)
        solver = build_nlp(key)
        n_points, n_disks = key.n_points, len(key.offsets)
        used = nlp.points.shape[0]
        if used > n_points:
            raise ValueError(f"{used} points for {n_points} slots")
        points = np.full((n_points, 2), FAR_AWAY)
        radii = np.ones((n_points, n_disks))
        relief = np.zeros((n_points, n_disks))
        points[:used], radii[:used], relief[:used] = nlp.points, nlp.radii, nlp.relief
        parameters = np.concatenate((nlp.velocity, nlp.target, points.ravel(), radii.ravel(order="F"),
                                     relief.ravel(order="F")))
        knots_lower, knots_upper = layout.knot_bounds(nlp.lower, nlp.upper)
        lower = np.concatenate((knots_lower.ravel(), (0.0, 0.0)))
        upper = np.concatenate((knots_upper.ravel(), (nlp.buffer, np.inf)))
        change = knot_changes(layout, nlp.step).ravel()
        interpolated = _interpolated(layout)
        n_clearance = n_points * n_disks * (layout.periods + (1 if key.time_constant > 0.0 else 0))
        lbg = np.concatenate((-change, nlp.lower[interpolated].ravel(), np.zeros(n_clearance)))
        ubg = np.concatenate((change, nlp.upper[interpolated].ravel(), np.full(n_clearance, np.inf)))
        x0 = np.concatenate((np.clip(nlp.start, knots_lower, knots_upper).ravel(), (0.0, 0.0)))
        try:
            result = solver(x0=x0, p=parameters, lbx=lower, ubx=upper, lbg=lbg, ubg=ubg)
        except RuntimeError as error:  # casadi raises RuntimeError for evaluation errors
            elapsed = clock() - start
            return NLPOutcome(None, 0.0, 0.0, f"error: {error}", 0, elapsed, longest_step=elapsed)
        elapsed = clock() - start
        try:
            stats = solver.stats()
        except RuntimeError:  # some plugins leave no statistics behind after a failure
            stats = {}
        x = np.asarray(result["x"], dtype=float).ravel()
        status = str(stats.get("return_status", "unknown"))
        iterations = int(stats.get("iter_count", 0))
        if x.shape != (2 * layout.n_knots + 2,) or not np.all(np.isfinite(x)):
            return NLPOutcome(None, 0.0, 0.0, status, iterations, elapsed, longest_step=elapsed)
        return NLPOutcome(x[:-2].reshape(-1, 2), float(x[-2]), float(x[-1]), status, iterations, elapsed,
                          longest_step=elapsed)

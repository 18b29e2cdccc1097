"""The MPC's NLP and its fast solver: sequential quadratic programming with a QP back-end called directly.

**The NLP** (:class:`PlanNLP`), over the control knots' commands ``U`` (the commands of every
period are ``u = B U``: interpolated, or in blocks held for a late call's period,
:class:`~safenav.filters.mpc.plan.PlanLayout`) and two slacks::

    min   sum_k c_k [w_v (v_k - v_t)^2 + w_omega (omega_k - omega_t)^2]
          + buffer_weight s_b^2 + slack_weight (s_h + s_h^2)
    s.t.  lower_k <= u_k <= upper_k                         every period k (limits, reach, unknown space, stop)
          |U_{j+1} - U_j| <= c_j (a_max, alpha_max) dt     (acceleration between knots, c_j periods)
          (||c_kd - o||^2 - r_od^2) / (2 r_od) + relief_od s_b + s_h >= 0   every knot k, disk d, point o
          0 <= s_b <= buffer,  s_h >= 0

``c_kd`` is the centre of body disk ``d`` at the end of period ``k`` (and where a lagging base
drifts to); ``(v_t, omega_t)`` is the nominal clipped to the velocity limits, held along the
plan (*tracking*): ``c_0 = 1`` for the command sent and ``c_k = tracking / (P - 1)`` for the
rest, so the plan prefers to keep the nominal's speed and turn (steer round an obstacle) over
braking in front of it, while the first command stays as near the nominal as the rest allows.
The planned radius ``r_od`` includes a buffer beyond the radius the filter guarantees; the
buffer slack ``s_b`` (cheap) may use it, ``relief_od`` being the share of the buffer the
point has (0 for a point already nearer than the guaranteed radius, which may not be
approached at all); ``s_h`` (heavy) relaxes the guaranteed radius itself.

**The solvers.** :class:`DirectSQP` (default): casadi gives the knot poses and their exact Jacobian
with respect to the knots' commands (:class:`~safenav.filters.mpc.nlp.PlanModel`, one Function per
layout, built with the filter, evaluated into buffers it owns), each SQP step's QP (the cost's own
constant Hessian, the clearance rows linearised) is assembled in numpy without loops over points
(every row as a (point, knot and disk) array entry) and solved by a
:class:`~safenav.filters.qp.QPBackend` (DAQP called directly by default, the CBF's back-end
interface), with full steps from the warm start, until the step is below :data:`STEP_TOLERANCE`.
Where the steps contract slowly (the Hessian leaves the rows' curvature out), or turn back and forth
round a cycle, the next linearisation point is the secant's estimate of the fixed point, through the
last two iterates and their QPs' answers (Anderson's acceleration with a memory of one,
:func:`_secant_jump`, :data:`ACCELERATION_WINDOW`, :data:`CYCLE_COSINE`); the fixed point, and the
test of convergence on a QP's own step, are unchanged (``benchmarks/sqp_iterations.py`` measures both
ways on the same NLPs). Only the clearance rows that
can bind are passed to the QP; any other row its answer violates is added and the QP solved again,
so each step is the step of the QP with every row. With a slack per point (``slack_groups``) the QP
has the slacks of the points with a row in it (any other is 0 at the optimum), and of each point's
violated rows the most violated is added (its slack is what covers the others): adding every one
made QPs of a thousand rows and a hundred variables, 5-20 ms in DAQP; one row a point settles in a
round or two. The products of a step are einsum contractions, not BLAS calls (a product large enough for
BLAS to thread can stall for milliseconds on a busy machine). The deadline is checked before every
step (an iteration, or another round of rows for its QP): a step is begun only when it can end
before the deadline, lasting as long as the caller's estimate (``step``) or the longest step so far
(:class:`~safenav.filters.deadline.StepClock`). :class:`~safenav.filters.mpc.nlp.CasadiNLP` hands
the same NLP to casadi's ``sqpmethod`` (the reference) or Ipopt.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, NamedTuple, Protocol

import numpy as np

from safenav.filters.deadline import StepClock
from safenav.filters.kernels import plain
from safenav.filters.mpc.nlp import PlanModel
from safenav.filters.mpc.plan import MIN_ROW_SCALE, PlanLayout, block_ramp
from safenav.filters.qp import QPBackend, QPData

__all__ = ["ACCELERATION_WINDOW", "STEP_TOLERANCE", "DirectSQP", "NLPOutcome", "PlanCost", "PlanNLP", "PlanSolver",
           "knot_changes"]

#: The SQP stops when no knot command moves by more than this in a step [m/s, rad/s].
STEP_TOLERANCE = 1e-5
#: A knot's nearest row goes to the QP at once when its value is at most this [m] (the others only
#: when an answer violates them).
ROW_WINDOW = 0.2
#: Rows with a larger value [m] are not even checked within a step (no step of one iteration moves
#: a disk that far); every row is re-evaluated at the next iterate.
CHECK_WINDOW = 1.0
#: A linearised row the QP's answer misses by more than this [m] is added to the QP.
ROW_TOLERANCE = 1e-9
#: A row within this of holding with equality [m] stays in the next iteration's QP.
ACTIVE_TOLERANCE = 1e-6
#: Rounds of row generation within one SQP step before every checked row goes to the QP.
MAX_ROW_ROUNDS = 8
#: A step smaller than this [m/s, rad/s] that shrinks the last by a ratio within ACCELERATION_RATIOS is followed
#: by the secant's estimate of the fixed point (the SQP converges linearly where the clearance rows' curvature,
#: which its Hessian leaves out, matters): its slow tail in a few jumps, its fixed point unchanged.
ACCELERATION_WINDOW = 1e-3
ACCELERATION_RATIOS = (0.1, 1.0)
#: A step of any size that turns back along the last (cosine below CYCLE_COSINE), its size within CYCLE_RATIOS of
#: the last's, is the SQP going round a cycle between two points: the secant puts the next one between them.
CYCLE_COSINE = -0.8
CYCLE_RATIOS = (0.5, 2.0)
#: The secant's jump is at most this many times the step [-] (where a series of steps shrinking by 0.95 ends).
MAX_JUMP = 19.0


@dataclass(frozen=True)
class PlanCost:
    """The cost of a plan (see the module docstring).

    Attributes:
        weights: ``(w_v, w_omega)`` on the command deviations [s^2/m^2, s^2/rad^2].
        tracking: total weight of the later commands' deviations, relative to the first's.
        buffer_weight: cost of the buffer slack [1/m^2].
        slack_weight: linear and quadratic cost of the slack [1/m, 1/m^2].
    """

    weights: tuple[float, float]
    tracking: float
    buffer_weight: float
    slack_weight: float

    def period_weights(self, periods: int) -> np.ndarray:
        """``c_k`` for ``k = 0..P-1``: 1 for the command sent, ``tracking / (P - 1)`` for each later one."""
        weights = np.full(periods, self.tracking / max(periods - 1, 1))
        weights[0] = 1.0
        return weights


class PlanNLP(NamedTuple):
    """One instance of the NLP: the data a solver needs besides the cost and the model."""

    velocity: np.ndarray
    """``(2,)`` the velocity the plan starts from [m/s, rad/s]."""
    target: np.ndarray
    """``(2,)`` the nominal command, clipped to the velocity limits [m/s, rad/s]."""
    points: np.ndarray
    """``(K, 2)`` obstacle points in the optimiser's slots [m]."""
    radii: np.ndarray
    """``(K, D)`` planned radius per point and disk [m]."""
    relief: np.ndarray
    """``(K, D)`` share of the buffer each row may use, in [0, 1]."""
    lower: np.ndarray
    """``(P, 2)`` lower bounds of every period's command."""
    upper: np.ndarray
    """``(P, 2)`` upper bounds of every period's command."""
    layout: PlanLayout
    """Which commands are chosen (``u = B U``)."""
    step: np.ndarray
    """``(2,)`` the largest command change per period ``(a_max dt, alpha_max dt)``."""
    buffer: float
    """The largest buffer slack [m]."""
    start: np.ndarray
    """``(n, 2)`` the knots' commands to start from (the warm start)."""
    slack_groups: np.ndarray | None = None
    """``(K,)`` which slack relaxes each point's rows (``0 .. G - 1``, each with the cost of ``s_h``), or
    ``None``: one slack for every row. The filter gives each point its own when one slack was not
    enough, so that a point that cannot be kept clear does not relax the rows of those that can."""


class NLPOutcome(NamedTuple):
    """What a solver returned for one :class:`PlanNLP`."""

    knots: np.ndarray | None
    """``(n, 2)`` the knots' commands, or ``None`` when the solver failed or gave up."""
    buffer_slack: float
    """``s_b`` [m]."""
    slack: float
    """``s_h`` [m] (with slack groups, the largest)."""
    status: str
    """The solver's own status word."""
    iterations: int
    """SQP iterations."""
    solve_time: float
    """Wall time of the solve [s]."""
    abandoned: bool = False
    """The deadline passed before the solve finished (``knots`` is ``None``)."""
    point_slacks: np.ndarray | None = None
    """``(K,)`` with slack groups, the slack relaxing each point's rows [m]; ``None``: :attr:`slack` for every row."""
    longest_step: float = 0.0
    """The longest time between two of the solver's checks of the clock, or its last check and its return [s]."""


class PlanSolver(Protocol):
    """A solver of the MPC's NLP (:class:`DirectSQP`, or the casadi reference)."""

    name: str

    def solve(self, nlp: PlanNLP, deadline: float = float("inf"),
              clock: Callable[[], float] = time.perf_counter, step: float = 0.0) -> NLPOutcome:
        """Solve ``nlp`` from ``nlp.start``; give up rather than begin a step that, lasting ``step`` [s] or as
        long as the longest step of this solve, would end after ``deadline`` (``abandoned``)."""


def knot_changes(layout: PlanLayout, step: np.ndarray) -> np.ndarray:
    """``(n - 1, 2)`` the largest ``|U_{j+1} - U_j|``: the layout's periods of acceleration times ``step``."""
    return np.outer(layout.changes, step)


class _LayoutData(NamedTuple):
    """What the direct SQP precomputes per layout."""

    hessian: np.ndarray
    column_weights: np.ndarray
    differences: np.ndarray
    model: PlanModel
    """The model whose variables are the knots' commands, or every period's for a late call's blocks."""
    blocks: bool
    """Whether ``model`` is the every-period one and the derivatives are summed per block (``hold >= 2``)."""
    ramp: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
    """For blocks without a lag, ``(R, r, s)``: the model is evaluated at the velocities the base reaches,
    ``R u + r w_0`` (:func:`~safenav.filters.mpc.plan.block_ramp`), period ``p`` of block ``b`` at ``s_p U_b +
    (1 - s_p) U_(b-1)``; its derivatives are summed per block with those weights."""


def _most_missed_per_point(missed: np.ndarray, linearised: np.ndarray) -> np.ndarray:
    """Of the rows ``missed`` (a flat mask over ``linearised``'s ``(points, columns)``), each point's most missed (the
    first column of a tie)."""
    values = np.where(missed.reshape(linearised.shape), linearised, np.inf)
    worst = np.argmin(values, axis=1)
    points = np.flatnonzero(np.isfinite(values[np.arange(values.shape[0]), worst]))
    picked = np.zeros_like(missed)
    picked[points * linearised.shape[1] + worst[points]] = True
    return picked


def _secant_jump(step: np.ndarray, last_step: np.ndarray, answer_change: np.ndarray) -> np.ndarray:
    """From the last QP's answer to the fixed point of the SQP's map as the secant through the last two iterates
    estimates it (Anderson's acceleration with a memory of one): ``step`` and ``last_step`` are the two QPs' steps
    (answer less linearisation point), ``answer_change`` the change between their answers. On a geometric series
    of steps along one direction it is the end of the series; on a cycle between two points, their middle. At most
    :data:`MAX_JUMP` times the step: near a stall the secant's estimate is unreliable."""
    residual_change = step - last_step
    norm = float(residual_change @ residual_change)
    if norm == 0.0:
        return np.zeros_like(step)
    jump = (-float(residual_change @ step) / norm) * answer_change
    largest = float(np.max(np.abs(jump)))
    limit = MAX_JUMP * float(np.max(np.abs(step)))
    return jump if largest <= limit else jump * (limit / largest)


class _Variables:
    """Which of an SQP's variables (the knots' commands, the buffer slack, the slacks) a QP has: all of them
    (``columns`` ``None``), or, with a slack per group, those before the slacks and the slacks of the groups with a
    row in the QP (``columns``: their indices)."""

    def __init__(self, n_vars: int, n_linear: int, n_shared: int, slack_column: np.ndarray) -> None:
        self.n_vars, self.n_shared = n_vars, n_shared
        self.slack_column = slack_column
        self._linear_state = n_vars + np.arange(n_linear)   # the linear rows' places in the active-set state
        self._position = np.full(n_vars, -1, dtype=np.intp)

    def select(self, row_points: np.ndarray | None) -> tuple[np.ndarray | None, np.ndarray]:
        """The QP's columns, and each point's slack column in the QP, for rows of the points ``row_points``
        (``None``: one slack for every row, so every variable)."""
        if row_points is None:
            return None, self.slack_column
        slacks = np.unique(self.slack_column[row_points])
        if self.n_shared + slacks.size == self.n_vars:
            return None, self.slack_column
        columns = np.concatenate((np.arange(self.n_shared), slacks))
        position = self._position
        position[:] = -1
        position[columns] = np.arange(columns.size)
        return columns, position[self.slack_column]     # -1 for a point with no row: never written

    @staticmethod
    def restrict(columns: np.ndarray | None, hessian: np.ndarray, gradient: np.ndarray, lower: np.ndarray,
                 upper: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The cost and the bounds over a QP's columns."""
        if columns is None:
            return hessian, gradient, lower, upper
        return hessian[np.ix_(columns, columns)], gradient[columns], lower[columns], upper[columns]

    def state(self, columns: np.ndarray | None, fixed_state: np.ndarray) -> np.ndarray:
        """The active-set state of the variables' bounds and the linear rows (over every variable) for a QP's
        columns."""
        return fixed_state if columns is None else fixed_state[np.concatenate((columns, self._linear_state))]

    def expand(self, columns: np.ndarray | None, x: np.ndarray, active: np.ndarray | None
               ) -> tuple[np.ndarray, np.ndarray | None]:
        """A QP's answer and active set over every variable: a slack left out is 0, at its lower bound."""
        if columns is None:
            return x, active
        full = np.zeros(self.n_vars)
        full[columns] = x
        if active is None:
            return full, None
        state = np.full(self.n_vars, -1, dtype=active.dtype)
        state[columns] = active[:columns.size]
        return full, np.concatenate((state, active[columns.size:]))


class DirectSQP:
    """Sequential quadratic programming over a :class:`~safenav.filters.qp.QPBackend` (see the module docstring).

    Args:
        model: the plan model of every period's command (knot poses and their Jacobian); each
            layout with move blocking gets its own (:meth:`prepare`).
        offsets: ``(D, 2)`` the body disks' centres in the base frame [m].
        cost: the cost.
        backend: the QP solver of each step.
        max_iter: SQP iterations before the last iterate is returned as it is (the filter verifies it).
    """

    def __init__(self, model: PlanModel, offsets: np.ndarray, cost: PlanCost, backend: QPBackend,
                 max_iter: int) -> None:
        self.model = model
        self.offsets = np.asarray(offsets, dtype=float).reshape(-1, 2)
        self.cost = cost
        self.qp = backend
        self.max_iter = int(max_iter)
        self.name = f"sqp+{backend.name}"
        self._centred = not np.any(self.offsets)
        self._layouts: dict[tuple[int, int, int], _LayoutData] = {}
        #: The compiled kernels (:func:`safenav.filters.kernels.load`) of the clearance rows' values, QP rows and
        #: check, or ``None``: numpy (the reference; the same rows to rounding).
        self.kernels: Any = None
        #: Whether a slow tail or a cycle jumps to the secant's fixed point (:func:`_secant_jump`); ``False``: every
        #: step in full, the plain SQP (``benchmarks/sqp_iterations.py`` and the tests compare both).
        self.secant = True

    def prepare(self, layout: PlanLayout) -> _LayoutData:
        """The cost's Hessian, the knot differences and the model of a layout, computed once (the
        filter prepares its every-period layout when it is built)."""
        key = (layout.periods, layout.max_commands, layout.hold)
        data = self._layouts.get(key)
        if data is not None:
            return data
        n = layout.n_knots
        n_vars = 2 * n + 2
        weights = self.cost.period_weights(layout.periods)
        interpolation = layout.interpolation
        hessian = np.zeros((n_vars, n_vars))
        for axis, weight in enumerate(self.cost.weights):
            hessian[axis:2 * n:2, axis:2 * n:2] = 2.0 * weight * interpolation.T @ (weights[:, None] * interpolation)
        hessian[2 * n, 2 * n] = 2.0 * self.cost.buffer_weight
        hessian[2 * n + 1, 2 * n + 1] = 2.0 * self.cost.slack_weight
        differences = np.zeros((2 * (n - 1), n_vars))
        for j in range(n - 1):
            for axis in range(2):
                differences[2 * j + axis, 2 * (j + 1) + axis] = 1.0
                differences[2 * j + axis, 2 * j + axis] = -1.0
        # The every-period layout's knots get a model of their own (built with the filter, it saves a
        # product by B per iteration); a late call's blocks sum the every-period model's derivatives,
        # so that a late call builds nothing.
        blocks = not layout.identity and layout.hold > 1
        model = self.model if layout.identity or blocks else PlanModel(layout.periods, self.model.model, layout)
        ramp = None
        if blocks and model.model.ramps(layout.hold):
            matrix, start = block_ramp(layout.periods, layout.hold)
            ramp = (matrix, start, np.diagonal(matrix).copy())
        data = _LayoutData(hessian, interpolation.T @ weights, differences, model, blocks, ramp)
        self._layouts[key] = data   # a handful per filter: one per call period seen
        return data

    def _linear_rows(self, nlp: PlanNLP, data: _LayoutData) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Rows that do not depend on the iterate: acceleration between knots, interpolated bounds."""
        layout = nlp.layout
        n_vars = 2 * layout.n_knots + 2
        pieces = [data.differences]
        change = knot_changes(layout, nlp.step).ravel()
        lows, highs = [-change], [change]
        if layout.interpolated:
            interpolation = layout.interpolation
            knots_lower, knots_upper = layout.knot_bounds(nlp.lower, nlp.upper)
            for axis in range(2):
                implied_low = interpolation @ knots_lower[:, axis]
                implied_high = interpolation @ knots_upper[:, axis]
                needed = (nlp.lower[:, axis] > implied_low + 1e-12) | (nlp.upper[:, axis] < implied_high - 1e-12)
                if needed.any():
                    rows = np.zeros((int(needed.sum()), n_vars))
                    rows[:, axis:2 * layout.n_knots:2] = interpolation[needed]
                    pieces.append(rows)
                    lows.append(nlp.lower[needed, axis])
                    highs.append(nlp.upper[needed, axis])
        return np.vstack(pieces), np.concatenate(lows), np.concatenate(highs)

    def _centres(self, poses: np.ndarray, jacobian: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Disk centres ``(2, K D)`` at the knots (knot-major: disk ``d`` of knot ``k`` is column
        ``k D + d``) and their Jacobian ``(2, K D, m)``, from the poses ``(K, 3)`` and their Jacobian
        ``(K, 3, m)``."""
        if self._centred:
            return poses[:, :2].T, jacobian[:, :2].transpose(1, 0, 2)
        cos, sin = np.cos(poses[:, 2])[:, None], np.sin(poses[:, 2])[:, None]
        ox, oy = self.offsets[None, :, 0], self.offsets[None, :, 1]
        rotated_x, rotated_y = cos * ox - sin * oy, sin * ox + cos * oy                  # (K, D)
        centres = np.stack((poses[:, None, 0] + rotated_x, poses[:, None, 1] + rotated_y)).reshape(2, -1)
        # d(R(yaw) o)/d yaw = perp(R(yaw) o) = (-y, x).
        turning = jacobian[:, None, 2, :]
        centre_jacobian = np.stack((jacobian[:, None, 0, :] - rotated_y[..., None] * turning,
                                    jacobian[:, None, 1, :] + rotated_x[..., None] * turning))
        return centres, centre_jacobian.reshape(2, centres.shape[1], -1)

    def solve(self, nlp: PlanNLP, deadline: float = float("inf"),
              clock: Callable[[], float] = time.perf_counter, step: float = 0.0) -> NLPOutcome:
        start_time = clock()
        steps = StepClock(deadline, clock, step)
        layout = nlp.layout
        data = self.prepare(layout)
        n = layout.n_knots
        # The slacks: one for every row (s_h), or one per group of points.
        groups = nlp.slack_groups
        n_groups = 1 if groups is None or groups.size == 0 else int(groups.max()) + 1
        n_vars = 2 * n + 1 + n_groups
        knots_lower, knots_upper = layout.knot_bounds(nlp.lower, nlp.upper)
        lower_bounds = np.concatenate((knots_lower.ravel(), np.zeros(1 + n_groups)))
        upper_bounds = np.concatenate((knots_upper.ravel(), (nlp.buffer,), np.full(n_groups, np.inf)))
        knots = np.clip(np.asarray(nlp.start, dtype=float).ravel(), knots_lower.ravel(), knots_upper.ravel())
        linear, linear_low, linear_high = self._linear_rows(nlp, data)
        hessian = data.hessian
        if n_groups > 1:
            linear = np.pad(linear, ((0, 0), (0, n_groups - 1)))
            hessian = np.pad(hessian, (0, n_groups - 1))
            hessian[2 * n + 1:, 2 * n + 1:] = np.diag(np.full(n_groups, 2.0 * self.cost.slack_weight))
        n_linear = linear.shape[0]
        gradient = np.zeros(n_vars)
        target = np.asarray(nlp.target, dtype=float)
        for axis, weight in enumerate(self.cost.weights):
            gradient[axis:2 * n:2] = -2.0 * weight * target[axis] * data.column_weights
        gradient[2 * n + 1:] = self.cost.slack_weight
        # Each point's slack column.
        slack_column = 2 * n + 1 + (groups if n_groups > 1 else np.zeros(nlp.points.shape[0], dtype=np.intp))
        # With a slack per group, each QP has the slacks of the groups with a row in it and no others: a slack in
        # no row sits at its bound 0 at the optimum (its cost rises from there), so the answer is the same, and
        # the QP has a few dozen variables rather than a hundred (DAQP's time grows with their square).
        variables = _Variables(n_vars, n_linear, 2 * n + 1, slack_column)
        compiled = self.kernels
        if compiled is not None:
            slack_column = slack_column.astype(np.intp, copy=False)
            point_array = plain(nlp.points)
        # Rows are kept as (point, knot-and-disk) arrays, column k D + d for disk d at knot k, and
        # picked by their flat index (point K D + column).
        n_knots = self.model.n_poses
        radii = np.tile(np.maximum(nlp.radii, MIN_ROW_SCALE), n_knots)          # (M, K D)
        inverse_radii = 1.0 / radii
        relief = np.tile(nlp.relief, n_knots)
        n_columns = radii.shape[1]
        columns = np.arange(n_columns)
        point_x, point_y = nlp.points[:, 0:1], nlp.points[:, 1:2]
        n_fixed = n_vars + n_linear
        # Which rows were active at the last answer: the next QP starts from them (a warm start of
        # the active set, kept per row by its point, knot and disk).
        row_state = np.zeros(radii.size, dtype=np.int8)
        fixed_state: np.ndarray | None = None
        buffer_slack = slack = 0.0
        point_slacks: np.ndarray | None = None
        status = "max_iter"
        iterations = 0
        previous: tuple[np.ndarray, np.ndarray, float] | None = None   # the last iterate, its QP's answer and step
        for iterations in range(1, self.max_iter + 1):
            if steps.late():
                return NLPOutcome(None, 0.0, 0.0, "deadline", iterations - 1, clock() - start_time, abandoned=True,
                                  longest_step=steps.finished())
            if data.ramp is not None:
                matrix, start, share = data.ramp
                reached = matrix @ layout.expand(knots.reshape(n, 2)) + start[:, None] * nlp.velocity[None, :]
                poses, jacobian = data.model.evaluate(reached, nlp.velocity)
                jacobian = jacobian.reshape(n_knots, 3, -1, 2)
                # A period depends on its block's command by its share and on the previous block's by the rest.
                own = np.add.reduceat(jacobian * share[:, None], layout.knots, axis=2)
                own[:, :, :-1] += np.add.reduceat(jacobian * (1.0 - share)[:, None], layout.knots, axis=2)[:, :, 1:]
                jacobian = own
            elif data.blocks:
                poses, jacobian = data.model.evaluate(layout.expand(knots.reshape(n, 2)), nlp.velocity)
                jacobian = np.add.reduceat(jacobian.reshape(n_knots, 3, -1, 2), layout.knots, axis=2)
            else:
                poses, jacobian = data.model.evaluate(knots, nlp.velocity)
            centres, centre_jacobian = self._centres(poses, jacobian.reshape(n_knots, 3, 2 * n))
            # Rows are (||c - o||^2 - r^2) / (2 r); their gradients (c - o) / r times the centre's Jacobian.
            # Per knot and disk the nearest point when it is within ROW_WINDOW, and the rows active at
            # the previous answer, go to the QP at once; any other row near enough to bind is added
            # when the answer violates it.
            if compiled is not None:
                centre_jacobian = plain(centre_jacobian)
                dx, dy, values, working, candidates = compiled.sqp_values(
                    plain(centres), point_array, inverse_radii, radii, row_state, ROW_WINDOW, CHECK_WINDOW)
                flat_values = values.ravel()
            else:
                dx, dy = centres[0] - point_x, centres[1] - point_y                         # (M, K D)
                values = dx * dx
                values += dy * dy
                values *= inverse_radii
                values -= radii
                values *= 0.5
                flat_values = values.ravel()
                working = row_state != 0
                if values.shape[0]:
                    nearest = np.argmin(values, axis=0) * n_columns + columns
                    working[nearest[flat_values[nearest] <= ROW_WINDOW]] = True
                candidates = flat_values <= CHECK_WINDOW
            answer = None
            for round_index in range(MAX_ROW_ROUNDS + 1):
                if round_index > 0 and steps.late():
                    return NLPOutcome(None, 0.0, 0.0, "deadline", iterations, clock() - start_time, abandoned=True,
                                      longest_step=steps.finished())
                if round_index == MAX_ROW_ROUNDS:
                    working |= candidates
                rows = np.flatnonzero(working)
                row_relief = relief.ravel()[rows]
                row_values = flat_values[rows]
                qp_columns, qp_slack_column = variables.select(rows // n_columns if n_groups > 1 else None)
                # The rows as the QP writes them, -gradient . x <= value - gradient . knots.
                matrix = np.empty((n_linear + rows.size, n_vars if qp_columns is None else qp_columns.size))
                matrix[:n_linear] = linear if qp_columns is None else linear[:, qp_columns]
                clearance = matrix[n_linear:, :2 * n]
                if compiled is not None:
                    row_upper = compiled.sqp_clearance_rows(rows, n_columns, centre_jacobian, dx, dy, inverse_radii,
                                                            relief, values, knots, matrix, n_linear, 2 * n,
                                                            qp_slack_column)
                else:
                    column = rows % n_columns
                    scale = inverse_radii.ravel()[rows, None]
                    np.multiply(centre_jacobian[0, column], dx.ravel()[rows, None] * -scale, out=clearance)
                    clearance -= centre_jacobian[1, column] * (dy.ravel()[rows, None] * scale)
                    matrix[n_linear:, 2 * n] = -row_relief
                    if n_groups > 1:
                        matrix[n_linear:, 2 * n + 1:] = 0.0
                        matrix[n_linear + np.arange(rows.size), qp_slack_column[rows // n_columns]] = -1.0
                    else:
                        matrix[n_linear:, 2 * n + 1] = -1.0
                    row_upper = row_values + np.einsum("rj,j->r", clearance, knots)
                guess = None if fixed_state is None else np.concatenate((variables.state(qp_columns, fixed_state),
                                                                          row_state[rows]))
                qp_hessian, qp_gradient, qp_lower, qp_upper = variables.restrict(
                    qp_columns, hessian, gradient, lower_bounds, upper_bounds)
                qp = QPData(qp_hessian, qp_gradient, matrix, np.concatenate((linear_high, row_upper)), qp_lower,
                            qp_upper, np.concatenate((linear_low, np.full(rows.size, -np.inf))), guess)
                outcome = self.qp.solve(qp)
                if outcome.x is None:
                    return NLPOutcome(None, 0.0, 0.0, f"QP failed ({outcome.status})", iterations,
                                      clock() - start_time, longest_step=steps.finished())
                answer, active = variables.expand(qp_columns, outcome.x, outcome.active)
                # Every row linearised at the answer, through the centres' displacement.
                move = answer[:2 * n] - knots
                slacks = answer[slack_column]                                           # (M,): each point's
                row_state = np.zeros(radii.size, dtype=np.int8)
                if active is not None:
                    fixed_state = active[:n_fixed]
                    row_state[rows] = active[n_fixed:]
                else:
                    row_state[rows] = (row_values - np.einsum("rj,j->r", clearance, move)
                                       + row_relief * answer[2 * n] + slacks[rows // n_columns]
                                       ) < ACTIVE_TOLERANCE
                if compiled is not None:
                    violated = compiled.sqp_violated(centre_jacobian, move, dx, dy, inverse_radii, values, relief,
                                                     float(answer[2 * n]), slacks, candidates, working, ROW_TOLERANCE,
                                                     n_groups > 1)
                else:
                    moved_x, moved_y = np.einsum("acj,j->ac", centre_jacobian, move)           # (K D,) each
                    linearised = dx * moved_x
                    linearised += dy * moved_y
                    linearised *= inverse_radii
                    linearised += values
                    linearised += relief * answer[2 * n] + slacks[:, None]
                    violated = candidates & (linearised.ravel() < -ROW_TOLERANCE)
                    violated &= ~working
                    if n_groups > 1 and violated.any():
                        violated = _most_missed_per_point(violated, linearised)
                if not violated.any():
                    break
                working |= violated
            step = answer[:2 * n] - knots
            change = float(np.max(np.abs(step)))
            linearised_at = knots
            knots = answer[:2 * n].copy()
            buffer_slack, slack = float(answer[2 * n]), float(np.max(answer[2 * n + 1:]))
            point_slacks = answer[slack_column].copy() if n_groups > 1 else None
            if change <= STEP_TOLERANCE:
                status = "converged"
                break
            if self.secant and previous is not None and iterations < self.max_iter:
                # Where the steps shrink slowly, or turn back round a cycle, the next linearisation point is where
                # the secant through this and the last iterate puts the fixed point. The next QP, linearised there,
                # makes the step that is checked for convergence, and the iterate returned is always a QP's answer.
                last_step = previous[1] - previous[0]
                ratio = change / previous[2]
                slow = change < ACCELERATION_WINDOW and ACCELERATION_RATIOS[0] < ratio <= ACCELERATION_RATIOS[1]
                cycling = CYCLE_RATIOS[0] < ratio < CYCLE_RATIOS[1] and float(step @ last_step) < CYCLE_COSINE * float(
                    np.linalg.norm(step) * np.linalg.norm(last_step))
                if slow or cycling:
                    knots = np.clip(knots + _secant_jump(step, last_step, knots - previous[1]),
                                    lower_bounds[:2 * n], upper_bounds[:2 * n])
            previous = (linearised_at, answer[:2 * n], change)
        return NLPOutcome(knots.reshape(n, 2), buffer_slack, slack, status, iterations, clock() - start_time,
                          point_slacks=point_slacks, longest_step=steps.finished())

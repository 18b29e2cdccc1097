"""Control-barrier-function QP safety filter built from lidar points.

Longer than most modules because the class docstring states the whole guarantee, row family by row
family, next to the code that enforces it; the families themselves live in
:mod:`safenav.filters.rows`, the QP back-ends in :mod:`safenav.filters.qp`.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass
from types import SimpleNamespace
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np

from safenav import _checks
from safenav.filters import kernels
from safenav.filters import rows as families
from safenav.filters.base import FilterResult, FilterStatus, Reason, SafetyFilter, View, _read_only, as_scans
from safenav.filters.body import BodyModel
from safenav.filters.deadline import StepClock
from safenav.filters.defaults import (
    BUDGET_FRACTION,
    default_gamma,
    default_margin,
    default_weights,
    lag_fraction,
    noise_allowance,
    reaction_time,
)
from safenav.filters.perception import nearest_per_bin
from safenav.filters.qp import DirectDAQP, QPBackend, QPData, QPOutcome, make_backend
from safenav.robot import RobotSpec
from safenav.scan import LaserScan

if TYPE_CHECKING:
    import qpsolvers

__all__ = ["CBFConfig", "CBFSafetyFilter"]

#: Tolerance of the filter's own check of a QP answer against every row [m/s]
#: (rows are barrier decrements per period divided by dt: 1e-6 m/s is 5e-8 m per 50 ms).
VERIFY_TOLERANCE = 1e-6
#: Regularisation of the auxiliary variables |v|, |omega| (keeps the Hessian positive definite).
AUX_REGULARISATION = 1e-9
#: Linear cost on the slack variable [s/m] (with slack_weight: an exact penalty in practice).
SLACK_LINEAR_WEIGHT = 1e3
#: The tiers of obstacle rows a slack may relax, in order: the rows of remembered points located
#: worse than the margin (odometry uncertainty > margin), then also those of points already inside
#: the margin, then every obstacle row. A tier is relaxed only when no command in the box keeps
#: every row of the later tiers: a point the filter can no longer place, or one it is already too
#: close to, never buys its recovery by relaxing the rows of the points the body is still clear of.
SLACK_TIERS = ("lost", "inside", "outside")
_BARRIER = families.FAMILIES.index("barrier")
#: Look-ahead distance [m] of the single-disk model (steering authority vs 2 l of conservatism head-on).
DEFAULT_LOOKAHEAD = 0.1
#: Room [m] the longer look-ahead's own barrier needs, over every point of a call, before it is tried
#: again after a narrow passage (hysteresis).
LOOKAHEAD_ROOM = 0.05
#: A row within this of its bound at the answer is active [m/s] (it moved the command; the result's active points).
ACTIVE_TOLERANCE = 1e-6
MAX_GENERATION_ROUNDS = 8
"""Rounds of constraint generation before the QP takes every candidate row."""
#: Upper limit on the rows a QP takes at once (one solve, no generation rounds); a back-end may
#: ask for fewer (:attr:`~safenav.filters.qp.QPBackend.direct_rows`).
DIRECT_ROWS = 512
BODIES = ("disk", "polygon", "cover")


@dataclass(frozen=True)
class CBFConfig:
    """Settings of :class:`CBFSafetyFilter`; ``None`` means "derive from the robot" (:meth:`resolve`).

    Attributes:
        gamma: decay of the discrete-time barrier condition, in (0, 1]; default ``min(1, a_max dt / v_max)``.
        far_gamma: largest fraction of its own barrier any point may lose per period, in
            (0, 1]; default 1 (only the minimum condition). ``far_gamma = gamma`` gives the
            classic point-wise condition ``h(o, x+) >= (1 - gamma) h(o, x)``, which the filter
            always uses when the velocity is given (acceleration limits).
        margin: clearance kept between the body and every obstacle point [m]; default
            ``0.02 m + 2 noise_std + 1 m x angle_increment``.
        lookahead: distance of the control points ahead of the disk centres [m]; default
            0.1 m for the single disk (whose centre turning does not move), 0 for a cover.
        min_lookahead: the look-ahead of a narrow passage [m] (while ``passage`` is set: a door or
            corridor narrower than ``2 (R + margin + lookahead)``); default 0. Switching to a
            shorter look-ahead never lowers a barrier, so it is always safe; the filter switches
            back once the longer one's answer needs no relaxation (see :class:`CBFSafetyFilter`,
            "Look-ahead"). ``min_lookahead = lookahead`` keeps one look-ahead.
        body: ``"disk"`` (the circumscribed disk), ``"polygon"`` (the exact convex footprint) or
            ``"cover"`` (``n_disks`` disks covering the footprint).
        narrow_body: a narrower body model (``"cover"``, the default, or ``"polygon"``) for the rows
            while :attr:`~safenav.filters.SafetyFilter.narrow` is set (the escape sets it while it drives
            through a gap the body does not fit), with no look-ahead; ``None``: none. Its rows
            guarantee the footprint as the body's do; the filter switches to it, and back, only to an
            answer that needs no relaxation (see :class:`CBFSafetyFilter`, "Narrow body"). A round
            robot (no footprint), or a model no narrower than ``body``, gives none.
        n_disks: disks of the cover (default 3).
        solver: QP back-end name (``"daqp"``, ``"quadprog"``, ``"osqp"``, any qpsolvers solver;
            case-insensitive).
        weights: cost weights on the ``(v, omega)`` deviations [s^2/m^2, s^2/rad^2];
            default ``(1 / v_max^2, 0.2 / omega_max^2)``.
        max_gap: widest run of invalid beams bridged by its neighbours [rad]; wider runs are unknown.
        side_tolerance: unknown space this close to exactly sideways does not block motion [rad].
        n_bins: angular bins of the initial working set (nearest point per bin).
        slack_weight: quadratic cost on the relaxation of the obstacle rows (in m/s) when no
            command satisfies them all; with the linear cost of 1e3 it acts as an exact penalty [s^2/m^2].
        time_constant: first-order lag of the base's velocity loop the filter allows for [s]
            (0: the base reaches each command within the period, at once, linearly or at its
            acceleration limit). Needs ``velocity`` at each call.
        memory_range: remembered points farther than this are forgotten [m] (default: reach + 1 m).
        memory_capacity: largest number of remembered points.
        smoothing: weight of the change from the previous command in the QP's cost, relative to
            the change from the nominal (0 = none); it damps chatter when the filter intervenes and
            changes neither the feasible set nor the answer when ``u_nom`` is safe.
        deadlock_time: how long the commands may stall while the nominal asks to move before the
            result reports a deadlock [s] (see :class:`~safenav.filters.base.Deadlock`).
        scan_timeout: scans older than this make the filter brake [s].
        compensate_latency: move a scan of known age into the current base frame first
            (see :meth:`SafetyFilter.latent_motion`).
        min_obstacle_width: the narrowest obstacle [m] the filter must see in time to brake clear of
            (``None``: whatever the lidars resolve where the robot must see an obstacle,
            :attr:`~safenav.filters.SafetyFilter.smallest_obstacle`). Thinner obstacles can hide
            between two beams until they are near; when this is smaller, the filter keeps able to stop
            within the range where a beam must hit one (it drives slower).
        kernels: how the obstacle rows of the disk and cover bodies are built: ``"auto"`` (compiled by
            numba when it is installed, ``pip install "safenav[fast]"``), ``"numba"`` (compiled; raises
            :class:`~safenav.errors.MissingDependency` without numba) or ``"numpy"`` (the reference;
            :mod:`safenav.filters.kernels`). The same rows to rounding either way.
        budget: compute budget of one call [s] (``math.inf``: none); default ``BUDGET_FRACTION * dt``
            (:data:`~safenav.filters.defaults.BUDGET_FRACTION` = 0.5, as the MPC's). A QP that could not
            end within it (:mod:`safenav.filters.deadline`) is not begun: the filter brakes at the
            acceleration limits (status ``FALLBACK``, reason ``deadline``). With a budget the answers
            depend on the machine's load (a call preempted past it brakes); sweeps that compare filters
            run without one (:func:`safenav.experiments.runner.reproducible_settings`).
    """

    gamma: float | None = None
    far_gamma: float | None = None
    margin: float | None = None
    lookahead: float | None = None
    min_lookahead: float = 0.0
    body: str = "disk"
    narrow_body: str | None = "cover"
    n_disks: int = 3
    solver: str = "daqp"
    weights: tuple[float, float] | None = None
    max_gap: float = math.radians(5.0)
    side_tolerance: float = math.radians(5.0)
    n_bins: int = 36
    slack_weight: float = 1e4
    time_constant: float = 0.0
    memory_range: float | None = None
    memory_capacity: int = 4000
    smoothing: float = 0.0
    deadlock_time: float = 1.5
    scan_timeout: float = 0.5
    compensate_latency: bool = True
    min_obstacle_width: float | None = None
    kernels: str = "auto"
    budget: float | None = None

    def __post_init__(self) -> None:
        name = "CBFConfig."
        if self.gamma is not None:
            _checks.number(name + "gamma", self.gamma, low=0.0, high=1.0, low_open=True)
        if self.far_gamma is not None:
            _checks.number(name + "far_gamma", self.far_gamma, low=0.0, high=1.0, low_open=True)
        if self.margin is not None:
            _checks.number(name + "margin", self.margin, low=0.0, high=10.0)
        if self.lookahead is not None:
            _checks.number(name + "lookahead", self.lookahead, low=0.0, high=10.0)
        _checks.number(name + "min_lookahead", self.min_lookahead, low=0.0, high=10.0)
        _checks.choice("CBF body model", self.body, BODIES)
        if self.narrow_body is not None:
            _checks.choice("CBF narrow body model", self.narrow_body, BODIES)
        _checks.integer(name + "n_disks", self.n_disks, low=1, high=16)
        if not isinstance(self.solver, str):
            raise _checks.InvalidConfig(f"{name}solver must be a solver name, got {self.solver!r}")
        if self.weights is not None:
            _checks.pair(name + "weights", self.weights, low=0.0, low_open=True)
        _checks.number(name + "max_gap", self.max_gap, low=0.0, high=2 * math.pi)
        _checks.number(name + "side_tolerance", self.side_tolerance, low=0.0, high=0.5 * math.pi)
        _checks.integer(name + "n_bins", self.n_bins, low=1)
        _checks.number(name + "slack_weight", self.slack_weight, low=1.0, high=1e12)
        _checks.number(name + "time_constant", self.time_constant, low=0.0, high=1.0)
        if self.memory_range is not None:
            _checks.positive(name + "memory_range", self.memory_range)
        _checks.integer(name + "memory_capacity", self.memory_capacity, low=0)
        _checks.number(name + "smoothing", self.smoothing, low=0.0, high=100.0)
        _checks.positive(name + "deadlock_time", self.deadlock_time)
        _checks.duration(name + "scan_timeout", self.scan_timeout, high=1e9)
        _checks.boolean(name + "compensate_latency", self.compensate_latency)
        if self.min_obstacle_width is not None:
            _checks.positive(name + "min_obstacle_width", self.min_obstacle_width)
        _checks.choice("CBF kernels", self.kernels, kernels.KERNELS)
        if self.budget is not None:
            _checks.number(name + "budget", self.budget, low=0.0, low_open=True, finite=False)

    def resolve(self, robot: RobotSpec, dt: float) -> CBFConfig:
        """This config with every robot-derived default filled in (see :mod:`safenav.filters.defaults`)."""
        gamma = self.gamma if self.gamma is not None else default_gamma(robot, dt)
        # The polygon and the cover steer without a look-ahead: their points off the base origin move
        # sideways when the robot turns.
        lookahead = self.lookahead if self.lookahead is not None else (
            DEFAULT_LOOKAHEAD if self.body == "disk" or robot.footprint is None else 0.0)
        return dataclasses.replace(
            self,
            gamma=gamma,
            far_gamma=max(gamma, self.far_gamma if self.far_gamma is not None else 1.0),
            margin=self.margin if self.margin is not None else default_margin(robot),
            lookahead=lookahead,
            min_lookahead=min(self.min_lookahead, lookahead),
            narrow_body=self.narrow_body if self.narrow_body is not None and robot.footprint is not None and (
                body_model(self.narrow_body, robot, self.n_disks).half_width
                < body_model(self.body, robot, self.n_disks).half_width) else None,
            weights=tuple(self.weights) if self.weights is not None else default_weights(robot),
            solver=self.solver.lower(),
            budget=self.budget if self.budget is not None else BUDGET_FRACTION * dt,
        )


def body_model(name: str, robot: RobotSpec, n_disks: int = 3) -> BodyModel:
    """The body model ``name`` (one of :data:`BODIES`) of ``robot``; a cover has ``n_disks`` disks."""
    if name == "cover":
        return BodyModel.cover(robot, n_disks)
    return BodyModel.polygon(robot) if name == "polygon" else BodyModel.disk(robot)


class _Shape(NamedTuple):
    """A body model with its control points ``lookahead`` ahead, as the rows use it."""

    body: BodyModel
    polygon: np.ndarray | None          # the footprint polygon of the exact barrier, else None
    lookahead: float                    # [m]
    arm: float                          # the farthest control point (or polygon vertex) from the base origin [m]
    extent: tuple[float, float]         # bounds of the cut before any trigonometry [m]
    control: np.ndarray | None = None   # (D, 2) the disks' control points [m] (disk bodies; the compiled rows)
    offsets: np.ndarray | None = None   # (D,) radius + look-ahead + margin of each disk [m] (likewise)


class _OutOfTime(Exception):
    """The next QP of a call could not end within its compute budget (caught within the call: it brakes)."""


class _Problem(NamedTuple):
    """Everything one call constrains: the rows, their points, the box on ``z``, and the barrier values."""

    rows: families.Rows
    points: np.ndarray          # (N, 2) obstacle points the pairs refer to
    barrier: np.ndarray         # (N,) smallest barrier of each point over the disks [m]
    uncertainty: np.ndarray     # (N,) position uncertainty of each point (remembered ones) [m]
    min_barrier: float
    lower: np.ndarray           # (4,) bounds on z
    upper: np.ndarray
    velocity: np.ndarray | None
    limits: tuple[np.ndarray, np.ndarray]   # the command's box (velocity limits and reachability)
    clearance: float            # distance from the body to the nearest point [m]
    blind_speed: float          # largest speed towards a side no lidar sees [m/s] (seen_travel)


class CBFSafetyFilter(SafetyFilter):
    """Minimal change of ``(v, omega)`` that keeps the body clear of every lidar point.

    **Barrier.** The body is one disk (radius ``R``, the circumscribed disk of the footprint)
    or a cover of the footprint by ``n_disks`` disks (``body="cover"``). For each disk ``j``,
    control point ``p_j`` (its centre plus the look-ahead ``l`` along the heading) and
    obstacle point ``o`` of the scans or of the memory (base frame, taken as static over one
    period)::

        h_j(o) = ||p_j - o|| - (rho_j + l + margin + e_o),        H = min over j, o

    ``H >= 0`` implies every disk, hence the footprint they cover, keeps ``margin`` from every
    point (``e_o`` is a remembered point's odometry uncertainty). A control point off the
    base origin moves with both ``v`` and ``omega``, so the filter can steer as well as brake;
    the look-ahead of the single disk costs up to ``2 l`` of extra distance head-on.

    **Look-ahead.** Two look-aheads, ``lookahead`` and ``min_lookahead`` (default 0): each answer is
    built with the rows of one of them (the attribute :attr:`lookahead` is the one of the last
    answer). A shorter look-ahead never lowers a pair's barrier (the control point moves back by
    the difference, the radius shrinks by it), so switching to it is safe at any call: the filter
    does so while :attr:`~safenav.filters.base.SafetyFilter.passage` is set (the escape sets it
    while it drives through a gap the body fits, a door narrower than ``2 (R + lookahead +
    margin)``), and the reason then ends "look-ahead 0 m (a narrow passage)". It switches back only
    to an answer with status ``OK``/``LATE`` (``H >= 0`` for the longer barrier, no relaxation),
    tried once the flag is cleared and the longer look-ahead's own barrier over the call's points is at
    least ``LOOKAHEAD_ROOM``.

    **Narrow body.** The circumscribed disk of a long robot is much wider than its footprint (the
    m2wr's 0.292 m radius against its 0.15 m half-width). While
    :attr:`~safenav.filters.base.SafetyFilter.narrow` is set (the escape sets it while it drives
    through a gap the disk does not fit) the rows are built from ``narrow_body`` (default the cover
    of the footprint by ``n_disks`` disks, no look-ahead; :attr:`rows_body` says which), tried from
    the shorter look-ahead once its own barrier has ``LOOKAHEAD_ROOM`` and taken only for an answer
    with status ``OK``/``LATE`` (its ``H >= 0`` then, so the barrier condition holds from there on
    for that body), and left, once the flag is cleared, for the disk when the disk's own barrier is
    not negative and its answer too is ``OK``/``LATE``. Either body covers
    the footprint, so either keeps the footprint ``margin`` from every point. The cover's end
    disks reach past the circumscribed disk along the heading: the stopping reach, the horizon
    and the memory are measured from the farther (:attr:`~safenav.filters.SafetyFilter.reach`); the
    unknown region stays measured from the body's outline (the disk contains the footprint).

    **Rows, by family** (:mod:`safenav.filters.rows`, each with its invariant):
    ``barrier`` (the discrete-time condition ``H(x+) >= (1 - gamma) H(x)``, with the arc of
    the period bounded exactly through auxiliaries ``t_v >= |v|``, ``t_omega >= |omega|``);
    with ``velocity`` given, ``braking`` (one period of reaction plus the lag, then the speed
    braking at ``a_max`` and the yaw rate at ``alpha_max``, must stop within each barrier) and ``sweep`` (speed along
    the heading capped for points the heading can still swing towards while braking), each
    written for every mean velocity a base between the current velocity and the command can
    have (:func:`~safenav.filters.rows.ramp_corners`); ``gap`` (no part of the outline moves
    towards a run of invalid beams) and ``blind`` (no translation towards a side no lidar
    sees, beyond what earlier scans saw free there: :meth:`seen_travel`); and the command box
    (velocity limits, reachable within one period). Only the
    obstacle families (``barrier``, ``braking``, ``sweep``) are *soft*: when no command
    satisfies every row, one slack relaxes them in tiers (:data:`SLACK_TIERS`: the rows of
    remembered points located worse than the margin; then those of points already inside the
    margin, first only held at "not approached", status ``RECOVERING``; then every obstacle
    row, status ``SLACK``), each tier only when no command keeps the later ones; the
    unknown-region rows and the box are hard, and when they cannot all hold the base brakes at
    its limits (status ``BRAKING``). A pair already inside the margin is left at its own rate
    ``h(x+) >= (1 - gamma) h(x)``, whatever the smallest barrier; with ``velocity`` every pair
    keeps its own rate (``far_gamma`` at most ``gamma``), so that a point is never approached
    faster than the base can slow down to once it becomes the nearest.

    **Unknown region and memory** (:mod:`safenav.filters.perception`). Unknown space is
    never free. It is measured from the body's outline and each lidar's mount, not from the
    laser origin. Points that leave every field of view (beside and behind the m2wr's
    180-degree lidar, which sits 0.15 m ahead of the base origin) are carried in the base
    frame by odometry (``pose``, else the measured ``velocity``, else the commands returned)
    and stay obstacles while within ``memory_range`` and not contradicted by a current beam.

    **Defaults derived from the robot** (:meth:`CBFConfig.resolve`). ``gamma = min(1, a_max
    dt / v_max)``: a head-on exponential approach at full speed brakes at ``a_max`` at most.
    ``margin = 0.02 m + 2 noise_std + 1 m x angle_increment``. Weights ``(1 / v_max^2,
    0.2 / omega_max^2)``: steering is preferred to braking.

    **Guarantee.** Stated in full, with its assumptions, in ``docs/safety.md``: if the world is
    static, every obstacle at least :attr:`smallest_obstacle` wide (the beam gap 1 m away, or where
    the robot must see an obstacle to brake clear of it) is seen within ``2 noise_std``
    by some lidar before the body comes within ``margin`` of it (the part of the body's blind
    region it sweeps was clear when the filter started, or was seen before it got there), the
    base holds each command for at most the period (``dt``, or the measured period when calls
    are late and ``now`` is given) and its velocity over the period stays between the current
    velocity and the command with a mean at most ``lag_fraction`` of the way back (any base
    that reaches each command within the period; a first-order lag up to ``time_constant``),
    and ``H >= 0`` at the start, then with status ``OK``/``LATE`` the new ``H`` is at least
    ``(1 - gamma) H`` (``H`` of the look-ahead the answer used): the body keeps ``margin`` from
    every point seen or remembered.
    Returned commands always respect the velocity limits, the acceleration limits (with
    ``velocity``) and every hard row.

    **Minimal intervention.** When ``u_nom`` satisfies every row and the box it is returned
    unchanged (bit for bit) and no QP is solved. Otherwise the QP minimises the weighted
    distance to ``u_nom`` clipped to the velocity limits.

    **Reduction (exact).** A point is skipped only when no row of any family built from it
    can bind for any command in the box: its barrier exceeds what the barrier rows
    (``(1 - gamma) H + dt S``) and the braking rows (``S T + S^2 / (2 a_max)``) can reach at
    the largest approach speed ``S`` the box allows. Rows no command in the box can violate
    are dropped; the QP starts from the nearest point per angular bin and adds any violated
    row until none is (constraint generation), so the answer is that of the QP with every
    row of every point. A row that no command in the box keeps (its smallest left side over the
    box above its right side) means that QP has no answer: the slack tiers follow without
    solving it. Every answer is verified against every row.

    **Deadline.** A call has a compute budget (``budget`` [s], default ``BUDGET_FRACTION = 0.5`` of
    ``dt``; ``math.inf``: none), counted from the call's start. Before each QP (the first, every
    round of constraint generation, every slack tier) the filter checks that the QP, lasting as
    long as the longest QP of its recent calls or of this call (at most, and until one has been
    timed, a quarter of the budget), can end before the budget less a reserve for the verification
    and the result (as long as the recent calls' took, at most, and until timed, a quarter;
    :mod:`safenav.filters.deadline`); when it cannot, it brakes at the acceleration limits (status
    ``FALLBACK``, reason ``deadline``). Its answers are otherwise those without a budget; the fast
    path solves nothing and is never cut short. A call ends within its budget unless the
    perception already takes it, a QP takes longer than that estimate, or the verification and
    result longer than the reserve.

    Args:
        robot: the robot to protect.
        dt: control period [s]: the longest time a command is held (at most 1 s).
        config: settings; keyword arguments override its fields.
        clock: the clock the compute budget is measured with [s] (default ``time.perf_counter``;
            a simulated clock in tests).
    """

    name = "cbf"

    def __init__(self, robot: RobotSpec, dt: float = 0.05, *, config: CBFConfig | None = None,
                 clock: Callable[[], float] | None = None, **overrides: Any):
        base_config = CBFConfig(**{**(config.__dict__ if config else {}), **overrides})
        dt = _checks.duration("dt", dt, high=1.0)
        self.config = base_config.resolve(robot, dt)
        cfg = self.config
        self.margin = float(cfg.margin)
        self._allowance = noise_allowance(robot, self.margin)
        body = body_model(cfg.body, robot, cfg.n_disks)
        narrow = None if cfg.narrow_body is None else body_model(cfg.narrow_body, robot, cfg.n_disks)
        super().__init__(robot, dt, body=body, other_bodies=() if narrow is None else (narrow,),
                         scan_timeout=cfg.scan_timeout,
                         compensate_latency=cfg.compensate_latency, max_gap=cfg.max_gap,
                         side_tolerance=cfg.side_tolerance, memory_range=cfg.memory_range,
                         memory_capacity=cfg.memory_capacity, time_constant=cfg.time_constant,
                         deadlock_time=cfg.deadlock_time, min_obstacle_width=cfg.min_obstacle_width,
                         budget=cfg.budget, clock=clock)
        self.gamma = float(cfg.gamma)
        self.far_gamma = float(cfg.far_gamma)
        self._P = np.diag([cfg.weights[0], cfg.weights[1], AUX_REGULARISATION, AUX_REGULARISATION])
        self._P_slack = np.diag([*np.diag(self._P), cfg.slack_weight])     # with the slack variable last
        self._abs_rows = families.abs_rows()
        self._shapes = {"long": self._shape_of(body, float(cfg.lookahead)),
                        "short": self._shape_of(body, float(cfg.min_lookahead))}
        if narrow is not None:
            self._shapes["narrow"] = self._shape_of(narrow, 0.0)
        self._use("long")
        self.backend: QPBackend = make_backend(cfg.solver)
        self._steps: StepClock | None = None     # this call's QPs against the budget
        self._ready(cfg.kernels)
        #: The decision's array work (_screen, _qp_rows, _violated, _answer, _stage): compiled, or numpy.
        self._decide = self._kernels if self._kernels is not None else _NUMPY_DECISION
        if isinstance(self.backend, DirectDAQP):
            self.backend.kernels = self._kernels

    def _shape_of(self, body: BodyModel, lookahead: float) -> _Shape:
        """``body`` with its control points ``lookahead`` ahead [m], the farthest of them from the base origin
        [m] and the bounds of the cut before any trigonometry (:meth:`_constraints`)."""
        if body.name == "polygon":
            polygon = body.outline
            vertices = np.hypot(polygon[:, 0], polygon[:, 1])
            edge = np.roll(polygon, -1, axis=0) - polygon
            normal = np.column_stack((edge[:, 1], -edge[:, 0])) / np.hypot(edge[:, 0], edge[:, 1])[:, None]
            inradius = float(np.min(np.einsum("ij,ij->i", normal, polygon)))   # origin to the nearest edge
            arm = float(vertices.max())          # the farthest body point [m]
            # Bounds for the cut before any trigonometry: H <= |o_min| - inradius - margin, h(o) >= |o| - R - margin.
            return _Shape(body, polygon, lookahead, arm, (-inradius - self.margin, arm + self.margin))
        control = body.centres + np.array([lookahead, 0.0])
        control_distance = np.hypot(control[:, 0], control[:, 1])
        radius = body.radii + lookahead + self.margin
        # Bounds for the cut before any trigonometry: H <= |o_min| + max(|p| - r); h(o) >= |o| - max(|p| + r).
        return _Shape(body, None, lookahead, float(np.max(control_distance)),
                      (float(np.max(control_distance - radius)), float(np.max(control_distance + radius))),
                      np.ascontiguousarray(control, dtype=float),
                      np.ascontiguousarray(body.radii + (lookahead + self.margin), dtype=float))

    def _use(self, shape: str) -> None:
        """Build the rows of the following calls with the body and look-ahead of ``shape``
        (``"long"``, ``"short"`` or ``"narrow"``, see :meth:`_filter`)."""
        self._shape_name = shape
        self._shape = self._shapes[shape]
        self.lookahead = self._shape.lookahead
        self._polygon, self._arm, self._extent = self._shape.polygon, self._shape.arm, self._shape.extent

    @property
    def narrowed(self) -> bool:
        return self._shape_name == "narrow"

    @property
    def rows_body(self) -> BodyModel:
        """The body model of the last answer's rows: :attr:`body`, or ``narrow_body`` in a narrow gap."""
        return self._shape.body

    def __repr__(self) -> str:
        return (f"CBFSafetyFilter(robot={self.robot.name!r}, dt={self.dt}, body={self.body.name!r}, "
                f"gamma={self.gamma:.4f}, margin={self.margin:.4f}, lookahead={self.lookahead:.4f}, "
                f"solver={self.backend.name!r})")

    @property
    def kappa(self) -> float:
        """Arc coefficient ``omega_max dt / 2`` of the nominal period."""
        return 0.5 * self.robot.omega_max * self.dt

    # ------------------------------------------------------------------ constraints

    def _constraints(self, view: View, velocity: np.ndarray | None, period: float, *, cut: bool = True,
                     u_nom: np.ndarray | None = None) -> _Problem:
        """Every row of every family, from every point that can matter (every point with ``cut=False``)."""
        robot, body = self.robot, self._shape.body
        lower, upper = robot.velocity_bounds(self.command_origin(velocity), period if velocity is not None else None)
        # The heading turns within the period at most at the fastest yaw rate of the box (and of the
        # current velocity): the arc coefficient of every row uses that rate, not omega_max.
        turn = max(abs(float(lower[1])), abs(float(upper[1])))
        if velocity is not None:
            turn = max(turn, abs(float(velocity[1])))
        kappa = 0.5 * turn * period
        t_low = np.abs(velocity) if velocity is not None else np.zeros(2)
        t_high = np.maximum(np.maximum(np.abs(lower), np.abs(upper)), t_low)
        z_lower, z_upper = np.concatenate((lower, t_low)), np.concatenate((upper, t_high))    # the box on z
        time_constant = self.time_constant if velocity is not None else 0.0
        reaction = reaction_time(period, time_constant)
        # Rows leave the travel along the heading free where a point allows it (rows.slide): one period's
        # travel, or with the velocity the braking distance, since every pair then keeps its own rate
        # (_own_rate) and a wall ahead-beside would otherwise be approached, point by point, at that rate.
        speed = max(abs(float(lower[0])), abs(float(upper[0])))
        travel = speed * period if velocity is None else speed * reaction + speed * speed / (2.0 * robot.a_max)
        geo, per_point, obstacle = None, np.empty(0), families.stack()
        if self._kernels is not None and cut and self._polygon is None:
            obstacle, points, uncertainty, per_point, min_barrier, clearance = self._compiled_rows(
                view, velocity, (lower, upper), (z_lower, z_upper), period, reaction, kappa, travel)
        else:
            points, uncertainty, clearance, cut_barrier = self._cut(view, velocity, (lower, upper), period, reaction,
                                                                    cut)
            min_barrier = cut_barrier
            if points.shape[0]:
                tilt = dict(drop=cut, floor_ratio=1.0 - self.gamma, travel=travel)
                if self._polygon is not None:
                    kept_distance = np.sqrt(points[:, 0] ** 2 + points[:, 1] ** 2)

                    def polygon_limit(smallest: float) -> np.ndarray:
                        return self._binding_reach(lower, upper, velocity, smallest, period, reaction, kept_distance)

                    geo, per_point = families.polygon_geometry(points, uncertainty, self._polygon, self.margin,
                                                               kappa, polygon_limit, **tilt)
                else:
                    def limit(smallest: float) -> float:
                        return self._binding_reach(lower, upper, velocity, smallest, period, reaction)

                    geo, per_point = families.geometry(points, uncertainty, body.centres, body.radii, self.lookahead,
                                                       self.margin, kappa, limit, **tilt)
                min_barrier = min(float(per_point.min()), cut_barrier)
        if geo is not None and geo.point.size:   # else compiled, or no point within the reach of any row
            barrier = families.barrier_rows(geo, self.gamma, self._own_rate(velocity), period, smallest=min_barrier)
            obstacle = barrier
            if velocity is not None:
                # The braking and sweep rows can bind only within the braking reach (their right side, the
                # stopping speed, exceeds every approach speed the box allows beyond it).
                pair_distance = 0.0 if self._polygon is None else np.sqrt(points[geo.point, 0] ** 2 +
                                                                          points[geo.point, 1] ** 2)
                near = geo.barrier + self._allowance <= self._braking_reach(lower, upper, velocity, period, reaction,
                                                                            pair_distance)
                close = families.Geometry(*(array[near] for array in geo)) if not near.all() else geo
                braking = families.braking_rows(close, robot.a_max, robot.alpha_max, reaction, self._allowance,
                                                box=(lower, upper))
                sweep = families.sweep_rows(close, velocity, robot.a_max, robot.alpha_max, period, reaction,
                                             self._allowance)
                obstacle = families.stack(barrier, braking, sweep)
                obstacle = families.ramp_corners(obstacle, velocity, lag_fraction(period, time_constant), self.gamma,
                                                 box=(z_lower, z_upper), reduce=cut)
        frontier = view.frontier
        blind_speed = 0.0
        if frontier.points.shape[0] or frontier.forward or frontier.backward:
            # The unknown region is the perception body's outline (self.body), whatever body the rows use.
            gap = families.gap_rows(frontier.points, frontier.normals, self.side_tolerance, self.body.reach)
            blind_speed = self._blind_speed(view, (lower, upper), velocity, period, reaction, u_nom)
            hard = families.stack(gap, families.blind_rows(frontier.forward, frontier.backward, blind_speed))
            rows = families.stack(obstacle, hard)
        else:
            rows = obstacle
        return _Problem(rows, points, per_point, uncertainty, min_barrier, z_lower, z_upper, velocity, (lower, upper),
                        clearance, blind_speed)

    def _cut(self, view: View, velocity: np.ndarray | None, box: tuple[np.ndarray, np.ndarray], period: float,
             reaction: float, cut: bool) -> tuple[np.ndarray, np.ndarray, float, float]:
        """The points that can matter (every point without ``cut``) and their uncertainty, the body's clearance [m]
        and the smallest barrier of the points the cut leaves out [m] (``inf`` when it leaves none out)."""
        points, uncertainty = view.points, view.uncertainty
        distance = np.sqrt(points[:, 0] ** 2 + points[:, 1] ** 2)
        clearance = self._clearance(points, distance)
        cut_barrier = math.inf
        if cut and points.shape[0]:
            # Before any trigonometry: a point farther from the base than the reach of every row plus the
            # body's extent cannot bind (its barrier is at least |o| - |p| - r, and H at most |o_min| + |p| - r).
            lower, upper = box
            ceiling = float(np.min(distance - uncertainty)) + self._extent[0]
            reach = self._binding_reach(lower, upper, velocity, ceiling, period, reaction, distance)
            near = distance - uncertainty <= reach + self._extent[1]
            if not near.all():
                # H is reported over every point. The point that sets it is within the ceiling plus the extent;
                # when the cut leaves it out, no kept row can bind either, whichever H it is written with.
                left_out = ~near & (distance - uncertainty <= ceiling + self._extent[1])
                if left_out.any():
                    cut_barrier = self._shape.body.barrier(points[left_out], self.margin, uncertainty[left_out],
                                                           self.lookahead)
                points, uncertainty = points[near], uncertainty[near]
        return points, uncertainty, clearance, cut_barrier

    def _compiled_rows(self, view: View, velocity: np.ndarray | None, box: tuple[np.ndarray, np.ndarray],
                       z_box: tuple[np.ndarray, np.ndarray], period: float, reaction: float, kappa: float,
                       travel: float) -> tuple[families.Rows, np.ndarray, np.ndarray, np.ndarray, float, float]:
        """What :meth:`_cut` and the numpy branch of :meth:`_constraints` give for the disk bodies with the cut, by
        :mod:`~safenav.filters.kernels`: the obstacle rows, the kept points and their uncertainty, every kept point's
        smallest barrier, ``H`` [m] and the body's clearance [m]."""
        compiled, shape = self._kernels, self._shape
        body, (lower, upper) = shape.body, box
        points, uncertainty = kernels.plain(view.points), kernels.plain(view.uncertainty)
        # the reach's parts that do not depend on the barrier, once (_binding_reach)
        approach = period * self._approach_bound(lower, upper, velocity, period)
        braking_reach = self._braking_reach(lower, upper, velocity, period, reaction) if velocity is not None else None
        centred = body.n_disks == 1 and not body.centres.any()
        spread = 0.0 if centred else float(np.max(np.hypot(body.centres[:, 0], body.centres[:, 1])))
        distance, ceiling, clearance = compiled.cbf_distances(points, uncertainty, body.centres, body.radii, centred,
                                                              spread)
        if not points.shape[0]:
            return families.stack(), points, uncertainty, np.empty(0), math.inf, clearance
        ceiling += self._extent[0]
        reach = self._reach(ceiling, approach, velocity, braking_reach)
        kept, kept_uncertainty, every, cut_barrier = compiled.cbf_cut(
            points, uncertainty, distance, reach + self._extent[1], ceiling + self._extent[1], body.centres,
            body.radii, float(self.lookahead), float(self.margin))
        if not every:
            points, uncertainty = kept, kept_uncertainty
        if not points.shape[0]:
            return families.stack(), points, uncertainty, np.empty(0), cut_barrier, clearance
        per_point = compiled.pair_minima(points, uncertainty, shape.control, shape.offsets)
        smallest = float(per_point.min())
        limit = float(self._reach(smallest, approach, velocity, braking_reach))
        min_barrier = min(smallest, cut_barrier)
        with_velocity = velocity is not None
        if with_velocity:
            lag = lag_fraction(period, self.time_constant)
            moving = kernels.plain(velocity)
        else:
            braking_reach, lag, moving = 0.0, 0.0, np.zeros(2)
        robot = self.robot
        # every scalar a float and every array plain: one compiled specialisation, no compilation in a control call
        G, h, point, family = compiled.obstacle_rows(
            points, uncertainty, shape.control, shape.offsets, per_point, limit, float(1.0 - self.gamma),
            float(travel), float(kappa), float(self.gamma), float(self._own_rate(velocity)), float(period),
            float(min_barrier), with_velocity, moving, float(robot.a_max), float(robot.alpha_max), float(reaction),
            float(self._allowance), float(braking_reach), kernels.plain(lower), kernels.plain(upper), float(lag),
            kernels.plain(z_box[0]), kernels.plain(z_box[1]))
        return families.Rows(G, h, point, family), points, uncertainty, per_point, min_barrier, clearance

    def _blind_speed(self, view: View, box: tuple[np.ndarray, np.ndarray], velocity: np.ndarray | None,
                     period: float, reaction: float, u_nom: np.ndarray | None) -> float:
        """Largest speed [m/s] towards a side no lidar sees: the base stops within the space earlier scans saw
        free that side (:meth:`seen_travel`), after ``reaction`` [s] at that speed, less what the period may
        still carry it the other way first (at most the current speed, ``velocity`` or the last command, for
        ``period`` [s]). Zero unless ``u_nom`` asks to move that way (the filter never moves towards a side no
        lidar sees of its own accord) and the command ``box`` reaches it (a base driving away from it faster
        than one period's braking needs none)."""
        frontier, (lower, upper) = view.frontier, box
        if u_nom is None or not ((frontier.backward and u_nom[0] < 0.0 and lower[0] < 0.0) or
                                 (frontier.forward and u_nom[0] > 0.0 and upper[0] > 0.0)):
            return 0.0
        origin = self.command_origin(velocity)
        away = 0.0 if origin is None else abs(float(origin[0]))
        travel = self.seen_travel(view) - away * period
        if travel <= 0.0:
            return 0.0
        a_max = self.robot.a_max
        return a_max * (math.sqrt(reaction * reaction + 2.0 * travel / a_max) - reaction)

    def _clearance(self, points: np.ndarray, distance: np.ndarray) -> float:
        """Distance from the body to the nearest point [m] (``distance``: each point's from the base)."""
        if points.shape[0] == 0:
            return math.inf
        body = self._shape.body
        if self._polygon is not None:
            # Only points within the polygon's extent of the nearest one can be nearest to the polygon.
            return body.clearance(points[distance <= float(distance.min()) + 2.0 * self._arm + 1e-9])
        if body.n_disks == 1 and not body.centres.any():
            return float(distance.min()) - float(body.radii[0])
        # Only points near the nearest one can be nearest to some disk.
        offset = float(np.max(np.hypot(body.centres[:, 0], body.centres[:, 1])))
        return body.clearance(points[distance <= float(distance.min()) + 2.0 * offset + 1e-9])

    @staticmethod
    def _top_rates(lower: np.ndarray, upper: np.ndarray, velocity: np.ndarray | None) -> tuple[float, float]:
        """Largest speed [m/s] and yaw rate [rad/s] magnitudes of the box and the current velocity."""
        speed = max(abs(float(lower[0])), abs(float(upper[0])))
        turn = max(abs(float(lower[1])), abs(float(upper[1])))
        if velocity is not None:
            speed, turn = max(speed, abs(float(velocity[0]))), max(turn, abs(float(velocity[1])))
        return speed, turn

    def _approach_bound(self, lower: np.ndarray, upper: np.ndarray, velocity: np.ndarray | None, period: float,
                        distance: float | np.ndarray = 0.0) -> float | np.ndarray:
        """Largest left side of any row [m/s] (approach speed plus arc terms) for a command in the box.

        (The command corner's headroom is held back only on rows that can bind without it,
        :func:`~safenav.filters.rows.ramp_corners`, so it does not widen the reach.)
        For the polygon body the arc term grows with the obstacle point's ``distance`` from the
        base origin [m] (scalar or per point); for disks it does not.
        """
        speed, turn = self._top_rates(lower, upper, velocity)
        kappa = 0.5 * self.robot.omega_max * period
        bound = (speed + self._arm * turn) * (1.0 + kappa)
        return bound + kappa * turn * distance if self._polygon is not None else bound

    def _braking_reach(self, lower: np.ndarray, upper: np.ndarray, velocity: np.ndarray | None, period: float,
                       reaction: float, distance: float | np.ndarray = 0.0) -> float | np.ndarray:
        """Largest barrier value [m] at which a braking or sweep row can bind for a command in the box.

        The braking and sweep rows are written for the pairs within it only: beyond it they hold for every
        command and get no headroom (:func:`~safenav.filters.rows.ramp_corners`).

        A row's left side is at most ``A + W |k_omega|`` with ``A`` the speed part (the speed, its
        arc terms) and ``W`` the turn (:func:`~safenav.filters.rows.braking_coefficient`: ``|k_v| <= 1``,
        and ``|k_omega|`` that of the farthest body point braking at ``alpha_max``). Splitting the
        right side in the shares ``sqrt(D_A)`` and ``sqrt(D_W)`` of the two braking distances ``D``,
        neither can exceed its share beyond ``(sqrt(D_A) + sqrt(D_W))^2``.
        """
        robot = self.robot
        speed, turn = self._top_rates(lower, upper, velocity)
        kappa = 0.5 * robot.omega_max * period
        arc_lever = self._arm if self._polygon is None else distance
        along = speed * (1.0 + kappa) + kappa * turn * arc_lever
        speed_part = along * reaction + along**2 / (2.0 * robot.a_max)
        turn_part = self._arm * (turn * reaction + turn**2 / (2.0 * robot.alpha_max))
        # (Python floats for one distance: numpy's per-call overhead would dominate.)
        root = np.sqrt(speed_part) if isinstance(speed_part, np.ndarray) else math.sqrt(speed_part)
        return (root + math.sqrt(turn_part)) ** 2 + 1e-9

    def _own_rate(self, velocity: np.ndarray | None) -> float:
        """Largest share of its own barrier a pair may lose per period.

        With the velocity (acceleration limits) every pair is held to ``gamma``: a pair approached
        faster than ``gamma h / dt`` while another is nearest would, once it becomes the nearest,
        need a deceleration the base does not have (``gamma = a_max dt / v_max`` makes the
        exponential approach brake at most at ``a_max``). Without it, ``far_gamma``.
        """
        return min(self.far_gamma, self.gamma) if velocity is not None else self.far_gamma

    def _binding_reach(self, lower: np.ndarray, upper: np.ndarray, velocity: np.ndarray | None, min_barrier: float,
                       period: float, reaction: float, distance: float | np.ndarray = 0.0) -> float | np.ndarray:
        """Largest barrier value [m] at which any row of any family can bind for a command in the box.

        A barrier row of a pair outside the margin holds at every command when both of its right
        sides, ``h - (1 - gamma) H`` and (own rate ``g < 1``) ``g h``, exceed the period's largest
        approach ``dt S``; pairs inside the margin always may bind.
        """
        travel = period * self._approach_bound(lower, upper, velocity, period, distance)
        braking = None if velocity is None else self._braking_reach(lower, upper, velocity, period, reaction, distance)
        return self._reach(min_barrier, travel, velocity, braking)

    def _reach(self, min_barrier: float, travel: float | np.ndarray, velocity: np.ndarray | None,
               braking: float | np.ndarray | None) -> float | np.ndarray:
        """:meth:`_binding_reach` from its parts: ``travel``, the period's largest approach [m], and ``braking``, the
        braking reach (``None`` without the velocity) [m]."""
        reach = (1.0 - self.gamma) * min_barrier + travel
        larger = np.maximum if isinstance(reach, np.ndarray) else max   # Python floats for one distance
        own = self._own_rate(velocity)
        if own < 1.0:
            reach = larger(reach, travel / own)
        reach = larger(reach, 0.0) + 1e-9
        if braking is not None:
            reach = larger(reach, braking)
        return reach

    @staticmethod
    def _lifted(u: np.ndarray, problem: _Problem) -> np.ndarray:
        """``z = (v, omega, t_v, t_omega)`` with the smallest auxiliaries ``u`` allows (Python floats: numpy's
        per-call overhead would dominate; ``max`` keeps a NaN command's NaN, as ``np.maximum`` does)."""
        v, omega = float(u[0]), float(u[1])
        t_v, t_omega = abs(v), abs(omega)
        velocity = problem.velocity
        if velocity is not None:
            t_v, t_omega = max(t_v, abs(float(velocity[0]))), max(t_omega, abs(float(velocity[1])))
        return np.array((v, omega, t_v, t_omega))

    def _target(self, u_nom: np.ndarray) -> np.ndarray:
        """The command the QP's cost pulls towards: ``u_nom`` clipped to the limits, blended with the
        previous command by ``smoothing`` ((1/2)|u - u_nom|^2_W + (s/2)|u - u_previous|^2_W, up to a factor)."""
        # A nominal beyond the velocity limits is first clipped to them (it keeps the QP well scaled; np.clip's
        # dispatch costs more than the two ufuncs).
        target = np.minimum(np.maximum(u_nom, self.robot.lower), self.robot.upper)
        smoothing = self.config.smoothing if self._called else 0.0
        return (target + smoothing * self._last_command) / (1.0 + smoothing) if smoothing > 0.0 else target

    def _qp(self, u_nom: np.ndarray, rows: families.Rows, problem: _Problem, slack: int | None = None) -> QPData:
        """The QP over ``rows``; with ``slack`` (a tier index) one slack relaxes the obstacle rows of
        tiers up to it (:data:`SLACK_TIERS`) and the other rows stay hard."""
        stage = None if slack is None else self._stage(rows, problem, slack)
        return self._assembler(u_nom, rows, problem, stage)(np.ones(len(rows), dtype=bool))

    def _assembler(self, u_nom: np.ndarray, rows: families.Rows, problem: _Problem,
                   stage: tuple[np.ndarray, np.ndarray] | None) -> Callable[[np.ndarray], QPData]:
        """The QP of :meth:`_qp` over the rows a mask picks, as a function of the mask; ``stage``: a slack tier's
        right sides and relaxed rows (:meth:`_stage`), or ``None`` (no slack). What does not depend on the
        mask (the cost, the bounds) is computed once for every round of a solve."""
        q = np.zeros(4 if stage is None else 5)
        q[:2] = -self._P[:2, :2] @ self._target(u_nom)
        P, lower, upper = self._P, problem.lower, problem.upper
        h, minus_relaxed = rows.h, _NO_RELAXATION
        if stage is not None:
            h, relaxed = stage
            minus_relaxed = -relaxed.astype(float)
            P, q[4] = self._P_slack, SLACK_LINEAR_WEIGHT
            lower, upper = np.append(lower, 0.0), np.append(upper, np.inf)
        abs_rows, with_slack, qp_rows = self._abs_rows, stage is not None, self._decide.cbf_qp_rows

        def assemble(mask: np.ndarray) -> QPData:
            G, bound = qp_rows(abs_rows.G, abs_rows.h, rows.G, h, minus_relaxed, mask, with_slack)
            return QPData(P, q, G, bound, lower, upper)

        return assemble

    def _stage(self, rows: families.Rows, problem: _Problem, tier: int) -> tuple[np.ndarray, np.ndarray]:
        """Right sides and the mask of the rows one slack relaxes in the stage of ``tier``.

        The slack relaxes the obstacle rows of the tiers up to ``tier`` (:data:`SLACK_TIERS`).
        From the ``inside`` tier on, a barrier row of a point inside the margin asks only that
        the point is not approached (right side at least 0) rather than left at the recovery
        rate: the deepest point's recovery never sets the slack every other row is relaxed by.
        """
        h, point, family = _plain(rows.h), _plain(rows.point, np.intp), _plain(rows.family, np.intp)
        return self._decide.cbf_stage(h, point, family, _plain(problem.uncertainty), _plain(problem.barrier),
                                      self.margin, tier, families.FIRST_HARD, _BARRIER, tier >= len(SLACK_TIERS) - 1)

    @staticmethod
    def _prune(rows: families.Rows, problem: _Problem) -> np.ndarray:
        """Mask of the rows some command in the box could violate (the others never bind)."""
        return families.worst_case(rows.G, problem.lower, problem.upper) > rows.h

    def rows(self, scan: LaserScan | Any, velocity: Any = None, *, reduce: bool = True) -> families.Rows:
        """The rows of every family for ``scan``, with their points and families (see :meth:`build_qp`).

        The auxiliary rows ``|v| <= t_v``, ``|omega| <= t_omega`` are not included; the point
        indices refer to :meth:`points`. Without a nominal the ``blind`` rows forbid any translation
        towards a side no lidar sees (:meth:`build_qp` gives those of its ``u_nom``).
        """
        view = self._inspected(scan)
        velocity = None if velocity is None else np.asarray(velocity, dtype=float)
        problem = self._constraints(view, velocity, self.dt, cut=reduce)
        return problem.rows.take(self._prune(problem.rows, problem)) if reduce else problem.rows

    @property
    def corridor_half_width(self) -> float:
        """``R + margin + min_lookahead`` [m]: the control points ahead of the disks keep the margin too,
        and in a narrow passage (:attr:`passage`) the look-ahead is ``min_lookahead``."""
        return super().corridor_half_width + float(self.config.min_lookahead)

    @property
    def narrow_half_width(self) -> float:
        """The narrow body's half-width plus the margin [m] (it has no look-ahead), when there is a narrow body
        and it is narrower; else :attr:`corridor_half_width`."""
        if "narrow" not in self._shapes:
            return self.corridor_half_width
        return min(self.corridor_half_width, self._shapes["narrow"].body.half_width + self.margin)

    def points(self, scan: LaserScan | Any) -> np.ndarray:
        """The obstacle points ``(N, 2)`` [m] (base frame) the rows of :meth:`rows` index.

        Every valid beam of every scan, then the remembered points (the memory is used but not
        changed).
        """
        return self._inspected(scan).points

    def _inspected(self, scan: LaserScan | Any) -> View:
        """The view of ``scan`` for the inspection methods (the memory is used but not changed)."""
        return self._observe(self._match(as_scans(scan)))

    def build_qp(self, u_nom: Any, scan: LaserScan | Any, velocity: Any = None, *, reduce: bool = True
                 ) -> qpsolvers.Problem:
        """The QP the filter would solve, for inspection, over ``z = (v, omega, t_v, t_omega)``.

        Rows 0-3 of ``G`` are ``|v| <= t_v`` and ``|omega| <= t_omega``; the rest are the
        families' rows (the filter's memory is used but not changed). With ``reduce=True``
        points and rows that cannot bind are dropped (the answer is the same); with
        ``reduce=False`` every family is built from every valid beam of every scan, with no cut.
        """
        u_nom = np.asarray(u_nom, dtype=float)
        view = self._inspected(scan)
        velocity = None if velocity is None else np.asarray(velocity, dtype=float)
        problem = self._constraints(view, velocity, self.dt, cut=reduce, u_nom=u_nom)
        rows = problem.rows.take(self._prune(problem.rows, problem)) if reduce else problem.rows
        return self._qp(u_nom, rows, problem).problem()

    # ------------------------------------------------------------------ filtering

    def _filter(self, u_nom: np.ndarray, view: View, velocity: np.ndarray | None, period: float) -> FilterResult:
        self._steps = None      # this call's QPs are timed afresh
        wanted = self._wanted()
        if wanted != "long" and self._shape_name == "long":
            # A shorter look-ahead never lowers a barrier (the control point moves back by the difference and
            # the radius shrinks by it): switching to it is safe at any call.
            self._use("short")
        tries = [wanted] if wanted != self._shape_name else []
        if wanted == "long" and self._shape_name == "narrow":
            tries.append("short")
        for shape in tries:
            # Another body or a longer look-ahead only once its barrier, over every point of this call, has room
            # and its answer needs no relaxation: every answer keeps the rows of the shape it used. The room is
            # LOOKAHEAD_ROOM from the shorter look-ahead (to the longer one, or to the narrow body: a call that
            # asks for it first takes the shorter look-ahead above), against flapping; 0 out of the narrow body,
            # which only the caller's flag asks for again.
            room = 0.0 if self._shape_name == "narrow" else LOOKAHEAD_ROOM
            if self._barrier_with(view, self._shapes[shape]) < room:
                continue
            keep = self._shape_name
            self._use(shape)
            result = self._filter_rows(u_nom, view, velocity, period)
            if result.status in (FilterStatus.OK, FilterStatus.LATE):
                return self._noted(result)
            self._use(keep)
        return self._noted(self._filter_rows(u_nom, view, velocity, period))

    def _wanted(self) -> str:
        """The shape the caller's flags ask for: ``"narrow"`` (the narrow body, in a gap), ``"short"`` (the
        shortest look-ahead, in a passage) or ``"long"``."""
        if self.narrow and "narrow" in self._shapes:
            return "narrow"
        if (self.passage or self.narrow) and self._shapes["short"].lookahead < self._shapes["long"].lookahead:
            return "short"
        return "long"

    def _barrier_with(self, view: View, shape: _Shape) -> float:
        """``H`` [m] of ``shape`` (its body, its control points ``lookahead`` ahead), over every point of ``view``."""
        return shape.body.barrier(view.points, self.margin, view.uncertainty, shape.lookahead)

    def _on_reset(self) -> None:
        self._use("long")

    def _noted(self, result: FilterResult) -> FilterResult:
        """``result`` with its reason saying which narrow setting built it (a passage's look-ahead, a gap's body)."""
        if result.reason is None or self._shape_name == "long":
            return result
        if self._shape_name == "narrow":
            note = f"{self._shape.body.name} body, look-ahead {self.lookahead:g} m (a narrow gap)"
        else:
            note = f"look-ahead {self.lookahead:g} m (a narrow passage)"
        reason = result.reason
        return dataclasses.replace(result, reason=Reason(reason.family, f"{reason.detail}; {note}", reason.point),
                                   message="")

    def _filter_rows(self, u_nom: np.ndarray, view: View, velocity: np.ndarray | None, period: float
                     ) -> FilterResult:
        """The answer with the rows of the current look-ahead."""
        problem = self._constraints(view, velocity, period, u_nom=u_nom)
        rows = problem.rows
        details: dict[str, Any] = dict(min_barrier=problem.min_barrier, clearance=problem.clearance)
        lower, upper = problem.limits
        if (lower[0] <= u_nom[0] <= upper[0] and lower[1] <= u_nom[1] <= upper[1]
                and (rows.G @ self._lifted(u_nom, problem) <= rows.h).all()):
            return FilterResult(u=u_nom, u_nom=u_nom, status=FilterStatus.OK, **details)
        try:
            return self._solved(u_nom, view, velocity, period, problem, details)
        except _OutOfTime:
            return self._brake(u_nom, velocity, FilterStatus.FALLBACK, "deadline",
                               f"no answer within the compute budget of {1e3 * self.budget:.3g} ms "
                               f"({1e3 * self._budget.spent():.3g} ms spent); braking at the acceleration limits",
                               solver=self.backend.name, period=period, **details)

    def _solved(self, u_nom: np.ndarray, view: View, velocity: np.ndarray | None, period: float,
                problem: _Problem, details: dict[str, Any]) -> FilterResult:
        """The answer of the QP (constraint generation, slack tiers), verified; ``u_nom`` is not safe as it is.
        Raises :class:`_OutOfTime` when the next QP cannot end within the call's budget."""
        rows, points = problem.rows, problem.points
        lower, upper = problem.limits
        G, h, row_point, row_family = _plain_rows(rows)
        # The rows some command in the box violates (_prune), and whether one is missed by every command in it.
        *taken, candidate, excluded = self._decide.cbf_screen(G, h, row_point, row_family, problem.lower,
                                                              problem.upper, VERIFY_TOLERANCE)
        if candidate.size == 0:
            # No row can bind anywhere in the box: the QP is separable, its answer the clipped target.
            u = _clipped(self._target(u_nom), lower, upper)
            return FilterResult(u=u, u_nom=u_nom, status=FilterStatus.OK,
                                reason=self._binding(u, u_nom, rows, -1, points, problem), **details)
        cand = families.Rows(*taken)
        direct_rows = min(self.backend.direct_rows, DIRECT_ROWS)
        if candidate.size <= direct_rows:
            working = np.ones(candidate.size, dtype=bool)
        else:
            # Initial working set: every hard row and the tightest obstacle row per angular bin.
            point_rows = np.flatnonzero(cand.point >= 0)
            chosen = nearest_per_bin(points[cand.point[point_rows]], cand.h[point_rows], (self.lookahead, 0.0),
                                     self.config.n_bins, compiled=self._kernels)
            working = cand.point < 0
            working[point_rows[chosen]] = True
        initial = working.copy()
        if excluded:   # no answer, and no solve is needed to say so (_screen)
            z, solve_time = None, 0.0
        else:
            z, working, solve_time, _ = self._solve_generating(u_nom, cand, working, problem)
        slack = 0.0
        tier: int | None = None
        status = FilterStatus.OK
        reason: Reason | None = None
        if z is None:
            hard = cand.take(cand.hard)
            if not self._hard_feasible(hard, problem):
                return self._brake(u_nom, velocity, FilterStatus.BRAKING, *self._hard_reason(hard, problem),
                                   solver=self.backend.name, solve_time=solve_time, period=period, **details)
            # No command satisfies every row: relax obstacle rows (never the hard ones) by one slack,
            # tier by tier, until some command keeps every row that is not relaxed.
            for tier in range(len(SLACK_TIERS)):
                stage = self._stage(cand, problem, tier)
                if tier == 0 and not stage[1].any():
                    continue
                z, working, more_time, solver_status = self._solve_generating(u_nom, cand, initial, problem,
                                                                               slack=tier, stage=stage)
                solve_time += more_time
                if z is not None:
                    break
            if z is None:
                return self._brake(u_nom, velocity, FilterStatus.FALLBACK, "solver",
                                   f"QP solver {self.backend.name} failed ({solver_status}) even with slack",
                                   solver=self.backend.name, solve_time=solve_time, period=period, **details)
            z, slack = z[:4], max(float(z[4]), 0.0)
            if slack > VERIFY_TOLERANCE:
                status = FilterStatus.SLACK
        bound = h
        if tier is not None:
            stage_h, stage_relaxed = self._stage(rows, problem, tier)
            bound = stage_h + np.where(stage_relaxed, slack, 0.0)
        u = _clipped(z, lower, upper)
        frontier = view.frontier
        # Exactly never faster towards an unseen side than the blind rows allow (the solver meets rows to ~1e-10).
        if frontier.backward:
            u[0] = max(u[0], min(-problem.blind_speed, upper[0]))
        if frontier.forward:
            u[0] = min(u[0], max(problem.blind_speed, lower[0]))
        rows_used = candidate[working]
        worst, excess, soft_worst, binding, used, active = self._decide.cbf_answer(
            G, h, _plain(bound), row_family, row_point, self._lifted(u, problem),
            self._lifted(_clipped(u_nom, lower, upper), problem), rows_used, len(points), families.FIRST_HARD,
            ACTIVE_TOLERANCE)
        if not excess <= VERIFY_TOLERANCE:   # (NaN too)
            return self._brake(u_nom, velocity, FilterStatus.FALLBACK, "solver",
                               f"QP answer from {self.backend.name} violates a {self._family(rows, worst)} row by "
                               f"{excess:.3g} m/s", solver=self.backend.name, solve_time=solve_time,
                               period=period, **details)
        if status is FilterStatus.SLACK:
            reason = self._slack_reason(rows, max(soft_worst, 0), points, problem.min_barrier, slack * period, tier)
        else:
            reason = self._binding(u, u_nom, rows, binding, points, problem)
            if problem.min_barrier < 0.0:
                status = FilterStatus.RECOVERING
                how = ("moving back out" if tier is None else
                       "holding its distance (no command in the box leaves at the recovery rate)")
                reason = Reason("barrier", f"inside the margin (barrier {problem.min_barrier:.3f} m); {how}",
                                _nearest(points, problem.barrier))
        return FilterResult(   # (arrays of this call's own: read-only as they are, not copied again)
            u=_read_only(u), u_nom=u_nom, status=status, reason=reason, n_constraints=int(working.sum()),
            constraint_points=_read_only(points[used]), active=np.flatnonzero(active[used]),
            slack=slack * period if status is FilterStatus.SLACK else 0.0, solver=self.backend.name,
            solve_time=solve_time, **details,
        )

    def _solve_qp(self, qp: QPData) -> QPOutcome:
        """``qp`` solved by the back-end, unless, lasting as long as the longest QP of the recent calls or of
        this call, it could not end within the call's budget: then :class:`_OutOfTime`."""
        budget = self._budget
        if self._steps is None:
            self._steps = StepClock(budget.solver_deadline(), self.clock, budget.step)
        if self._steps.late():
            budget.returned(self._steps.finished())
            raise _OutOfTime
        outcome = self.backend.solve(qp)
        budget.returned(self._steps.finished())
        return outcome

    def _solve_generating(self, u_nom: np.ndarray, rows: families.Rows, working: np.ndarray, problem: _Problem,
                          slack: int | None = None, stage: tuple[np.ndarray, np.ndarray] | None = None
                          ) -> tuple[np.ndarray | None, np.ndarray, float, str]:
        """Solve over the rows in ``working``, adding violated rows until none is (constraint generation).
        ``stage``: the slack tier's :meth:`_stage` of ``rows``, when the caller has it.

        Returns the solution (``None`` on failure), the final working set, the solve time [s]
        and the solver's last status word. The answer equals that of the QP with all rows.
        """
        working = working.copy()
        solve_time = 0.0
        outcome = None
        h, relaxed = rows.h, np.zeros(len(rows), dtype=bool)
        if slack is not None:   # the stage's right sides and relaxed rows, the same in every round
            stage = h, relaxed = self._stage(rows, problem, slack) if stage is None else stage
        else:
            stage = None
        assemble = self._assembler(u_nom, rows, problem, stage)
        violated = self._decide.cbf_violated
        for round_index in range(MAX_GENERATION_ROUNDS + 1):
            if round_index == MAX_GENERATION_ROUNDS:
                working[:] = True
            outcome = self._solve_qp(assemble(working))
            solve_time += outcome.solve_time
            z = outcome.x
            if z is None:
                return None, working, solve_time, outcome.status
            # every row the answer misses joins the working set
            if not violated(rows.G, h, relaxed, float(z[4]) if slack is not None else 0.0, _plain(z), working,
                            0.1 * VERIFY_TOLERANCE):
                return z, working, solve_time, outcome.status
        return None, working, solve_time, "constraint generation did not settle"

    def _hard_feasible(self, hard: families.Rows, problem: _Problem) -> bool:
        """Whether some command in the box satisfies every hard row (an LP, solved as a tiny QP, unless the
        command nearest a stop already does: the usual case, a blind side the base is not moving towards)."""
        if not len(hard):
            return True
        stop = self._lifted(_clipped((0.0, 0.0), *problem.limits), problem)
        if np.all(hard.G @ stop <= hard.h):
            return True
        qp = QPData(np.diag([1e-6, 1e-6, 1e-6, 1e-6]), np.zeros(4), np.vstack((self._abs_rows.G, hard.G)),
                    np.concatenate((self._abs_rows.h, hard.h)), problem.lower, problem.upper)
        z = self._solve_qp(qp).x
        return z is not None and bool(np.all(hard.G @ z <= hard.h + VERIFY_TOLERANCE))

    @staticmethod
    def _family(rows: families.Rows, index: int) -> str:
        return families.FAMILIES[int(rows.family[index])]

    def _hard_reason(self, hard: families.Rows, problem: _Problem) -> tuple[str, str]:
        names = sorted({families.FAMILIES[int(f)] for f in hard.family})
        what = "an unseen direction" if "blind" in names else "space behind invalid beams"
        return ("unknown", f"cannot stop before moving towards {what} ({', '.join(names)} rows) within the "
                           f"acceleration limits; braking at the limits")

    def _slack_reason(self, rows: families.Rows, worst: int, points: np.ndarray, min_barrier: float,
                      slack: float, tier: int) -> Reason:
        """Why no command satisfied every obstacle row; ``slack`` is the relaxation per period [m] of
        the rows of tiers up to ``tier`` (:data:`SLACK_TIERS`)."""
        point = _point(points, int(rows.point[worst]))
        family = self._family(rows, worst)
        which = ("the rows of remembered points located worse than the margin",
                 "the rows of points inside the margin (beyond not approaching them)",
                 "every obstacle row")[tier]
        if min_barrier < 0.0:
            return Reason(family, f"already inside the margin (barrier {min_barrier:.3f} m), moving away; {which} "
                                  f"relaxed by {slack:.4f} m", point)
        return Reason(family, f"cannot brake in time under the acceleration limits; {which} relaxed by "
                              f"{slack:.4f} m", point)

    def _binding(self, u: np.ndarray, u_nom: np.ndarray, rows: families.Rows, index: int, points: np.ndarray,
                 problem: _Problem) -> Reason | None:
        """The constraint that bound ``u`` (``None`` when ``u`` is ``u_nom``): the row ``index`` (of the rows active at
        ``u``, the one the nominal violates most: the one that moved the command; :func:`_answer`), or with ``-1``
        (no row active) the velocity limits or the acceleration limits."""
        if u[0] == u_nom[0] and u[1] == u_nom[1]:
            return None
        if index >= 0:
            family = self._family(rows, index)
            text = _blind_text(problem.blind_speed) if family == "blind" else _ROW_TEXT[family]
            return Reason(family, text, _point(points, int(rows.point[index])))
        robot = self.robot
        if np.any(u_nom < robot.lower) or np.any(u_nom > robot.upper):
            return Reason("limits", f"clipped to the velocity limits {robot.lower.tolist()}..{robot.upper.tolist()}")
        return Reason("acceleration", f"not reachable within one period from the velocity "
                                      f"{problem.velocity.tolist() if problem.velocity is not None else None}")


_ROW_TEXT = {"barrier": "keeps the barrier condition", "braking": "keeps the speed it can brake from",
             "sweep": "caps the speed along a heading the base may still turn to",
             "gap": "does not move towards space behind invalid beams"}
"""What a binding row of each family (but ``blind``, :func:`_blind_text`) does, for the reason."""


def _clipped(u: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """``np.clip(u, lower, upper)`` of a command ``(v, omega)``, to the bit (NaN kept, the bound taken on a tie, as
    numpy's clip does), in Python floats: numpy's per-call overhead would dominate."""
    v, omega = float(u[0]), float(u[1])
    low, high = float(lower[0]), float(upper[0])
    v = v if v != v or v > low else low
    v = v if v != v or v < high else high
    low, high = float(lower[1]), float(upper[1])
    omega = omega if omega != omega or omega > low else low
    omega = omega if omega != omega or omega < high else high
    return np.array((v, omega))


def _blind_text(speed: float) -> str:
    if speed <= 0.0:
        return "does not translate towards a side no lidar sees"
    return (f"translates towards a side no lidar sees at most at {speed:.3f} m/s, the speed it stops from within "
            f"the space earlier scans saw free there")


def _point(points: np.ndarray, index: int) -> tuple[float, float] | None:
    return None if index < 0 else (float(points[index, 0]), float(points[index, 1]))


def _nearest(points: np.ndarray, barrier: np.ndarray) -> tuple[float, float] | None:
    return None if barrier.size == 0 else _point(points, int(np.argmin(barrier)))


# ---------------------------------------------------------------- the decision's array work (numpy references)
# Each has a compiled twin of the same name with the prefix cbf_ in safenav.filters._compiled_rows (the filter uses
# those with kernels; tests/filters/test_kernels.py checks both give the same answers).

_NO_RELAXATION = np.zeros(0)
_plain = kernels.plain


def _plain_rows(rows: families.Rows) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``rows``' arrays as the compiled decision takes them (float64 and intp, C-contiguous, writable)."""
    return _plain(rows.G), _plain(rows.h), _plain(rows.point, np.intp), _plain(rows.family, np.intp)


def _screen(G: np.ndarray, h: np.ndarray, point: np.ndarray, family: np.ndarray, lower: np.ndarray,
            upper: np.ndarray, tolerance: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray,
                                                          bool]:
    """The rows some ``z`` in the box ``lower <= z <= upper`` violates (their ``G``, ``h``, points, families and
    indices: the others never bind), and whether some row is missed by every ``z`` in the box by more than
    ``tolerance`` [m/s]: then the QP has no answer, and no solve is needed to say so (inside the margin, the deepest
    point's recovery row under the acceleration limits, the usual cause of a first QP without answer)."""
    largest, smallest = families.box_range(G, lower, upper)
    candidate = np.flatnonzero(largest > h)
    return (G[candidate], h[candidate], point[candidate], family[candidate], candidate,
            bool(np.any(smallest > h + tolerance)))


def _qp_rows(fixed_G: np.ndarray, fixed_h: np.ndarray, G: np.ndarray, h: np.ndarray, minus_relaxed: np.ndarray,
             working: np.ndarray, with_slack: bool) -> tuple[np.ndarray, np.ndarray]:
    """A QP's rows and right sides: the fixed rows (the auxiliaries'), then the rows of ``G``, ``h`` that ``working``
    picks; ``with_slack``: a fifth column, ``-0.0`` on the fixed rows (bit for bit the QP of ``-relaxed`` over them)
    and ``minus_relaxed`` on the others."""
    index = np.flatnonzero(working)
    fixed = fixed_h.size
    matrix = np.empty((fixed + index.size, 5 if with_slack else 4))
    matrix[:fixed, :4] = fixed_G
    matrix[fixed:, :4] = G[index]
    bound = np.empty(fixed + index.size)
    bound[:fixed] = fixed_h
    bound[fixed:] = h[index]
    if with_slack:
        matrix[:fixed, 4] = -0.0
        matrix[fixed:, 4] = minus_relaxed[index]
    return matrix, bound


def _violated(G: np.ndarray, h: np.ndarray, relaxed: np.ndarray, slack: float, z: np.ndarray, working: np.ndarray,
              tolerance: float) -> bool:
    """Adds to ``working`` (in place) every row ``z`` misses by more than ``tolerance`` [m/s], the rows ``relaxed``
    marks relaxed by ``slack``; whether it added any."""
    violated = (G @ z[:4] > h + np.where(relaxed, slack, 0.0) + tolerance) & ~working
    working |= violated
    return bool(violated.any())


def _answer(G: np.ndarray, h: np.ndarray, bound: np.ndarray, family: np.ndarray, point: np.ndarray,
            lifted: np.ndarray, nominal: np.ndarray, used_rows: np.ndarray, n_points: int, first_hard: int,
            near: float) -> tuple[int, float, int, int, np.ndarray, np.ndarray]:
    """The rows at the answer ``lifted`` (``z``): the row it misses its ``bound`` most by (the first ``NaN`` first; -1
    without rows) and by how much, the soft row (family below ``first_hard``) it misses its right side ``h`` most by
    (-1 when none), the row that bound it (of the rows within ``near`` of ``h``, the one the lifted ``nominal``
    misses most: the one that moved the command; -1 when none), and of the ``n_points`` points which the rows
    ``used_rows`` refer to and which of those hold within ``near`` of their bounds."""
    left = G @ lifted
    residual = left - bound
    worst = int(np.argmax(residual)) if residual.size else -1
    excess = float(residual[worst]) if residual.size else -math.inf
    own = left - h
    soft = family < first_hard
    soft_worst = int(np.argmax(np.where(soft, own, -np.inf))) if soft.any() else -1
    near_rows = np.flatnonzero(own >= -near)
    binding = int(near_rows[int(np.argmax(G[near_rows] @ nominal - h[near_rows]))]) if near_rows.size else -1
    row_points = point[used_rows]
    used = np.zeros(n_points + 1, dtype=bool)   # the extra slot absorbs rows without a point (-1)
    used[row_points] = True
    active = np.zeros(n_points + 1, dtype=bool)
    active[row_points[np.abs(residual[used_rows]) <= near]] = True
    return worst, excess, soft_worst, binding, used[:-1], active[:-1]


def _stage(h: np.ndarray, point: np.ndarray, family: np.ndarray, uncertainty: np.ndarray, barrier: np.ndarray,
           margin: float, tier: int, first_hard: int, barrier_family: int, every: bool
           ) -> tuple[np.ndarray, np.ndarray]:
    """:meth:`CBFSafetyFilter._stage`: the right sides and the relaxed rows of the slack tier ``tier`` over rows of
    right sides ``h``, points ``point`` (-1: none) and families ``family`` (hard from ``first_hard``), with each
    point's ``uncertainty`` and ``barrier`` [m]; ``every``: the last tier (every soft row relaxed)."""
    soft = family < first_hard
    with_point = soft & (point >= 0)
    index = np.where(with_point, point, 0)
    lost = with_point & (uncertainty[index] > margin)
    if tier == 0:
        return h, lost
    inside = with_point & (barrier[index] <= 0.0)
    bound = np.where(inside & (family == barrier_family), np.maximum(h, 0.0), h)
    return bound, soft if every else inside | lost


_NUMPY_DECISION = SimpleNamespace(cbf_screen=_screen, cbf_qp_rows=_qp_rows, cbf_violated=_violated, cbf_answer=_answer,
                                  cbf_stage=_stage)
"""The numpy references of the compiled decision (the filter's ``_decide`` without kernels)."""

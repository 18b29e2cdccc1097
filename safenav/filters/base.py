"""What every safety filter shares: the result, the statuses and their reasons, and the call template.

A safety filter takes a nominal command ``u_nom = (v, omega)``, the latest scan (or the
latest scan of each of several lidars) and optionally the measured velocity, the odometry
pose and the time, and returns a frozen :class:`FilterResult`: the command to send and what
the filter did, with a :class:`Reason` whenever the command differs from ``u_nom``. It never
reads simulator truth, never returns NaN, and never raises inside the control loop for an
input it can still act on: it brakes and says why. It raises only for structural mistakes
(a ``u_nom`` of the wrong shape, something that is not a scan, a scan that contradicts the
robot's lidar).

:meth:`SafetyFilter.filter` is a template every filter shares: input checks, the call
period and scan ages, the odometry that carries remembered points, the perception
(:mod:`safenav.filters.perception`), then the filter's own :meth:`SafetyFilter._filter`,
then the bookkeeping. Subclasses implement ``_filter`` and may use the hooks
:meth:`SafetyFilter._on_reset` and :meth:`SafetyFilter._on_brake`; the template counts a filter's
compute budget (:mod:`safenav.filters.deadline`) from the call's start (the MPC overrides ``filter``
only to begin it before its reference's call).

Longer than most modules because the call template owns every check a filter must make before and
after its step (input, clock, staleness, late calls, base lag, deadlock, braking), so that no filter
can skip one; the statuses and the result sit here with it.
"""

from __future__ import annotations

import abc
import collections
import enum
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import numpy as np

from safenav import _checks
from safenav.errors import InvalidConfig, InvalidScanType
from safenav.filters import heap, kernels
from safenav.filters.body import BodyModel, inscribed_radius
from safenav.filters.deadline import CallBudget
from safenav.filters.perception import (
    SEEN_FREE_MAX_TRAVEL,
    SEEN_FREE_TRAVEL,
    SHADOW_SPACING,
    Frontier,
    PointMemory,
    SeenFree,
    beam_gap,
    beam_points,
    classify,
    dead_reckoning,
    horizon_points,
    motion_spread,
    reckoning,
    resolved_range,
    seam_gap,
    shadow_points,
    sweep_poses,
    sweep_step,
    unknown_region,
)
from safenav.geometry import Pose2D, unicycle_step
from safenav.robot import RobotSpec, as_command, as_pose
from safenav.scan import LaserScan

__all__ = [
    "BRAKING_STATUSES",
    "MAX_DT",
    "Deadlock",
    "FilterResult",
    "FilterStatus",
    "Reason",
    "SafetyFilter",
    "View",
]

#: Longest control period any filter accepts [s]; a larger ``dt`` is most likely in milliseconds.
MAX_DT = 1.0
#: A call this much later than ``dt`` (relative) counts as late.
LATE_TOLERANCE = 0.05
#: A scan stamped this far in the future [s] means the clocks disagree.
FUTURE_TOLERANCE = 1e-3
#: A nominal below this fraction of the velocity limits does not ask to move.
STILL = 0.05
#: Commands keeping less than this share of the nominal's progress count as stalled.
STALL_PROGRESS = 0.1
#: Progress must last this long to end a stall [s]: a nominal that flips between turning and
#: driving (a go-to-goal at its heading threshold) makes progress for a period now and then
#: while the robot stays put, and one such period must not reset the deadlock clock.
PROGRESS_RESET_TIME = 0.25
#: How many periods a filter keeps (the command returned, the velocities measured about it) to move a scan of known
#: age into the current base frame (:meth:`SafetyFilter.latent_motion`): 0.5 s (``scan_timeout``'s default) at 64 Hz.
COMMAND_HISTORY = 32


class FilterStatus(enum.Enum):
    """What the filter did with the nominal command."""

    OK = "ok"
    """Every constraint holds for the returned command (``u_nom`` itself when it was already safe)."""
    RECOVERING = "recovering"
    """The robot is already inside the margin of some obstacle (a barrier is negative, e.g.
    after noise or a push); the command satisfies the barrier condition, which moves it back out."""
    SLACK = "slack"
    """The obstacle constraints could not all hold (the robot is already too close, or cannot
    brake in time); the command violates them as little as possible. Hard constraints (the
    limits, the unknown region) still hold."""
    LATE = "late"
    """The call came later than ``dt`` after the previous one: the command was planned for the
    measured period (:attr:`FilterResult.period`), and every constraint holds for it."""
    BRAKING = "braking"
    """No command keeps every hard constraint (e.g. moving too fast towards space that has just
    become unknown): the base brakes at its acceleration limits."""
    FALLBACK = "fallback"
    """The optimiser failed, ran out of time, or its answer failed verification; the robot
    brakes (the MPC filter follows its last verified plan, which ends stopped)."""
    NO_DATA = "no_data"
    """The scan holds no informative beam; the robot brakes."""
    STALE = "stale"
    """A scan is older than the timeout, from the future, or of unknown age while the time is
    given; the robot brakes."""
    BAD_INPUT = "bad_input"
    """The nominal command or the measured velocity is not finite; the robot brakes."""


BRAKING_STATUSES = frozenset({FilterStatus.BRAKING, FilterStatus.FALLBACK, FilterStatus.NO_DATA,
                              FilterStatus.STALE, FilterStatus.BAD_INPUT})
"""Statuses in which the filter ignores ``u_nom`` and brakes."""


@dataclass(frozen=True)
class Reason:
    """Why the command differs from the nominal: the binding constraint and what is behind it.

    Attributes:
        family: what bound the command: a constraint family (``"barrier"``, ``"braking"``,
            ``"sweep"``, ``"gap"``, ``"blind"``, ``"plan"``), ``"limits"`` (velocity limits),
            ``"acceleration"`` (not reachable within one period), or the cause of a braking
            status (``"stale"``, ``"late"``, ``"no_data"``, ``"bad_input"``, ``"solver"``,
            ``"deadline"``, ``"unknown"``, ``"zone"``), or ``"reference"`` (an MPC that tracks a CBF took
            the CBF's answer; with the CBF's reason, its family).
        detail: one human-readable sentence.
        point: the obstacle point behind it, base frame [m] (``None`` when there is none).
    """

    family: str
    detail: str
    point: tuple[float, float] | None = None

    @property
    def distance(self) -> float | None:
        """Distance of :attr:`point` from the base origin [m]."""
        return None if self.point is None else math.hypot(*self.point)

    @property
    def bearing(self) -> float | None:
        """Direction of :attr:`point` in the base frame [rad] (0 ahead, positive to the left)."""
        return None if self.point is None else math.atan2(self.point[1], self.point[0])

    def __str__(self) -> str:
        where = ""
        if self.point is not None:
            where = f" (obstacle at {self.distance:.2f} m, bearing {math.degrees(self.bearing):+.0f} deg)"
        return f"{self.family}: {self.detail}{where}"


@dataclass(frozen=True)
class Deadlock:
    """The nominal asks to move and the filtered command has made (almost) no progress along it.

    Attributes:
        time: how long the commands have made less than ``stall_progress`` of the nominal's
            progress, while the nominal asked to move [s].
        point: the obstacle point behind the binding constraint, base frame [m] (``None`` when
            an unknown region or a limit binds).
        family: the constraint family that binds (see :class:`Reason`).
    """

    time: float
    point: tuple[float, float] | None
    family: str

    def __str__(self) -> str:
        where = "" if self.point is None else f" at ({self.point[0]:.2f}, {self.point[1]:.2f}) m"
        article = "an" if self.family[:1] in "aeiou" else "a"
        return f"deadlocked for {self.time:.1f} s by {article} {self.family} constraint{where}"


def progress(u: np.ndarray, u_nom: np.ndarray, scale: np.ndarray) -> float:
    """How much of the nominal's motion ``u`` keeps, in ``[-inf, 1]`` (1 for ``u = u_nom``).

    Commands are compared as fractions of the velocity limits ``scale``, the nominal clipped to
    them; the progress is the projection of ``u`` on ``u_nom`` divided by ``|u_nom|^2`` (capped at 1).
    """
    nominal = np.clip(u_nom, -scale, scale) / scale
    size = float(nominal @ nominal)
    if size <= 0.0:
        return 1.0
    return min(float((u / scale) @ nominal) / size, 1.0)


def _read_only(array: np.ndarray) -> np.ndarray:
    array.flags.writeable = False
    return array


_NO_POINTS = _read_only(np.empty((0, 2)))


def _odometry(pose: Any) -> tuple[Pose2D | None, Pose2D | None]:
    """A call's ``pose`` checked (:func:`~safenav.robot.as_pose`) and split: ``(the pose, None)`` when it is finite,
    ``(None, the pose)`` when it is not (an odometry glitch: the call goes on as without a pose, and says so), and
    ``(None, None)`` without one."""
    if pose is None:
        return None, None
    odometry = as_pose(pose)
    if math.isfinite(odometry.x) and math.isfinite(odometry.y) and math.isfinite(odometry.yaw):
        return odometry, None
    return None, odometry


def _finite(pair: np.ndarray) -> bool:
    """Whether both values of a command or velocity pair are finite (without numpy's per-call overhead)."""
    return math.isfinite(pair[0]) and math.isfinite(pair[1])


def _frozen(array: Any, shape: tuple[int, ...] | None = None) -> np.ndarray:
    """A read-only float copy of ``array`` (arrays already read-only float are kept)."""
    if isinstance(array, np.ndarray) and not array.flags.writeable and array.dtype == np.float64:
        result = array
    else:
        result = np.array(array, dtype=float)
        result.flags.writeable = False
    return result if shape is None or result.shape == shape else result.reshape(shape)


@dataclass(frozen=True, eq=False)
class FilterResult:
    """The filtered command and what the filter did to get it.

    Attributes:
        u: the command to send, ``(v [m/s], omega [rad/s])``; always finite and within the limits.
        u_nom: the nominal command as given (may be non-finite when ``status`` is ``BAD_INPUT``).
        status: see :class:`FilterStatus`.
        message: why the filter changed the command, braked or relaxed a constraint (empty when
            ``u`` is ``u_nom`` and nothing is wrong); ``str(reason)`` plus any detail.
        reason: the binding constraint or the cause (``None`` only when ``u`` is ``u_nom`` and
            the status is ``OK``).
        min_barrier: smallest barrier value at the current state [m] (``inf`` without points).
        clearance: distance from the body (its disks) to the nearest obstacle point [m]
            (``inf`` when no point is seen); negative means inside the body.
        n_constraints: number of obstacle constraints the optimiser saw (after reduction).
        constraint_points: ``(n, 2)`` obstacle points behind those constraints, base frame [m].
        active: indices into ``constraint_points`` of the constraints that hold with equality.
        slack: largest relaxation of an obstacle constraint [m] (0 unless ``status`` is ``SLACK``).
        solver: name of the back-end that produced ``u`` (empty when no optimisation ran).
        solve_time: time spent in the optimiser [s].
        filter_time: time spent in the whole call [s].
        period: the period this command was planned for [s]: ``dt``, or the measured time since
            the previous call when that was longer (status ``LATE``).
        plan: the predicted trajectory, ``(N + 1, 5)`` rows of ``(x, y, yaw, v, omega)`` in the
            current base frame, for predictive filters; ``None`` otherwise.
        warnings: conditions that do not change the command but void part of the guarantee
            (e.g. the base does not follow the model), for logs.
        deadlock: set when the nominal has asked to move for ``deadlock_time`` without the
            commands making progress along it (see :class:`Deadlock`).
        escape: what an escape wrapper is doing instead of the nominal (empty when it is not;
            see :class:`~safenav.filters.escape.Escape`).
    """

    u: np.ndarray
    u_nom: np.ndarray
    status: FilterStatus
    message: str = ""
    reason: Reason | None = None
    min_barrier: float = math.inf
    clearance: float = math.inf
    n_constraints: int = 0
    constraint_points: np.ndarray = field(default_factory=lambda: _NO_POINTS)
    active: tuple[int, ...] = ()
    slack: float = 0.0
    solver: str = ""
    solve_time: float = 0.0
    filter_time: float = 0.0
    period: float = math.nan
    plan: np.ndarray | None = None
    warnings: tuple[str, ...] = ()
    deadlock: Deadlock | None = None
    escape: str = ""

    def __post_init__(self) -> None:
        same = self.u is self.u_nom       # minimal intervention: u is u_nom, share the read-only copy
        u_nom = _frozen(self.u_nom, (2,))
        object.__setattr__(self, "u_nom", u_nom)
        object.__setattr__(self, "u", u_nom if same else _frozen(self.u, (2,)))
        if self.constraint_points is not _NO_POINTS:
            object.__setattr__(self, "constraint_points", _frozen(self.constraint_points, (-1, 2)))
        active = self.active
        object.__setattr__(self, "active", tuple(active.tolist()) if isinstance(active, np.ndarray)
                           and active.dtype.kind in "iu" else tuple(map(int, active)))
        if self.plan is not None:
            object.__setattr__(self, "plan", _frozen(self.plan))
        if self.reason is not None and not self.message:
            object.__setattr__(self, "message", str(self.reason))

    @property
    def braked(self) -> bool:
        """True when the filter ignored ``u_nom`` and braked (see :data:`BRAKING_STATUSES`)."""
        return self.status in BRAKING_STATUSES

    @property
    def modified(self) -> bool:
        """True when ``u`` differs from ``u_nom``."""
        return not np.array_equal(self.u, self.u_nom)

    @property
    def timed_out(self) -> bool:
        """True when the call gave up at its compute budget (reason family ``deadline``): it braked, or
        followed the MPC's last verified plan (:mod:`safenav.filters.deadline`)."""
        return self.reason is not None and self.reason.family == "deadline"

    intervened = modified

    @property
    def intervention(self) -> float:
        """Euclidean size of the change ``||u - u_nom||`` in ``(m/s, rad/s)`` (``inf`` if ``u_nom`` is not finite)."""
        difference = self.u - self.u_nom
        return float(np.hypot(*difference)) if np.all(np.isfinite(difference)) else math.inf

    def explain(self) -> str:
        """One line for a log: the status, the command and, when it differs from the nominal, why."""
        line = (f"{self.status.value}: u=({self.u[0]:.3f}, {self.u[1]:.3f})"
                f" from u_nom=({self.u_nom[0]:.3f}, {self.u_nom[1]:.3f})")
        if self.message:
            line += f"; {self.message}"
        if self.deadlock is not None:
            line += f"; {self.deadlock}"
        if self.escape:
            line += f"; escape: {self.escape}"
        if math.isfinite(self.min_barrier):
            line += f"; barrier {self.min_barrier:.3f} m"
        for warning in self.warnings:
            line += f"; warning: {warning}"
        return line


class View(NamedTuple):
    """What a filter sees at one call, in the current base frame."""

    scans: tuple[LaserScan, ...]
    """The current sources."""
    points: np.ndarray
    """``(N, 2)`` obstacle points [m]: the current scans' first, then the remembered ones."""
    uncertainty: np.ndarray
    """``(N,)`` position uncertainty of each point [m] (0 for the current scans' points, but those of a scan moved
    into the current base frame by the measured velocities since it was taken, A5)."""
    n_current: int
    """How many of :attr:`points` the current scans' readings give (the first ones)."""
    frontier: Frontier
    """The part of the outline facing unknown space (see :func:`~safenav.filters.perception.unknown_region`)."""
    n_horizon: int = 0
    """How many points follow those as the edge of what the lidars see (at ``range_max``,
    :func:`~safenav.filters.perception.horizon_points`, and along the edges of what obstacles hide,
    :func:`~safenav.filters.perception.shadow_points`); the remembered ones come last."""

    @property
    def horizon(self) -> np.ndarray:
        """``(K, 2)`` the points where what the lidars see ends [m] (none where the range is long enough)."""
        return self.points[self.n_current:self.n_current + self.n_horizon]


class Period(NamedTuple):
    """One period between two calls of a filter, as the next call knows it."""

    held: float
    """How long it lasted [s]."""
    command: np.ndarray
    """The command returned at its start [m/s, rad/s]."""
    start: np.ndarray | None
    """The velocity measured at its start [m/s, rad/s] (``None`` when not given)."""
    end: np.ndarray | None
    """The velocity measured at its end [m/s, rad/s] (``None`` when not given)."""


def as_scans(scan: Any) -> tuple[LaserScan, ...]:
    """``scan`` (one :class:`~safenav.scan.LaserScan` or a sequence of them) as a non-empty tuple."""
    if isinstance(scan, LaserScan):
        return (scan,)
    if isinstance(scan, Sequence) and not isinstance(scan, (str, bytes)) and len(scan) > 0 and all(
            isinstance(item, LaserScan) for item in scan):
        return tuple(scan)
    raise InvalidScanType(
        "scan must be a safenav LaserScan or a non-empty sequence of them (use LaserScan.from_msg for ROS "
        f"messages), got {type(scan).__name__}")


class SafetyFilter(abc.ABC):
    """Base of the safety filters: the call template, input checks, the clock and the memory.

    Args:
        robot: the robot whose body and limits the filter protects.
        dt: control period [s]: the longest time one returned command may be held.
        body: the body model the filter keeps clear (default: the circumscribed disk); its outline is
            the one the unknown region is measured from.
        other_bodies: further body models the filter's rows may use (the CBF's ``narrow_body``): the
            reach of the farthest of them sets the stopping reach, the horizon and the memory.
        scan_timeout: largest scan age [s] the filter acts on; older scans make it brake.
        compensate_latency: move a scan of known age into the current base frame before filtering: by the
            velocities measured since it was taken (the trapezoid of each period's two measurements, whose error
            bound its points carry, A5), or, without the velocity, by the commands this filter returned since
            then (its base executes them, A5; at rest before the first call); see :meth:`latent_motion`.
        max_gap: widest run of invalid beams bridged by its neighbours [rad].
        side_tolerance: unknown space this close to exactly sideways does not block motion [rad].
        memory_range: remembered points farther than this from the base are forgotten [m];
            ``None``: the body's reach, the margin, the stopping distance from full speed and 1 m.
        memory_capacity: largest number of remembered points (0 disables the memory).
        time_constant: the base's first-order lag the filter allows for [s] (0: a base that
            reaches each command within the period).
        deadlock_time: how long the commands may make less than ``stall_progress`` of the
            nominal's progress, while the nominal asks to move, before the result reports a
            :class:`Deadlock` [s].
        min_obstacle_width: the narrowest obstacle [m] to see in time to brake clear of; ``None``
            for what the lidars resolve where the robot must see one (:attr:`smallest_obstacle`).
        budget: compute budget of one call [s] (``math.inf``: none), counted from the call's start
            (:mod:`safenav.filters.deadline`; the filter decides what it cuts short).
        clock: the clock the budget is measured with [s] (default ``time.perf_counter``; a simulated
            clock in tests).
    """

    name = "filter"
    margin: float = 0.0
    _kernels: Any = None
    """The compiled kernels (:func:`safenav.filters.kernels.select`) the subclass's config picks; ``None``: numpy."""

    def __init__(self, robot: RobotSpec, dt: float, *, body: BodyModel | None = None,
                 other_bodies: Sequence[BodyModel] = (), scan_timeout: float = 0.5,
                 compensate_latency: bool = True, max_gap: float = math.radians(5.0),
                 side_tolerance: float = math.radians(5.0), memory_range: float | None = None,
                 memory_capacity: int = 4000, time_constant: float = 0.0, deadlock_time: float = 1.5,
                 min_obstacle_width: float | None = None, budget: float = math.inf,
                 clock: Callable[[], float] | None = None) -> None:
        if not isinstance(robot, RobotSpec):
            raise InvalidConfig(f"robot must be a RobotSpec (see safenav.robot.preset), got {robot!r}")
        self.robot = robot
        self.dt = _checks.duration("dt", dt, high=MAX_DT)
        self.body = body if body is not None else BodyModel.disk(robot)
        #: Largest distance from the base origin to any body model the rows may use [m]: the stopping reach,
        #: the horizon and the memory are measured from it.
        self.reach = max(b.reach for b in (self.body, *other_bodies))
        self.scan_timeout = _checks.duration("scan_timeout", scan_timeout, high=1e9)
        self.compensate_latency = _checks.boolean("compensate_latency", compensate_latency)
        self.max_gap = _checks.number("max_gap", max_gap, low=0.0, high=2.0 * math.pi)
        self.side_tolerance = _checks.number("side_tolerance", side_tolerance, low=0.0, high=0.5 * math.pi)
        self.time_constant = _checks.number("time_constant", time_constant, low=0.0, high=MAX_DT)
        self.deadlock_time = _checks.positive("deadlock_time", deadlock_time)
        self.min_obstacle_width = (None if min_obstacle_width is None
                                   else _checks.positive("min_obstacle_width", min_obstacle_width))
        if self.min_obstacle_width is not None:
            for lidar in robot.lidars:
                # Beyond this from the lidar such an obstacle can hide between two beams; the robot must stay able
                # to stop within it, so it must lie beyond the body and the margin.
                lever = math.hypot(lidar.mount.x, lidar.mount.y)
                resolved = resolved_range(self.min_obstacle_width, lidar.angle_increment)
                if resolved - lever <= self.reach + self.margin:
                    raise InvalidConfig(
                        f"min_obstacle_width={self.min_obstacle_width!r} m: the {lidar.n_beams}-beam lidar "
                        f"{lidar.frame_id!r} sees an obstacle that narrow for sure only within {resolved:.3f} m of "
                        f"itself, inside the body and its margin (the robot could not move); expected more than "
                        f"{beam_gap(self.reach + self.margin + lever, lidar.angle_increment):.4f} m")
        self._stalled = 0.0
        self._progressing = 0.0
        self._scale = (float(robot.upper[0]), float(robot.upper[1]))
        capacity = _checks.integer("memory_capacity", memory_capacity, low=0)
        def stopping(speed: float) -> float:
            return speed * (self.dt + self.time_constant) + speed**2 / (2.0 * robot.a_max)

        if memory_range is None:
            memory_range = self.reach + self.margin + stopping(max(robot.v_max, -robot.v_min)) + 1.0
        self.memory = PointMemory(_checks.positive("memory_range", memory_range), capacity) if capacity else None
        #: Earlier scans that say which space no lidar sees now was seen free: a robot with a side no lidar
        #: sees translates towards it only that far (:meth:`seen_travel`). Kept with the memory.
        self.seen_free = SeenFree(float(memory_range)) if capacity else None
        # The seen-free grid reaches the body, the margin and a stop from full speed that way (forward, backward),
        # at least SEEN_FREE_TRAVEL and at most SEEN_FREE_MAX_TRAVEL (a robot that needs more backs slower).
        self._seen_free_extent = tuple(
            self.body.reach + self.margin + min(max(1.25 * stopping(side), SEEN_FREE_TRAVEL), SEEN_FREE_MAX_TRAVEL)
            for side in (robot.v_max, max(-robot.v_min, 0.0)))
        self._inside = inscribed_radius(robot)
        self._travel_view: View | None = None     # the view seen_travel answers for, and its answer
        self._travel: float | None = None
        self._last_view: View | None = None       # the last call's view
        self._last_time: float | None = None
        self._last_pose: Pose2D | None = None
        self._last_velocity: np.ndarray | None = None
        self._last_command = np.zeros(2)
        #: Each period since the earlier calls, the latest last: how long it lasted [s], the command returned at its
        #: start, and the velocity measured at its start and at its end (``None`` when not given).
        self._returned: collections.deque[Period] = collections.deque(maxlen=COMMAND_HISTORY)
        self._called = False
        self._recalled = (np.empty((0, 2)), np.empty(0))
        #: The clock the compute budget is measured with [s].
        self.clock: Callable[[], float] = clock if clock is not None else time.perf_counter
        self._budget = CallBudget(budget, self.clock)
        #: Set by a caller while the robot drives through a passage the body fits with
        #: :attr:`corridor_half_width` (the escape, through a gap): a filter that trades room for
        #: steering (the CBF's look-ahead) then uses its narrow settings. It never weakens a guarantee.
        self.passage = False
        #: Set by a caller while the robot drives through a gap narrower than :attr:`corridor_half_width`
        #: that the filter's narrowest body fits (:attr:`narrow_half_width`; the escape, through such a gap):
        #: a filter with a narrower body model for gaps (the CBF's ``narrow_body``) then uses it. The
        #: guarantee is the footprint's either way.
        self.narrow = False

    @property
    def corridor_half_width(self) -> float:
        """Half-width [m] of the narrowest straight corridor the filter lets the body drive along.

        The body's half-width (the disk's radius; a cover's or a polygon's lateral extent) plus the
        margin; a filter whose rows look further ahead (the CBF's ``min_lookahead``, with
        :attr:`passage` set) adds that. A passage narrower than twice this holds the body back.
        """
        return self.body.half_width + self.margin

    @property
    def narrowed(self) -> bool:
        """Whether the last answer was built for the filter's narrow body (see :attr:`narrow`)."""
        return False

    @property
    def narrow_half_width(self) -> float:
        """Half-width [m] of the narrowest straight corridor the filter lets the body drive along with
        :attr:`narrow` set (its narrowest body model); :attr:`corridor_half_width` for a filter with one body."""
        return self.corridor_half_width

    # ------------------------------------------------------------------ hooks

    def _on_reset(self) -> None:  # noqa: B027 - an optional hook: stateless filters need nothing
        """Forget the filter's own state (warm starts, stored plans)."""

    def _on_brake(self) -> None:  # noqa: B027 - an optional hook
        """Called when the filter brakes instead of filtering (stale, bad input, no data, hard rows)."""

    def _braking_start(self, velocity: np.ndarray | None) -> np.ndarray | None:
        """Where braking starts from: :meth:`command_origin` (``None``: stop at once, an instant base)."""
        return self.command_origin(velocity)

    def command_origin(self, velocity: np.ndarray | None) -> np.ndarray | None:
        """The centre of the box of commands the next call may return [m/s, rad/s] (``None``: no box).

        The measured ``velocity``: the base reaches each command within the period, so the box is
        what its acceleration limits reach from there in one period. For a lagging base
        (``time_constant > 0``), after the first call, the last command returned: a lagging base
        is commanded a sequence that slews at the acceleration limits, and its velocity follows
        that sequence ``time_constant`` behind, braking at ``a_max`` once the lag has passed, as
        the filters' braking rows and plans assume. A box centred on the measured velocity would
        let each command lead the velocity by one period's change at most, and the base would
        brake at only ``(1 - exp(-dt / time_constant)) a_max``: too slowly for those rows
        (``tests/filters/test_safety_holes.py::test_a_lagging_base_brakes_at_its_limit_behind_the_commands``).
        """
        if velocity is None:
            return None
        if self.time_constant > 0.0 and self._called:
            return self._last_command
        return velocity

    @abc.abstractmethod
    def _filter(self, u_nom: np.ndarray, view: View, velocity: np.ndarray | None, period: float) -> FilterResult:
        """Filter a finite ``u_nom`` with fresh, informative scans.

        Args:
            u_nom: the nominal command.
            view: the obstacle points and unknown region in the current base frame.
            velocity: the measured velocity, or ``None``.
            period: how long the command will be held [s] (``dt``, or longer when calls are late).
        """

    # ------------------------------------------------------------------ the template

    def reset(self) -> None:
        """Forget everything from earlier calls (call between episodes): memory, clock, warm starts."""
        if self.memory is not None:
            self.memory.clear()
        if self.seen_free is not None:
            self.seen_free.clear()
        self._travel_view, self._travel, self._last_view = None, None, None
        self._last_time = None
        self._last_pose = None
        self._last_velocity = None
        self._last_command = np.zeros(2)
        self._returned.clear()
        self._called = False
        self._stalled = 0.0
        self._progressing = 0.0
        self.passage = False
        self.narrow = False
        self._on_reset()

    def __call__(self, u_nom: Any, scan: LaserScan | Sequence[LaserScan], **kwargs: Any) -> FilterResult:
        return self.filter(u_nom, scan, **kwargs)

    def filter(
        self,
        u_nom: Any,
        scan: LaserScan | Sequence[LaserScan],
        *,
        velocity: Any = None,
        pose: Pose2D | Sequence[float] | None = None,
        scan_age: float | Sequence[float] | None = None,
        now: float | None = None,
    ) -> FilterResult:
        """Filter one nominal command.

        Args:
            u_nom: nominal command ``(v [m/s], omega [rad/s])``.
            scan: the latest scan, or the latest scan of each lidar; a scan built without a
                mount gets the robot's lidar mount.
            velocity: measured ``(v [m/s], omega [rad/s])`` (odometry); when given, the
                returned command is reachable within one period under the acceleration limits,
                and remembered points are carried by it.
            pose: the odometry pose ``(x [m], y [m], yaw [rad])`` in any fixed frame; when given,
                remembered points are carried by its change since the previous call (exact).
            scan_age: how old each scan is [s]; past ``scan_timeout`` the filter brakes. With
                ``compensate_latency``, a scan is first moved into the current base frame by the motion
                since it was taken (:meth:`latent_motion`: the velocities measured since then, with their
                error bound added to its points, or without ``velocity`` the commands returned since then).
            now: the current time [s]; with the scans' stamps it gives their ages, and between
                calls the period (a call later than ``dt`` is planned for the measured period
                and reported ``LATE``).

        Returns:
            The command to send and what the filter did.

        Raises:
            InvalidCommand: ``u_nom`` or ``velocity`` is not a pair of numbers, or ``pose`` is not three (a pose
                that is not finite is an odometry glitch: the call brakes with ``BAD_INPUT`` and carries the
                remembered points as without the pose).
            InvalidScanType: ``scan`` is not a LaserScan (or a sequence of them).
        """
        start = time.perf_counter()
        budget = self._budget
        began = budget.start is None     # (a filter may begin it earlier in its call)
        if began:
            budget.begin()
        try:
            nominal = as_command(u_nom, "u_nom")
            scans = self._match(as_scans(scan))
            current = None if velocity is None else as_command(velocity, "velocity")
            odometry, glitch = _odometry(pose)   # a glitch: carried as without the pose
            period, clock_note = self._clock(now)
            base_note = self._check_base(current, period if period is not None else self.dt)
            if self._called:   # the last command, held since the previous call, and the velocities measured then
                self._returned.append(self._period_since(period, current))
            self._carry(period if period is not None else self.dt, current, odometry)
            result = self._screened(nominal, scans, current, scan_age, now, period,
                                    "; ".join(note for note in (clock_note, base_note) if note), glitch)
            result = self._watch_progress(result)
            self._last_command = np.array(result.u, dtype=float)
            self._called = True
        finally:
            if began:
                budget.end()
        object.__setattr__(result, "filter_time", time.perf_counter() - start)
        return result

    @property
    def budget(self) -> float:
        """The compute budget of one call [s] (``math.inf``: none)."""
        return self._budget.budget

    def _watch_progress(self, result: FilterResult) -> FilterResult:
        """Count how long the nominal has asked to move without progress; report a deadlock past the limit."""
        v_scale, omega_scale = self._scale
        v_nom, omega_nom = float(result.u_nom[0]), float(result.u_nom[1])
        if not (math.isfinite(v_nom) and math.isfinite(omega_nom)):
            self._stalled = 0.0
            return result
        # The nominal clipped to the limits, both axes as fractions of them (see progress()).
        n_v = max(-1.0, min(1.0, v_nom / v_scale))
        n_omega = max(-1.0, min(1.0, omega_nom / omega_scale))
        size = n_v * n_v + n_omega * n_omega
        kept = (float(result.u[0]) / v_scale * n_v + float(result.u[1]) / omega_scale * n_omega) / size \
            if size > 0.0 else 1.0
        period = result.period if math.isfinite(result.period) else self.dt
        if max(abs(n_v), abs(n_omega)) <= STILL:
            self._stalled = self._progressing = 0.0
            return result
        if kept >= STALL_PROGRESS:
            self._progressing += period
            if self._progressing >= PROGRESS_RESET_TIME - 1e-9:
                self._stalled = 0.0
            return result
        self._progressing = 0.0
        self._stalled += period
        if self._stalled < self.deadlock_time - 1e-9:
            return result
        reason = result.reason
        deadlock = Deadlock(self._stalled, None if reason is None else reason.point,
                            "limits" if reason is None else reason.family)
        return _replace(result, deadlock=deadlock)

    def _match(self, scans: tuple[LaserScan, ...]) -> tuple[LaserScan, ...]:
        """The scans in the robot's base frame (the robot's lidar mount for scans without one)."""
        match = getattr(self.robot, "match_scan", None)
        return scans if match is None else tuple(match(scan) for scan in scans)

    def _clock(self, now: float | None) -> tuple[float | None, str]:
        """The measured time since the previous call [s] (``None`` when unknown), and a note for the result."""
        if now is None:
            return None, ""
        now = _checks.number("now", now)
        last, self._last_time = self._last_time, now
        if last is None:
            return None, ""
        elapsed = now - last
        if elapsed < 0.0:
            return None, f"the clock went back by {-elapsed:.3f} s; the period is unknown for this call"
        return elapsed, ""

    def _check_base(self, velocity: np.ndarray | None, elapsed: float) -> str:
        """Whether the base followed the last command as the filter assumes; a warning when it did not.

        A base covered by the guarantee keeps its velocity between the previous measurement and
        the command it was sent, and ends the period at the command (``time_constant = 0``) or
        at most ``exp(-elapsed / time_constant)`` of the way back (a first-order lag).
        """
        previous = self._last_velocity
        if velocity is None or previous is None or not self._called:
            return ""
        measured = (float(velocity[0]), float(velocity[1]))
        if not _finite(measured):
            return ""
        command = (float(self._last_command[0]), float(self._last_command[1]))
        left = math.exp(-elapsed / self.time_constant) if self.time_constant > 0.0 else 0.0
        robot = self.robot
        for axis, tolerance in ((0, 0.25 * robot.a_max * self.dt + 0.01), (1, 0.25 * robot.alpha_max * self.dt + 0.02)):
            start, target, now = float(previous[axis]), command[axis], measured[axis]
            if abs(now - target) > left * abs(start - target) + tolerance or not (
                    min(start, target) - tolerance <= now <= max(start, target) + tolerance):
                return (f"the base does not follow its commands as assumed: measured "
                        f"{np.round(velocity, 3).tolist()} after {elapsed:.3f} s from "
                        f"{np.round(previous, 3).tolist()} towards {np.round(command, 3).tolist()} "
                        f"(time_constant={self.time_constant}); the guarantee needs time_constant set to the "
                        f"base's lag")
        return ""

    def _carry(self, elapsed: float, velocity: np.ndarray | None, odometry: Pose2D | None) -> None:
        """Move the remembered points by the motion since the previous call (``odometry``: the pose now, finite)."""
        moving = self._called and ((self.memory is not None and len(self.memory)) or
                                   (self.seen_free is not None and len(self.seen_free)))
        if moving:
            motion = self._motion(elapsed, velocity, odometry)
            if self.memory is not None and len(self.memory):
                self.memory.carry(*motion)
            if self.seen_free is not None and len(self.seen_free):
                self.seen_free.carry(*motion)
        self._last_pose = odometry
        self._last_velocity = None if velocity is None or not _finite(velocity) else velocity.copy()

    def _motion(self, elapsed: float, velocity: np.ndarray | None, odometry: Pose2D | None
                ) -> tuple[Pose2D, tuple[float, float]]:
        """The base's motion since the previous call [m, m, rad] and the bound of its error (A5) [m, rad]:
        by the odometry pose's change (exact), else between the two velocity measurements, else by the last
        command (an instant base)."""
        if odometry is not None and self._last_pose is not None:
            return self._last_pose.inverse().compose(odometry), (0.0, 0.0)
        if self._last_velocity is not None and velocity is not None and _finite(velocity):
            return dead_reckoning(self._last_velocity, velocity, elapsed)
        return unicycle_step(Pose2D(), float(self._last_command[0]), float(self._last_command[1]), elapsed), (0.0, 0.0)

    @property
    def blind_travel(self) -> float:
        """How far [m] the base may translate towards a side no lidar sees, as of the last call
        (:meth:`seen_travel` of its view): 0 before the first call, for a robot without such a side,
        without a memory, and until earlier scans saw that side free."""
        return self.seen_travel(self._last_view) if self._last_view is not None else 0.0

    def seen_travel(self, view: View) -> float:
        """How far [m] the base may translate towards the side no lidar sees in ``view`` (its frontier's
        ``forward`` or ``backward``) with the body and the margin in space earlier scans saw free
        (:meth:`~safenav.filters.perception.SeenFree.travel`); 0 without such a side or such scans.

        Computed at most once per call, and only when asked: a filter asks when its command box lets the
        base move that way.
        """
        if view is not self._travel_view:
            self._travel_view, self._travel = view, None
        if self._travel is None:
            frontier = view.frontier
            travel = 0.0
            if (frontier.forward or frontier.backward) and self.seen_free is not None:
                extent = max(self._seen_free_extent[0] if frontier.forward else 0.0,
                             self._seen_free_extent[1] if frontier.backward else 0.0)
                travel = self.seen_free.travel(view.scans, self._inside, self.body.reach + self.margin, extent)
            self._travel = travel
        return self._travel

    def remembered_points(self, *, velocity: Any = None, pose: Pose2D | Sequence[float] | None = None,
                          now: float | None = None) -> np.ndarray:
        """The remembered points ``(M, 2)`` [m] in the base frame of a call made now with these arguments.

        A call carries the memory into its own frame when it begins (by the odometry pose's change,
        else the measured velocities, else the last command: :meth:`filter`); this says where that
        call will find the points, without changing the filter. A wrapper that looks at the
        memory before calling the filter (the escape) reads it here. Every remembered point,
        including those the next scan will see again or contradict. Empty before the first call
        and without a memory.

        Args:
            velocity: as :meth:`filter`'s.
            pose: as :meth:`filter`'s.
            now: as :meth:`filter`'s.

        Raises:
            InvalidCommand: ``velocity`` is not a pair of numbers, or ``pose`` is not three.
            InvalidConfig: ``now`` is not a number.
        """
        current = None if velocity is None else as_command(velocity, "velocity")
        now = None if now is None else _checks.number("now", now)
        odometry = _odometry(pose)[0]     # as the call does: a glitch is carried as without the pose
        if self.memory is None or not self._called or len(self.memory) == 0:
            return np.empty((0, 2))
        elapsed = self.dt
        if now is not None and self._last_time is not None:
            since = now - self._last_time
            elapsed = since if since >= 0.0 else elapsed
        return self.memory.moved(self._motion(elapsed, current, odometry)[0])

    def _screened(self, nominal: np.ndarray, scans: tuple[LaserScan, ...], current: np.ndarray | None,
                  scan_age: Any, now: float | None, period: float | None, clock_note: str,
                  glitch: Pose2D | None = None) -> FilterResult:
        """The checks every filter needs around :meth:`_filter` (see :meth:`filter`; ``glitch``: the odometry pose
        given, when it is not finite)."""
        warnings = (clock_note,) if clock_note else ()
        # The command is held until the next call: dt, or a late call's measured period (A3). Braking too is
        # planned for that period: the nearest stop the acceleration limits reach within it.
        late = period is not None and period > self.dt * (1.0 + LATE_TOLERANCE)
        held = period if late else self.dt
        if current is not None and not _finite(current):
            return self._brake(nominal, None, FilterStatus.BAD_INPUT, "bad_input",
                               f"velocity is not finite: {current.tolist()}", warnings=warnings, period=held)
        if glitch is not None:
            carried = "the measured velocities" if current is not None else "the commands"
            return self._brake(nominal, current, FilterStatus.BAD_INPUT, "bad_input",
                               f"pose is not finite: {tuple(glitch)}; the remembered points were carried by {carried}",
                               warnings=warnings, period=held)
        ages, stale = self._ages(scans, scan_age, now)
        if stale:
            return self._brake(nominal, current, FilterStatus.STALE, "stale", stale, warnings=warnings, period=held)
        if not _finite(nominal):
            return self._brake(nominal, current, FilterStatus.BAD_INPUT, "bad_input",
                               f"u_nom is not finite: {nominal.tolist()}", warnings=warnings, period=held)
        classify(scans, self._kernels)
        if all(scan.n_informative == 0 for scan in scans):
            beams = sum(scan.n_beams for scan in scans)
            return self._brake(nominal, current, FilterStatus.NO_DATA, "no_data",
                               f"none of the {beams} beams is informative (all NaN or out of range)",
                               warnings=warnings, period=held)
        scans, error = self._compensated(scans, current, ages)
        view = self._observe(scans, held, error)
        result = self._filter(nominal, view, current, held)
        self._remember(view, error)
        result = self._told_horizon(result, view)
        if not _finite(result.u):
            return self._brake(nominal, current, FilterStatus.FALLBACK, "solver",
                               f"the filter produced a non-finite command {result.u.tolist()}", warnings=warnings,
                               period=held)
        extras: dict[str, Any] = dict(period=held)
        if warnings or result.warnings:
            extras["warnings"] = result.warnings + warnings
        if late and result.status is FilterStatus.OK:
            late_reason = Reason("late", f"called {period:.3f} s after the previous call, longer than dt = "
                                         f"{self.dt:.3f} s; planned for {period:.3f} s")
            extras.update(status=FilterStatus.LATE, reason=late_reason if result.reason is None else result.reason,
                          message=str(late_reason) + (f"; {result.message}" if result.message else ""))
        return _replace(result, **extras)

    def _ready(self, kernels_name: str) -> None:
        """The end of a filter's construction: its kernels (``kernels`` of its config, compiled now rather than in a
        control call) and, for the first filter of a process, the heap frozen (:func:`safenav.filters.heap.settle`:
        no full garbage collection then scans what is alive now)."""
        self._kernels = kernels.select(kernels_name)
        heap.settle()

    def _period_since(self, elapsed: float | None, velocity: np.ndarray | None) -> Period:
        """The period since the previous call: its length [s] (``dt`` when the time is not given), the command
        returned then, and the velocities measured then and now."""
        end = None if velocity is None or not _finite(velocity) else np.array(velocity, dtype=float)
        return Period(elapsed if elapsed is not None else self.dt, self._last_command.copy(), self._last_velocity, end)

    def _compensated(self, scans: tuple[LaserScan, ...], velocity: np.ndarray | None,
                     ages: Sequence[float | None], pending: Period | None = None
                     ) -> tuple[tuple[LaserScan, ...], tuple[float, float]]:
        """The scans moved into the current base frame by the motion since each was taken (``compensate_latency``),
        and the bound of that motion's error (A5, the largest over the scans): see :meth:`latent_motion`.
        ``pending``: the period since the previous call, not yet in the history (a look before the call).

        A scan of a turning lidar (``time_increment`` not 0) is moved beam by beam: each beam by the motion since
        its own time (:attr:`~safenav.scan.LaserScan.beam_times`, after the stamp), as the lidar pose of its middle
        beam (the mount) and each beam's pose relative to it (:attr:`~safenav.scan.LaserScan.sweep_motion`); the
        error bound is that of its oldest beam, the first."""
        if not self.compensate_latency:
            return scans, (0.0, 0.0)
        moved, error = [], (0.0, 0.0)
        for scan, age in zip(scans, ages, strict=True):
            if age is None or age <= 0.0:
                moved.append(scan)
                continue
            parts = self._latent_parts(age, velocity, pending)
            motion, (translation, rotation) = _composed(parts)
            if scan.time_increment == 0.0 or scan.n_beams == 1:
                moved.append(scan.with_mount(motion.inverse().compose(scan.mount)))
            else:
                moved.append(_swept(scan, parts, np.maximum(age - scan.beam_times, 0.0), self._kernels))
            error = (max(error[0], translation), max(error[1], rotation))
        return tuple(moved), error

    def latent_motion(self, age: float, velocity: np.ndarray | None, pending: Period | None = None
                      ) -> tuple[Pose2D, tuple[float, float]]:
        """The base's motion over the last ``age`` [s], and the bound of its error (A5) [m, rad].

        Walking back through the periods since the earlier calls (the latest first; the part of a period that the
        age covers is its end): with the velocity measured at both ends of a period, the trapezoid of the two
        measurements over that part, off by at most half their difference times the part
        (:func:`~safenav.filters.perception.dead_reckoning`: the velocity moves monotonically within a period,
        A4); without the velocity, the command returned at its start, which the base executes (A5: exact). The
        errors add up as the memory's do (a turn error also times the travel of every later part). Before the
        first call, or past the kept periods, the base is taken to have held ``velocity`` (at rest without
        one), as a scan taken before the filter started was.
        """
        return _composed(self._latent_parts(age, velocity, pending))

    def _latent_parts(self, age: float, velocity: np.ndarray | None, pending: Period | None
                      ) -> list[tuple[float, float, float, tuple[float, float]]]:
        """The parts of the last ``age`` [s] as :meth:`latent_motion` walks them, the latest first: each part's
        length [s], the velocity held over it [m/s, rad/s] and the bound of its motion's error [m, rad]."""
        periods = [*self._returned, *([pending] if pending is not None else [])]
        parts: list[tuple[float, float, float, tuple[float, float]]] = []
        left = float(age)
        for period in reversed(periods):
            if left <= 0.0:
                break
            part = min(float(period.held), left)
            if period.start is not None and period.end is not None:
                parts.append((part, *reckoning(period.start, period.end, part)))
            else:
                parts.append((part, float(period.command[0]), float(period.command[1]), (0.0, 0.0)))
            left -= part
        if left > 0.0 and velocity is not None:
            parts.append((left, float(velocity[0]), float(velocity[1]), (0.0, 0.0)))
        return parts

    def current_scans(self, scan: LaserScan | Sequence[LaserScan], *, velocity: Any = None,
                      scan_age: float | Sequence[float] | None = None, now: float | None = None
                      ) -> tuple[LaserScan, ...]:
        """The scans as a call with these arguments uses them: in the base frame, and with a known age moved
        into the current base frame (:meth:`latent_motion`, when ``compensate_latency``). Changes nothing; a
        wrapper that looks at the scans before calling the filter (the escape) reads them here. Scans the call
        would reject as stale, and a non-finite velocity, are returned unmoved.

        Raises:
            InvalidCommand: ``velocity`` is not a pair of numbers.
            InvalidScanType: ``scan`` is not a LaserScan (or a sequence of them), or ``scan_age`` is bad.
        """
        scans = self._match(as_scans(scan))
        current = None if velocity is None else as_command(velocity, "velocity")
        if current is not None and not _finite(current):
            return scans
        ages, stale = self._ages(scans, scan_age, now)
        pending = None
        if self._called:    # the call appends the period since the previous call
            held = None
            if now is not None and self._last_time is not None and now >= self._last_time:
                held = float(now) - self._last_time
            pending = self._period_since(held, current)
        return scans if stale else self._compensated(scans, current, ages, pending)[0]

    def _ages(self, scans: tuple[LaserScan, ...], scan_age: Any, now: float | None
              ) -> tuple[list[float | None], str]:
        """Each scan's age [s] and, when one cannot be trusted, why (empty when all are fresh)."""
        if scan_age is not None:
            given = [scan_age] * len(scans) if not isinstance(scan_age, Sequence) else list(scan_age)
            if len(given) != len(scans):
                raise InvalidScanType(f"scan_age must give one age per scan ({len(scans)}), got {scan_age!r}")
            for age in given:
                if not _checks.is_real(age):
                    raise InvalidScanType(f"scan_age must be a number of seconds (or one per scan), got {age!r}")
            ages: list[float | None] = [float(age) for age in given]
        elif now is not None:
            ages = []
            for scan in scans:
                if scan.stamp is None:
                    return [], (f"scan from {scan.frame_id!r} has no stamp, so its age cannot be checked against "
                                f"now={now!r}; pass scan_age= or stamped scans")
                ages.append(float(now) - scan.stamp)
        else:
            return [None] * len(scans), ""
        for scan, age in zip(scans, ages, strict=True):
            if age is None:
                continue
            if math.isnan(age):
                return ages, f"scan from {scan.frame_id!r} has an unknown age (NaN)"
            if age < -FUTURE_TOLERANCE:
                return ages, (f"scan from {scan.frame_id!r} is stamped {-age:.3f} s in the future (clocks out of "
                              f"sync, or a stamp in the wrong unit)")
            if age > self.scan_timeout:
                return ages, f"scan from {scan.frame_id!r} is {age:.3f} s old; timeout {self.scan_timeout:.3f} s"
        return ages, ""

    def horizon_reach(self, period: float | None = None) -> float:
        """How far from the base origin [m] the edge of what a lidar sees is an obstacle to a call of ``period``.

        Twice the stopping path of the fastest body point (reacting for the period, one more and the
        lag, then braking at the acceleration limits), plus the body and the margin: a lidar whose
        ``range_max`` reaches farther gives no horizon points
        (:func:`~safenav.filters.perception.horizon_points`).
        """
        robot = self.robot
        held = self.dt if period is None else max(float(period), self.dt)
        speed, lever = max(robot.v_max, -robot.v_min), self.reach
        reaction = held + self.dt + self.time_constant
        stop = (speed + lever * robot.omega_max) * reaction + speed**2 / (2.0 * robot.a_max) \
            + lever * robot.omega_max**2 / (2.0 * robot.alpha_max)
        return self.reach + self.margin + 2.0 * stop

    @property
    def smallest_obstacle(self) -> float:
        """The narrowest obstacle [m] the filter sees in time to keep its guarantee (assumption A2).

        An obstacle can hide between two neighbouring beams wherever they are farther apart than it is
        wide, and comes into view only nearer. The robot must see an obstacle by the time it is
        :meth:`horizon_reach` away (within the body, the margin and twice the stopping path) to stay
        able to brake clear of it, and within 1 m to keep the margin (the default margin covers the
        gap between two beams there). So this is the gap between two beams of the coarsest lidar at
        ``max(1 m, horizon_reach + its mount's offset)``, or ``min_obstacle_width`` when that is given
        and smaller: the filter then treats the range beyond which such an obstacle can hide as a
        horizon it stays able to stop within (:func:`~safenav.filters.perception.horizon_points`).
        """
        reach = self.horizon_reach()
        resolved = max(beam_gap(max(1.0, reach + math.hypot(lidar.mount.x, lidar.mount.y)), lidar.angle_increment)
                       for lidar in self.robot.lidars)
        return resolved if self.min_obstacle_width is None else min(resolved, self.min_obstacle_width)

    @property
    def shadow_jump(self) -> float:
        """How much farther [m] a beam's neighbour must read for its hit to be an occluder's edge
        (:func:`~safenav.filters.perception.shadow_points`): four range-noise deviations and the points' spacing
        (a surface seen obliquely or through noise is not an edge)."""
        return 4.0 * max(scan_noise(self.robot), 0.0) + SHADOW_SPACING

    def _observe(self, scans: tuple[LaserScan, ...], period: float | None = None,
                 error: tuple[float, float] = (0.0, 0.0)) -> View:
        """Obstacle points (current, the edge of what the lidars see, remembered) and the unknown region of a call.

        ``error``: the bound ``(e_translation [m], e_rotation [rad])`` of where the scans were moved into the
        current base frame (:meth:`latent_motion`): a point ``d`` from the base origin is uncertain by
        ``e_translation + d e_rotation``, and so is where it shows a remembered point again or free."""
        current = beam_points(scans, self.body, compiled=self._kernels)
        reach = self.horizon_reach(period)
        horizon = horizon_points(scans, reach, self.min_obstacle_width)
        shadows = shadow_points(scans, reach, self.shadow_jump, self._kernels)
        if shadows.shape[0]:
            horizon = np.vstack((horizon, shadows)) if horizon.shape[0] else shadows
        seen = np.vstack((current, horizon)) if horizon.shape[0] else current
        seen_uncertainty = motion_spread(seen, error) if any(error) else np.zeros(seen.shape[0])
        frontier = unknown_region(scans, self.body, self.max_gap, self.side_tolerance)
        if self.memory is None:
            return View(scans, seen, seen_uncertainty, current.shape[0], frontier, horizon.shape[0])
        if frontier.complete and not any(seam_gap(scan) > 0.0 for scan in scans):
            # Every direction round the body is seen now: a remembered point is either seen again or
            # occluded, and an occluded point cannot be the first to come within the margin. (Not where a turning
            # lidar's full turn left a gap at its seam, the base turning against its spin: there the memory holds
            # what the scan did not look at.)
            recalled, uncertainty = np.empty((0, 2)), np.empty(0)
        else:
            noise = max(scan_noise(self.robot), 0.0)
            recalled, uncertainty = self.memory.recall(scans, tolerance=2.0 * noise + 0.01,
                                                       scan_error=_placed(scans, error), compiled=self._kernels)
        self._recalled = (recalled, uncertainty)
        points = np.vstack((seen, recalled)) if recalled.shape[0] else seen
        return View(scans, points, np.concatenate((seen_uncertainty, uncertainty)), current.shape[0],
                    frontier, horizon.shape[0])

    @staticmethod
    def _told_horizon(result: FilterResult, view: View) -> FilterResult:
        """``result``, its reason saying so when the point behind it is the edge of what the lidars see."""
        reason = result.reason
        if reason is None or reason.point is None or view.n_horizon == 0:
            return result
        horizon, (x, y) = view.horizon, reason.point
        if not ((horizon[:, 0] == x) & (horizon[:, 1] == y)).any():
            return result
        told = Reason(reason.family, f"{reason.detail}; the point is where what the lidars see ends (range_max, "
                                     f"the edge of what an obstacle hides, or where an obstacle of "
                                     f"min_obstacle_width can hide between two beams): the robot keeps able to "
                                     f"stop within it", reason.point)
        message = result.message.replace(str(reason), str(told), 1) if result.message else str(told)
        return _replace(result, reason=told, message=message)

    def _remember(self, view: View, error: tuple[float, float] = (0.0, 0.0)) -> None:
        """Keep the call's points (with their uncertainty) and, for a robot with a side no lidar sees, its scans as
        space seen free; not a scan moved by the measured velocities, whose place is uncertain (``error``), nor one
        whose beams were measured from several places (a turning lidar's on a moving base)."""
        self._last_view = view
        if self.memory is not None:
            recalled, uncertainty = self._recalled
            self.memory.store(view.points[: view.n_current], recalled, uncertainty,
                              view.uncertainty[: view.n_current])
        if (self.seen_free is not None and (view.frontier.forward or view.frontier.backward) and not any(error)
                and not _swept_in_place(view.scans)):
            self.seen_free.store(view.scans, max(scan_noise(self.robot), 0.0))

    @staticmethod
    def current_frame(scan: LaserScan, velocity: np.ndarray, scan_age: float) -> LaserScan:
        """The scan re-expressed in the current base frame, ``scan_age`` [s] after it was taken.

        Assumes the base held ``velocity`` ``(v [m/s], omega [rad/s])`` since then (the world
        is static): the base has moved by the exact arc ``unicycle_step(0, v, omega, age)``,
        so the laser now sits at the inverse of that motion composed with its mount. Only
        the mount pose changes; the readings are untouched. (A filter call moves a late scan by
        :meth:`latent_motion`, the velocities measured since it was taken, with an error bound.)
        """
        moved = unicycle_step(Pose2D(), float(velocity[0]), float(velocity[1]), scan_age)
        return scan.replace(mount=moved.inverse().compose(scan.mount))

    def _brake(self, nominal: np.ndarray, velocity: np.ndarray | None, status: FilterStatus, family: str,
               detail: str, **details: Any) -> FilterResult:
        """A result that brakes as hard as the acceleration limits allow (from ``velocity`` when known) over the
        period the command is held (``details["period"]`` [s]: the call's, ``dt`` when not given): the command
        nearest a stop that the limits reach within it."""
        self._on_brake()
        start = self._braking_start(velocity)
        period = details.setdefault("period", self.dt)
        u = self.robot.brake(start, period if start is not None else None)
        return FilterResult(u=u, u_nom=nominal, status=status, reason=Reason(family, detail), **details)


def _composed(parts: list[tuple[float, float, float, tuple[float, float]]]) -> tuple[Pose2D, tuple[float, float]]:
    """The motion over :meth:`SafetyFilter._latent_parts` (the latest first) and the bound of its error (A5)."""
    motion, translation, rotation, drag = Pose2D(), 0.0, 0.0, 0.0
    for part, v, omega, (arc_translation, arc_rotation) in reversed(parts):     # the oldest part first
        arc = unicycle_step(Pose2D(), v, omega, part)
        drag += rotation * math.hypot(arc.x, arc.y)
        translation += arc_translation
        rotation += arc_rotation
        motion = motion.compose(arc)
    return motion, (translation + drag, rotation)


def _placed(scans: tuple[LaserScan, ...], error: tuple[float, float]) -> tuple[float, float]:
    """How uncertain [m, rad] the scans' place in the base frame is where the memory looks at a point from the pose of
    the beam that looks at it (:func:`~safenav.filters.perception.sweep_shift`): the motion's ``error`` plus, for a
    turning lidar, one beam's motion (:func:`~safenav.filters.perception.sweep_step`)."""
    steps = [sweep_step(scan) for scan in scans if scan.sweep_motion is not None]
    if not steps:
        return error
    return error[0] + max(item[0] for item in steps), error[1] + max(item[1] for item in steps)


def _swept_in_place(scans: tuple[LaserScan, ...]) -> bool:
    """Whether a turning lidar measured the beams of some scan from more than one place (the base moved)."""
    return any(scan.sweep_motion is not None and any(scan.sweep_error) for scan in scans)


def _swept(scan: LaserScan, parts: list[tuple[float, float, float, tuple[float, float]]], ages: np.ndarray,
           compiled: Any = None) -> LaserScan:
    """``scan`` in the current base frame, each beam moved by the motion over the last ``ages[i]`` [s] (along
    ``parts``, the latest first): on the lidar pose of its middle beam, with each beam's pose relative to it
    (:func:`~safenav.filters.perception.sweep_poses`)."""
    reference, relative = sweep_poses(ages, [(part, v, omega) for part, v, omega, _ in parts], scan.mount, compiled)
    return scan.with_mount(reference).with_sweep_motion(relative)


def scan_noise(robot: RobotSpec) -> float:
    """Largest range noise standard deviation of the robot's lidars [m]."""
    return max(lidar.noise_std for lidar in getattr(robot, "lidars", (robot.lidar,)))


def _replace(result: FilterResult, **changes: Any) -> FilterResult:
    """``result`` with some fields changed, in place: it is a result this call made and nobody holds yet."""
    for name, value in changes.items():
        object.__setattr__(result, name, value)
    return result

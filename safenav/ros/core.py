"""The safety node without its middleware: inputs, the timer step, state and diagnostics.

:class:`SafetyCore` is everything the ROS 2 and ROS 1 nodes share. A transport
(:mod:`safenav.ros.ros2`, :mod:`safenav.ros.ros1`) only subscribes, keeps time and publishes:
it hands every message to :meth:`SafetyCore.on_scan`, :meth:`~SafetyCore.on_command` and
:meth:`~SafetyCore.on_odometry`, calls :meth:`~SafetyCore.tick` every control period (and, with
``step_on_scan``, when a scan arrives), and implements :class:`Outputs`.

What one tick does, in order of precedence:

==========================================  ===============  =======================================
situation                                   ``status``       command published
==========================================  ===============  =======================================
no ``cmd_vel_in`` received yet              ``idle``         none
``cmd_vel_in`` older than its timeout       ``idle``         zero once, then none
``~/enable`` set false                      ``disabled``     the input, unchanged
a source never received                     ``waiting``      brake
a source's last message malformed           ``bad_message``  brake
a source older than its timeout             ``stale``        brake
odometry missing, stale or malformed        ``stale``        brake
otherwise                                   the filter's     the filter's command
==========================================  ===============  =======================================

"Brake" is the command nearest a stop that the acceleration limits allow from the measured
velocity (zero without odometry). A zero command is published once and then the node stays
silent until the command changes (the collision monitor's ``stop_pub_timeout``), so a
velocity multiplexer behind it can hand over. The node never raises from a callback: a bad
message brakes, is logged once per cause, and is reported in the state.

One module on purpose: the inputs, the precedence table above and the state they produce are one
contract that both transports call; split, each half would need the other's private bookkeeping
(latest messages, the causes logged, the last command published).
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, NamedTuple, Protocol

import numpy as np

from safenav.errors import LidarMismatch, SafeNavError
from safenav.filters import BRAKING_STATUSES, FilterResult, SafetyFilter, escaped, make_filter
from safenav.filters.escape import Escape
from safenav.geometry import Pose2D
from safenav.robot import LidarSpec, RobotSpec
from safenav.ros.messages import pose_of, twist_of
from safenav.ros.params import NodeConfig
from safenav.ros.sources import SOURCE_TYPES, Source
from safenav.scan import LaserScan

__all__ = ["CauseLog", "NodeState", "Outputs", "SafetyCore", "Timed"]

DIAGNOSTICS_PERIOD = 1.0
"""Seconds between two ``/diagnostics`` messages while the status, its level and the escape do not change."""

LATE_FACTOR = 1.5
"""A tick later than this many control periods after the previous one is reported as late."""


# Statuses of the node itself (the filter's are FilterStatus values).
IDLE, DISABLED, WAITING, BAD_MESSAGE, STALE, ERROR = "idle", "disabled", "waiting", "bad_message", "stale", "error"
_ERROR_STATUSES = frozenset({WAITING, BAD_MESSAGE, STALE, ERROR, *(s.value for s in BRAKING_STATUSES)})
_WARN_STATUSES = frozenset({IDLE, DISABLED, "recovering", "slack", "late"})


class Timed(NamedTuple):
    """A value and the node time it arrived [s]; ``perf`` is ``time.perf_counter()`` at arrival."""

    value: Any
    time: float
    perf: float


class Odometry(NamedTuple):
    """What the node keeps of a ``nav_msgs/Odometry`` message."""

    velocity: tuple[float, float]
    """``(v [m/s], omega [rad/s])`` in the base frame (``twist.twist``)."""
    pose: Pose2D
    """``(x [m], y [m], yaw [rad])`` in the odometry frame (``pose.pose``)."""


class CauseLog:
    """Logs each cause of trouble once, and once more when it clears.

    Args:
        warn: logs a warning line.
        info: logs an information line.
    """

    def __init__(self, warn: Callable[[str], None], info: Callable[[str], None]) -> None:
        self._warn = warn
        self._info = info
        self.active: dict[str, str] = {}

    def report(self, cause: str, text: str) -> None:
        """Log ``text`` unless ``cause`` is already active."""
        if cause not in self.active:
            self._warn(text)
        self.active[cause] = text

    def clear(self, cause: str) -> None:
        """End ``cause`` (logged once) so that it is logged again if it comes back."""
        if self.active.pop(cause, None) is not None:
            self._info(f"cleared: {cause}")


@dataclass(frozen=True)
class NodeState:
    """What the node did at one tick: published on ``~/state`` (as JSON) and in ``/diagnostics``.

    Attributes:
        time: node time of the tick [s].
        status: the node's status (see the module table) or the filter's
            (:class:`~safenav.filters.FilterStatus` value).
        reason: why, in words; empty when ``status`` is ``ok``.
        enabled: filtering is on.
        published: a command left at this tick (``False`` while silent).
        u_nom: the input command ``(v [m/s], omega [rad/s])``, ``None`` before the first.
        u: the command the node decided ``(v, omega)``, ``None`` when it decided none.
        intervened: ``u`` differs from ``u_nom``.
        binding: what bound the command: the filter's constraint family or cause (``"barrier"``,
            ``"braking"``, ``"limits"``, ``"stale"``, ...; :class:`safenav.filters.Reason`), ``None`` when
            the nominal passed unchanged or the filter was not called.
        warnings: the filter's warnings (conditions that void part of its guarantee).
        min_barrier: the filter's smallest barrier value [m] (``None``: no constraint, or no filter call).
        clearance: distance from the body disk to the nearest point seen [m] (``None``: none seen).
        active_points: number of constraints that hold with equality.
        solver: QP or NLP back-end of the filter call.
        filter_time: time spent in the filter [s].
        period: measured time since the previous tick [s] (``None`` at the first).
        trigger: ``"timer"`` or ``"scan"`` (a fresh scan of the first source).
        latency: time from the triggering scan's arrival to the command leaving [s]
            (``None`` for timer ticks or without a command).
        source_ages: age of each source's latest message [s] (``None``: never received).
        odom_age: age of the latest odometry [s] (``None``: none, or no odometry topic).
        deadlock: how long the filter has held back a nominal that asks to move [s], once it
            reports a deadlock (:attr:`safenav.filters.FilterResult.deadlock`); ``None`` otherwise.
        escape: what the escape wrapper does instead of the nominal (``escape`` parameter); empty
            when it is not escaping.
        escape_enabled: the filter is wrapped in the deadlock escape (``escape`` parameter, on by default).
    """

    time: float
    status: str
    reason: str = ""
    enabled: bool = True
    published: bool = False
    u_nom: tuple[float, float] | None = None
    u: tuple[float, float] | None = None
    intervened: bool = False
    binding: str | None = None
    warnings: tuple[str, ...] = ()
    min_barrier: float | None = None
    clearance: float | None = None
    active_points: int = 0
    solver: str = ""
    filter_time: float = 0.0
    period: float | None = None
    trigger: str = "timer"
    latency: float | None = None
    source_ages: dict[str, float | None] = field(default_factory=dict)
    odom_age: float | None = None
    deadlock: float | None = None
    escape: str = ""
    escape_enabled: bool = False

    @property
    def level(self) -> int:
        """``diagnostic_msgs/DiagnosticStatus`` level: 0 OK, 1 WARN, 2 ERROR."""
        if self.status in _ERROR_STATUSES:
            return 2
        return 1 if self.status in _WARN_STATUSES or self.deadlock is not None else 0

    def as_dict(self) -> dict[str, Any]:
        """The state as JSON-safe values (non-finite numbers become ``None``)."""
        return {name: _json_safe(value) for name, value in self.__dict__.items()}


def _json_safe(value: Any) -> Any:
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, tuple):
        return [_json_safe(v) for v in value]
    if isinstance(value, dict):
        return {k: _json_safe(v) for k, v in value.items()}
    return value


def _finite_or_none(value: float) -> float | None:
    return float(value) if math.isfinite(value) else None


class Outputs(Protocol):
    """What a transport publishes for the core."""

    def command(self, u: tuple[float, float]) -> None:
        """Publish ``u = (v [m/s], omega [rad/s])`` on the output topic."""

    def state(self, state: NodeState) -> None:
        """Publish ``state`` on ``~/state``."""

    def diagnostics(self, state: NodeState) -> None:
        """Publish ``state`` on ``/diagnostics``."""

    def markers(self, footprint: np.ndarray, points: np.ndarray, active: np.ndarray) -> None:
        """Publish the footprint outline, the constraint points and the active ones (base frame [m])."""


class SafetyCore:
    """The safety node's logic, shared by every transport.

    Args:
        config: the node's configuration.
        warn: logs a warning line (each cause once).
        info: logs an information line.

    Raises:
        InvalidConfig: a filter setting is out of range.
    """

    def __init__(self, config: NodeConfig, *, warn: Callable[[str], None] = print,
                 info: Callable[[str], None] = print) -> None:
        self.config = config
        self.sources: dict[str, Source] = {s.name: SOURCE_TYPES[s.type](s) for s in config.sources}
        self.causes = CauseLog(warn, info)
        self._info = info
        first = config.sources[0]
        lidars = [source.lidar for source in config.sources if source.lidar]   # point-cloud sensors, known ahead
        if first.lidar is None:     # a scan source: the preset's lidar on the source's mount
            lidars.insert(0, dataclasses.replace(config.robot.lidar, mount=first.mount, frame_id=first.name))
        self._build(config.robot.replace(lidar=lidars[0], extra_lidars=tuple(lidars[1:])))
        self._confirmed: set[str] = set()
        self.enabled = config.enabled
        self._scans: dict[str, Timed | None] = dict.fromkeys(self.sources)
        self._bad: dict[str, str] = {}
        self._command: Timed | None = None
        self._odometry: Timed | None = None
        self._last_tick: float | None = None
        self._last_published: tuple[float, float] | None = None
        self._input_cause: str | None = None
        self._warnings: set[str] = set()
        self._last_diagnostics: tuple[float, tuple[str, int, bool]] | None = None
        self.state = NodeState(time=0.0, status=IDLE, reason="no cmd_vel_in received yet", enabled=self.enabled,
                               escape_enabled=config.escape)
        self.last_result: FilterResult | None = None

    # ------------------------------------------------------------------ inputs

    @property
    def trigger_source(self) -> str:
        """The source whose arrivals trigger a tick with ``step_on_scan`` (the first listed)."""
        return self.config.sources[0].name

    def on_scan(self, source: str, msg: Any, now: float) -> bool:
        """Keep the latest message of ``source``; whether the transport should tick now.

        A malformed message replaces the source's scan with nothing (the robot brakes until a
        good one arrives) and is logged once.
        """
        perf = time.perf_counter()
        try:
            scan = self._placed(source, self.sources[source].convert(msg))
        except (SafeNavError, ValueError, TypeError, AttributeError, ArithmeticError) as error:
            self._scans[source] = None
            self._bad[source] = f"source {source!r}: malformed message: {error}"
            return False
        self._bad.pop(source, None)
        self._scans[source] = Timed(scan, now, perf)
        return self.config.step_on_scan and source == self.trigger_source

    def _build(self, robot: RobotSpec) -> None:
        """Protect ``robot`` (its lidars are the sources) with a new filter."""
        self.robot = robot
        # By name, so that the filter inside the escape gets the escape's presets (ESCAPE_PRESETS).
        name = escaped(self.config.filter) if self.config.escape else self.config.filter
        self.filter: SafetyFilter | Escape = make_filter(name, robot, self.config.control_period,
                                                         **self.config.filter_kwargs())

    def _placed(self, source: str, scan: LaserScan) -> LaserScan:
        """``scan`` checked against its source's lidar (:meth:`~safenav.robot.RobotSpec.match_scan`).

        The first source starts as the preset's lidar on the source's mount. A source's first
        message that does not fit its lidar (an extra source, or a driver whose layout differs
        from the preset's) describes that lidar from then on: the filter is built again, once.
        A later message that does not fit is malformed.
        """
        try:
            placed = self.robot.match_scan(scan)
        except LidarMismatch:
            if source in self._confirmed:
                raise
            lidar = _lidar_of(scan, self.robot.lidar.noise_std if source == self.config.sources[0].name else 0.0)
            lidars = [known for known in self.robot.lidars if known.frame_id != source]
            lidars.insert(0 if source == self.config.sources[0].name else len(lidars), lidar)
            self._build(self.robot.replace(lidar=lidars[0], extra_lidars=tuple(lidars[1:])))
            self._info(f"source {source!r}: lidar from its first message: {lidar.n_beams} beams over "
                       f"[{lidar.angle_min:.4f}, {lidar.angle_max:.4f}] rad, "
                       f"{lidar.range_min:g}-{lidar.range_max:g} m, "
                       f"mount {tuple(round(v, 4) for v in lidar.mount)}{self._sighting()}")
            placed = self.robot.match_scan(scan)
        self._confirmed.add(source)
        return placed

    def on_command(self, msg: Any, now: float) -> None:
        """Keep the latest nominal command (``Twist``, or ``TwistStamped`` with ``stamped``)."""
        try:
            u = twist_of(msg.twist if self.config.stamped else msg)
        except (AttributeError, TypeError, ValueError) as error:
            self.causes.report("bad cmd_vel_in", f"malformed {self.config.cmd_vel_in_topic} message ignored: {error}")
            return
        self.causes.clear("bad cmd_vel_in")
        self._command = Timed(u, now, time.perf_counter())

    def on_odometry(self, msg: Any, now: float) -> None:
        """Keep the latest measured velocity and pose from a ``nav_msgs/Odometry`` message."""
        try:
            odometry = Odometry(twist_of(msg.twist.twist), pose_of(msg))
        except (AttributeError, TypeError, ValueError) as error:
            self._odometry = None
            self.causes.report("bad odometry", f"malformed {self.config.odom_topic} message: {error}")
            return
        self.causes.clear("bad odometry")
        self._odometry = Timed(odometry, now, time.perf_counter())

    def set_enabled(self, enabled: bool) -> str:
        """Switch filtering on or off (``~/enable``); the answer's message."""
        self.enabled = bool(enabled)
        if self.enabled:
            self.causes.clear("disabled")
            return "safety filter enabled"
        self.causes.report("disabled", "safety filter DISABLED: cmd_vel_in passes through unchanged")
        return "safety filter disabled: commands pass through unchanged"

    # ------------------------------------------------------------------ the step

    def tick(self, now: float, outputs: Outputs, trigger: str = "timer") -> NodeState:
        """Decide and publish one command; publish the state (and diagnostics, markers).

        Never raises for bad input: whatever goes wrong brakes and shows in the state.
        """
        period = None if self._last_tick is None else now - self._last_tick
        self._last_tick = now
        if period is not None and period > LATE_FACTOR * self.config.control_period:
            self.causes.report("late", f"tick {period:.3f} s after the previous one; control period "
                                       f"{self.config.control_period:.3f} s (is the machine overloaded?)")
        elif period is not None:
            self.causes.clear("late")
        trigger_scan = self._scans.get(self.trigger_source) if trigger == "scan" else None
        try:
            state = self._decide(now, period)
        except Exception as error:  # the node must brake, not die, on anything unforeseen
            self.causes.report("error", f"filter error, braking: {type(error).__name__}: {error}")
            state = NodeState(time=now, status=ERROR, reason=f"{type(error).__name__}: {error}",
                              u=(0.0, 0.0), u_nom=self._command.value if self._command else None)
        else:
            self.causes.clear("error")
        published = False
        if state.u is not None and not (state.u == (0.0, 0.0) and self._last_published == (0.0, 0.0)):
            outputs.command(state.u)
            published = True
        if state.u is not None or self._last_published is None:
            self._last_published = state.u
        latency = time.perf_counter() - trigger_scan.perf if published and trigger_scan else None
        state = _replace(state, published=published, period=period, trigger=trigger, latency=latency,
                         escape_enabled=self.config.escape, **self._ages(now))
        self.state = state
        outputs.state(state)
        if self._diagnostics_due(now, (state.status, state.level, bool(state.escape))):
            outputs.diagnostics(state)
        if self.config.markers and self.last_result is not None:
            result = self.last_result
            outputs.markers(self.footprint(), result.constraint_points, result.constraint_points[list(result.active)])
        return state

    def _decide(self, now: float, period: float | None = None) -> NodeState:
        """The command for this tick and why (before publishing); ``period``: the time since the previous tick [s]."""
        config = self.config
        enabled = self.enabled
        if self._command is None:
            return NodeState(time=now, status=IDLE, reason=f"no {config.cmd_vel_in_topic} received yet",
                             enabled=enabled)
        u_nom = self._command.value
        command_age = now - self._command.time
        if command_age > config.cmd_vel_timeout:
            reason = (f"{config.cmd_vel_in_topic} is {command_age:.2f} s old (timeout {config.cmd_vel_timeout:g} s): "
                      f"zero once, then silent")
            self.causes.report("cmd_vel_in timeout", reason)
            return NodeState(time=now, status=IDLE, reason=reason, enabled=enabled, u_nom=u_nom, u=(0.0, 0.0),
                             intervened=True)
        self.causes.clear("cmd_vel_in timeout")
        if not enabled:
            return NodeState(time=now, status=DISABLED, reason="filter disabled by ~/enable: passing through",
                             enabled=False, u_nom=u_nom, u=u_nom)
        odometry, odometry_problem = self._fresh_odometry(now)
        velocity = None if odometry is None else np.asarray(odometry.velocity, dtype=float)
        scans, ages, source_problem = self._fresh_scans(now)
        problem = source_problem or odometry_problem
        cause = None if problem is None else _cause(*problem)
        if self._input_cause is not None and cause != self._input_cause:
            self.causes.clear(self._input_cause)
        self._input_cause = cause
        if problem is not None:
            status, reason = problem
            self.causes.report(cause, f"braking: {reason}")
            # Held until the next tick: the control period, or as long as this tick came after the previous one
            # (as the filters plan a late call): the nearest stop the acceleration limits reach within it.
            held = config.control_period if period is None else max(config.control_period, period)
            brake = self.robot.brake(velocity, held if velocity is not None else None)
            return NodeState(time=now, status=status, reason=reason, enabled=enabled, u_nom=u_nom,
                             u=_pair(brake), intervened=True)
        result = self._filter(u_nom, scans, odometry, ages, now)
        self.last_result = result
        status = result.status.value
        if result.braked:
            self.causes.report(f"filter {status}", f"filter brakes ({status}): {result.message}")
        else:
            for braking in BRAKING_STATUSES:
                self.causes.clear(f"filter {braking.value}")
        self._report_warnings(result.warnings)
        return NodeState(time=now, status=status, reason=result.message, enabled=enabled, u_nom=u_nom,
                         u=_pair(result.u), intervened=result.modified,
                         binding=None if result.reason is None else result.reason.family, warnings=result.warnings,
                         deadlock=None if result.deadlock is None else result.deadlock.time, escape=result.escape,
                         min_barrier=_finite_or_none(result.min_barrier), clearance=_finite_or_none(result.clearance),
                         active_points=len(result.active), solver=result.solver, filter_time=result.filter_time)

    def _filter(self, u_nom: tuple[float, float], scans: Sequence[LaserScan], odometry: Odometry | None,
                ages: Sequence[float], now: float) -> FilterResult:
        """The one place the node calls the filter (``now``: the node's time [s], for the call period)."""
        velocity = None if odometry is None else np.asarray(odometry.velocity, dtype=float)
        pose = None if odometry is None else odometry.pose
        if len(scans) == 1:
            return self.filter.filter(u_nom, scans[0], velocity=velocity, pose=pose, scan_age=ages[0], now=now)
        return self.filter.filter(u_nom, tuple(scans), velocity=velocity, pose=pose, scan_age=list(ages), now=now)

    def _report_warnings(self, warnings: Sequence[str]) -> None:
        """Log each kind of filter warning once (the text before its first colon names the kind)."""
        causes = {f"filter warning: {warning.split(':')[0]}": warning for warning in warnings}
        for cause in self._warnings - set(causes):
            self.causes.clear(cause)
        for cause, warning in causes.items():
            self.causes.report(cause, f"filter warning: {warning}")
        self._warnings = set(causes)

    def _fresh_odometry(self, now: float) -> tuple[Odometry | None, tuple[str, str] | None]:
        """The latest odometry, or the reason it is missing or stale."""
        topic = self.config.odom_topic
        if not topic:
            return None, None
        if self._odometry is None:
            return None, (STALE, f"odometry: no valid {topic} message received")
        age = now - self._odometry.time
        if age > self.config.odom_timeout:
            return None, (STALE, f"odometry: {topic} is {age:.2f} s old (timeout {self.config.odom_timeout:g} s)")
        return self._odometry.value, None

    def _fresh_scans(self, now: float) -> tuple[list[LaserScan], list[float], tuple[str, str] | None]:
        """The latest scan of every source and its age, or the first reason one cannot be used.

        A scan's age is the larger of the time since it arrived and the time since its header
        stamp (when the stamp is set), so neither a late delivery nor a skewed clock hides it.
        """
        scans, ages = [], []
        for config in self.config.sources:
            name = config.name
            if name in self._bad:
                return [], [], (BAD_MESSAGE, self._bad[name])
            latest = self._scans[name]
            if latest is None:
                return [], [], (WAITING, f"source {name!r}: no message on {config.topic} yet")
            scan = latest.value
            age = now - latest.time
            if scan.stamp:
                age = max(age, now - scan.stamp)
            if age > config.timeout:
                return [], [], (STALE, f"source {name!r}: {config.topic} is {age:.2f} s old "
                                       f"(timeout {config.timeout:g} s)")
            scans.append(scan)
            ages.append(max(age, 0.0))
        return scans, ages, None

    def _ages(self, now: float) -> dict[str, Any]:
        source_ages = {name: (None if latest is None else round(now - latest.time, 6))
                       for name, latest in self._scans.items()}
        odom_age = None if self._odometry is None else round(now - self._odometry.time, 6)
        return {"source_ages": source_ages, "odom_age": odom_age}

    def _diagnostics_due(self, now: float, condition: tuple[str, int, bool]) -> bool:
        """Whether to publish diagnostics: when ``condition`` (status, level, escaping) changes, else once
        every :data:`DIAGNOSTICS_PERIOD`."""
        last = self._last_diagnostics
        if last is None or last[1] != condition or now - last[0] >= DIAGNOSTICS_PERIOD:
            self._last_diagnostics = (now, condition)
            return True
        return False

    def describe(self) -> str:
        """One line for the log at start: topics, filter (the MPC's reference; with the escape or not), robot,
        period, sources, and the narrowest obstacle the filter sees in time (``smallest_obstacle``, assumption A2)."""
        config = self.config
        escape = "with the deadlock escape" if config.escape else "without the deadlock escape (escape: false)"
        inner = self.filter.inner if isinstance(self.filter, Escape) else self.filter
        reference = getattr(inner.config, "reference", None)     # the MPC's, as built
        tracks = f" (tracking the {reference} reference)" if reference is not None else ""
        return (f"filtering {config.cmd_vel_in_topic} -> {config.cmd_vel_out_topic} with {config.filter}{tracks} "
                f"{escape} for {config.robot.name} every {config.control_period:g} s; sources: "
                + ", ".join(f"{s.name} ({s.topic}, mount {tuple(round(v, 4) for v in s.mount)})"
                            for s in config.sources) + self._sighting())

    def _sighting(self) -> str:
        """The narrowest obstacle the filter guarantees to see in time, for the log ('' for the zones)."""
        if self.config.filter == "zones":
            return ""
        return (f"; obstacles at least {100.0 * self.filter.smallest_obstacle:.1f} cm wide are seen in time to "
                f"brake (thinner: set {self.config.filter}.min_obstacle_width)")

    def footprint(self) -> np.ndarray:
        """The body outline in the base frame [m]: the footprint polygon, or the disk as 32 vertices."""
        if self.robot.footprint is not None:
            return np.asarray(self.robot.footprint, dtype=float)
        angles = np.linspace(0.0, 2.0 * math.pi, 32, endpoint=False)
        return self.robot.radius * np.column_stack((np.cos(angles), np.sin(angles)))

    def diagnostic_values(self, state: NodeState) -> list[tuple[str, str]]:
        """Key/value pairs of ``/diagnostics`` for ``state``."""
        values = [("filter", self.config.filter), ("robot", self.robot.name)]
        values += [(name, _text(value)) for name, value in state.as_dict().items()
                   if name not in ("time", "reason")]
        return values


def _cause(status: str, reason: str) -> str:
    """The log-once key of an input problem: its subject (``source 'scan'``, ``odometry``), and for a
    malformed message what is wrong with it (ages change every tick; a malformation does not)."""
    return f"{status}: {reason if status == BAD_MESSAGE else reason.split(':')[0]}"


def _text(value: Any) -> str:
    if isinstance(value, float):
        return f"{value:.6g}"
    return "" if value is None else str(value)


def _pair(u: Any) -> tuple[float, float]:
    return float(u[0]), float(u[1])


def _replace(state: NodeState, **changes: Any) -> NodeState:
    return NodeState(**{**state.__dict__, **changes})


def _lidar_of(scan: LaserScan, noise_std: float) -> LidarSpec:
    """The lidar that took ``scan``: its layout, range limits, mount and frame."""
    last = scan.angle_min + (scan.n_beams - 1) * scan.angle_increment
    return LidarSpec(n_beams=scan.n_beams, angle_min=scan.angle_min, angle_max=last, range_min=scan.range_min,
                     range_max=scan.range_max, mount=scan.mount, scan_time=scan.scan_time, noise_std=noise_std,
                     frame_id=scan.frame_id)

"""A way out of deadlocks, as a wrapper around any safety filter; its commands pass through that filter.

Barrier filters have stable equilibria at obstacle boundaries: a nominal that aims straight
through an obstacle is stopped, not deflected, when the geometry is symmetric (Reis et al.,
2020), and a predictive filter brakes in front of it. The wrapped filter reports such a
stall as :attr:`~safenav.filters.FilterResult.deadlock`; :class:`Escape` then replaces the
nominal by an escape command until the nominal's way is clear again:

1. **Start** at the call after the wrapped filter reports a deadlock, or after it has held back a
   clear forward request (``v`` of the nominal over a quarter of ``v_max``, less than a tenth of it
   let through) for its ``deadlock_time`` whatever it did with the yaw rate (a predictive filter can
   swing the heading to and fro in front of a wall without ever reporting a stall), or after the
   robot has stood (both commands under a tenth of the limits) for ``stand_time`` while the nominal
   asked to drive straight on (a clear forward request, ``|omega|`` under a quarter of ``omega_max``:
   no turn of the nominal's own to wait for; standing before a hard turn is how the yaw rate
   reverses). The result's reason says which of the three started it. The wrapped
   filter is called once per call, with the nominal or with the escape's command: a call is one
   period to it (it carries its memory, shifts its plan and counts the stall).
2. **Side, once per deadlock.** Round the blocking obstacle (the point behind the filter's binding
   row, else the nearest point ahead) towards the opening nearest the way the nominal was heading
   (the chord of its arc over one second): the nearest (in bearing) place where two
   neighbouring scan points are farther apart than the body's corridor (``2 clear_half_width``),
   that is, an edge of the blocking obstacle or a door beside it, else than the wrapped filter's
   narrow body's (``2 gap_half_width``: a door only it fits, which 5. drives through). The side is
   the sense of the turn from the obstacle's bearing to the opening's (facing a wall obliquely, a
   door up the wall may lie right of the heading and still be reached by going left); without an
   opening, the side with more free space, or the side the nominal turns to (by more than
   :data:`SIDE_DEADBAND` of ``omega_max``: not the sign of a rounding error), else left. An opening
   that leads back to a place where a deadlock began (5.) does not choose the side: the second
   deadlock beside a box went round it towards its far end, back to where the first began.
3. **Follow the boundary.** Drive at ``speed`` (a fraction of ``v_max``) along the obstacle with it on the other
   side (its nearest current or remembered point there, or ahead within the following distance on either side: the
   obstacle faced obliquely at the start is still on the chosen side; a lidar that does not look back loses an
   obstacle's end as the robot goes round it), holding ``follow_distance`` beyond the margin, its yaw rate twice the
   heading error averaged with the last one it asked while following (the nearest point jumps with the range noise
   and from one obstacle to the next; each change of the base's yaw rate adds to the dead-reckoning bound of
   remembered points, A5 of docs/safety.md); turn in place towards the chosen side when something is ahead, or when
   the filter blocks the following (for one period while the robot still moves, creeping or turning; when it stands
   still, until the base has turned ``stall_turn``, unless the filter blocks the turn too: one period's turn, at the
   acceleration limit, barely starts, and going back to following at once kept a robot held by its remembered points
   turning a degree every third of a second).
4. **Back out** when forward is blocked and the rear is seen and free (by a lidar now, or, behind a lidar
   that does not look back, by earlier scans: the wrapped filter's
   :attr:`~safenav.filters.SafetyFilter.blind_travel`). **Drive out of a pocket**
   when the escape has turned :data:`WAY_OUT_TURN` (half a turn) in place without driving
   (something within the following distance ahead every way it faced): along the direction whose
   corridor, among the current and remembered points, is free the longest, up to the following
   distance short of its end, or as far as the filter lets it; then it follows again.
5. **Through a gap.** While following, a corridor within ``gap_window`` of the m-line (below), clear for twice
   ``clear_distance`` (it leads somewhere) and with obstacle points on both sides near it (within ``gap_band`` of
   its edges: a passage, a door, not open floor), is a gap the body fits through: the escape turns into it, aims
   through its middle, drives ``clear_distance`` along it, then hands back (if the filter blocks it, it follows on
   and looks again after ``gap_retry``). A gap that leads back to a place where a deadlock began (6.: one lies ahead
   along it, within twice ``clear_distance``, and within twice ``clear_half_width`` of its centre line or
   :data:`SPOT_CONE` of it) is not taken: the next deadlock's escape would take the gap the last one came through.
   Meanwhile it sets the wrapped filter's ``passage``, so that a filter that trades room for steering uses its
   narrow settings (the CBF its ``min_lookahead``; never a weaker guarantee). Gaps are looked for with the body's
   corridor first, then with the filter's narrow body's (``gap_half_width``: the CBF's and the MPC's cover of a long
   robot's footprint); through a gap only that one fits, or one where the filter holds the body (the range noise
   takes what the scan showed to spare), it also sets the filter's ``narrow``, and the filter keeps the footprint
   clear with the narrow body's rows or plans (its guarantee is the footprint's either way). It sets it too while it
   turns in place (3. and the gap's turns): the CBF's control point ahead of the body swings sideways in a turn, and
   between two obstacles it can forbid both turns while the body itself would move nowhere.
6. **Leave** after at least ``min_time`` when the way is clear, either along the m-line (the way
   the nominal was heading for when the deadlock began, the chord of its arc over one second, not
   the robot's heading, which the stall may have swung; tracked by the odometry pose when the caller
   gives one, else by integrating the commands sent, as in a bug algorithm), or in the direction
   of the nominal's own arc over one second when it drives forward; or after ``max_time`` (the
   next deadlock then tries the other side). Clear means for
   ``clear_distance``, or, when the corridor passes a place where a deadlock began (ahead, within twice
   ``clear_half_width`` of its centre line or :data:`SPOT_CONE` of it; the last :data:`SPOTS` such places within
   :data:`SPOT_RANGE` are remembered, dead-reckoned by the commands or taken from the odometry pose
   when the caller gives one), for ``clear_distance`` beyond that place: a bug algorithm's leave
   condition, progress past where the robot got stuck. Without it the escape hands back at the
   mouth of a U-shaped trap (the way in is clear for ``clear_distance`` there), and a goal-seeking
   nominal drives straight back in. The filter never learns the goal; only where it got stuck.
   Through a gap (5.) it hands back at once, unless the m-line leads back past such a place and is
   not clear beyond it (out of a trap through its own mouth); then it follows on and leaves as above.

A corridor is **clear** when the body fits along it with the wrapped filter's margin: no current
or remembered point (the escape looks at the scans and the memory where the wrapped filter will see
them in this call: :meth:`~safenav.filters.SafetyFilter.current_scans`,
:meth:`~safenav.filters.SafetyFilter.remembered_points`) closer to its centre line than
the filter's ``corridor_half_width`` (the body's half-width, the disk's radius or a cover's or
polygon's lateral extent; the filter's margin; and the look-ahead of a filter that keeps a control
point ahead of the body that far from every point, as the CBF does: its straight path needs exactly
that much room), with some lidar looking at
least partly along it. No further tolerance: the escape decides progress only, never safety (its
commands go through the filter), and a corridor wider than the filter needs hides the doors the
filter would let the body through.

Every escape command goes through the wrapped filter exactly like a nominal would, so the
safety guarantee is the wrapped filter's, untouched; only progress depends on the escape.
The result keeps the original nominal as ``u_nom``, reports what the escape does in
:attr:`~safenav.filters.FilterResult.escape` and the reason family ``"escape"``.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from safenav import _checks
from safenav.filters.base import STALL_PROGRESS, FilterResult, Reason, SafetyFilter, _odometry, progress
from safenav.geometry import Pose2D, unicycle_step, wrap_angle
from safenav.robot import RobotSpec, as_command
from safenav.scan import LaserScan

__all__ = ["Escape", "EscapeConfig"]

#: How long the filter may block the escape's own commands before it turns in place instead [s].
STALLED_ESCAPE = 0.3

#: The robot stands when both commands it is sent stay under this fraction of the velocity limits.
STANDING = 0.1

#: Angle between two directions the gap search tries [rad].
GAP_RESOLUTION = math.radians(1.0)

#: How far either side of its heading the way through a gap is re-aimed at each call [rad].
GAP_TRACKING = math.radians(15.0)

#: An escape that has turned this far in place [rad] without driving (something ahead every way it
#: faced, and no way through a gap) drives out the way with the longest free corridor: half a turn, after
#: which a robot has faced every way and its memory holds what a 180-degree lidar saw.
WAY_OUT_TURN = math.pi

#: A forward request is clear when the nominal's ``v`` exceeds this fraction of ``v_max``.
FORWARD_REQUEST = 0.25

#: Openings farther than this from the robot do not choose the side [m].
OPENING_RANGE = 2.0

#: A nominal turning slower than this share of ``omega_max`` does not choose the side (a heading straight at the
#: goal turns by a rounding error's sign).
SIDE_DEADBAND = 1e-3

#: A way passes a place where a deadlock began when that place lies ahead within twice ``clear_half_width`` of its
#: centre line, or within this ratio of its distance along it (the tangent of 30 degrees): an obstacle that blocked
#: the robot there stretches round that place, and a way aimed at it from afar runs into the same obstacle.
SPOT_CONE = math.tan(math.radians(30.0))

#: How many places where deadlocks began the escape remembers (the oldest is forgotten first).
SPOTS = 8

#: Places farther than this from the robot are forgotten [m] (dead reckoning drifts with the distance).
SPOT_RANGE = 5.0


@dataclass(frozen=True)
class EscapeConfig:
    """Settings of :class:`Escape`.

    Attributes:
        speed: forward speed while following an obstacle, as a fraction of ``v_max``.
        turn: largest yaw rate while escaping, as a fraction of ``omega_max``.
        follow_distance: distance kept from the followed obstacle beyond the filter's margin [m].
        clear_distance: how far the nominal's direction must be clear to hand back [m].
        min_time: shortest escape [s] (hysteresis against flipping back at once).
        max_time: longest escape [s]; the next deadlock tries the other side.
        back_time: how long to back out when forward is blocked and the rear is free [s].
        side_memory: a deadlock within this time after an escape ended keeps its side [s]
            (hysteresis: the robot keeps going round the same obstacle).
        gap_window: how far either side of the m-line a gap is looked for [rad].
        gap_band: how near a corridor's edges obstacle points must be on both sides for it to be
            a passage [m].
        gap_retry: distance to follow on after the filter blocked the way through a gap before
            looking for a gap again [m].
        stall_turn: how far the escape turns in place [rad] once the filter has blocked its following
            and the robot has stood still for ``STALLED_ESCAPE`` (the turn lasts until the base has
            turned that much, or the filter blocks the turn too: a turn of one period, at the
            acceleration limit, barely starts).
        stand_time: how long the robot may stand (both commands sent under a tenth of the limits) while
            the nominal asks to drive straight on (``v`` over a quarter of ``v_max``, ``|omega|`` under a
            quarter of ``omega_max``) before an escape starts [s]: a request no turn explains, let through
            not at all, is a deadlock long before the filter's ``deadlock_time`` (``math.inf``: only the
            other two starts).
    """

    speed: float = 0.4
    turn: float = 0.6
    follow_distance: float = 0.15
    clear_distance: float = 1.0
    min_time: float = 1.0
    max_time: float = 20.0
    back_time: float = 0.6
    side_memory: float = 5.0
    gap_window: float = 0.6 * math.pi
    gap_band: float = 0.25
    gap_retry: float = 0.5
    stall_turn: float = 0.25 * math.pi
    stand_time: float = 0.5

    def __post_init__(self) -> None:
        name = "EscapeConfig."
        _checks.number(name + "speed", self.speed, low=0.0, high=1.0, low_open=True)
        _checks.number(name + "turn", self.turn, low=0.0, high=1.0, low_open=True)
        _checks.positive(name + "follow_distance", self.follow_distance)
        _checks.positive(name + "clear_distance", self.clear_distance)
        _checks.number(name + "min_time", self.min_time, low=0.0)
        _checks.positive(name + "max_time", self.max_time)
        _checks.number(name + "back_time", self.back_time, low=0.0)
        _checks.number(name + "side_memory", self.side_memory, low=0.0)
        _checks.number(name + "gap_window", self.gap_window, low=0.0, high=math.pi)
        _checks.positive(name + "gap_band", self.gap_band)
        _checks.number(name + "gap_retry", self.gap_retry, low=0.0)
        _checks.number(name + "stall_turn", self.stall_turn, low=0.0, high=2.0 * math.pi)
        _checks.number(name + "stand_time", self.stand_time, low=0.0, low_open=True, finite=False)


class Escape:
    """Wrap a safety filter with a deadlock escape (see the module docstring).

    Has the filter interface (``filter``, ``__call__``, ``reset``, ``robot``, ``dt``,
    ``margin``, ``name``), so it can stand wherever a filter does.

    It wraps ``inner`` as it is given. Built by name (``make_filter("mpc+escape", ...)``, as the CLI,
    the ROS node and the Gymnasium shield do), the filter inside also gets
    :data:`safenav.filters.ESCAPE_PRESETS` (the MPC then tracks the CBF's answer); to wrap an MPC
    yourself with the same behaviour, build it with ``reference="cbf"``.

    Args:
        inner: the safety filter every command goes through.
        config: settings; keyword arguments override its fields.
    """

    def __init__(self, inner: SafetyFilter, *, config: EscapeConfig | None = None, **overrides: Any) -> None:
        if not isinstance(inner, SafetyFilter):
            raise _checks.InvalidConfig(f"Escape wraps a SafetyFilter, got {inner!r}")
        self.inner = inner
        self.config = dataclasses.replace(config or EscapeConfig(), **overrides)
        self.name = f"{inner.name}+escape"
        self._side = 0          # +1 left, -1 right, 0 not escaping
        self._elapsed = 0.0
        self._backing = 0.0
        self._last_side = 0
        self._start_yaw = 0.0   # the m-line's heading in _odometry's frame, set when the deadlock began [rad]
        self._since = math.inf  # time since the last escape ended [s]
        self._stalled = 0.0     # how long the filter has blocked the escape's own commands [s]
        self._gap: float | None = None   # heading through the gap being driven, off the m-line [rad]
        self._gap_width = 0.0   # the half-width it was found with [m]: the body's, or the filter's narrow body's
        self._gap_left = 0.0    # distance still to drive through it [m]
        self._gap_wait = 0.0    # distance to follow before looking for a gap again [m]
        self._spun = 0.0        # angle turned in place without driving since then [rad]
        self._out: float | None = None   # heading of the way out being driven, off the m-line [rad]
        self._out_left = 0.0    # distance still to drive along it [m]
        self._held = 0.0        # how long the filter has held back a clear forward request [s]
        self._standing = 0.0    # how long the robot has stood while the nominal asked to drive straight on [s]
        self._follow_omega = 0.0   # the yaw rate the last following command asked for [rad/s]
        self._started_by = ""   # why the current escape started (the reason says it)
        self._odometry = Pose2D()        # the base's pose since the reset (odometry, else the commands) [m, m, rad]
        self._spots: list[np.ndarray] = []   # where deadlocks began, in the frame of _odometry [m]
        self._pending = False   # a deadlock was reported at the last call: the escape starts at this one
        self._blocking: tuple[float, float] | None = None   # its blocking point, moved by the command sent [m]

    @property
    def robot(self) -> RobotSpec:
        return self.inner.robot

    @property
    def dt(self) -> float:
        return self.inner.dt

    @property
    def margin(self) -> float:
        return self.inner.margin

    @property
    def smallest_obstacle(self) -> float:
        """The narrowest obstacle [m] the wrapped filter sees in time (its guarantee is the wrapper's)."""
        return self.inner.smallest_obstacle

    @property
    def clear_half_width(self) -> float:
        """Half-width of a corridor the wrapped filter lets the body drive along [m] (its ``corridor_half_width``)."""
        return self.inner.corridor_half_width

    @property
    def gap_half_width(self) -> float:
        """Half-width of the narrowest gap the wrapped filter lets the body through [m] (its ``narrow_half_width``:
        with a narrower body model for gaps, that body's; else ``clear_half_width``)."""
        return self.inner.narrow_half_width

    @property
    def escaping(self) -> bool:
        """Whether the escape has replaced the nominal."""
        return self._side != 0

    @property
    def _turned(self) -> float:
        """The heading off the m-line [rad] (0 facing along it; odometry's when the caller gives the pose)."""
        return float(wrap_angle(self._odometry.yaw - self._start_yaw))

    def __repr__(self) -> str:
        return f"Escape({self.inner!r})"

    def reset(self) -> None:
        """Forget the escape and reset the wrapped filter."""
        self.inner.reset()
        self._side, self._elapsed, self._backing, self._last_side, self._start_yaw = 0, 0.0, 0.0, 0, 0.0
        self._since, self._stalled, self._still, self._turn_left = math.inf, 0.0, 0.0, 0.0
        self._gap, self._gap_left, self._gap_wait, self._held, self._standing = None, 0.0, 0.0, 0.0, 0.0
        self._spun, self._out, self._out_left, self._follow_omega = 0.0, None, 0.0, 0.0
        self._odometry, self._spots, self._pending, self._blocking, self._started_by = Pose2D(), [], False, None, ""

    def __call__(self, u_nom: Any, scan: LaserScan | Sequence[LaserScan], **kwargs: Any) -> FilterResult:
        return self.filter(u_nom, scan, **kwargs)

    def filter(self, u_nom: Any, scan: LaserScan | Sequence[LaserScan], **kwargs: Any) -> FilterResult:
        """Filter ``u_nom`` (see :meth:`SafetyFilter.filter`), escaping deadlocks; same arguments."""
        nominal = as_command(u_nom, "u_nom")
        odometry = _odometry(kwargs.get("pose"))[0]
        if odometry is not None:   # (not at a glitch: the wrapped filter brakes and says so)
            self._odometry = odometry
        pending, self._pending = self._pending, False
        starting = pending and bool(np.all(np.isfinite(nominal)))
        if self._side or starting:
            # The scans and the memory where the wrapped filter will see them in this call (it moves an old scan
            # into the current base frame, and carries its memory there, only when it is called).
            scans = self.inner.current_scans(scan, velocity=kwargs.get("velocity"), scan_age=kwargs.get("scan_age"),
                                             now=kwargs.get("now"))
            points = np.vstack([s.points() for s in scans])
            memory = self.inner.remembered_points(velocity=kwargs.get("velocity"), pose=kwargs.get("pose"),
                                                  now=kwargs.get("now"))
            known = np.vstack((points, memory)) if memory.shape[0] else points
            if self._side and self._should_leave(nominal, known, scans):
                self._last_side, self._side, self._since, self._gap = self._side, 0, 0.0, None
            if not self._side and starting:
                self._start(nominal, scans, points, self._blocking)
        if not self._side:
            self.inner.passage = self.inner.narrow = False
            result = self.inner.filter(nominal, scan, **kwargs)
            held = result.period if math.isfinite(result.period) else self.dt
            self._move(result.u, held)
            self._since += held
            forward = nominal[0] > FORWARD_REQUEST * self.robot.v_max
            self._held = self._held + held if forward and result.u[0] < STALL_PROGRESS * nominal[0] else 0.0
            straight = forward and abs(nominal[1]) <= FORWARD_REQUEST * self.robot.omega_max
            standing = straight and self._stands(result.u)
            self._standing = self._standing + held if standing else 0.0
            cause = self._cause(result)
            if cause:
                # The escape starts at the next call: the filter is called once per period (a second call
                # now would carry its memory, shift its plan and count the stall a second time).
                point = None if result.reason is None else result.reason.point
                moved = None if point is None else unicycle_step(Pose2D(), float(result.u[0]), float(result.u[1]),
                                                                 held).to_local(np.array([point]))[0]
                self._pending, self._blocking = True, None if moved is None else (float(moved[0]), float(moved[1]))
                self._started_by = cause
            return result
        backing = self._gap is None and self._backing > 0.0     # the command this call: backing out
        command = self._command(points, known, scans)
        # Through a gap the body fits, and turning in place, the filter uses its narrow settings (the CBF's
        # shortest look-ahead: a control point ahead of the body swings sideways when the robot turns in
        # place, and between two obstacles it can forbid both turns while the body itself moves nowhere).
        self.inner.passage = self._gap is not None or (command[0] == 0.0 and command[1] != 0.0)
        # Past the gap's length the flag is cleared, and the escape drives on until the filter is back on its body.
        self.inner.narrow = self._gap is not None and self._gap_width < self.clear_half_width and self._gap_left > 0.0
        result = self.inner.filter(command, scan, **kwargs)
        held = result.period if math.isfinite(result.period) else self.dt
        self._move(result.u, held)
        self._elapsed += held
        if backing:      # for back_time [s], whatever the calls' period
            self._backing -= held
        blocked = progress(result.u, command, np.abs(self.robot.upper)) < STALL_PROGRESS
        self._stalled = self._stalled + held if blocked else 0.0
        still = self._stands(result.u)
        self._still = self._still + held if still else 0.0
        if self._turn_left > 0.0:
            # A turn in place after a stall lasts until the base has turned that far; a turn the filter blocks as
            # long as it blocked the following ends it (following is tried again).
            turned = abs(float(result.u[1])) * held
            self._turn_left = 0.0 if self._stalled >= STALLED_ESCAPE else self._turn_left - turned
        self._travel(abs(float(result.u[0])) * held)
        in_place = command[0] == 0.0 and command[1] != 0.0 and self._gap is None and self._out is None
        self._spun = self._spun + abs(float(result.u[1])) * held if in_place else 0.0
        side = "left" if self._side > 0 else "right"
        if self._gap is not None:
            doing = f"driving through a gap {math.degrees(wrap_angle(self._gap)):+.0f} deg off the m-line"
        elif self._out is not None:
            doing = (f"driving out of a pocket the freest way, {math.degrees(wrap_angle(self._out)):+.0f} deg off the "
                     "m-line")
        elif self._backing > 0.0:
            doing = "backing out"
        else:
            doing = f"following the obstacle with it on the {'right' if self._side > 0 else 'left'}"
        description = f"{doing}, turning {side}, for {self._elapsed:.1f} s"
        reason = Reason("escape", f"deadlocked ({self._started_by}): {description}; command ({command[0]:.2f}, "
                                  f"{command[1]:.2f}) sent through the {self.inner.name} filter",
                        None if result.reason is None else result.reason.point)
        message = str(reason) + (f"; {result.message}" if result.message else "")
        values = {field.name: getattr(result, field.name) for field in dataclasses.fields(result)}
        values.update(u_nom=nominal, reason=reason, message=message, escape=description, deadlock=None)
        return FilterResult(**values)

    def _stands(self, command: np.ndarray) -> bool:
        """Whether a command sent leaves the robot standing: both parts under :data:`STANDING` of the limits."""
        return bool(np.all(np.abs(command) < STANDING * np.abs(self.robot.upper)))

    def _cause(self, result: FilterResult) -> str:
        """Why an escape starts at the next call (empty: it does not; see the module docstring, 1.)."""
        if result.deadlock is not None:
            return f"the filter reported it {result.deadlock}"
        if self._held >= self.inner.deadlock_time - 1e-9:
            return f"the filter held back a forward request for {self._held:.1f} s"
        if self._standing >= self.config.stand_time - 1e-9:
            return f"the robot stood for {self._standing:.1f} s while the nominal asked to drive straight on"
        return ""

    # ------------------------------------------------------------------ the escape

    def _start(self, nominal: np.ndarray, scans: tuple[LaserScan, ...], points: np.ndarray,
               blocking: tuple[float, float] | None) -> None:
        """Choose a side once for this deadlock (the other one after a timed-out escape).

        ``blocking`` is the obstacle point the filter's binding row came from (base frame [m]), if any.
        """
        left = _free(points, 0.25 * math.pi, 0.75 * math.pi)
        right = _free(points, -0.75 * math.pi, -0.25 * math.pi)
        intent = _intent(nominal)
        opening = None
        for width in dict.fromkeys((self.clear_half_width, min(self.gap_half_width, self.clear_half_width))):
            opening = self._nearest_opening(scans, intent, width)    # the body's corridor, then the narrow body's
            if opening is not None:
                break
        if opening is not None:
            side = _side_towards(opening, _blocking_bearing(points, blocking))
        elif abs(left - right) > 0.2:
            side = 1 if left > right else -1
        elif abs(nominal[1]) > SIDE_DEADBAND * self.robot.omega_max:   # not the sign of a rounding error
            side = 1 if nominal[1] > 0.0 else -1
        else:
            side = 1
        if self._last_side and self._since <= self.config.side_memory:
            # Still round the same obstacle: keep the side, unless that escape timed out.
            side = -self._last_side if self._elapsed >= self.config.max_time else self._last_side
        self._side, self._elapsed, self._backing, self._stalled = side, 0.0, 0.0, 0.0
        self._still, self._turn_left = 0.0, 0.0
        self._start_yaw = self._odometry.yaw + intent      # the m-line: where the nominal was heading for
        self._gap, self._gap_left, self._gap_wait, self._held, self._standing = None, 0.0, 0.0, 0.0, 0.0
        self._spun, self._out, self._out_left, self._follow_omega = 0.0, None, 0.0, 0.0
        self._spots = [*self._spots, np.array(self._odometry[:2])][-SPOTS:]

    def _move(self, command: np.ndarray, held: float) -> None:
        """Dead-reckon the base by the command sent and held for ``held`` [s] (the odometry pose, when the caller
        gives one, replaces it at the next call), and forget the deadlock places that are too far to matter."""
        if not np.all(np.isfinite(command)):
            return
        self._odometry = unicycle_step(self._odometry, float(command[0]), float(command[1]), held)
        here = np.array(self._odometry[:2])
        self._spots = [spot for spot in self._spots if math.hypot(*(spot - here)) <= SPOT_RANGE]

    def _needed(self, direction: float) -> float:
        """How far the base-frame ``direction`` [rad] must be clear to hand back [m]: ``clear_distance``, or
        ``clear_distance`` beyond the farthest place where a deadlock began that a corridor along it passes
        (ahead and :meth:`_beside` it): the way must be clear past where the robot
        got stuck, not just up to the trap's mouth (a bug algorithm's leave condition)."""
        length = self.config.clear_distance
        if not self._spots:
            return length
        along, across = self._spot_offsets(np.array([direction]))
        passed = (along > 0.0) & self._beside(along, across)
        return max(length, float(along[passed].max()) + length) if passed.any() else length

    def _spot_offsets(self, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(S, D)`` each place where a deadlock began: its distance [m] along each base-frame direction [rad]
        from the base, and to the left of that direction's centre line."""
        x, y, yaw = self._odometry
        return _along_across(np.array(self._spots) - np.array([x, y]), yaw + directions)

    def _nearest_opening(self, scans: tuple[LaserScan, ...], intent: float, half_width: float) -> float | None:
        """Bearing [rad] of the opening nearest the ``intent`` bearing [rad], within ``gap_window`` of it;
        ``None`` if none.

        An opening lies between two neighbouring points of one scan (in beam order, so across
        beams with no return) farther apart than ``2 half_width`` [m] (``clear_half_width``, or the
        narrow body's ``gap_half_width``), the nearer of them within :data:`OPENING_RANGE`; its
        bearing is that of the pair's midpoint.
        """
        best = None
        for scan in scans:
            points = scan.points()
            if points.shape[0] < 2:
                continue
            first, second = points[:-1], points[1:]
            wide = np.hypot(*(second - first).T) > 2.0 * half_width
            near = np.minimum(np.hypot(*first.T), np.hypot(*second.T)) < OPENING_RANGE
            middle = 0.5 * (first + second)[wide & near]
            if middle.shape[0] == 0:
                continue
            bearings = np.arctan2(middle[:, 1], middle[:, 0])
            off = np.where(self._back(bearings), np.inf, np.abs(wrap_angle(bearings - intent)))
            nearest = int(np.argmin(off))
            if off[nearest] <= self.config.gap_window and (
                    best is None or off[nearest] < abs(wrap_angle(best - intent))):
                best = float(bearings[nearest])
        return best

    def _travel(self, distance: float) -> None:
        """Count ``distance`` [m] driven against the way through a gap, and against the wait before the next search."""
        if self._gap is not None:
            self._gap_left -= distance
            if self._stalled >= STALLED_ESCAPE and self._gap_width > self.gap_half_width:
                # The filter does not let the body through (its margin and the range noise take what the scan
                # showed to spare): on through the same gap with the filter's narrow body.
                self._gap_width, self._stalled = self.gap_half_width, 0.0
            elif self._stalled >= STALLED_ESCAPE:      # not even the narrow body: follow on
                self._gap, self._gap_wait = None, self.config.gap_retry
        else:
            self._gap_wait = max(self._gap_wait - distance, 0.0)
        if self._out is not None:
            self._out_left -= distance
            if self._out_left <= 0.0 or self._stalled >= STALLED_ESCAPE:    # out, or as far as the filter lets it
                self._out = None

    def _command(self, points: np.ndarray, known: np.ndarray, scans: tuple[LaserScan, ...]) -> np.ndarray:
        """The escape command: through a gap, back out, or follow the obstacle on the chosen side.

        Args:
            points: the current scans' points (base frame) [m].
            known: those and the remembered points [m].
            scans: the current scans.
        """
        robot, cfg = self.robot, self.config
        side = self._side
        speed, turn = cfg.speed * robot.v_max, cfg.turn * robot.omega_max
        if self._gap is None and self._backing <= 0.0 and self._gap_wait <= 0.0:
            self._gap = self._find_gap(known, scans)
            self._gap_left = cfg.clear_distance
            if self._gap is not None:
                self._turn_left = 0.0     # a way through: the turn after a blocked follow is not needed
        if self._gap is not None:
            self._aim(known, scans)
            return self._steer(self._gap, speed, turn)
        if self._backing > 0.0:
            return np.array([-min(cfg.speed * -robot.v_min, 0.5 * -robot.v_min) if robot.v_min < 0 else 0.0,
                             side * 0.5 * turn])
        keep = robot.radius + self.margin + cfg.follow_distance
        if self._out is None and self._spun >= WAY_OUT_TURN:
            self._way_out(known, keep)
        if self._out is not None:
            return self._steer(self._out, speed, turn)
        ahead = _corridor(points, 0.0, self.clear_half_width, keep + 0.1)
        if not ahead and min(self._stalled, self._still) >= STALLED_ESCAPE and self._turn_left <= 0.0:
            # The filter blocks following and the robot stands still: turn, and for long enough.
            self._turn_left, self._stalled = cfg.stall_turn, 0.0
        if ahead or self._stalled >= STALLED_ESCAPE or self._turn_left > 0.0:
            if robot.v_min < 0.0 and self._rear_free(scans, keep) and self._elapsed > 2.0 * cfg.min_time:
                self._backing, self._turn_left = cfg.back_time, 0.0
            return np.array([0.0, side * turn])          # turn towards the chosen side in place
        if known.shape[0] == 0:
            return np.array([speed, 0.0])
        # Keep the nearest point on the other side at `keep`, moving along its tangent (remembered points too:
        # a lidar that does not look back loses an obstacle's end as the robot goes round it).
        # Points ahead within `keep` count on either side: the obstacle the escape goes round, while it is still on the
        # chosen side (the start, facing it obliquely), is the one to turn away from, not one on the other side.
        distance = np.hypot(known[:, 0], known[:, 1])
        followed = (np.sign(known[:, 1]) == -side) | ((known[:, 0] > 0.0) & (distance < keep))
        candidates = np.flatnonzero(followed) if followed.any() else np.arange(known.shape[0])
        nearest = int(candidates[np.argmin(distance[candidates])])
        bearing = math.atan2(known[nearest, 1], known[nearest, 0])
        tangent = wrap_angle(bearing + side * 0.5 * math.pi)      # the obstacle stays on the other side
        correction = float(np.clip((keep - float(distance[nearest])) / keep, -1.0, 1.0)) * side * 0.5
        heading_error = float(wrap_angle(tangent + correction))
        self._follow_omega = 0.5 * (float(np.clip(2.0 * heading_error, -turn, turn)) + self._follow_omega)
        return np.array([speed * max(math.cos(heading_error), 0.2), self._follow_omega])

    def _steer(self, heading: float, speed: float, turn: float) -> np.ndarray:
        """Towards ``heading`` (off the m-line) [rad]: turn at twice the error, at most ``turn`` [rad/s],
        and drive at ``speed`` [m/s] times the error's cosine once it is under 0.5 rad."""
        heading_error = float(wrap_angle(heading - self._turned))
        omega = float(np.clip(2.0 * heading_error, -turn, turn))
        return np.array([speed * max(math.cos(heading_error), 0.0) if abs(heading_error) < 0.5 else 0.0, omega])

    def _way_out(self, known: np.ndarray, keep: float) -> None:
        """Turned half a turn in place without driving: aim along the direction whose corridor (the filter's
        ``corridor_half_width``) is free the longest, among the current and remembered points, and drive along
        it until ``keep`` short of its end (at least ``follow_distance``), or as far as the filter lets it."""
        offsets = _fan(math.pi)
        free = _free_length(known, offsets - self._turned, self.clear_half_width, 2.0 * self.config.clear_distance)
        best = int(np.argmax(free))      # nearest the m-line among equals (the fan comes nearest zero first)
        self._out, self._spun = float(offsets[best]), 0.0
        self._out_left = max(float(free[best]) - keep, self.config.follow_distance)

    def _rear_free(self, scans: tuple[LaserScan, ...], keep: float) -> bool:
        """Whether a lidar sees the 90 degrees behind free beyond ``keep + 0.2`` [m], or, when none looks
        there, whether earlier scans saw the space behind free for ``follow_distance``
        (:attr:`~safenav.filters.SafetyFilter.blind_travel`: the filter lets the base back that far)."""
        rears = [scan.sector(0.75 * math.pi, -0.75 * math.pi) for scan in scans]
        if any(rear.complete and rear.min_range > keep + 0.2 for rear in rears):
            return True
        return all(rear.n_beams == 0 for rear in rears) and self.inner.blind_travel >= self.config.follow_distance

    def _find_gap(self, known: np.ndarray, scans: tuple[LaserScan, ...]) -> float | None:
        """The passage heading nearest the m-line within ``gap_window`` of it (off it) [rad]:
        among the passages the body fits (``clear_half_width``), else among those only the wrapped filter's narrow
        body fits (``gap_half_width``; the escape then sets the filter's ``narrow`` while it drives through)."""
        offsets = _fan(self.config.gap_window)
        for width in dict.fromkeys((self.clear_half_width, min(self.gap_half_width, self.clear_half_width))):
            passage, _ = self._passages(known, scans, offsets, width)
            if passage.any():
                self._gap_width = width
                return float(offsets[int(np.argmax(passage))])
        return None

    def _aim(self, known: np.ndarray, scans: tuple[LaserScan, ...]) -> None:
        """Re-aim through the gap from where the robot is now: the passage heading within
        :data:`GAP_TRACKING` of the current one that keeps the body farthest from both sides."""
        headings = self._gap + _fan(GAP_TRACKING)
        passage, room = self._passages(known, scans, headings, self._gap_width)
        if passage.any():
            self._gap = float(headings[int(np.argmax(np.where(passage, room, -np.inf)))])

    def _passages(self, known: np.ndarray, scans: tuple[LaserScan, ...], headings: np.ndarray,
                  width: float) -> tuple[np.ndarray, np.ndarray]:
        """For headings off the m-line [rad]: which are passages for a body of half-width ``width`` [m]
        (with the margin), and the room on their tighter side [m].

        A passage has points within ``gap_band`` of both edges of its corridor over ``clear_distance``
        (a door, not open floor), and its corridor is clear for twice that (it leads somewhere: the
        inside of a U-shaped trap is no way out of it).
        """
        directions = headings - self._turned
        cfg = self.config
        left, right = _side_room(known, directions, cfg.clear_distance, width + cfg.gap_band)
        room = np.minimum(*_side_room(known, directions, 2.0 * cfg.clear_distance, width))
        passage = self._seen(scans, directions) & (room >= width) & np.isfinite(left) & np.isfinite(right)
        return passage & ~self._back(directions), np.minimum(left, right)

    def _back(self, directions: np.ndarray) -> np.ndarray:
        """Which base-frame ``directions`` [rad] lead back to a place where a deadlock began: one lies ahead
        along them, beyond ``clear_half_width`` and within twice ``clear_distance``, and within twice
        ``clear_half_width`` of their centre line or :data:`SPOT_CONE` of it (as :meth:`_needed` counts a way that
        passes such a place: the obstacle that blocked the robot there stretches round it). A gap that leads there
        is not taken: after a gap that led sideways with the way still blocked, the next deadlock's escape took the
        same gap back, to and fro between two obstacles."""
        if not self._spots:
            return np.zeros(len(directions), dtype=bool)
        along, across = self._spot_offsets(directions)
        ahead = (along > self.clear_half_width) & (along < 2.0 * self.config.clear_distance)
        return (ahead & self._beside(along, across)).any(axis=0)

    def _beside(self, along: np.ndarray, across: np.ndarray) -> np.ndarray:
        """Whether places ``along`` a way and ``across`` it [m] lie beside it: within twice ``clear_half_width`` of
        its centre line or :data:`SPOT_CONE` of it (an obstacle that blocked the robot at such a place stretches round
        it, and a way aimed at it from afar runs into the same obstacle). :meth:`_needed` and :meth:`_back` both ask."""
        return np.abs(across) < np.maximum(2.0 * self.clear_half_width, SPOT_CONE * along)

    def _seen(self, scans: tuple[LaserScan, ...], directions: np.ndarray, length: float | None = None) -> np.ndarray:
        """Which base-frame ``directions`` [rad] some lidar looks along now, at least partly, over a corridor
        ``length`` long [m] (default ``clear_distance``; its edge beams are enough: a corridor's sides are in
        the memory, but the longer the corridor the nearer its direction they must be)."""
        spread = math.atan2(self.clear_half_width, self.config.clear_distance if length is None else length)
        return np.array([any(scan.covers(d) or scan.coverage(d - spread, d + spread) > 0.0 for scan in scans)
                         for d in directions], dtype=bool)

    def _clear(self, known: np.ndarray, scans: tuple[LaserScan, ...], direction: float) -> bool:
        """Whether the base-frame ``direction`` [rad] is clear for as long as :meth:`_needed` asks (see the module
        docstring): seen now, and no point, current or remembered, in its corridor (unknown is never clear)."""
        directions = np.array([direction])
        width, length = self.clear_half_width, self._needed(direction)
        left, right = _side_room(known, directions, length, width)
        return bool(self._seen(scans, directions, length)[0] and min(left[0], right[0]) >= width)

    def _should_leave(self, nominal: np.ndarray, known: np.ndarray, scans: tuple[LaserScan, ...]) -> bool:
        """Whether to hand back: through the gap, or the way clear again (after ``min_time``), or timed out."""
        cfg = self.config
        if self._elapsed >= cfg.max_time:
            return True
        if self._gap is not None:
            # Through the gap, and on along it until the filter has left its narrow body (a long robot's cover turns
            # badly where its disk does not fit: the nominal would turn it there).
            if self._gap_left > 0.0 or self.inner.narrowed:
                return False
            m_line = -self._turned
            if self._needed(m_line) <= cfg.clear_distance or self._clear(known, scans, m_line):
                return True
            # Through, but the m-line leads back past where the robot got stuck and is blocked beyond: out of a
            # U-shaped trap through its own mouth, where a goal-seeking nominal would drive straight back in.
            # Follow on round the obstacle instead, and leave as below.
            self._gap, self._gap_wait = None, cfg.gap_retry
        if self._elapsed < cfg.min_time:
            return False
        if self._clear(known, scans, -self._turned):
            return True      # the way the robot was going when it got stuck is clear again
        if nominal[0] <= 0.0:
            return False
        return self._clear(known, scans, _intent(nominal))


def _free(points: np.ndarray, low: float, high: float, horizon: float = 3.0) -> float:
    """Nearest obstacle distance in the base-frame sector ``[low, high]`` [m] (``horizon`` if none)."""
    if points.shape[0] == 0:
        return horizon
    bearing = np.arctan2(points[:, 1], points[:, 0])
    inside = (bearing >= low) & (bearing <= high)
    if not inside.any():
        return horizon
    return min(float(np.min(np.hypot(points[inside, 0], points[inside, 1]))), horizon)


def _blocking_bearing(points: np.ndarray, blocking: tuple[float, float] | None) -> float:
    """Bearing [rad] of the obstacle that blocks the robot: the filter's binding point, else the nearest
    point ahead (within 90 degrees of the heading), else straight ahead."""
    if blocking is not None:
        return math.atan2(blocking[1], blocking[0])
    ahead = points[points[:, 0] > 0.0]
    if ahead.shape[0] == 0:
        return 0.0
    nearest = ahead[int(np.argmin(np.hypot(ahead[:, 0], ahead[:, 1])))]
    return math.atan2(nearest[1], nearest[0])


def _side_towards(opening: float, blocking: float) -> int:
    """The side (+1 left, -1 right) to go round an obstacle at bearing ``blocking`` [rad] towards an opening
    at bearing ``opening`` [rad].

    Facing the obstacle and turning left, the robot moves along it counter-clockwise (as seen from
    the robot): the side is the sense of the turn from the obstacle's bearing to the opening's; an
    opening straight behind the obstacle (less than a degree apart) is reached on its own side of the
    heading.
    """
    turn = math.sin(opening - blocking)
    if abs(turn) < math.sin(math.radians(1.0)):
        return 1 if opening > 0.0 else -1
    return 1 if turn > 0.0 else -1


def _intent(nominal: np.ndarray) -> float:
    """The bearing [rad] the nominal is heading for: the chord of its arc over one second, within +-pi/2."""
    return float(np.clip(0.5 * nominal[1], -0.5 * math.pi, 0.5 * math.pi))


def _fan(window: float) -> np.ndarray:
    """Offsets ``-window..window`` [rad] every :data:`GAP_RESOLUTION`, nearest zero first."""
    steps = int(window / GAP_RESOLUTION)
    offsets = GAP_RESOLUTION * np.arange(-steps, steps + 1)
    return offsets[np.argsort(np.abs(offsets), kind="stable")]


def _side_room(points: np.ndarray, directions: np.ndarray, length: float,
               reach: float) -> tuple[np.ndarray, np.ndarray]:
    """Per direction [rad]: the distance [m] from its centre line to the nearest point on the left and on
    the right, among the points ahead (up to ``length``) and within ``reach`` of it (``inf``: none)."""
    points = points[np.hypot(points[:, 0], points[:, 1]) < math.hypot(length, reach)]   # the rest is too far
    if points.shape[0] == 0:
        return np.full(len(directions), math.inf), np.full(len(directions), math.inf)
    along, across = _along_across(points, directions)
    ahead = (along > 0.0) & (along < length) & (np.abs(across) < reach)
    left = np.where(ahead & (across >= 0.0), across, math.inf).min(axis=0)
    right = np.where(ahead & (across < 0.0), -across, math.inf).min(axis=0)
    return left, right


def _free_length(points: np.ndarray, directions: np.ndarray, half_width: float, horizon: float) -> np.ndarray:
    """Per direction [rad]: how far [m] its corridor of ``half_width`` is free of ``points`` (``horizon`` at most)."""
    points = points[np.hypot(points[:, 0], points[:, 1]) < math.hypot(horizon, half_width)]
    if points.shape[0] == 0:
        return np.full(len(directions), horizon)
    along, across = _along_across(points, directions)
    inside = (along > 0.0) & (np.abs(across) < half_width)
    return np.minimum(np.where(inside, along, math.inf).min(axis=0), horizon)


def _along_across(points: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(N, D)`` each point's distance [m] along each direction [rad] and to the left of its centre line."""
    c, s = np.cos(directions), np.sin(directions)
    return np.outer(points[:, 0], c) + np.outer(points[:, 1], s), np.outer(points[:, 1], c) - np.outer(points[:, 0], s)


def _corridor(points: np.ndarray, direction: float, half_width: float, length: float) -> bool:
    """Whether any point lies in the corridor of ``half_width`` [m] along ``direction`` [rad], up to ``length``."""
    left, right = _side_room(points, np.array([direction]), length, half_width)
    return bool(min(left[0], right[0]) < half_width)

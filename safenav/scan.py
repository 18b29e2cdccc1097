"""The laser-scan model: ``sensor_msgs/LaserScan`` semantics without ROS.

A :class:`LaserScan` carries the fields of ``sensor_msgs/LaserScan`` plus the
pose of the laser frame on the robot base (:attr:`LaserScan.mount`). Beam ``i``
points at ``angle_min + i * angle_increment`` in the laser frame; everything
that needs a direction on the robot goes through the mount pose, never through
a hard-coded beam index (the ROSbot's lidar is mounted backwards, so its beam 0
looks forward and its beam 360 looks backward).

**Mount.** ROS keeps the mount in tf, not in the message, so a scan built without
``mount=`` (``LaserScan(...)``, :meth:`LaserScan.from_msg`) has
:attr:`LaserScan.mount_given` ``False``: it behaves as if mounted at the base origin,
and :meth:`safenav.robot.RobotSpec.match_scan` (which the filters call) puts it on the
robot's lidar. Scans of a :class:`~safenav.robot.LidarSpec` always carry its mount.
Angles are radians: a mount yaw or an ``angle_min``/``angle_max`` beyond one turn
(``|angle| > 2*pi``), or an ``angle_increment`` that only fits the beam count in
degrees, is rejected with "looks like degrees; expected radians".

Readings follow REP-117 (see :class:`Reading`):

======================  ===================  ====================================
value                   :class:`Reading`     meaning
======================  ===================  ====================================
finite, in range        ``HIT``              an obstacle at that range
``+inf``                ``NO_RETURN``        nothing within ``range_max``: free up to it
``-inf``                ``TOO_CLOSE``        an object closer than ``range_min``
``NaN``                 ``INVALID``          no information
finite, out of range    ``INVALID``          discarded, as the sensor's spec says
======================  ===================  ====================================

Directions with no informative beam (outside the field of view, or only
``INVALID`` readings) are *unknown*, never free.

**Drivers that mark "no return" with a number.** Many drivers (Hokuyo's, some
RPLIDAR and Gazebo versions) report ``0.0`` or ``range_max`` instead of ``+inf``.
Plain REP-117 reads ``0.0`` as ``INVALID`` (below ``range_min``) and ``range_max`` as
a hit, so runs of them become unknown directions or phantom walls. Say what the
driver does with ``no_return=`` (:data:`NO_RETURN_CONVENTIONS`), and those readings
become ``+inf`` when the scan is built:

==================  ===============================================  ===========
``no_return``       readings that become ``+inf`` (``NO_RETURN``)     default
==================  ===============================================  ===========
``None``            none: plain REP-117                              yes
``"zero"``          exactly ``0.0``
``"range_max"``     at or above ``range_max`` (finite)
==================  ===============================================  ===========

**Timestamps** (:func:`stamp_seconds`) are seconds as a float. Accepted: a real number
of seconds; an integer of nanoseconds, recognised by its size (an integer ``>= 1e14``
is nanoseconds: as seconds it would be three million years, while any clock in
nanoseconds passes 1e14 ns 28 hours after its epoch; a nanosecond count smaller than
that, such as simulation time, must be converted by the caller); ROS 2 / ``rosbags`` /
``builtin_interfaces`` times (``sec``, ``nanosec``); ROS 1 times (``secs``, ``nsecs``);
rclpy ``Time`` (``nanoseconds``); anything with ``to_sec()``. Anything else raises
:class:`~safenav.errors.InvalidScanType` naming its type.

One module for the scan model on purpose: the REP-117 reading classes, the mount, the ROS message
conversions (ROS 1, ROS 2, rosbags, stamps) and the geometric queries all act on the same few
arrays, and splitting them would scatter one data type over several files.
"""

from __future__ import annotations

import dataclasses
import enum
import functools
import math
import numbers
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import numpy as np

from safenav._checks import choice, is_real, number
from safenav.errors import InvalidScan, InvalidScanType, SafeNavError
from safenav.geometry import TWO_PI, Pose2D, wrap_angle

__all__ = [
    "NANOSECOND_STAMP_THRESHOLD",
    "NO_RETURN_CONVENTIONS",
    "BeamGeometry",
    "LaserScan",
    "Reading",
    "SectorReading",
    "SectorState",
    "check_radians",
    "check_scan",
    "stamp_seconds",
]

#: Slack on the beam-count check: ROS drivers differ by one beam in whether
#: ``angle_max`` is the last beam's angle or one increment past it.
COUNT_TOLERANCE = 1.0 + 1e-6
_ANGLE_TOL = 1e-9

#: How a driver may mark "no return" with a number (``no_return=``; see the module docstring).
NO_RETURN_CONVENTIONS = ("zero", "range_max")

#: An integer timestamp at least this large is nanoseconds, not seconds (module docstring).
NANOSECOND_STAMP_THRESHOLD = 10**14
_NANOSECONDS_PER_SECOND = 10**9


#: Cached properties of :class:`LaserScan` computed from its ranges.
_RANGE_CACHES = ("readings", "_hit_mask", "n_informative")


class Reading(enum.IntEnum):
    """What one range reading means (REP-117)."""

    HIT = 0
    """A finite range inside ``[range_min, range_max]``: an obstacle at that range."""
    NO_RETURN = 1
    """``+inf``: no return within ``range_max``; the beam is free up to ``range_max``."""
    TOO_CLOSE = 2
    """``-inf``: an object closer than ``range_min`` (right at the sensor)."""
    INVALID = 3
    """``NaN`` or a finite value outside ``[range_min, range_max]``: no information."""


# The readings' codes as plain ints (an enum member's lookup costs more than the array operation it feeds).
_HIT, _NO_RETURN, _TOO_CLOSE, _INVALID = (int(reading) for reading in Reading)


class SectorState(enum.Enum):
    """What a sector of the scan says about the space it covers."""

    OBSTACLE = "obstacle"
    """At least one beam hit something (or reported an object closer than ``range_min``)."""
    FREE = "free"
    """Every informative beam reported no return within ``range_max``."""
    UNKNOWN = "unknown"
    """No informative beam: outside the field of view, or only invalid readings."""


@dataclass(frozen=True)
class SectorReading:
    """The nearest reading in an angular sector of the base frame.

    Attributes:
        min_range: smallest range in the sector [m], measured from the laser.
            ``range_min`` when a beam reported ``-inf`` (the object is at least
            that close), ``inf`` when every informative beam saw nothing, ``nan``
            when the sector holds no informative beam.
        state: obstacle, free or unknown (see :class:`SectorState`).
        n_beams: beams whose direction lies in the sector.
        n_informative: of those, beams that are not ``INVALID``.
        n_too_close: of those, beams that read ``-inf``.
        coverage: fraction of the sector's angular width inside the field of view [0..1].
    """

    min_range: float
    state: SectorState
    n_beams: int
    n_informative: int
    n_too_close: int
    coverage: float

    @property
    def complete(self) -> bool:
        """True when the field of view covers the whole sector and every beam in it is informative."""
        return self.coverage >= 1.0 - 1e-9 and self.n_informative == self.n_beams > 0


class BeamGeometry(NamedTuple):
    """Beam directions of one scan layout (cached; arrays are read-only)."""

    laser_angles: np.ndarray
    """Beam angles in the laser frame [rad], ``angle_min + i * angle_increment``."""
    base_angles: np.ndarray
    """Beam directions in the base frame [rad], wrapped into ``[-pi, pi)``."""
    cos_base: np.ndarray
    """``cos(base_angles)``."""
    sin_base: np.ndarray
    """``sin(base_angles)``."""


@functools.lru_cache(maxsize=64)
def _beam_geometry(angle_min: float, angle_increment: float, n_beams: int, mount_yaw: float) -> BeamGeometry:
    laser = angle_min + angle_increment * np.arange(n_beams, dtype=float)
    base = wrap_angle(laser + mount_yaw)
    arrays = (laser, base, np.cos(base), np.sin(base))
    for array in arrays:
        array.flags.writeable = False
    return BeamGeometry(*arrays)


class _UnstatedMount(Pose2D):
    """The identity pose of a scan built without a mount (:attr:`LaserScan.mount_given` is ``False``).

    Its own type, so "not given" survives :func:`dataclasses.replace`, copies and pickling,
    while every computation sees the identity pose.
    """

    __slots__ = ()

    def __repr__(self) -> str:
        return "Pose2D(x=0.0, y=0.0, yaw=0.0)"


_UNSTATED_MOUNT = _UnstatedMount()
_UNCHANGED = object()   # LaserScan.with_ranges: the stamp stays
#: LaserScan.sector's beams and coverage per (layout, sector), at most _SECTORS_KEPT of them.
_SECTORS: dict[tuple[float, ...], tuple[np.ndarray, float]] = {}
_SECTORS_KEPT = 1024
_NO_INTENSITIES = np.empty(0)
_NO_INTENSITIES.flags.writeable = False


def _is_unstated(mount: Any) -> bool:
    return mount is None or (type(mount) is _UnstatedMount and tuple(mount) == (0.0, 0.0, 0.0))


def check_radians(name: str, value: Any, *, error: type[SafeNavError] = InvalidScan) -> float:
    """``value`` as a finite angle [rad] within one turn, or ``error`` naming ``name``.

    No angle of a planar scan or mount needs more than one turn, so ``|value| > 2*pi`` is
    taken for degrees (``mount=(0, 0, 180)``) and rejected with "looks like degrees;
    expected radians".
    """
    result = number(name, value, error=error)
    if abs(result) > TWO_PI + _ANGLE_TOL:
        raise error(f"{name}={value!r} looks like degrees; expected radians within one turn (|{name}| <= 2*pi)")
    return result


def stamp_seconds(stamp: Any, name: str = "stamp") -> float | None:
    """A timestamp in seconds from any accepted form; ``None`` stays ``None``.

    Accepted forms (see the module docstring): a real number of seconds; an integer of
    nanoseconds, recognised as an integer ``>= 1e14`` (:data:`NANOSECOND_STAMP_THRESHOLD`);
    an object with ``sec`` and ``nanosec`` (ROS 2, ``builtin_interfaces/Time``, rosbags) or
    ``secs`` and ``nsecs`` (ROS 1); an rclpy ``Time`` (``nanoseconds``); anything with
    ``to_sec()`` (rospy). Use it for ``Odometry`` and ``TwistStamped`` stamps too, so every
    time in a loop is on the same scale.

    Args:
        stamp: the time.
        name: how error messages name it (``"header.stamp"``).

    Returns:
        The time [s], or ``None`` when ``stamp`` is ``None``.

    Raises:
        InvalidScanType: ``stamp`` is none of the accepted forms (the message names its type).
        InvalidScan: the value is not finite, a float at least 1e14 (nanoseconds as a float:
            pass them as an integer, or seconds), or a nanosecond field outside ``[0, 1e9)``.
    """
    if stamp is None:
        return None
    if is_real(stamp):
        if isinstance(stamp, numbers.Integral) and stamp >= NANOSECOND_STAMP_THRESHOLD:
            return _nanoseconds_to_seconds(int(stamp))
        result = float(stamp)
        if not math.isfinite(result):
            raise InvalidScan(f"{name} must be finite, got {result!r}")
        if abs(result) >= NANOSECOND_STAMP_THRESHOLD:
            raise InvalidScan(
                f"{name}={stamp!r} looks like nanoseconds; expected seconds, or nanoseconds as an integer >= 1e14"
            )
        return result
    for seconds_field, nanoseconds_field in (("sec", "nanosec"), ("secs", "nsecs")):
        if hasattr(stamp, seconds_field):
            if not hasattr(stamp, nanoseconds_field):
                raise InvalidScanType(
                    f"{name} of type {type(stamp).__name__} has {seconds_field!r} but no {nanoseconds_field!r}; "
                    f"expected a ROS time with both"
                )
            seconds = number(f"{name}.{seconds_field}", getattr(stamp, seconds_field), error=InvalidScan)
            nanoseconds = number(f"{name}.{nanoseconds_field}", getattr(stamp, nanoseconds_field), low=0.0,
                                 high=float(_NANOSECONDS_PER_SECOND), high_open=True, error=InvalidScan)
            return seconds + nanoseconds * 1e-9
    if hasattr(stamp, "nanoseconds"):  # rclpy.time.Time
        nanoseconds = stamp.nanoseconds
        if isinstance(nanoseconds, numbers.Integral) and not isinstance(nanoseconds, bool):
            return _nanoseconds_to_seconds(int(nanoseconds))
        return number(f"{name}.nanoseconds", nanoseconds, error=InvalidScan) * 1e-9
    to_sec = getattr(stamp, "to_sec", None)
    if callable(to_sec):  # rospy.Time
        return number(f"{name}.to_sec()", to_sec(), error=InvalidScan)
    raise InvalidScanType(
        f"{name} must be a real number of seconds, integer nanoseconds (>= 1e14) or a ROS time "
        f"(sec/nanosec, secs/nsecs, nanoseconds or to_sec()), got {stamp!r} of type {type(stamp).__name__}"
    )


def _nanoseconds_to_seconds(nanoseconds: int) -> float:
    """Integer nanoseconds as seconds, split first so that the float keeps the nanoseconds it can."""
    seconds, remainder = divmod(nanoseconds, _NANOSECONDS_PER_SECOND)
    return seconds + remainder * 1e-9


def _degrees_hint(angle_min: float, angle_max: float, angle_increment: float, n_beams: int) -> str:
    """Why the layout looks like degrees (empty when it does not)."""
    hints = [f"{name}={value!r}" for name, value in (("angle_min", angle_min), ("angle_max", angle_max))
             if abs(value) > TWO_PI + _ANGLE_TOL]
    if n_beams > 1 and not hints:
        span = angle_max - angle_min
        fits_radians = abs((n_beams - 1) * angle_increment - span) <= angle_increment * COUNT_TOLERANCE
        increment_if_degrees = math.radians(angle_increment)
        fits_degrees = abs((n_beams - 1) * increment_if_degrees - span) <= increment_if_degrees * COUNT_TOLERANCE
        if fits_degrees and not fits_radians:
            hints.append(f"angle_increment={angle_increment!r}")
    if not hints:
        return ""
    return f"{' and '.join(hints)} {'look' if len(hints) > 1 else 'looks'} like degrees; expected radians"


def _mark_no_returns(ranges: np.ndarray, convention: str | None, range_max: float) -> np.ndarray:
    """``ranges`` with the driver's no-return marker replaced by ``+inf`` (read-only; unchanged for ``None``)."""
    if convention is None:
        return ranges
    marked = ranges == 0.0 if convention == "zero" else (ranges >= range_max) & np.isfinite(ranges)
    if not marked.any():
        return ranges
    converted = np.where(marked, math.inf, ranges)
    converted.flags.writeable = False
    return converted


def _real(name: str, value: Any) -> float:
    """``value`` as a finite float, or the error that names ``name``."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise InvalidScanType(f"{name} must be a real number, got {value!r} of type {type(value).__name__}")
    result = float(value)
    if not math.isfinite(result):
        raise InvalidScan(f"{name} must be finite, got {result!r}")
    return result


def _real_array(name: str, values: Any) -> np.ndarray:
    """``values`` as a fresh, read-only 1-D float64 array, or the error that names ``name``."""
    if values is None or isinstance(values, (str, bytes)):
        raise InvalidScanType(f"{name} must be a 1-D sequence of real numbers, got {values!r}")
    try:
        array = np.array(values)
    except (TypeError, ValueError) as exc:  # ragged nesting
        raise InvalidScanType(
            f"{name} must be a 1-D sequence of real numbers, got {type(values).__name__}: {exc}"
        ) from None
    if array.dtype.kind == "O":
        bad = [v for v in array.ravel() if isinstance(v, bool) or not isinstance(v, numbers.Real)][:1]
        if bad:
            raise InvalidScanType(
                f"{name} must be a 1-D sequence of real numbers, "
                f"got an element {bad[0]!r} of type {type(bad[0]).__name__}"
            )
    elif array.dtype.kind not in "fiu":
        raise InvalidScanType(f"{name} must be a 1-D sequence of real numbers, got elements of dtype {array.dtype}")
    if array.ndim != 1:
        raise InvalidScanType(f"{name} must be 1-D, got an array of shape {array.shape}")
    try:
        array = array.astype(np.float64, copy=False)
    except (OverflowError, TypeError, ValueError) as exc:
        raise InvalidScanType(f"{name} must hold real numbers that fit a float64: {exc}") from None
    array.flags.writeable = False
    return array


@dataclass(frozen=True, eq=False, kw_only=True)
class LaserScan:
    """One 2D laser scan with ``sensor_msgs/LaserScan`` fields and its mount pose.

    Construct it from keyword arguments, from any message-like object with
    :meth:`from_msg`, or from a robot's template (:meth:`safenav.robot.LidarSpec.scan`).
    Construction validates every field and raises :class:`~safenav.errors.InvalidScan`
    (or :class:`~safenav.errors.InvalidScanType`) naming the field and the value.
    ``ranges`` and ``intensities`` are copied into read-only float64 arrays; with
    ``no_return`` set, the driver's no-return marker is already ``+inf`` in ``ranges``.

    Attributes:
        angle_min: angle of beam 0 in the laser frame [rad].
        angle_max: angle of the last beam in the laser frame [rad] (informative:
            beam angles are always ``angle_min + i * angle_increment``).
        angle_increment: angle between beams [rad], > 0. A clockwise scan (``angle_increment < 0``, as
            drivers of lidars mounted upside down or spinning clockwise publish it) is stored in
            counter-clockwise order at construction: ``ranges`` and ``intensities`` reversed,
            ``angle_min`` its last beam, ``angle_max`` its first, ``time_increment`` negated; every
            beam keeps its direction.
        ranges: range readings [m], REP-117 special values allowed.
        range_min: smallest range the sensor reports [m].
        range_max: largest range the sensor reports [m].
        time_increment: time between beams [s].
        scan_time: time between scans [s].
        intensities: per-beam intensities (device units), empty or one per range.
        mount: pose of the laser frame in the robot base frame [m, m, rad]. ``None`` (the
            default) means "not given": the scan is placed at the identity pose and
            :attr:`mount_given` is ``False``, so :meth:`safenav.robot.RobotSpec.match_scan`
            puts it on the robot's lidar. Radians: ``|yaw| > 2*pi`` is rejected as degrees.
        stamp: acquisition time of the scan [s], if known (``header.stamp``); every form
            :func:`stamp_seconds` accepts, stored as seconds.
        frame_id: name of the laser frame (picks the lidar on a robot with several).
        no_return: how the driver marks "no return" (:data:`NO_RETURN_CONVENTIONS`):
            ``"zero"`` or ``"range_max"`` readings become ``+inf`` here; ``None`` is plain REP-117.
    """

    angle_min: float
    angle_max: float
    angle_increment: float
    ranges: np.ndarray
    range_min: float
    range_max: float
    time_increment: float = 0.0
    scan_time: float = 0.0
    intensities: np.ndarray = field(default_factory=lambda: np.empty(0))
    # None at construction means "not given"; after it, always a Pose2D (see mount_given).
    mount: Pose2D = None  # type: ignore[assignment]
    stamp: float | None = None
    frame_id: str = "laser"
    no_return: str | None = None

    def __post_init__(self) -> None:
        put = functools.partial(object.__setattr__, self)
        for name in ("angle_min", "angle_max", "angle_increment", "range_min", "range_max",
                     "time_increment", "scan_time"):
            put(name, _real(name, getattr(self, name)))
        ranges = _real_array("ranges", self.ranges)
        intensities = _real_array("intensities", self.intensities)
        n = ranges.size
        if n == 0:
            raise InvalidScan("ranges is empty; expected at least one beam")
        if self.angle_increment == 0.0:
            raise InvalidScan(f"angle_increment must be nonzero, got {self.angle_increment!r}")
        if self.angle_increment < 0.0:
            ranges, intensities = self._counter_clockwise(ranges, intensities)
        put("intensities", intensities)
        if self.range_min < 0.0:
            raise InvalidScan(f"range_min must be >= 0, got {self.range_min!r}")
        if self.range_max <= self.range_min:
            raise InvalidScan(f"range_max must be > range_min = {self.range_min!r}, got {self.range_max!r}")
        degrees = _degrees_hint(self.angle_min, self.angle_max, self.angle_increment, n)
        expected = (self.angle_max - self.angle_min) / self.angle_increment + 1.0
        if abs(expected - n) > COUNT_TOLERANCE:
            raise InvalidScan(
                f"ranges has {n} values but angle_min={self.angle_min!r}, angle_max={self.angle_max!r} and "
                f"angle_increment={self.angle_increment!r} describe {expected:.3f} beams"
                + (f"; {degrees}" if degrees else "")
            )
        if (n - 1) * self.angle_increment > TWO_PI + self.angle_increment + _ANGLE_TOL:
            raise InvalidScan(
                f"angle_increment={self.angle_increment!r} over {n} beams spans "
                f"{(n - 1) * self.angle_increment:.6f} rad; expected at most one turn (2*pi)"
                + (f"; {degrees}" if degrees else "")
            )
        if degrees:
            raise InvalidScan(degrees)
        if intensities.size not in (0, n):
            raise InvalidScan(f"intensities has {intensities.size} values; expected 0 or {n} (one per range)")
        if _is_unstated(self.mount):
            put("mount", _UNSTATED_MOUNT)
        else:
            put("mount", _pose("mount", self.mount))
        put("stamp", stamp_seconds(self.stamp))
        if not isinstance(self.frame_id, str):
            raise InvalidScanType(f"frame_id must be a string, got {self.frame_id!r}")
        if self.no_return is not None:
            choice("no_return convention", self.no_return, NO_RETURN_CONVENTIONS)
        put("ranges", _mark_no_returns(ranges, self.no_return, self.range_max))

    def _counter_clockwise(self, ranges: np.ndarray, intensities: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Store a clockwise scan (``angle_increment < 0``) in counter-clockwise order; returns its readings so.

        Beam ``i`` of the message, at ``angle_min + i * angle_increment``, becomes beam ``n - 1 - i``: the
        stored ``angle_min`` is the message's last beam, ``angle_max`` its first, the increment positive and
        ``time_increment`` negated (stored beam ``j`` was measured ``j * time_increment`` after stored beam 0).
        """
        put = functools.partial(object.__setattr__, self)
        n, step = ranges.size, self.angle_increment
        last = self.angle_min + (n - 1) * step
        expected = (self.angle_max - self.angle_min) / step + 1.0
        if abs(expected - n) > COUNT_TOLERANCE:
            raise InvalidScan(
                f"ranges has {n} values but angle_min={self.angle_min!r}, angle_max={self.angle_max!r} and "
                f"angle_increment={step!r} describe {expected:.3f} beams; a clockwise scan (angle_increment < 0) "
                f"ends at angle_max = angle_min + (n - 1) * angle_increment = {last!r}"
            )
        put("angle_max", self.angle_min)
        put("angle_min", last)
        put("angle_increment", -step)
        put("time_increment", -self.time_increment)

        def reverse(values: np.ndarray) -> np.ndarray:
            flipped = np.ascontiguousarray(values[::-1])
            flipped.flags.writeable = False
            return flipped

        return reverse(ranges), reverse(intensities)

    # ------------------------------------------------------------------ construction

    @classmethod
    def from_msg(cls, msg: Any, *, mount: Pose2D | Sequence[float] | None = None, stamp: Any = None,
                 no_return: str | None = None) -> LaserScan:
        """Convert any object with ``sensor_msgs/LaserScan`` attributes.

        Works with rospy, rclpy and rosbags messages and with a
        ``types.SimpleNamespace``; ROS is not imported. ``header.stamp`` (any form
        :func:`stamp_seconds` accepts) becomes :attr:`stamp` unless ``stamp`` is given,
        and ``header.frame_id`` becomes :attr:`frame_id`.

        Args:
            msg: the message-like object.
            mount: pose of the laser frame in the base frame [m, m, rad]. ROS keeps it in
                tf, not in the message; leave it out and the robot's lidar mount is used
                (:meth:`safenav.robot.RobotSpec.match_scan`, which the filters call).
            stamp: acquisition time, overriding the header (seconds, or any form of
                :func:`stamp_seconds`).
            no_return: the driver's no-return marker, ``"zero"`` or ``"range_max"``
                (:data:`NO_RETURN_CONVENTIONS`); ``None`` is plain REP-117.

        Raises:
            InvalidScan: a field is missing or inconsistent (the message names it).
            InvalidScanType: a field has the wrong type, or the stamp is of no known form.
        """
        values: dict[str, Any] = {}
        for name in ("angle_min", "angle_max", "angle_increment", "time_increment", "scan_time",
                     "range_min", "range_max", "ranges"):
            try:
                values[name] = getattr(msg, name)
            except AttributeError:
                raise InvalidScan(
                    f"message {type(msg).__name__} has no field {name!r}; expected a sensor_msgs/LaserScan-like object"
                ) from None
        values["intensities"] = getattr(msg, "intensities", ())
        header = getattr(msg, "header", None)
        if stamp is None and header is not None:
            stamp = stamp_seconds(getattr(header, "stamp", None), "header.stamp")
        frame_id = getattr(header, "frame_id", "laser") if header is not None else "laser"
        return cls(**values, mount=mount, stamp=stamp, frame_id=frame_id if isinstance(frame_id, str) else "laser",
                   no_return=no_return)

    def with_ranges(self, ranges: Any, intensities: Any = (), *, stamp: Any = _UNCHANGED) -> LaserScan:
        """A scan with the same layout and new readings (validated), stamped ``stamp`` [s] when given.

        Only what changes is validated (the layout was when this scan was built), so the call costs a few
        microseconds (the simulator makes every scan so).

        Raises:
            InvalidScanType: ``ranges`` or ``intensities`` is not a 1-D sequence of real numbers.
            InvalidScan: ``ranges`` does not hold one value per beam of this layout, or ``intensities`` neither
                that nor none.
        """
        values = _real_array("ranges", ranges)
        n = self.n_beams
        if values.size != n:
            raise InvalidScan(f"ranges has {values.size} values; expected {n}, one per beam of this scan's layout "
                              f"(angle_min={self.angle_min!r}, angle_increment={self.angle_increment!r})")
        extra = {} if stamp is _UNCHANGED else {"stamp": stamp_seconds(stamp)}
        if not (isinstance(intensities, tuple) and not intensities):
            intensities = _real_array("intensities", intensities)
            if intensities.size not in (0, n):
                raise InvalidScan(f"intensities has {intensities.size} values; expected 0 or {n} (one per range)")
        else:
            intensities = _NO_INTENSITIES
        return self._copy_with(ranges=_mark_no_returns(values, self.no_return, self.range_max),
                               intensities=intensities, derived_from_ranges=True, **extra)

    def replace(self, **changes: Any) -> LaserScan:
        """A copy with some fields changed (validated), as :func:`dataclasses.replace`.

        An unchanged mount stays as it was, given or not; ``mount=None`` makes it "not given".
        """
        return dataclasses.replace(self, **changes)

    def with_mount(self, mount: Pose2D | Sequence[float]) -> LaserScan:
        """This scan on another mount pose [m, m, rad] (:attr:`mount_given` ``True``).

        Only the mount is validated: the readings and everything derived from them are
        shared with this scan, so the call costs a few microseconds (the filters call it
        on every scan through :meth:`safenav.robot.RobotSpec.match_scan`).
        """
        return self._copy_with(mount=_pose("mount", mount))

    def with_no_return(self, convention: str | None) -> LaserScan:
        """This scan read with the driver's no-return convention (:data:`NO_RETURN_CONVENTIONS`).

        A scan that already states a convention keeps its readings (markers already became
        ``+inf``); asking for a different one raises, since its markers are gone.

        Raises:
            InvalidScan: the scan states another convention.
            UnknownName: ``convention`` is not one of :data:`NO_RETURN_CONVENTIONS`.
        """
        if convention == self.no_return:
            return self
        if self.no_return is not None:
            raise InvalidScan(
                f"scan was built with no_return={self.no_return!r}; cannot re-read it with no_return={convention!r}"
            )
        choice("no_return convention", convention, NO_RETURN_CONVENTIONS)
        ranges = _mark_no_returns(self.ranges, convention, self.range_max)
        return self._copy_with(no_return=convention, ranges=ranges, derived_from_ranges=ranges is not self.ranges)

    def _copy_with(self, *, derived_from_ranges: bool = False, **values: Any) -> LaserScan:
        """A shallow copy with already validated ``values``; cached readings are kept unless the ranges change."""
        copy = object.__new__(LaserScan)
        state = dict(self.__dict__)
        if derived_from_ranges:
            for name in _RANGE_CACHES:
                state.pop(name, None)
            state.pop("_sweep_motion", None)    # new readings: measured on another sweep
        if "mount" in values or "_sweep_motion" in values or derived_from_ranges:
            state.pop("_sweep_error", None)
        state.update(values)
        copy.__dict__.update(state)
        return copy

    @property
    def mount_given(self) -> bool:
        """Whether the mount was given (``False``: placed at the identity until matched to a robot)."""
        return type(self.mount) is not _UnstatedMount

    # ------------------------------------------------------------------ geometry

    @property
    def n_beams(self) -> int:
        """Number of beams."""
        return int(self.ranges.size)

    @property
    def geometry(self) -> BeamGeometry:
        """Beam directions in the laser and base frames (shared by scans of the same layout)."""
        return _beam_geometry(self.angle_min, self.angle_increment, self.n_beams, self.mount.yaw)

    @property
    def angles(self) -> np.ndarray:
        """Beam angles in the laser frame [rad]."""
        return self.geometry.laser_angles

    @property
    def base_angles(self) -> np.ndarray:
        """Beam directions in the base frame [rad], in ``[-pi, pi)``."""
        return self.geometry.base_angles

    @property
    def field_of_view(self) -> float:
        """Angular width the beams cover, half an increment either side of the end beams [rad]."""
        return min(self.n_beams * self.angle_increment, TWO_PI)

    def beam_index(self, direction: float) -> int | None:
        """Index of the beam nearest a base-frame direction.

        Args:
            direction: direction in the base frame [rad] (any value; wrapped).

        Returns:
            The beam index, or ``None`` when the direction is outside the field of
            view (more than half an increment beyond the first or last beam).
            When two beams point the same way (a 360-degree scan whose first and
            last beams coincide) the lower index is returned.
        """
        increment = self.angle_increment
        offset = (direction - self.mount.yaw - self.angle_min) % TWO_PI
        best_error, best_index = math.inf, 0
        for turn in (0.0, -TWO_PI):
            t = offset + turn
            # Half-way between two beams, take the counter-clockwise one (m2wr's front is beam 360).
            index = min(max(math.floor(t / increment + 0.5 + 1e-9), 0), self.n_beams - 1)
            error = abs(t - index * increment)
            if error < best_error - _ANGLE_TOL:
                best_error, best_index = error, index
        error, index = best_error, best_index
        return index if error <= 0.5 * increment * (1.0 + 1e-9) + _ANGLE_TOL else None

    def covers(self, direction: float) -> bool:
        """Whether a base-frame direction [rad] lies inside the field of view."""
        return self.beam_index(direction) is not None

    def coverage(self, lo: float, hi: float) -> float:
        """Fraction of the base-frame sector from ``lo`` counter-clockwise to ``hi`` inside the field of view."""
        width = _sector_width(lo, hi)
        if width <= 0.0:
            return 1.0 if self.covers(lo) else 0.0
        fov_start = (self.mount.yaw + self.angle_min - 0.5 * self.angle_increment - lo) % TWO_PI
        fov = self.field_of_view
        overlap = 0.0
        for start in (fov_start - TWO_PI, fov_start):
            overlap += max(0.0, min(width, start + fov) - max(0.0, start))
        return min(overlap / width, 1.0)

    def sector_mask(self, lo: float, hi: float) -> np.ndarray:
        """Boolean mask of the beams whose base-frame direction lies in ``[lo, hi]`` counter-clockwise [rad]."""
        width = _sector_width(lo, hi)
        return (self.base_angles - lo) % TWO_PI <= width + _ANGLE_TOL

    # ------------------------------------------------------------------ readings

    @functools.cached_property
    def readings(self) -> np.ndarray:
        """The :class:`Reading` of every beam, as a read-only int8 array."""
        r = self.ranges
        codes = np.full(r.size, _INVALID, dtype=np.int8)
        codes[self._hit_mask] = _HIT
        if np.isinf(r).any():
            codes[r == math.inf] = _NO_RETURN
            codes[r == -math.inf] = _TOO_CLOSE
        codes.flags.writeable = False
        return codes

    @functools.cached_property
    def _hit_mask(self) -> np.ndarray:
        r = self.ranges
        return (r >= self.range_min) & (r <= self.range_max)

    @functools.cached_property
    def n_informative(self) -> int:
        """Number of beams that are not ``INVALID`` (in range, or ``+-inf``)."""
        return int(np.count_nonzero(self._hit_mask)) + int(np.count_nonzero(np.isinf(self.ranges)))

    def _classified(self, readings: np.ndarray, hits: np.ndarray, n_informative: int) -> None:
        """Set :attr:`readings`, its hit mask and :attr:`n_informative` as computed elsewhere (the filters' compiled
        kernel, :func:`safenav.filters.perception.classify`: the same values in one pass)."""
        readings.flags.writeable = False
        self.__dict__.update(readings=readings, _hit_mask=hits, n_informative=int(n_informative))

    def obstacle_beams(self) -> tuple[np.ndarray, np.ndarray]:
        """Indices of the beams that give an obstacle point, and their ranges [m].

        ``HIT`` beams at their range, ``TOO_CLOSE`` beams at ``range_min``.
        """
        r = self.ranges
        too_close = r == -math.inf
        if too_close.any():
            index = np.flatnonzero(self._hit_mask | too_close)
            return index, np.where(too_close[index], self.range_min, r[index])
        index = np.flatnonzero(self._hit_mask)
        return index, r[index]

    def points(self, frame: str = "base") -> np.ndarray:
        """Obstacle points of the scan as an ``(N, 2)`` array [m].

        ``HIT`` beams give the point at their range; ``TOO_CLOSE`` beams give a point
        at ``range_min`` (the object is at least that close). ``NO_RETURN`` and
        ``INVALID`` beams give no point.

        Args:
            frame: ``"base"`` (through :attr:`mount`) or ``"laser"``.
        """
        index, r = self.obstacle_beams()
        if frame == "laser":
            angles = self.angles[index]
            return np.column_stack((r * np.cos(angles), r * np.sin(angles)))
        if frame != "base":
            raise InvalidScan(f"frame must be 'base' or 'laser', got {frame!r}")
        return self.beam_points(index, r)

    def beam_points(self, index: np.ndarray, ranges: np.ndarray) -> np.ndarray:
        """The base-frame points ``(N, 2)`` [m] at ``ranges`` [m] along the beams ``index``, each from where the lidar
        was when it measured that beam (:attr:`sweep_motion`)."""
        geometry = self.geometry
        out = np.empty((len(index), 2))
        sweep = self.sweep_motion
        if sweep is None:
            out[:, 0] = self.mount.x + ranges * geometry.cos_base[index]
            out[:, 1] = self.mount.y + ranges * geometry.sin_base[index]
            return out
        mount = self.mount
        c, s = math.cos(mount.yaw), math.sin(mount.yaw)
        dx, dy = sweep[index, 0], sweep[index, 1]
        direction = geometry.base_angles[index] + sweep[index, 2]
        out[:, 0] = mount.x + c * dx - s * dy + ranges * np.cos(direction)
        out[:, 1] = mount.y + s * dx + c * dy + ranges * np.sin(direction)
        return out

    @property
    def beam_times(self) -> np.ndarray:
        """When each beam was measured, after the stamp [s] (``sensor_msgs/LaserScan``: the stamp is the first beam's
        time, beam ``i`` of the message ``i * time_increment`` after it; a clockwise message's first beam is the
        last one stored). All 0 when ``time_increment`` is 0 (every beam at once)."""
        n, step = self.n_beams, self.time_increment
        if step == 0.0:
            return np.zeros(n)
        first = 0 if step > 0.0 else n - 1
        return (np.arange(n) - first) * step

    @property
    def sweep_motion(self) -> np.ndarray | None:
        """``(n_beams, 3)`` where the lidar was when it measured each beam, in the lidar frame at :attr:`mount`
        [m, m, rad], or ``None``: every beam from :attr:`mount`. A filter sets it when it moves a scan of a turning
        lidar into the current base frame (:meth:`with_sweep_motion`); the points of :meth:`beam_points` use it."""
        return self.__dict__.get("_sweep_motion")

    @property
    def sweep_error(self) -> tuple[float, float]:
        """How far [m] and how much [rad] the lidar was, at any beam, from :attr:`mount` (:attr:`sweep_motion`), as a
        bound ``(e_translation, e_rotation)`` on a base-frame point ``d`` from the base origin:
        ``e_translation + d e_rotation`` (the turn is about the lidar, ``|mount|`` from the base origin);
        ``(0, 0)`` without a sweep motion."""
        sweep = self.sweep_motion
        if sweep is None:
            return 0.0, 0.0
        known = self.__dict__.get("_sweep_error")
        if known is None:
            turn = float(np.max(np.abs(sweep[:, 2])))
            known = (float(np.max(np.hypot(sweep[:, 0], sweep[:, 1]))) + math.hypot(self.mount.x, self.mount.y) * turn,
                     turn)
            self.__dict__["_sweep_error"] = known
        return known

    def with_sweep_motion(self, motion: np.ndarray | None) -> LaserScan:
        """This scan with each beam measured from the lidar pose ``motion[i]`` ``(n_beams, 3)`` in the lidar frame at
        :attr:`mount` [m, m, rad] (:attr:`sweep_motion`; ``None``: every beam from the mount). The readings are
        shared; a new mount (:meth:`with_mount`) keeps the motion relative to it; new readings (:meth:`with_ranges`)
        and :meth:`replace` drop it.

        Raises:
            InvalidScan: ``motion`` is not ``(n_beams, 3)`` finite numbers.
        """
        if motion is not None:
            motion = np.array(motion, dtype=float)
            if motion.shape != (self.n_beams, 3) or not np.isfinite(motion).all():
                problem = f"shape {motion.shape}" if motion.shape != (self.n_beams, 3) else "non-finite values"
                raise InvalidScan(f"sweep motion must be ({self.n_beams}, 3) finite numbers (x [m], y [m], yaw [rad] "
                                  f"of the lidar at each beam), got {problem}")
            motion.flags.writeable = False
        return self._copy_with(_sweep_motion=motion)

    def sector(self, lo: float, hi: float) -> SectorReading:
        """The nearest reading in the base-frame sector from ``lo`` counter-clockwise to ``hi`` [rad].

        ``sector(-pi/12, pi/12)`` is the 30-degree cone ahead; ``sector(3*pi/4, -3*pi/4)``
        the 90 degrees behind. A sector with no informative beam is ``UNKNOWN``,
        never ``FREE``.
        """
        # The beams and the coverage depend on the layout alone: kept per layout and sector (a policy asks for
        # the same few sectors of every scan).
        key = (self.angle_min, self.angle_increment, self.n_beams, self.mount.yaw, lo, hi)
        layout = _SECTORS.get(key)
        if layout is None:
            if len(_SECTORS) >= _SECTORS_KEPT:
                _SECTORS.clear()
            layout = _SECTORS[key] = (np.flatnonzero(self.sector_mask(lo, hi)), self.coverage(lo, hi))
        beams, coverage = layout
        readings = self.readings[beams]
        n_beams = int(readings.size)
        n_informative = n_beams - int(np.count_nonzero(readings == _INVALID))
        n_too_close = int(np.count_nonzero(readings == _TOO_CLOSE))
        hits = self.ranges[beams][readings == _HIT]
        if n_too_close:
            min_range, state = self.range_min, SectorState.OBSTACLE
        elif hits.size:
            min_range, state = float(hits.min()), SectorState.OBSTACLE
        elif n_informative:
            min_range, state = math.inf, SectorState.FREE
        else:
            min_range, state = math.nan, SectorState.UNKNOWN
        return SectorReading(min_range, state, n_beams, n_informative, n_too_close, coverage)

    def __repr__(self) -> str:
        counts = np.bincount(self.readings, minlength=len(Reading))
        summary = ", ".join(f"{reading.name.lower()}={counts[reading]}" for reading in Reading if counts[reading])
        mount = tuple(round(v, 4) for v in self.mount) if self.mount_given else "not given"
        no_return = f", no_return={self.no_return!r}" if self.no_return else ""
        return (
            f"LaserScan({self.n_beams} beams, angle_min={self.angle_min:.4f}, "
            f"angle_increment={self.angle_increment:.6f}, range=[{self.range_min:g}, {self.range_max:g}] m, "
            f"mount={mount}{no_return}, {summary})"
        )


def check_scan(scan: Any, name: str = "scan") -> LaserScan:
    """``scan`` if it is a :class:`LaserScan`, else :class:`~safenav.errors.InvalidScanType` saying how to make one."""
    if not isinstance(scan, LaserScan):
        raise InvalidScanType(
            f"{name} must be a safenav LaserScan (use LaserScan.from_msg for ROS messages), got {type(scan).__name__}"
        )
    return scan


def _sector_width(lo: float, hi: float) -> float:
    """Counter-clockwise width from ``lo`` to ``hi`` [rad]; a full turn when ``hi - lo >= 2*pi``."""
    if hi - lo >= TWO_PI - _ANGLE_TOL:
        return TWO_PI
    return (hi - lo) % TWO_PI


def _pose(name: str, pose: Any) -> Pose2D:
    """``pose`` as a :class:`Pose2D` of finite floats, yaw in radians, or the error naming ``name``."""
    if type(pose) is Pose2D and all(type(value) is float for value in pose):  # fast path: a checked spec's mount
        x, y, yaw = pose
        if math.isfinite(x + y + yaw) and abs(yaw) <= TWO_PI + _ANGLE_TOL:
            return pose
    if not isinstance(pose, Sequence) or isinstance(pose, (str, bytes)) or len(pose) != 3:
        raise InvalidScanType(f"{name} must be a pose (x, y, yaw), got {pose!r}")
    x, y, yaw = (_real(f"{name}.{axis}", value) for axis, value in zip(Pose2D._fields, pose, strict=True))
    return Pose2D(x, y, check_radians(f"{name}.yaw", yaw))

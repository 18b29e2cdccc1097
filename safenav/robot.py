"""Robot descriptions: body, velocity and acceleration limits, lidars, and the three tutorial presets.

A :class:`RobotSpec` is everything a filter, a policy and the simulator need to
know about a differential-drive base. :func:`preset` returns the three robots of
the classic ROS tutorials (:data:`PRESET_NAMES`), from their public descriptions:

=============  ===================  =========================================  ==========
preset         tutorial             lidar                                      mount yaw
=============  ===================  =========================================  ==========
``rosbot``     stop at a wall       720 beams over -pi..pi, 0.15-12 m          pi
``puzzlebot``  obstacle avoidance   360 beams over 0..2pi, 0.15-12 m           0
``m2wr``       wall follower        720 beams over -pi/2..pi/2, 0.10-30 m      0
=============  ===================  =========================================  ==========

**Lidars and scans.** A robot has one lidar (:attr:`RobotSpec.lidar`) or several
(:attr:`RobotSpec.extra_lidars`, each named by its :attr:`LidarSpec.frame_id`). A scan
from a driver carries its layout but not its mount (that lives in tf);
:meth:`RobotSpec.match_scan` puts it on the lidar that took it and raises
:class:`~safenav.errors.LidarMismatch` when the scan contradicts that lidar, so a
wrong robot description or a wrong mount is an error, not a silent void of the
filters' guarantee. A robot that is not a preset is described with a
:class:`RobotSpec` and a :class:`LidarSpec` (README, "Your own robot").

Commands are ``(v, omega)``: linear velocity along base x [m/s] and yaw rate
[rad/s], as ``geometry_msgs/Twist`` ``linear.x`` and ``angular.z``.

One module for the robot description: the spec, its limits and the three presets with their sources
are read together, and the presets' numbers are documented next to them.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any, NamedTuple

import numpy as np

from safenav._checks import choice, integer, number, positive
from safenav.errors import (
    InvalidCommand,
    InvalidCommandType,
    InvalidConfig,
    InvalidScan,
    LidarMismatch,
    LidarMismatchWarning,
)
from safenav.geometry import Pose2D, wrap_angle
from safenav.pointcloud import CloudSlice
from safenav.scan import NO_RETURN_CONVENTIONS, LaserScan, check_scan

__all__ = [
    "ANGLE_TOLERANCE",
    "MOUNT_POSITION_TOLERANCE",
    "PRESET_NAMES",
    "RANGE_TOLERANCE",
    "Command",
    "LidarSpec",
    "RobotSpec",
    "as_command",
    "preset",
]

#: Largest difference between a scan's beam directions (first and last beam) or mount yaw
#: and its lidar's that :meth:`RobotSpec.match_scan` accepts [rad] (1 mrad, 0.057 deg: float32
#: rounding in messages is 1e-7 rad and a spec typed to four decimals passes; one beam of any
#: common 2D lidar, 2.5 mrad and up, does not).
ANGLE_TOLERANCE = 1e-3
#: Largest difference of ``range_min``/``range_max`` accepted by :meth:`RobotSpec.match_scan` [m].
RANGE_TOLERANCE = 1e-3
#: Largest difference of a given mount's position from its lidar's accepted by
#: :meth:`RobotSpec.match_scan` [m].
MOUNT_POSITION_TOLERANCE = 1e-3
#: Scan layouts remembered per robot by :meth:`RobotSpec.match_scan` (a robot sees a handful).
_LAYOUT_CACHE_SIZE = 32


class Command(NamedTuple):
    """A velocity command: ``v`` along base x [m/s], ``omega`` yaw rate [rad/s]."""

    v: float
    omega: float


def as_command(u: Any, name: str = "u") -> np.ndarray:
    """``u`` as a float array of shape ``(2,)``; the values may still be non-finite.

    Raises:
        InvalidCommandType: ``u`` is not a pair of real numbers (``None``, strings, objects).
        InvalidCommand: ``u`` has the wrong shape.
    """
    return _real_values(u, name, "a pair", "(v [m/s], omega [rad/s])", 2)


def as_pose(pose: Any, name: str = "pose") -> Pose2D:
    """``pose`` (a :class:`~safenav.geometry.Pose2D` or three real numbers ``(x [m], y [m], yaw [rad])``) as a Pose2D of
    floats; the values may still be non-finite.

    Raises:
        InvalidCommandType: ``pose`` is not three real numbers (``None``, strings, objects).
        InvalidCommand: ``pose`` has the wrong number of values.
    """
    x, y, yaw = _real_values(pose, name, "three values", "(x [m], y [m], yaw [rad])", 3).tolist()
    return Pose2D(x, y, yaw)


def _real_values(value: Any, name: str, count: str, fields: str, size: int) -> np.ndarray:
    """``value`` as a float array of shape ``(size,)`` (the values ``fields`` names, ``count`` in words), or the error
    that names ``name`` and what was wrong."""
    if value is None or isinstance(value, (str, bytes)):
        raise InvalidCommandType(f"{name} must be {count} {fields} of real numbers, got {value!r}")
    try:
        array = np.asarray(value)
    except (TypeError, ValueError):
        raise InvalidCommandType(f"{name} must be {count} {fields} of real numbers, got {value!r}") from None
    if array.dtype.kind not in "fiu":
        raise InvalidCommandType(f"{name} must be {count} {fields} of real numbers, got {value!r}")
    if array.shape != (size,):
        raise InvalidCommand(f"{name} must have shape {(size,)} as {fields}, got shape {array.shape}")
    return array.astype(float)


def _read_only(array: np.ndarray) -> np.ndarray:
    array.flags.writeable = False
    return array


def _pose_text(pose: Pose2D) -> str:
    return f"({pose.x:.4g}, {pose.y:.4g}, {pose.yaw:.4g})"


@dataclass(frozen=True)
class LidarSpec:
    """A 2D lidar (or a point-cloud source flattened to a scan): beam layout, range limits, mount.

    Beam ``i`` points at ``angle_min + i * angle_increment`` in the laser frame, with
    ``angle_increment = (angle_max - angle_min) / (n_beams - 1)``: ``angle_max`` is the
    *last beam's* angle. To describe a driver's scan, copy ``n_beams = len(ranges)``,
    ``angle_min``, ``angle_min + (n_beams - 1) * angle_increment`` (its ``angle_max``,
    or one increment less for drivers that publish the end of the last beam's sector),
    ``range_min`` and ``range_max`` from one message, and measure the mount.

    Attributes:
        n_beams: number of beams per scan.
        angle_min: angle of beam 0 in the laser frame [rad].
        angle_max: angle of the last beam in the laser frame [rad].
        range_min: smallest reported range [m].
        range_max: largest reported range [m].
        mount: pose of the laser frame in the base frame [m, m, rad] (tf ``base_link`` ->
            laser frame; yaw pi for a lidar mounted backwards).
        scan_time: time between scans [s].
        noise_std: standard deviation of the range noise [m] (the filters' margin covers
            twice it; the simulator adds it).
        height: height of the scan plane above the ground [m].
        frame_id: the scans' ``header.frame_id``; on a robot with several lidars it tells
            which one took a scan.
        no_return: how the driver marks "no return" (``"zero"``, ``"range_max"``, or
            ``None`` for plain REP-117; see :mod:`safenav.scan`). Applied by
            :meth:`RobotSpec.match_scan` to scans that state none.
        cloud: for a depth camera or 3D lidar publishing ``PointCloud2``: the height band and
            empty-beam reading of :func:`safenav.pointcloud.scan_from_cloud`; ``None`` for a
            lidar publishing ``LaserScan``.
    """

    n_beams: int
    angle_min: float
    angle_max: float
    range_min: float
    range_max: float
    mount: Pose2D = Pose2D()
    scan_time: float = 0.1
    noise_std: float = 0.0
    height: float = 0.2
    frame_id: str = "laser"
    no_return: str | None = None
    cloud: CloudSlice | None = None

    def __post_init__(self) -> None:
        put = functools.partial(object.__setattr__, self)
        put("n_beams", integer("LidarSpec.n_beams", self.n_beams, low=1))
        put("scan_time", number("LidarSpec.scan_time", self.scan_time, low=0.0))
        put("noise_std", number("LidarSpec.noise_std", self.noise_std, low=0.0))
        put("height", positive("LidarSpec.height", self.height))
        if not isinstance(self.frame_id, str) or not self.frame_id:
            raise InvalidConfig(f"LidarSpec.frame_id must be a non-empty string, got {self.frame_id!r}")
        if self.no_return is not None:
            choice("LidarSpec.no_return convention", self.no_return, NO_RETURN_CONVENTIONS)
        if self.mount is None:
            raise InvalidConfig("LidarSpec.mount must be a pose (x [m], y [m], yaw [rad]) of the laser on the base, "
                                "got None")
        if self.cloud is not None and not isinstance(self.cloud, CloudSlice):
            raise InvalidConfig(f"LidarSpec.cloud must be a CloudSlice or None, got {self.cloud!r}")
        if self.n_beams > 1 and not self.angle_max > self.angle_min:
            raise InvalidConfig(
                f"LidarSpec.angle_max={self.angle_max!r} must be greater than angle_min={self.angle_min!r}: describe "
                f"the beams counter-clockwise (angle_min={self.angle_max!r}, angle_max={self.angle_min!r} for a driver "
                f"that publishes them clockwise, angle_increment < 0; its scans are stored counter-clockwise when read)"
            )
        # The template scan validates angles (radians), range limits and the mount.
        try:
            template = self.scan()
        except InvalidScan as error:
            raise InvalidConfig(f"LidarSpec: {error}") from None
        for name in ("angle_min", "angle_max", "range_min", "range_max"):
            put(name, getattr(template, name))
        put("mount", Pose2D(*template.mount))

    @classmethod
    def from_scan(cls, scan: LaserScan, *, mount: Pose2D | Sequence[float] | None = None, **fields: Any) -> LidarSpec:
        """The lidar that took ``scan``: its beam layout, range limits, period, frame id and no-return convention.

        The quickest way to describe a driver's lidar: read one message with
        :meth:`LaserScan.from_msg` and add the mount, which messages do not carry.

        Args:
            scan: a scan of the lidar.
            mount: the laser's pose on the base [m, m, rad] (tf ``base_link`` -> laser frame);
                by default the scan's own, when it was given.
            **fields: other :class:`LidarSpec` fields (``noise_std``, ``height``, ``cloud``).

        Raises:
            InvalidConfig: no ``mount`` and the scan has none.
        """
        if mount is None:
            if not scan.mount_given:
                raise InvalidConfig(
                    "LidarSpec.from_scan: the scan carries no mount; pass mount=(x, y, yaw) of the laser on the base "
                    "(tf base_link -> laser frame)"
                )
            mount = scan.mount
        return cls(n_beams=scan.n_beams, angle_min=scan.angle_min,
                   angle_max=scan.angle_min + (scan.n_beams - 1) * scan.angle_increment, range_min=scan.range_min,
                   range_max=scan.range_max, mount=mount, scan_time=scan.scan_time, frame_id=scan.frame_id,
                   no_return=scan.no_return, **fields)

    @property
    def angle_increment(self) -> float:
        """Angle between beams [rad]."""
        if self.n_beams == 1:
            return 2.0 * math.pi
        return (self.angle_max - self.angle_min) / (self.n_beams - 1)

    def scan(self, ranges: Any = None, *, stamp: float | None = None) -> LaserScan:
        """A :class:`~safenav.scan.LaserScan` of this lidar, on its mount (given) and with its frame id.

        Every beam is taken at once (``time_increment`` 0), as the simulators cast them; a real lidar's driver
        gives its own (:func:`safenav.synthetic.swept_scan` casts a turning one).

        Args:
            ranges: the readings [m]; ``None`` gives an all-``+inf`` scan (nothing in range).
            stamp: acquisition time [s].
        """
        if ranges is None:
            ranges = np.full(self.n_beams, math.inf)
        return LaserScan(
            angle_min=self.angle_min,
            angle_max=self.angle_max,
            angle_increment=self.angle_increment,
            time_increment=0.0,
            scan_time=self.scan_time,
            range_min=self.range_min,
            range_max=self.range_max,
            ranges=ranges,
            mount=self.mount,
            stamp=stamp,
            frame_id=self.frame_id,
            no_return=self.no_return,
        )


class _LayoutMatch(NamedTuple):
    """What :meth:`RobotSpec.match_scan` found for one scan layout (cached per robot)."""

    lidar: LidarSpec | None
    """The lidar that took scans of this layout, ``None`` when the frame id names none."""
    problems: tuple[tuple[str, str], ...]
    """``(cause, message)`` of every contradiction with that lidar."""


def _clip(value: float, low: float, high: float) -> float:
    """``numpy.clip`` of one float: NaN when any argument is NaN."""
    return min(max(value, low), high) if low <= high else math.nan


@dataclass(frozen=True)
class RobotSpec:
    """A differential-drive robot: body, limits and lidars.

    The body is the disk of :attr:`radius` around the base origin (the
    circumscribed disk of :attr:`footprint` when one is given); the filters
    guarantee clearance for that disk.

    Attributes:
        name: preset name or a user label.
        radius: radius of the body disk around the base origin [m].
        v_max: largest forward velocity [m/s].
        v_min: largest reverse velocity, as a value <= 0 [m/s].
        omega_max: largest yaw rate magnitude [rad/s].
        a_max: largest linear acceleration magnitude [m/s^2].
        alpha_max: largest angular acceleration magnitude [rad/s^2].
        lidar: the main lidar (the simulator's, and the one :meth:`scan` describes).
        footprint: optional body polygon in the base frame [m], inside the disk.
        height: body height [m], for drawing and simulation.
        source: where the numbers come from.
        extra_lidars: further scan sources (a rear lidar, a second corner lidar, a depth
            camera), each with its own mount and a distinct :attr:`LidarSpec.frame_id`.
    """

    name: str
    radius: float
    v_max: float
    v_min: float
    omega_max: float
    a_max: float
    alpha_max: float
    lidar: LidarSpec
    footprint: tuple[tuple[float, float], ...] | None = None
    height: float = 0.2
    source: str = ""
    extra_lidars: tuple[LidarSpec, ...] = ()

    def __post_init__(self) -> None:
        put = functools.partial(object.__setattr__, self)
        for name in ("radius", "v_max", "omega_max", "a_max", "alpha_max", "height"):
            put(name, positive(f"RobotSpec.{name}", getattr(self, name)))
        put("v_min", number("RobotSpec.v_min", self.v_min, high=0.0))
        if not isinstance(self.lidar, LidarSpec):
            raise InvalidConfig(f"RobotSpec.lidar must be a LidarSpec, got {self.lidar!r}")
        extra = self.extra_lidars
        if isinstance(extra, LidarSpec) or not isinstance(extra, Sequence) or not all(
                isinstance(lidar, LidarSpec) for lidar in extra):
            raise InvalidConfig(f"RobotSpec.extra_lidars must be a tuple of LidarSpec, got {extra!r}")
        put("extra_lidars", tuple(extra))
        frame_ids = [lidar.frame_id for lidar in self.lidars]
        repeated = sorted({frame_id for frame_id in frame_ids if frame_ids.count(frame_id) > 1})
        if repeated:
            raise InvalidConfig(
                f"RobotSpec lidars share frame_id {repeated[0]!r}; give each LidarSpec the frame_id of its "
                f"scans' header so that a scan finds its lidar (frame ids: {', '.join(map(repr, frame_ids))})"
            )
        if self.footprint is not None:
            polygon = np.asarray(self.footprint, dtype=float)
            if polygon.ndim != 2 or polygon.shape[1] != 2 or polygon.shape[0] < 3:
                raise InvalidConfig(f"RobotSpec.footprint must be >= 3 (x, y) vertices, got {self.footprint!r}")
            farthest = float(np.max(np.hypot(polygon[:, 0], polygon[:, 1])))
            if farthest > self.radius + 1e-9:
                raise InvalidConfig(
                    f"RobotSpec.footprint reaches {farthest:.4f} m from the base origin; "
                    f"expected inside radius={self.radius!r}"
                )
            put("footprint", tuple((float(x), float(y)) for x, y in polygon))

    @property
    def lidars(self) -> tuple[LidarSpec, ...]:
        """Every scan source: :attr:`lidar` first, then :attr:`extra_lidars`."""
        return (self.lidar, *self.extra_lidars)

    def lidar_for(self, frame_id: str) -> LidarSpec:
        """The lidar whose scans carry ``frame_id``; a robot with one lidar returns it for any frame id.

        Raises:
            LidarMismatch: the robot has several lidars and none has that frame id.
        """
        lidars = self.lidars
        if len(lidars) == 1:
            return lidars[0]
        for lidar in lidars:
            if lidar.frame_id == frame_id:
                return lidar
        raise LidarMismatch(self._unknown_frame_message(frame_id))

    @functools.cached_property
    def lower(self) -> np.ndarray:
        """Lower velocity limits ``(v_min, -omega_max)`` [m/s, rad/s] (read-only)."""
        return _read_only(np.array([self.v_min, -self.omega_max]))

    @functools.cached_property
    def upper(self) -> np.ndarray:
        """Upper velocity limits ``(v_max, omega_max)`` [m/s, rad/s] (read-only)."""
        return _read_only(np.array([self.v_max, self.omega_max]))

    def velocity_bounds(self, velocity: Sequence[float] | np.ndarray | None = None,
                        dt: float | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Box of commands reachable within one period.

        Args:
            velocity: current ``(v, omega)`` [m/s, rad/s]; ``None`` gives the velocity limits alone.
            dt: period [s] over which the acceleration limits apply.

        Returns:
            ``(lower, upper)`` arrays [m/s, rad/s]: the velocity limits intersected with
            ``velocity +- (a_max, alpha_max) * dt``. The box is never empty and always inside
            the limits: from a current velocity beyond a limit (an odometry glitch, a push),
            the only command left is that limit, which the base approaches as fast as it can.
        """
        if velocity is None or dt is None:
            return self.lower, self.upper
        v, omega = np.asarray(velocity, dtype=float)
        v_low, v_high, omega_low, omega_high = self._bounds(float(v), float(omega), dt)
        return np.array([v_low, omega_low]), np.array([v_high, omega_high])

    def _bounds(self, v: float, omega: float, dt: float) -> tuple[float, float, float, float]:
        """:meth:`velocity_bounds` from ``(v, omega)`` in Python floats (called several times a period: numpy's
        per-call overhead would dominate): ``(v_low, v_high, omega_low, omega_high)``."""
        (v_min, v_max), (omega_min, omega_max) = self._limits
        step = self.a_max * dt
        v_low, v_high = _clip(v - step, v_min, v_max), _clip(v + step, v_min, v_max)
        step = self.alpha_max * dt
        omega_low, omega_high = _clip(omega - step, omega_min, omega_max), _clip(omega + step, omega_min, omega_max)
        return min(v_low, v_high), max(v_low, v_high), min(omega_low, omega_high), max(omega_low, omega_high)

    @functools.cached_property
    def _limits(self) -> tuple[tuple[float, float], tuple[float, float]]:
        return (float(self.v_min), float(self.v_max)), (-float(self.omega_max), float(self.omega_max))

    def clip(self, u: Any, velocity: Sequence[float] | np.ndarray | None = None, dt: float | None = None) -> np.ndarray:
        """``u`` clipped to :meth:`velocity_bounds` [m/s, rad/s]."""
        if velocity is None or dt is None:
            (v_low, v_high), (omega_low, omega_high) = self._limits
        else:
            current_v, current_omega = np.asarray(velocity, dtype=float)
            v_low, v_high, omega_low, omega_high = self._bounds(float(current_v), float(current_omega), dt)
        v, omega = as_command(u)
        return np.array([_clip(float(v), v_low, v_high), _clip(float(omega), omega_low, omega_high)])

    def ramp(self, command: Any, velocity: Sequence[float] | np.ndarray, dt: float, steps: int) -> np.ndarray:
        """The velocity after each of ``steps`` steps of ``dt`` [s] from ``velocity`` towards ``command``, each step
        :meth:`clip` of ``command`` from the last (tracking at the acceleration limits) [m/s, rad/s].

        Returns:
            ``(steps, 2)``: row ``k`` is ``clip(command, row k - 1, dt)``, row ``-1`` being ``velocity``.
        """
        v, omega = (float(value) for value in as_command(command))
        current_v, current_omega = (float(value) for value in as_command(velocity, "velocity"))
        rows = []
        for _ in range(steps):
            v_low, v_high, omega_low, omega_high = self._bounds(current_v, current_omega, dt)
            current_v, current_omega = _clip(v, v_low, v_high), _clip(omega, omega_low, omega_high)
            rows.append((current_v, current_omega))
        return np.array(rows, dtype=float).reshape(steps, 2)

    def brake(self, velocity: Sequence[float] | np.ndarray | None = None, dt: float | None = None) -> np.ndarray:
        """The command nearest a stop that the acceleration limits allow within ``dt`` [m/s, rad/s]."""
        lower, upper = self.velocity_bounds(velocity, dt)
        return np.clip(np.zeros(2), lower, upper)

    def scan(self, ranges: Any = None, *, stamp: float | None = None) -> LaserScan:
        """A scan of this robot's main lidar (see :meth:`LidarSpec.scan`); all ``+inf`` by default."""
        return self.lidar.scan(ranges, stamp=stamp)

    def replace(self, **changes: Any) -> RobotSpec:
        """A copy with some fields changed (validated)."""
        return dataclasses.replace(self, **changes)

    def to_dict(self) -> dict[str, Any]:
        """The robot as plain JSON values, which :meth:`from_dict` turns back into an equal robot.

        Lidars are dicts of :class:`LidarSpec` fields, mounts ``[x, y, yaw]`` [m, m, rad], the
        footprint a list of ``[x, y]`` vertices [m].
        """
        data = {field.name: getattr(self, field.name) for field in dataclasses.fields(self)}
        data["lidar"] = _lidar_dict(self.lidar)
        data["extra_lidars"] = [_lidar_dict(lidar) for lidar in self.extra_lidars]
        if self.footprint is not None:
            data["footprint"] = [list(vertex) for vertex in self.footprint]
        return data

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> RobotSpec:
        """A robot from the plain values of :meth:`to_dict` (a JSON or YAML file of your own robot).

        ``lidar`` (and each of ``extra_lidars``) is a mapping of :class:`LidarSpec` fields, with
        ``mount`` as ``[x, y, yaw]`` [m, m, rad] and ``cloud`` as a mapping of
        :class:`~safenav.pointcloud.CloudSlice` fields; every value is checked as the classes check it.

        Raises:
            InvalidConfig: a field is missing or unknown (the message lists the known ones), or a
                value is out of range.
        """
        fields = _known_fields(cls, data, "RobotSpec")
        if "lidar" in fields:
            fields["lidar"] = _lidar_from(fields["lidar"], "RobotSpec.lidar")
        if "extra_lidars" in fields:
            extra = fields["extra_lidars"]
            if isinstance(extra, (str, Mapping)) or not isinstance(extra, Sequence):
                raise InvalidConfig(f"RobotSpec.extra_lidars must be a list of lidars, got {extra!r}")
            fields["extra_lidars"] = tuple(_lidar_from(item, f"RobotSpec.extra_lidars[{index}]")
                                           for index, item in enumerate(extra))
        try:
            return cls(**fields)
        except TypeError as error:   # a required field is missing
            raise InvalidConfig(f"RobotSpec.from_dict: {error}") from None

    # ------------------------------------------------------------------ scans from drivers

    def match_scan(self, scan: LaserScan, *, strict: bool = True) -> LaserScan:
        """``scan`` placed on the lidar that took it, after checking that it is that lidar's scan.

        The lidar is the one whose :attr:`LidarSpec.frame_id` equals ``scan.frame_id`` (the
        only lidar, whatever the frame id, on a robot with one). Then:

        * **layout**: the beam count must be equal, and the directions of the first and last
          beams (``angle_min`` and ``angle_min + (n - 1) * angle_increment``) within
          :data:`ANGLE_TOLERANCE` of the lidar's ``angle_min`` and ``angle_max``;
          ``range_min`` and ``range_max`` within :data:`RANGE_TOLERANCE`. (The message's own
          ``angle_max`` field may be one increment off in some drivers; the scan model already
          checked it against the count.)
        * **mount**: a scan built without one (:attr:`LaserScan.mount_given` ``False``) gets the
          lidar's; a given mount must agree within :data:`MOUNT_POSITION_TOLERANCE` and
          :data:`ANGLE_TOLERANCE` (yaw compared modulo a turn).
        * **no return**: a scan that states no convention gets the lidar's
          (:attr:`LidarSpec.no_return`: its markers become ``+inf``); one that states the same
          is kept; a scan and a lidar that state different ones contradict each other. (The
          scan's own convention is kept when the lidar states none.)

        The checks of a layout are cached per robot, so a scan of a known layout costs a few
        microseconds (:meth:`LaserScan.with_mount` shares the readings). Call it before
        moving the scan (latency compensation changes the mount).

        Args:
            scan: a scan from a driver (:meth:`LaserScan.from_msg`) or any other source.
            strict: raise on a contradiction; ``False`` warns once per robot and cause
                (:class:`~safenav.errors.LidarMismatchWarning`) and returns the scan on its own
                mount if it has one, else on the lidar's.

        Returns:
            The scan in the robot's base frame: ``scan`` itself when nothing needs changing.

        Raises:
            LidarMismatch: the scan contradicts its lidar (``strict``), or names no lidar of a
                robot with several and has no mount of its own (even with ``strict=False``:
                it cannot be placed). The message names both values and the fix.
            InvalidScanType: ``scan`` is not a :class:`~safenav.scan.LaserScan`.
        """
        check_scan(scan)
        key = (scan.frame_id, scan.n_beams, scan.angle_min, scan.angle_increment, scan.range_min, scan.range_max,
               scan.no_return)
        matches = self._layout_matches
        match = matches.get(key)
        if match is None:
            if len(matches) >= _LAYOUT_CACHE_SIZE:
                matches.clear()
            match = matches[key] = self._match_layout(scan)
        lidar, problems = match
        if scan.mount_given and lidar is not None and not _same_pose(scan.mount, lidar.mount):
            problems = (*problems, ("mount", self._mount_message(scan, lidar)))
        if problems:
            if strict or (lidar is None and not scan.mount_given):
                raise LidarMismatch("; and ".join(message for _, message in problems))
            for cause, message in problems:
                self._warn_once(cause, lidar.frame_id if lidar is not None else scan.frame_id, message)
        if lidar is None:
            return scan
        matched = scan if scan.mount_given else scan.with_mount(lidar.mount)
        if scan.no_return is None and lidar.no_return is not None:
            matched = matched.with_no_return(lidar.no_return)
        return matched

    @functools.cached_property
    def _layout_matches(self) -> dict[tuple[Any, ...], _LayoutMatch]:
        """Scan layout -> what it matched (created on first use: a preset's table entry has none)."""
        return {}

    @functools.cached_property
    def _warned_mismatches(self) -> set[tuple[str, str]]:
        """``(cause, frame id)`` of the mismatches already warned about."""
        return set()

    def _warn_once(self, cause: str, frame_id: str, message: str) -> None:
        if (cause, frame_id) in self._warned_mismatches:
            return
        self._warned_mismatches.add((cause, frame_id))
        warnings.warn(f"{message} (warned once per robot and cause)", LidarMismatchWarning, stacklevel=3)

    def _match_layout(self, scan: LaserScan) -> _LayoutMatch:
        """The lidar of ``scan``'s frame and how the scan's layout contradicts it."""
        try:
            lidar = self.lidar_for(scan.frame_id)
        except LidarMismatch as error:
            return _LayoutMatch(None, (("frame_id", str(error)),))
        last_beam = scan.angle_min + (scan.n_beams - 1) * scan.angle_increment
        differences = []
        if scan.n_beams != lidar.n_beams:
            differences.append(f"{scan.n_beams} beams vs {lidar.n_beams}")
        if abs(wrap_angle(scan.angle_min - lidar.angle_min)) > ANGLE_TOLERANCE:
            differences.append(f"angle_min {scan.angle_min:.6g} vs {lidar.angle_min:.6g} rad")
        if abs(wrap_angle(last_beam - lidar.angle_max)) > ANGLE_TOLERANCE:
            differences.append(f"last beam at {last_beam:.6g} vs angle_max {lidar.angle_max:.6g} rad "
                               f"(angle_increment {scan.angle_increment:.6g} vs {lidar.angle_increment:.6g} rad)")
        for name in ("range_min", "range_max"):
            if abs(getattr(scan, name) - getattr(lidar, name)) > RANGE_TOLERANCE:
                differences.append(f"{name} {getattr(scan, name):.6g} vs {getattr(lidar, name):.6g} m")
        problems = []
        if differences:
            problems.append(("layout", (
                f"scan of frame {scan.frame_id!r} does not fit lidar {lidar.frame_id!r} of robot {self.name!r} "
                f"(scan vs lidar: {'; '.join(differences)}). Describe the robot's real lidar, e.g. "
                f"RobotSpec(..., lidar=LidarSpec(n_beams={scan.n_beams}, angle_min={scan.angle_min:.6g}, "
                f"angle_max={last_beam:.6g}, range_min={scan.range_min:.6g}, range_max={scan.range_max:.6g}, "
                f"mount=(x, y, yaw))) (README, 'Your own robot'), or pass strict=False to only warn"
            )))
        if scan.no_return is not None and lidar.no_return is not None and scan.no_return != lidar.no_return:
            problems.append(("no_return", (
                f"scan of frame {scan.frame_id!r} was read with no_return={scan.no_return!r} but lidar "
                f"{lidar.frame_id!r} of robot {self.name!r} says no_return={lidar.no_return!r}: leave no_return= "
                f"out of the scan to use the lidar's, or correct LidarSpec.no_return"
            )))
        return _LayoutMatch(lidar, tuple(problems))

    def _mount_message(self, scan: LaserScan, lidar: LidarSpec) -> str:
        return (
            f"scan mount {_pose_text(scan.mount)} contradicts the mount {_pose_text(lidar.mount)} [m, m, rad] of "
            f"lidar {lidar.frame_id!r} on robot {self.name!r}: leave mount= out to use the robot's lidar mount, "
            f"or describe the lidar with LidarSpec(..., mount={_pose_text(scan.mount)})"
        )

    def _unknown_frame_message(self, frame_id: str) -> str:
        return (
            f"scan frame_id {frame_id!r} names none of the lidars of robot {self.name!r} "
            f"({', '.join(repr(lidar.frame_id) for lidar in self.lidars)}); set each LidarSpec.frame_id "
            f"to the header.frame_id of its scans"
        )


def _same_pose(a: Pose2D, b: Pose2D) -> bool:
    """Whether two mounts agree within :data:`MOUNT_POSITION_TOLERANCE` and :data:`ANGLE_TOLERANCE`."""
    return (abs(a.x - b.x) <= MOUNT_POSITION_TOLERANCE and abs(a.y - b.y) <= MOUNT_POSITION_TOLERANCE
            and abs(wrap_angle(a.yaw - b.yaw)) <= ANGLE_TOLERANCE)


def _lidar_dict(lidar: LidarSpec) -> dict[str, Any]:
    data = {field.name: getattr(lidar, field.name) for field in dataclasses.fields(lidar)}
    data["mount"] = [float(value) for value in lidar.mount]
    if lidar.cloud is not None:
        data["cloud"] = dataclasses.asdict(lidar.cloud)
    return data


def _known_fields(cls: type, data: Any, label: str) -> dict[str, Any]:
    """``data`` as keyword arguments of the dataclass ``cls``; an unknown key is an error that lists the known ones."""
    if not isinstance(data, Mapping):
        raise InvalidConfig(f"{label} must be a mapping of its fields, got {data!r}")
    known = [field.name for field in dataclasses.fields(cls)]
    unknown = sorted(str(key) for key in data if key not in known)
    if unknown:
        raise InvalidConfig(f"{label}: unknown field {unknown[0]!r}; expected some of {', '.join(known)}")
    return dict(data)


def _lidar_from(data: Any, label: str) -> LidarSpec:
    fields = _known_fields(LidarSpec, data, label)
    if "mount" in fields:
        mount = fields["mount"]
        if isinstance(mount, (str, Mapping)) or not isinstance(mount, Sequence) or len(mount) != 3:
            raise InvalidConfig(f"{label}.mount must be [x, y, yaw] [m, m, rad], got {mount!r}")
        fields["mount"] = Pose2D(*mount)
    if fields.get("cloud") is not None:
        fields["cloud"] = CloudSlice(**_known_fields(CloudSlice, fields["cloud"], f"{label}.cloud"))
    try:
        return LidarSpec(**fields)
    except TypeError as error:   # a required field is missing
        raise InvalidConfig(f"{label}: {error}") from None


def _box(half_length: float, half_width: float) -> tuple[tuple[float, float], ...]:
    """A rectangular footprint centred on the base origin [m]."""
    return ((half_length, half_width), (-half_length, half_width), (-half_length, -half_width),
            (half_length, -half_width))


def _circumscribed(half_length: float, half_width: float) -> float:
    """Radius of the disk around a rectangle, rounded up to the millimetre [m]."""
    return round(math.hypot(half_length, half_width) + 0.0005, 3)


#: The tutorial robots, by name. :func:`preset` returns a fresh copy of an entry.
_PRESETS: Mapping[str, RobotSpec] = MappingProxyType({
    # Husarion ROSbot 2: 200 x 235 mm chassis, up to 1.0 m/s; RPLIDAR A2/A3 on top,
    # mounted backwards (yaw pi), so beam 0 at angle_min = -pi looks forward.
    "rosbot": RobotSpec(
        name="rosbot",
        radius=_circumscribed(0.100, 0.1175),
        v_max=1.0, v_min=-1.0, omega_max=3.0, a_max=1.5, alpha_max=6.0,
        lidar=LidarSpec(n_beams=720, angle_min=-math.pi, angle_max=math.pi, range_min=0.15, range_max=12.0,
                        mount=Pose2D(0.0, 0.0, math.pi), scan_time=0.1, height=0.22, frame_id="laser"),
        footprint=_box(0.100, 0.1175),
        height=0.22,
        source="Husarion ROSbot 2 (200 x 235 x 220 mm, 1.0 m/s); tutorial 'stop at a wall'",
    ),
    # Manchester Robotics Puzzlebot: about 0.19 m across; RPLIDAR A1 over 0..2pi, beam 0 forward.
    "puzzlebot": RobotSpec(
        name="puzzlebot",
        radius=0.100,
        v_max=0.4, v_min=-0.4, omega_max=2.0, a_max=0.8, alpha_max=4.0,
        lidar=LidarSpec(n_beams=360, angle_min=0.0, angle_max=2.0 * math.pi, range_min=0.15, range_max=12.0,
                        mount=Pose2D(0.0, 0.0, 0.0), scan_time=0.1, height=0.15, frame_id="laser"),
        height=0.15,
        source="Manchester Robotics Puzzlebot (about 0.19 m across); tutorial 'simple obstacle avoidance'",
    ),
    # The Construct's two-wheeled robot: 0.5 x 0.3 m chassis, 180-degree lidar at the front
    # (x = 0.15 m, link and frame 'sensor_laser'), 720 samples over -pi/2..pi/2, 0.10-30 m
    # with 1 cm Gaussian noise in Gazebo.
    "m2wr": RobotSpec(
        name="m2wr",
        radius=_circumscribed(0.25, 0.15),
        v_max=1.0, v_min=-0.5, omega_max=2.0, a_max=1.0, alpha_max=3.0,
        lidar=LidarSpec(n_beams=720, angle_min=-0.5 * math.pi, angle_max=0.5 * math.pi, range_min=0.10,
                        range_max=30.0, mount=Pose2D(0.15, 0.0, 0.0), scan_time=0.05, noise_std=0.01,
                        height=0.1, frame_id="sensor_laser"),
        footprint=_box(0.25, 0.15),
        height=0.1,
        source="m2wr of 'Exploring ROS with a 2 wheeled robot' (0.5 x 0.3 m chassis); tutorial 'wall follower'",
    ),
})

#: Names of the tutorial robots, in the order of :data:`_PRESETS`.
PRESET_NAMES = tuple(_PRESETS)


def preset(name: str) -> RobotSpec:
    """One of the tutorial robots (:data:`PRESET_NAMES`): ``"rosbot"``, ``"puzzlebot"`` or ``"m2wr"``.

    Each call returns a fresh :class:`RobotSpec` (equal to the last), with its own caches.

    Raises:
        UnknownName: ``name`` is not a preset (the message lists them).
    """
    return dataclasses.replace(_PRESETS[choice("robot preset", name, PRESET_NAMES)])

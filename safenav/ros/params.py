"""The safety node's parameters: one table, read the same way on ROS 2 and ROS 1.

Both transports hand :meth:`NodeConfig.from_parameters` a flat mapping of the parameters
the user set (ROS 2: ``--ros-args -p filter:=mpc`` or a parameters file; ROS 1: ``_filter:=mpc``
or ``<param>`` in a launch file, nested names joined with dots). Every value is checked with
:mod:`safenav._checks`; an unknown name is an error that lists the known ones, so a typo
(``scan_timout``) never silently keeps a default.

Names follow ROS 2 Navigation's collision monitor where the concept is the same
(``cmd_vel_in_topic``, ``cmd_vel_out_topic``, a list of ``sources`` each with its own
``<source>.topic``, ``<source>.type`` and timeout).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any, NamedTuple

from safenav import _checks
from safenav.errors import InvalidConfig, UnknownName
from safenav.filters import CBFConfig, MPCConfig, ZonesConfig
from safenav.geometry import TWO_PI, Pose2D
from safenav.pointcloud import CLOUD_AXES, EMPTY_BIN_READINGS, CloudSlice
from safenav.robot import PRESET_NAMES, LidarSpec, RobotSpec, preset
from safenav.ros.sources import SOURCE_TYPES

__all__ = ["FILTER_CONFIGS", "PARAMETERS", "ROBOT_OVERRIDES", "NodeConfig", "Parameter", "SourceConfig"]

FILTER_CONFIGS: Mapping[str, type] = MappingProxyType({"cbf": CBFConfig, "mpc": MPCConfig, "zones": ZonesConfig})
"""The filters the node can run, and the config class whose fields ``<filter>.<field>`` set."""

ROBOT_OVERRIDES = ("radius", "v_max", "v_min", "omega_max", "a_max", "alpha_max")
""":class:`~safenav.robot.RobotSpec` fields a parameter may override on the preset."""

#: Largest timeout or period accepted [s]; a larger value is most likely in milliseconds.
_LONGEST = 60.0


class Parameter(NamedTuple):
    """One node parameter: its name, default (``None``: see the description) and meaning."""

    name: str
    default: Any
    description: str


PARAMETERS: tuple[Parameter, ...] = (
    Parameter("robot", "rosbot", f"robot preset ({', '.join(PRESET_NAMES)}): body, limits and lidar mount"),
    Parameter("radius", None, "body disk radius [m] (default: the preset's; the footprint's circumscribed disk)"),
    Parameter("footprint", None, "body polygon [x1, y1, x2, y2, ...] in the base frame [m]"),
    Parameter("v_max", None, "largest forward speed [m/s] (default: the preset's)"),
    Parameter("v_min", None, "largest reverse speed, <= 0 [m/s] (default: the preset's)"),
    Parameter("omega_max", None, "largest yaw rate [rad/s] (default: the preset's)"),
    Parameter("a_max", None, "largest linear acceleration [m/s^2] (default: the preset's)"),
    Parameter("alpha_max", None, "largest angular acceleration [rad/s^2] (default: the preset's)"),
    Parameter("filter", "cbf", "safety filter: cbf, mpc or zones; its settings are <filter>.<field> "
                               "(e.g. cbf.margin, mpc.horizon_time), fields of CBFConfig/MPCConfig/ZonesConfig"),
    Parameter("escape", True, "wrap the filter in safenav.filters.escape.Escape: a deadlock escape whose "
                              "commands pass through the filter (false: the filter alone, which may hold the "
                              "robot in a deadlock)"),
    Parameter("control_period", 0.05, "period of the cmd_vel output and the filter's dt [s]"),
    Parameter("step_on_scan", True, "also filter at once when a scan arrives (the timer then restarts), "
                                    "so a fresh scan never waits for the next tick"),
    Parameter("sources", ["scan"], "names of the obstacle sources; each has <source>.topic, .type, .mount, .timeout "
                                    "(and a pointcloud source its height band and field of view)"),
    Parameter("<source>.topic", "<source>", "topic of the source"),
    Parameter("<source>.type", "scan", f"message type: {', '.join(SOURCE_TYPES)} "
                                       "(sensor_msgs/LaserScan, sensor_msgs/PointCloud2)"),
    Parameter("<source>.mount", None, "pose of the sensor on the base [x, y, yaw] [m, m, rad] "
                                      "(default: the preset's lidar mount)"),
    Parameter("<source>.timeout", 0.5, "a source older than this brakes the robot [s]"),
    Parameter("<source>.z_min", None, "pointcloud, required: lowest point kept [m], sensor frame, z up"),
    Parameter("<source>.z_max", None, "pointcloud, required: highest point kept [m], sensor frame, z up"),
    Parameter("<source>.angle_min", None, "pointcloud, required: first bearing of the field of view [rad], "
                                          "sensor frame"),
    Parameter("<source>.angle_max", None, "pointcloud, required: last bearing of the field of view [rad]; "
                                          "bearings outside it are unknown"),
    Parameter("<source>.angle_increment", math.pi / 360, "pointcloud: width of a bearing bin (one beam) [rad]"),
    Parameter("<source>.range_min", 0.0, "pointcloud: nearer points read as an object at the sensor [m]"),
    Parameter("<source>.range_max", 10.0, "pointcloud: farther points read as free up to it [m]"),
    Parameter("<source>.empty", "invalid", "pointcloud: a bin with no point is invalid (unknown: a depth "
                                           "camera's hole) or no_return (free: a 3D lidar's sky)"),
    Parameter("<source>.axes", "rep103", "pointcloud: the cloud frame's axes, rep103 (x forward, z up) or "
                                         "optical (z forward, y down: a camera's optical frame)"),
    Parameter("cmd_vel_in_topic", "cmd_vel_in", "nominal command input"),
    Parameter("cmd_vel_out_topic", "cmd_vel", "filtered command output"),
    Parameter("stamped", False, "cmd_vel in and out are geometry_msgs/TwistStamped instead of Twist"),
    Parameter("cmd_vel_timeout", 0.5, "an input command older than this publishes zero once, then nothing [s]"),
    Parameter("odom_topic", "odom", "nav_msgs/Odometry for the measured velocity; empty: no odometry"),
    Parameter("odom_timeout", 0.5, "odometry older than this brakes the robot [s]"),
    Parameter("base_frame", "base_link", "frame of the markers and of stamped output"),
    Parameter("markers", False, "publish visualization_msgs/MarkerArray on ~/markers (footprint, active points)"),
    Parameter("enabled", True, "start filtering; ~/enable (std_srvs/SetBool) switches it at run time"),
)
"""Every parameter of the safety node (``<source>`` stands for each name in ``sources``)."""

_PLAIN = {p.name: p for p in PARAMETERS if not p.name.startswith("<")}
_PER_SOURCE = {p.name.split(".", 1)[1]: p for p in PARAMETERS if p.name.startswith("<source>.")}
_CLOUD_KEYS = ("z_min", "z_max", "angle_min", "angle_max", "angle_increment", "range_min", "range_max", "empty", "axes")
"""Per-source parameters of ``pointcloud`` sources only (how :mod:`safenav.pointcloud` flattens the cloud)."""


def _string(name: str, value: Any, *, empty: bool = False) -> str:
    if not isinstance(value, str) or (not empty and not value):
        raise InvalidConfig(f"parameter {name} must be a {'' if empty else 'non-empty '}string, got {value!r}")
    return value


def _duration(name: str, value: Any, high: float = _LONGEST) -> float:
    return _checks.duration(f"parameter {name}", value, high=high)


@dataclass(frozen=True)
class SourceConfig:
    """One obstacle source: a topic, its message type and where the sensor sits on the base.

    Attributes:
        name: the source's name (its parameters are ``<name>.topic`` and so on).
        topic: topic to subscribe to.
        type: key of :data:`~safenav.ros.sources.SOURCE_TYPES` (``"scan"`` or ``"pointcloud"``).
        mount: pose of the sensor frame on the base [m, m, rad].
        timeout: largest age the filter acts on [s]; older data brakes the robot.
        lidar: the sensor as a planar lidar, for the types whose messages do not describe it
            (``pointcloud``: field of view, range limits and the :class:`~safenav.pointcloud.CloudSlice`);
            ``None`` for ``scan`` (a LaserScan describes its own layout). Its mount and
            ``frame_id`` are set to the source's.
    """

    name: str
    topic: str
    type: str = "scan"
    mount: Pose2D = Pose2D()
    timeout: float = 0.5
    lidar: LidarSpec | None = None

    def __post_init__(self) -> None:
        _string("sources[]", self.name)
        _string(f"{self.name}.topic", self.topic)
        _checks.choice("source type", self.type, tuple(SOURCE_TYPES))
        x, y, yaw = _triple(f"{self.name}.mount", self.mount)
        object.__setattr__(self, "mount", Pose2D(x, y, yaw))
        object.__setattr__(self, "timeout", _duration(f"{self.name}.timeout", self.timeout))
        if SOURCE_TYPES[self.type].cloud:
            if not isinstance(self.lidar, LidarSpec) or self.lidar.cloud is None:
                raise InvalidConfig(f"source {self.name!r} of type {self.type} needs a LidarSpec with a CloudSlice "
                                    f"(its field of view and height band), got {self.lidar!r}")
            object.__setattr__(self, "lidar", dataclasses.replace(self.lidar, mount=self.mount, frame_id=self.name))
        elif self.lidar is not None:
            raise InvalidConfig(f"source {self.name!r} of type {self.type} takes no LidarSpec (its messages "
                                f"describe the sensor), got {self.lidar!r}")


def _triple(name: str, value: Any) -> tuple[float, float, float]:
    if isinstance(value, (str, bytes)) or not isinstance(value, Sequence) or len(value) != 3:
        raise InvalidConfig(f"parameter {name} must be [x, y, yaw] in [m, m, rad], got {value!r}")
    x, y = _checks.pair(f"parameter {name}[0:2]", (value[0], value[1]))
    return x, y, _checks.number(f"parameter {name}[2]", value[2], low=-2 * math.pi, high=2 * math.pi)


@dataclass(frozen=True)
class NodeConfig:
    """Everything the safety node needs, validated on construction.

    Attributes:
        robot: the robot to protect.
        filter: ``"cbf"``, ``"mpc"`` or ``"zones"``.
        filter_settings: keyword settings of the filter (fields of its config class).
        escape: wrap the filter in the deadlock escape (:class:`safenav.filters.escape.Escape`), on by
            default: the node drives the robot on its own, and the escape's commands pass through
            the same filter, so only progress depends on it.
        control_period: output period and the filter's ``dt`` [s].
        step_on_scan: filter at once when a scan arrives, and restart the timer.
        sources: the obstacle sources (at least one).
        cmd_vel_in_topic: nominal command input.
        cmd_vel_out_topic: filtered command output.
        stamped: use ``TwistStamped`` for the commands.
        cmd_vel_timeout: input command age after which the node publishes zero once, then nothing [s].
        odom_topic: odometry topic; empty for none.
        odom_timeout: odometry age after which the node brakes [s].
        base_frame: frame of markers and stamped output.
        markers: publish markers.
        enabled: filter (``False``: pass the input through, with a warning in the state).
    """

    robot: RobotSpec
    filter: str = "cbf"
    filter_settings: Mapping[str, Any] = field(default_factory=dict)
    escape: bool = True
    control_period: float = 0.05
    step_on_scan: bool = True
    sources: tuple[SourceConfig, ...] = ()
    cmd_vel_in_topic: str = "cmd_vel_in"
    cmd_vel_out_topic: str = "cmd_vel"
    stamped: bool = False
    cmd_vel_timeout: float = 0.5
    odom_topic: str = "odom"
    odom_timeout: float = 0.5
    base_frame: str = "base_link"
    markers: bool = False
    enabled: bool = True

    def __post_init__(self) -> None:
        put = object.__setattr__
        if not isinstance(self.robot, RobotSpec):
            raise InvalidConfig(f"NodeConfig.robot must be a RobotSpec, got {self.robot!r}")
        _checks.choice("filter", self.filter, tuple(FILTER_CONFIGS))
        known = tuple(f.name for f in dataclasses.fields(FILTER_CONFIGS[self.filter]))
        for setting in self.filter_settings:
            _checks.choice(f"{self.filter} setting", setting, known)
        put(self, "filter_settings", MappingProxyType(dict(self.filter_settings)))
        put(self, "control_period", _duration("control_period", self.control_period, high=1.0))
        sources = tuple(self.sources) or (SourceConfig("scan", "scan", mount=self.robot.lidar.mount),)
        if not all(isinstance(source, SourceConfig) for source in sources):
            raise InvalidConfig(f"NodeConfig.sources must be SourceConfig objects, got {self.sources!r}")
        names = [source.name for source in sources]
        if len(set(names)) != len(names):
            raise InvalidConfig(f"parameter sources names a source twice: {names}")
        put(self, "sources", sources)
        for name in ("cmd_vel_in_topic", "cmd_vel_out_topic", "base_frame"):
            _string(name, getattr(self, name))
        _string("odom_topic", self.odom_topic, empty=True)
        for name in ("cmd_vel_timeout", "odom_timeout"):
            put(self, name, _duration(name, getattr(self, name)))
        for name in ("escape", "step_on_scan", "stamped", "markers", "enabled"):
            put(self, name, _checks.boolean(f"parameter {name}", getattr(self, name)))

    @property
    def scan_timeout(self) -> float:
        """The longest source timeout [s] (the filter's own watchdog; each source also has its own)."""
        return max(source.timeout for source in self.sources)

    def filter_kwargs(self) -> dict[str, Any]:
        """Keyword arguments of :func:`safenav.filters.make_filter` (settings, and the scan timeout)."""
        return {"scan_timeout": self.scan_timeout, **self.filter_settings}

    @classmethod
    def from_parameters(cls, parameters: Mapping[str, Any]) -> NodeConfig:
        """The configuration from the parameters the user set (names as in :data:`PARAMETERS`).

        Args:
            parameters: flat mapping of parameter name to value; nested names joined by dots
                (``"scan.mount"``, ``"cbf.margin"``). Names the node does not know raise.

        Raises:
            InvalidConfig: a value out of range (the message names the parameter).
            UnknownName: an unknown parameter, preset, filter, filter setting or source type.
        """
        given = dict(parameters)
        robot = _robot(given)
        filter_name = _checks.choice("filter", given.pop("filter", _PLAIN["filter"].default), tuple(FILTER_CONFIGS))
        source_names = given.pop("sources", _PLAIN["sources"].default)
        if isinstance(source_names, str) or not isinstance(source_names, Sequence) or not source_names:
            raise InvalidConfig(f"parameter sources must be a non-empty list of names, got {source_names!r}")
        sources = tuple(_source(str(name), given, robot) for name in source_names)
        settings = {}
        prefix = f"{filter_name}."
        for name in [name for name in given if name.startswith(prefix)]:
            settings[name[len(prefix):]] = _setting(given.pop(name))
        for name in [name for name in given if name.split(".", 1)[0] in FILTER_CONFIGS]:
            given.pop(name)  # settings of the filters not chosen are allowed (one file for all three)
        unknown = sorted(set(given) - set(_PLAIN))
        if unknown:
            known = sorted({*_PLAIN, *(f"{s.name}.{key}" for s in sources for key in _PER_SOURCE),
                            *(f"{filter_name}.{f.name}" for f in dataclasses.fields(FILTER_CONFIGS[filter_name]))})
            raise UnknownName("parameter", unknown[0], known)
        plain = {name: given.pop(name, _PLAIN[name].default) for name in
                 ("escape", "control_period", "step_on_scan", "cmd_vel_in_topic", "cmd_vel_out_topic", "stamped",
                  "cmd_vel_timeout", "odom_topic", "odom_timeout", "base_frame", "markers", "enabled")}
        return cls(robot=robot, filter=filter_name, filter_settings=settings, sources=sources, **plain)


def _setting(value: Any) -> Any:
    """A filter setting from a parameter: ROS arrays arrive as lists; the configs want tuples."""
    return tuple(value) if isinstance(value, list) else value


def _robot(given: dict[str, Any]) -> RobotSpec:
    """The preset named by ``robot`` with the overrides given (removed from ``given``)."""
    name = given.pop("robot", _PLAIN["robot"].default)
    robot = preset(_checks.choice("robot preset", name, PRESET_NAMES))
    changes: dict[str, Any] = {}
    footprint = given.pop("footprint", None)
    if footprint is not None:
        flat = list(footprint) if isinstance(footprint, Sequence) and not isinstance(footprint, str) else None
        if flat is None or len(flat) < 6 or len(flat) % 2:
            raise InvalidConfig(f"parameter footprint must be [x1, y1, x2, y2, ...] with >= 3 vertices [m], "
                                f"got {footprint!r}")
        vertices = tuple(_checks.pair(f"parameter footprint vertex {i // 2}", flat[i:i + 2])
                         for i in range(0, len(flat), 2))
        changes["footprint"] = vertices
        changes["radius"] = max(math.hypot(x, y) for x, y in vertices)
    for name in ROBOT_OVERRIDES:
        if name in given:
            changes[name] = given.pop(name)
    if not changes:
        return robot
    if "footprint" not in changes and "radius" in changes:
        changes["footprint"] = None  # the preset's polygon may not fit a smaller disk
    try:
        return robot.replace(**changes)
    except InvalidConfig as error:
        raise InvalidConfig(f"robot parameters: {error}") from None


def _source(name: str, given: dict[str, Any], robot: RobotSpec) -> SourceConfig:
    """The source ``name`` from its ``<name>.*`` parameters (removed from ``given``)."""
    values = {key: given.pop(f"{name}.{key}") for key in _PER_SOURCE if f"{name}.{key}" in given}
    source_type = _checks.choice("source type", values.get("type", _PER_SOURCE["type"].default), tuple(SOURCE_TYPES))
    lidar = None
    if SOURCE_TYPES[source_type].cloud:
        lidar = _cloud_lidar(name, values)
    else:
        cloud_only = [key for key in values if key in _CLOUD_KEYS]
        if cloud_only:
            raise InvalidConfig(f"parameter {name}.{cloud_only[0]} applies to pointcloud sources only; "
                                f"source {name!r} is of type {source_type}")
    return SourceConfig(name=name, topic=values.get("topic", name), type=source_type,
                        mount=values.get("mount", robot.lidar.mount),
                        timeout=values.get("timeout", _PER_SOURCE["timeout"].default), lidar=lidar)


def _cloud_lidar(name: str, values: Mapping[str, Any]) -> LidarSpec:
    """A ``pointcloud`` source's sensor as a planar lidar, from its ``<name>.*`` parameters.

    Beam ``i`` is the bearing bin ``angle_min + i * angle_increment`` up to ``angle_max``, and at
    most one turn of bins (``-pi..pi`` does not repeat the direction ``pi``).

    Raises:
        InvalidConfig: a required parameter is missing, or a value is out of range (named).
        UnknownName: ``empty`` or ``axes`` is not a known convention.
    """
    missing = [f"{name}.{key}" for key in ("mount", *_CLOUD_KEYS)
               if key not in values and _PER_SOURCE[key].default is None]
    if missing:
        raise InvalidConfig(f"pointcloud source {name!r} needs parameter{'s' * (len(missing) > 1)} "
                            f"{', '.join(missing)}: the sensor's mount, height band and field of view have no default")

    def value(key: str, **bounds: Any) -> float:
        return _checks.number(f"parameter {name}.{key}", values.get(key, _PER_SOURCE[key].default), **bounds)

    z_min = value("z_min")
    z_max = value("z_max", low=z_min, low_open=True)
    angle_min = value("angle_min", low=-TWO_PI, high=TWO_PI)
    angle_max = value("angle_max", low=angle_min, high=angle_min + TWO_PI, low_open=True)
    increment = value("angle_increment", low=0.0, high=angle_max - angle_min, low_open=True)
    range_min = value("range_min", low=0.0)
    range_max = value("range_max", low=range_min, low_open=True)
    empty = _checks.choice(f"{name}.empty reading", values.get("empty", _PER_SOURCE["empty"].default),
                           EMPTY_BIN_READINGS)
    axes = _checks.choice(f"{name}.axes convention", values.get("axes", _PER_SOURCE["axes"].default), CLOUD_AXES)
    slack = 1e-9   # a span that is a whole number of increments in decimal is not always one in binary
    n_beams = min(math.floor((angle_max - angle_min) / increment + slack) + 1, math.floor(TWO_PI / increment + slack))
    return LidarSpec(n_beams=n_beams, angle_min=angle_min, angle_max=angle_min + (n_beams - 1) * increment,
                     range_min=range_min, range_max=range_max, frame_id=name,
                     cloud=CloudSlice(z_min=z_min, z_max=z_max, empty=empty, axes=axes))

"""The node's logic without middleware: parameters, and what a tick publishes (messages as plain objects).

``SafetyCore`` reads ROS messages by their fields only, so a ``SimpleNamespace`` with the fields
of ``sensor_msgs/LaserScan`` or ``geometry_msgs/Twist`` is a real input here, not a mock of ROS;
the same paths run over real middleware in ``test_node.py``.
"""

from __future__ import annotations

import math
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from safenav import SafeNavError, preset
from safenav.errors import InvalidConfig, UnknownName
from safenav.filters import MPCSafetyFilter
from safenav.ros import PARAMETERS, NodeConfig, SafetyCore
from safenav.synthetic import Scene, synthetic_scan, wall
from tests.ros.clouds import BAND, CLOUD_MOUNT, cloud_fields, cloud_parameters, wall_points

ROOT = Path(__file__).resolve().parents[2]
ROSBOT = preset("rosbot")
#: A depth camera as the only source ``cloud``.
CAMERA = {"sources": ["cloud"], **cloud_parameters("cloud", full_turn=False)}


def test_defaults_protect_the_rosbot_with_the_cbf_and_its_lidar_mount():
    config = NodeConfig.from_parameters({})
    assert (config.robot, config.filter, config.control_period) == (ROSBOT, "cbf", 0.05)
    (source,) = config.sources
    assert (source.name, source.topic, source.type, source.timeout) == ("scan", "scan", "scan", 0.5)
    assert source.mount == ROSBOT.lidar.mount     # yaw pi: the ROSbot's lidar is mounted backwards


def test_robot_overrides_filter_settings_and_sources():
    config = NodeConfig.from_parameters({
        "robot": "puzzlebot", "v_max": 0.3, "footprint": [0.1, 0.08, -0.1, 0.08, -0.1, -0.08, 0.1, -0.08],
        "filter": "mpc", "mpc.horizon_time": 1.5, "cbf.margin": 0.2, "sources": ["front"], "front.topic": "/lidar/scan",
        "front.mount": [0.1, 0.0, math.pi], "front.timeout": 0.3, "stamped": True})
    assert config.robot.v_max == 0.3 and config.robot.radius == pytest.approx(math.hypot(0.1, 0.08))
    assert dict(config.filter_settings) == {"horizon_time": 1.5}      # cbf.* is for another filter: ignored
    assert config.filter_kwargs() == {"scan_timeout": 0.3, "horizon_time": 1.5}
    (source,) = config.sources
    assert (source.topic, tuple(source.mount), source.timeout) == ("/lidar/scan", (0.1, 0.0, math.pi), 0.3)
    assert config.stamped


def test_the_nodes_mpc_tracks_the_cbf_inside_the_escape_and_the_nominal_without_it():
    # The escape's preset (ESCAPE_PRESETS) reaches the node, which wraps the filter itself; a given reference wins.
    assert make_core(filter="mpc")[0].filter.inner.config.reference == "cbf"
    assert make_core(filter="mpc", **{"mpc.reference": "nominal"})[0].filter.inner.config.reference == "nominal"
    assert make_core(filter="mpc", escape=False)[0].filter.config.reference == "nominal"
    assert "with mpc (tracking the cbf reference) with the deadlock escape" in make_core(filter="mpc")[0].describe()
    assert "with mpc (tracking the nominal reference) without" in make_core(filter="mpc", escape=False)[0].describe()
    assert "with cbf with the deadlock escape" in make_core()[0].describe()


def test_the_node_builds_the_mpc_that_tracks_the_cbf_from_its_parameters():
    config = NodeConfig.from_parameters({"filter": "mpc", "mpc.reference": "cbf"})
    assert dict(config.filter_settings) == {"reference": "cbf"}
    safety = MPCSafetyFilter(config.robot, config.control_period, **config.filter_kwargs())
    assert safety.reference is not None and safety.reference.margin == safety.margin


BAD_PARAMETERS = [
    ({"filter": "rrt"}, UnknownName, "unknown filter 'rrt'; expected one of: cbf, mpc, zones"),
    ({"robot": "turtlebot"}, UnknownName, "unknown robot preset 'turtlebot'; expected one of: m2wr, puzzlebot, rosbot"),
    ({"scan_timout": 1.0}, UnknownName, "unknown parameter 'scan_timout'; expected one of: "),
    ({"cbf.gama": 0.1}, UnknownName, "unknown cbf setting 'gama'; expected one of: "),
    ({"scan.type": "sonar"}, UnknownName, "unknown source type 'sonar'; expected one of: pointcloud, scan"),
    ({"scan.z_min": 0.1}, InvalidConfig, "parameter scan.z_min applies to pointcloud sources only; "
                                         "source 'scan' is of type scan"),
    ({"scan.type": "pointcloud", "scan.z_min": -0.1, "scan.z_max": 0.3}, InvalidConfig,
     "pointcloud source 'scan' needs parameters scan.mount, scan.angle_min, scan.angle_max: the sensor's mount, "
     "height band and field of view have no default"),
    ({**CAMERA, "cloud.z_max": -0.2}, InvalidConfig, "parameter cloud.z_max must be a finite number > -0.15, got -0.2"),
    ({**CAMERA, "cloud.angle_max": -1.0}, InvalidConfig, "parameter cloud.angle_max must be a finite number > -0.75 "
                                                         "and <= 5.53319, got -1.0"),
    ({**CAMERA, "cloud.angle_increment": 0.0}, InvalidConfig, "parameter cloud.angle_increment must be a finite "
                                                              "number > 0 and <= 1.5, got 0.0"),
    ({**CAMERA, "cloud.range_max": 0.0}, InvalidConfig, "parameter cloud.range_max must be a finite number > 0, "
                                                        "got 0.0"),
    ({**CAMERA, "cloud.empty": "free"}, UnknownName, "unknown cloud.empty reading 'free'; expected one of: invalid, "
                                                     "no_return"),
    ({**CAMERA, "cloud.axes": "camera"}, UnknownName, "unknown cloud.axes convention 'camera'; expected one of: "
                                                      "optical, rep103"),
    ({**CAMERA, "cloud.mount": [0.1, 0.0]}, InvalidConfig, "cloud.mount must be [x, y, yaw] in [m, m, rad]"),
    ({"control_period": 50}, InvalidConfig, "control_period must be a duration in seconds in (0, 1], got 50"),
    ({"scan.timeout": -1.0}, InvalidConfig, "scan.timeout must be a finite number > 0, got -1.0"),
    ({"scan.mount": [0.0, 0.0]}, InvalidConfig, "scan.mount must be [x, y, yaw] in [m, m, rad], got [0.0, 0.0]"),
    ({"sources": []}, InvalidConfig, "sources must be a non-empty list of names, got []"),
    ({"sources": ["a", "a"]}, InvalidConfig, "names a source twice: ['a', 'a']"),
    ({"stamped": "yes"}, InvalidConfig, "stamped must be True or False, got 'yes'"),
    ({"cmd_vel_out_topic": ""}, InvalidConfig, "cmd_vel_out_topic must be a non-empty string, got ''"),
    ({"footprint": [0.1, 0.1, 0.2]}, InvalidConfig, "footprint must be [x1, y1, x2, y2, ...] with >= 3 vertices"),
    ({"v_max": -1.0}, InvalidConfig, "v_max must be a finite number > 0, got -1.0"),
]


@pytest.mark.parametrize(("parameters", "error", "message"), BAD_PARAMETERS)
def test_bad_parameters_raise_errors_that_name_the_value(parameters, error, message):
    with pytest.raises(error) as caught:
        NodeConfig.from_parameters(parameters)
    assert isinstance(caught.value, SafeNavError) and isinstance(caught.value, ValueError)
    assert message in str(caught.value)


def test_every_parameter_is_documented():
    text = (ROOT / "docs" / "ros.md").read_text()
    assert [p.name for p in PARAMETERS if f"`{p.name}`" not in text] == []


class Recorder:
    """The transport's outputs, kept in lists."""

    def __init__(self) -> None:
        self.commands: list[tuple[float, float]] = []
        self.states: list = []
        self.diagnosed: list = []
        self.marker_sets: list = []

    def command(self, u):
        self.commands.append(u)

    def state(self, state):
        self.states.append(state)

    def diagnostics(self, state):
        self.diagnosed.append(state)

    def markers(self, footprint, points, active):
        self.marker_sets.append((footprint, points, active))


def scan_message(distance: float | None, stamp: float | None = None) -> SimpleNamespace:
    scan = synthetic_scan(ROSBOT, Scene.of(wall(distance=distance))) if distance else ROSBOT.scan()
    fields = {name: getattr(scan, name) for name in ("angle_min", "angle_max", "angle_increment", "time_increment",
                                                      "scan_time", "range_min", "range_max")}
    header = SimpleNamespace(frame_id="laser", stamp=SimpleNamespace(sec=0, nanosec=0) if stamp is None else stamp)
    return SimpleNamespace(header=header, ranges=list(scan.ranges), intensities=[], **fields)


def twist(v: float, omega: float) -> SimpleNamespace:
    return SimpleNamespace(linear=SimpleNamespace(x=v, y=0.0, z=0.0), angular=SimpleNamespace(x=0.0, y=0.0, z=omega))


def odometry(v: float, omega: float, x: float = 0.0) -> SimpleNamespace:
    pose = SimpleNamespace(position=SimpleNamespace(x=x, y=0.0, z=0.0),
                           orientation=SimpleNamespace(x=0.0, y=0.0, z=0.0, w=1.0))
    return SimpleNamespace(pose=SimpleNamespace(pose=pose), twist=SimpleNamespace(twist=twist(v, omega)))


def make_core(**parameters) -> tuple[SafetyCore, Recorder, list[str]]:
    warnings: list[str] = []
    core = SafetyCore(NodeConfig.from_parameters({"odom_topic": "", **parameters}), warn=warnings.append,
                      info=lambda line: None)
    return core, Recorder(), warnings


def test_silent_until_a_command_arrives_then_filters_every_tick():
    core, out, _ = make_core()
    core.on_scan("scan", scan_message(None), 0.0)
    assert core.tick(0.0, out).status == "idle" and out.commands == []
    core.on_command(twist(0.5, 0.0), 0.01)
    state = core.tick(0.05, out)
    assert (state.status, state.published, state.intervened) == ("ok", True, False)
    assert out.commands == [(0.5, 0.0)]                   # free space: the nominal, bit for bit
    core.on_scan("scan", scan_message(0.4), 0.06)
    state = core.tick(0.1, out)
    # Without odometry the base executes the commands (A5): the scan, 0.04 s old at the tick, shows the wall 2 cm
    # farther than it is by then, at 0.5 m/s.
    assert state.intervened and out.commands[-1][0] < 0.3
    assert state.clearance == pytest.approx(0.4 - 0.5 * 0.04 - ROSBOT.radius, abs=1e-9)


def test_a_stale_command_publishes_zero_once_then_nothing():
    core, out, warnings = make_core(cmd_vel_timeout=0.2)
    core.on_command(twist(0.5, 0.0), 0.0)
    for k in range(10):
        core.on_scan("scan", scan_message(None), 0.05 * k)
        core.tick(0.05 * k, out)
    assert out.commands[:5] == [(0.5, 0.0)] * 5 and out.commands[5:] == [(0.0, 0.0)]
    assert core.state.status == "idle" and "0.2 s" in core.state.reason
    assert len([w for w in warnings if "cmd_vel_in is" in w]) == 1       # logged once


def test_stale_odometry_brakes_and_fresh_odometry_limits_the_step():
    core, out, _ = make_core(odom_topic="odom", odom_timeout=0.2)
    core.on_command(twist(0.5, 0.0), 0.0)
    core.on_scan("scan", scan_message(None), 0.0)
    assert core.tick(0.0, out).status == "stale" and out.commands == [(0.0, 0.0)]
    core.on_odometry(odometry(0.0, 0.0), 0.01)
    state = core.tick(0.05, out)
    assert state.status == "ok"
    assert out.commands[-1] == pytest.approx((ROSBOT.a_max * 0.05, 0.0))   # from rest: one period of a_max
    state = core.tick(0.3, out)
    assert state.status == "stale" and "odometry" in state.reason


@pytest.mark.parametrize("periods", [1, 3])
def test_a_tick_that_brakes_for_a_stale_scan_brakes_at_the_limits_over_the_time_since_the_previous_tick(periods):
    # The command is held until the next tick; a tick `periods` control periods after the previous one (an
    # overloaded machine) plans for as long, like the filters' late calls: the nearest stop within that time.
    # Before, always within one control period: a third of the limits when ticks came three periods apart.
    core, out, _ = make_core(odom_topic="odom")
    core.on_scan("scan", scan_message(None), 0.0)      # 0.5 s later it is stale
    core.tick(0.5, out)
    now = 0.5 + 0.05 * periods
    core.on_command(twist(0.8, 0.0), now)
    core.on_odometry(odometry(0.8, 0.0), now)
    state = core.tick(now, out)
    assert state.status == "stale" and "scan" in state.reason, state.reason
    assert out.commands[-1] == pytest.approx(tuple(ROSBOT.brake((0.8, 0.0), 0.05 * periods)), abs=1e-12)


def test_a_header_stamp_older_than_the_timeout_is_stale_even_if_the_message_just_arrived():
    core, out, _ = make_core()
    core.on_command(twist(0.5, 0.0), 10.0)
    core.on_scan("scan", scan_message(None, stamp=SimpleNamespace(sec=9, nanosec=0)), 10.0)
    state = core.tick(10.0, out)
    assert state.status == "stale" and "1.00 s old" in state.reason


def test_a_non_finite_command_brakes_with_bad_input():
    core, out, _ = make_core()
    core.on_scan("scan", scan_message(1.0), 0.0)
    core.on_command(twist(math.nan, 0.0), 0.0)
    state = core.tick(0.0, out)
    assert state.status == "bad_input" and out.commands == [(0.0, 0.0)]


def test_state_is_json_safe_and_diagnostics_rate_limited_and_markers_optional():
    import json

    core, out, _ = make_core(markers=True, escape=False)
    for k in range(30):
        core.on_command(twist(0.5, 0.0), 0.05 * k)
        core.on_scan("scan", scan_message(0.4 if k < 20 else None), 0.05 * k)
        core.tick(0.05 * k, out)
    json.dumps([s.as_dict() for s in out.states], allow_nan=False)
    assert [s.time for s in out.diagnosed] == [0.0, 1.0]    # once a second while the status holds
    # With the escape (the default) its start is published at once: the robot stood 0.5 s before the wall.
    escaped, seen, _ = make_core()
    for k in range(20):
        escaped.on_command(twist(0.5, 0.0), 0.05 * k)
        escaped.on_scan("scan", scan_message(0.4), 0.05 * k)
        escaped.tick(0.05 * k, seen)
    escaping = next(s for s in seen.states if s.escape)
    assert [s.time for s in seen.diagnosed] == [0.0, escaping.time] and escaping.time == pytest.approx(0.5)
    assert "stood for 0.5 s" in escaping.reason, escaping.reason
    footprint, points, active = out.marker_sets[0]
    assert footprint.shape == (4, 2) and len(points) and np.all(np.isin(active, points))


def _drive_into_a_wall(core, out, seconds: float):
    state = None
    for k in range(round(seconds / 0.05)):
        core.on_scan("scan", scan_message(0.39), 0.05 * k)    # a wall at the margin, straight ahead
        core.on_command(twist(0.5, 0.0), 0.05 * k)
        state = core.tick(0.05 * k, out)
    return state


def test_a_deadlock_is_reported_and_the_escape_parameter_gets_out_of_it():
    core, out, _ = make_core(escape=False)
    state = _drive_into_a_wall(core, out, 3.0)
    assert state.deadlock is not None and state.deadlock >= 1.0 and state.escape == "" and state.level >= 1
    assert not state.escape_enabled and not core.state.escape_enabled
    escaping, out, _ = make_core(escape=True)
    _drive_into_a_wall(escaping, out, 3.0)
    escapes = [s for s in out.states if s.escape]
    assert escapes and all(s.u_nom == (0.5, 0.0) and abs(s.u[1]) > 0.1 for s in escapes)   # turning away
    assert "following the obstacle" in escapes[0].escape


def test_the_escape_is_on_by_default_and_reported_in_the_state_and_the_diagnostics():
    """The node drives the robot on its own: the escape wraps the filter unless ``escape: false``."""
    assert NodeConfig.from_parameters({}).escape and not NodeConfig.from_parameters({"escape": False}).escape
    core, out, _ = make_core()
    assert core.filter.name == "cbf+escape" and core.state.escape_enabled
    assert "with cbf with the deadlock escape for rosbot" in core.describe()
    smallest = 100.0 * core.filter.smallest_obstacle
    assert f"obstacles at least {smallest:.1f} cm wide are seen in time" in core.describe()
    assert "cm wide" not in make_core(filter="zones")[0].describe()
    assert "without the deadlock escape (escape: false)" in make_core(escape=False)[0].describe()
    _drive_into_a_wall(core, out, 3.0)
    assert all(s.escape_enabled for s in out.states)
    escaping = [s for s in out.states if s.escape]
    assert escaping and escaping[0].deadlock is None and escaping[0].binding == "escape"
    assert all(abs(s.u[1]) > 0.1 for s in escaping)                         # it turns away from the wall
    assert escaping[0] in out.diagnosed                                     # a new status: diagnosed at once
    values = dict(core.diagnostic_values(escaping[0]))
    assert values["escape_enabled"] == "True" and "following the obstacle" in values["escape"]



def test_without_ros2_the_command_names_the_pip_line(monkeypatch, capsys):
    import sys

    from safenav.ros.cli import ros2_main

    monkeypatch.setitem(sys.modules, "rclpy", None)
    monkeypatch.delitem(sys.modules, "safenav.ros.ros2", raising=False)
    assert ros2_main(["--help"]) == 2
    assert capsys.readouterr().err.strip() == ('safenav-ros2: safenav-ros2 (the ROS 2 node) needs the optional package '
                                               '\'rclpy\': pip install "safenav[ros2]"')


def test_without_ros1_the_command_names_the_debian_packages(monkeypatch, capsys, tmp_path):
    import sys

    from safenav.ros.cli import ros1_main

    monkeypatch.setitem(sys.modules, "rospy", None)
    monkeypatch.delitem(sys.modules, "safenav.ros.ros1", raising=False)
    monkeypatch.setenv("SAFENAV_ROS1_PYTHONPATH", str(tmp_path))
    assert ros1_main(["--help"]) == 2
    error = capsys.readouterr().err
    assert "apt-get install ros-core python3-rospy" in error and str(tmp_path) in error


def test_several_sources_each_with_its_mount_and_timeout():
    front_half = preset("m2wr")      # a 180-degree lidar at x = 0.15 m, looking forward
    core, out, _ = make_core(robot="m2wr", sources=["front", "rear"], **{
        "front.mount": list(front_half.lidar.mount), "rear.mount": [-0.15, 0.0, math.pi], "rear.timeout": 0.2})
    ahead = synthetic_scan(front_half, Scene.of(wall(distance=0.8)))
    behind = front_half.scan()     # the rear lidar sees nothing within range
    for source, scan in (("front", ahead), ("rear", behind)):
        fields = {n: getattr(scan, n) for n in ("angle_min", "angle_max", "angle_increment", "time_increment",
                                                "scan_time", "range_min", "range_max")}
        core.on_scan(source, SimpleNamespace(ranges=list(scan.ranges), intensities=[], **fields), 0.0)
    core.on_command(twist(1.0, 0.0), 0.0)
    state = core.tick(0.0, out)
    assert state.status == "ok" and state.intervened and out.commands[-1][0] < 1.0
    assert 0.0 < state.clearance < 0.8 + 0.15      # the wall, seen by the front lidar 0.15 m ahead of the base
    assert state.binding is not None
    state = core.tick(0.3, out)     # the rear source is now older than its 0.2 s timeout
    assert state.status == "stale" and "source 'rear'" in state.reason


def clockwise(message: SimpleNamespace) -> SimpleNamespace:
    """The same beams published clockwise (``angle_increment < 0``), as a driver of an upside-down lidar does."""
    n = len(message.ranges)
    return SimpleNamespace(**{**vars(message), "ranges": message.ranges[::-1],
                              "angle_increment": -message.angle_increment, "angle_max": message.angle_min,
                              "angle_min": message.angle_min + (n - 1) * message.angle_increment})


def test_a_driver_that_publishes_clockwise_is_filtered_as_its_counter_clockwise_twin():
    commands, statuses = [], []
    for convert in (lambda message: message, clockwise):
        core, out, _ = make_core()
        core.on_command(twist(0.5, 0.0), 0.0)
        for step in range(4):
            core.on_scan("scan", convert(scan_message(0.6 - 0.02 * step)), 0.05 * step)
            statuses.append(core.tick(0.05 * step, out).status)
        assert core.state.intervened
        commands.append(out.commands)
    assert statuses == ["ok"] * 8
    np.testing.assert_allclose(commands[0], commands[1], atol=1e-9)


def test_a_driver_layout_is_learned_from_the_first_message_and_a_later_change_is_malformed():
    core, out, _ = make_core()
    other = preset("puzzlebot").lidar           # 360 beams over 0..2pi: not the ROSbot preset's layout
    first = other.scan(np.full(other.n_beams, 2.0))
    fields = {n: getattr(first, n) for n in ("angle_min", "angle_max", "angle_increment", "time_increment",
                                             "scan_time", "range_min", "range_max")}
    core.on_scan("scan", SimpleNamespace(ranges=list(first.ranges), intensities=[], **fields), 0.0)
    core.on_command(twist(0.5, 0.0), 0.0)
    assert core.tick(0.0, out).status == "ok"
    assert core.robot.lidar.n_beams == 360 and core.robot.lidar.mount == ROSBOT.lidar.mount
    core.on_scan("scan", scan_message(None), 0.05)      # now 720 beams: the driver changed under the node
    state = core.tick(0.05, out)
    assert state.status == "bad_message" and "720" in state.reason and out.commands[-1] == (0.0, 0.0)


# ============================================================================ point-cloud sources


def cloud_message(distance: float | None, **changes) -> SimpleNamespace:
    """A ``PointCloud2``'s fields (see ``clouds.py``): a wall ``distance`` ahead of the base, and the floor."""
    fields = {**cloud_fields(wall_points(distance)), **changes}
    header = SimpleNamespace(frame_id=fields.pop("frame_id"), stamp=SimpleNamespace(sec=0, nanosec=0))
    points = [SimpleNamespace(name=name, offset=offset, datatype=datatype, count=count)
              for name, offset, datatype, count in fields.pop("fields")]
    return SimpleNamespace(header=header, fields=points, **fields)


def test_a_pointcloud_source_is_a_lidar_of_its_field_of_view_band_and_mount():
    config = NodeConfig.from_parameters({"sources": ["scan", "cloud"], **cloud_parameters("cloud", full_turn=False),
                                         "cloud.axes": "optical", "cloud.range_min": 0.2})
    scan, cloud = config.sources
    assert (scan.type, scan.lidar) == ("scan", None)
    lidar = cloud.lidar
    assert (cloud.type, cloud.topic, tuple(cloud.mount)) == ("pointcloud", "cloud", CLOUD_MOUNT)
    assert (lidar.frame_id, tuple(lidar.mount), lidar.range_min, lidar.range_max) == ("cloud", CLOUD_MOUNT, 0.2, 8.0)
    assert (lidar.cloud.z_min, lidar.cloud.z_max, lidar.cloud.empty, lidar.cloud.axes) == (*BAND, "invalid", "optical")
    # Half-degree bins from -0.75 rad, the last one inside the field of view.
    assert lidar.angle_min == -0.75 and lidar.angle_increment == pytest.approx(math.pi / 360)
    assert lidar.n_beams == 172 and 0.75 - lidar.angle_increment < lidar.angle_max <= 0.75
    # A full turn -pi..pi holds each direction once (pi is -pi's bin).
    turn = NodeConfig.from_parameters({"sources": ["cloud"], **cloud_parameters("cloud", full_turn=False),
                                       "cloud.angle_min": -math.pi, "cloud.angle_max": math.pi}).sources[0].lidar
    assert turn.n_beams == 720 and turn.angle_max == pytest.approx(math.pi - math.pi / 360)
    # The node's robot knows the cloud's lidar from the start, next to the preset's for the scan.
    core, _, _ = make_core(sources=["scan", "cloud"], **cloud_parameters("cloud", full_turn=False))
    assert [known.frame_id for known in core.robot.lidars] == ["scan", "cloud"]
    assert core.robot.lidars[1] == NodeConfig.from_parameters(
        {"sources": ["scan", "cloud"], **cloud_parameters("cloud", full_turn=False)}).sources[1].lidar


def _drive(core, out, clouds, scan=None, steps: int = 5):
    """``steps`` control periods of the cloud (and the scan) and a forward command, after the last tick."""
    start = 0.0 if core.state.time == 0.0 else core.state.time + 0.05
    state = None
    for k in range(steps):
        now = start + 0.05 * k
        if scan is not None:
            core.on_scan("scan", scan, now)
        core.on_scan("cloud", clouds, now)
        core.on_command(twist(0.5, 0.0), now)
        state = core.tick(now, out)
    return state


def test_a_cloud_of_a_wall_ahead_brakes_and_the_floor_below_the_band_does_not():
    lidar_3d = {"sources": ["cloud"], **cloud_parameters("cloud", full_turn=True)}
    core, out, _ = make_core(**lidar_3d)
    state = _drive(core, out, cloud_message(None))
    assert (state.status, state.intervened) == ("ok", False) and out.commands[-1] == (0.5, 0.0)
    state = _drive(core, out, cloud_message(0.4))
    assert state.status == "ok" and state.intervened and state.binding == "barrier"
    assert 0.0 <= out.commands[-1][0] < 0.3 and out.commands[-1][1] == pytest.approx(0.0, abs=1e-9)
    assert 0.0 < state.clearance <= 0.4 - ROSBOT.radius + 1e-6      # the wall, through the cloud's mount
    # A band that takes in the floor (0.25 m below the sensor) sees it as obstacles 0.2 m ahead.
    floor_too, out, _ = make_core(**{**lidar_3d, "cloud.z_min": -0.3})
    state = _drive(floor_too, out, cloud_message(None))
    assert state.intervened and out.commands[-1][0] < 0.5


def test_a_scan_and_a_cloud_are_merged_and_a_wall_only_the_cloud_sees_brakes():
    core, out, _ = make_core(sources=["scan", "cloud"], **cloud_parameters("cloud", full_turn=False))
    state = _drive(core, out, cloud_message(None), scan=scan_message(None))
    assert (state.status, state.intervened) == ("ok", False)     # the camera's empty bins: the scan sees them free
    state = _drive(core, out, cloud_message(0.4), scan=scan_message(None))
    assert state.status == "ok" and state.intervened and 0.0 <= out.commands[-1][0] < 0.3
    later = core.state.time + 0.6                  # a fresh scan and command, the cloud older than its 0.5 s timeout
    core.on_scan("scan", scan_message(None), later)
    core.on_command(twist(0.5, 0.0), later)
    state = core.tick(later, out)
    assert state.status == "stale" and "source 'cloud'" in state.reason


def test_a_malformed_cloud_brakes_names_the_field_and_the_next_good_one_recovers():
    core, out, warnings = make_core(sources=["scan", "cloud"], **cloud_parameters("cloud", full_turn=False))
    good = cloud_message(0.4)
    malformed = cloud_message(0.4, row_step=good.row_step + 12)
    for k, clouds in enumerate((good, malformed, malformed, good, good)):
        core.on_scan("scan", scan_message(None), 0.05 * k)
        core.on_scan("cloud", clouds, 0.05 * k)
        core.on_command(twist(0.5, 0.0), 0.05 * k)
        core.tick(0.05 * k, out)
        if clouds is malformed:
            assert core.state.status == "bad_message" and "PointCloud2.data has" in core.state.reason
    assert out.commands[1] == (0.0, 0.0) and len(out.commands) == 4      # zero once, then silent
    assert core.state.status == "ok" and 0.0 < out.commands[-1][0] < 0.3      # (the first after is late)
    assert len([w for w in warnings if "malformed message" in w]) == 1
    # A message without a field: the reason names the message's own type and the field.
    fields = vars(cloud_message(0.4))
    core.on_scan("cloud", SimpleNamespace(**{k: v for k, v in fields.items() if k != "height"}), 0.3)
    core.on_command(twist(0.5, 0.0), 0.3)
    state = core.tick(0.3, out)
    assert state.status == "bad_message" and "message SimpleNamespace has no field 'height'" in state.reason

import math

import numpy as np
import pytest

from safenav import (
    PRESET_NAMES,
    InvalidCommand,
    InvalidCommandType,
    InvalidConfig,
    LidarSpec,
    UnknownName,
    as_command,
    preset,
)


def test_presets_follow_the_design_table():
    rosbot, puzzlebot, m2wr = (preset(name) for name in PRESET_NAMES)
    assert (rosbot.lidar.n_beams, rosbot.lidar.angle_min, rosbot.lidar.angle_max) == (720, -math.pi, math.pi)
    assert rosbot.lidar.mount.yaw == math.pi
    assert rosbot.lidar.angle_increment == pytest.approx(2 * math.pi / 719)
    assert (puzzlebot.lidar.n_beams, puzzlebot.lidar.angle_min) == (360, 0.0)
    assert puzzlebot.lidar.angle_increment == pytest.approx(2 * math.pi / 359)
    assert (m2wr.lidar.n_beams, m2wr.lidar.angle_min, m2wr.lidar.angle_max) == (720, -math.pi / 2, math.pi / 2)
    assert m2wr.lidar.noise_std == 0.01 and m2wr.lidar.range_max == 30.0
    # Circumscribed disks of the public body sizes.
    assert rosbot.radius >= math.hypot(0.100, 0.1175)
    assert m2wr.radius >= math.hypot(0.25, 0.15)
    assert 0.09 <= puzzlebot.radius <= 0.12


def test_every_preset_can_reach_the_tutorial_speeds(robot):
    tutorial_speeds = {"rosbot": (0.5, 0.0), "puzzlebot": (0.2, 0.5), "m2wr": (0.5, 0.3)}
    v, omega = tutorial_speeds[robot.name]
    assert robot.v_max >= v and robot.omega_max >= omega
    assert robot.v_min <= 0.0 and robot.a_max > 0 and robot.alpha_max > 0


def test_preset_template_scan_has_the_right_layout(robot):
    scan = robot.scan()
    assert scan.n_beams == robot.lidar.n_beams
    assert np.all(np.isinf(scan.ranges))
    assert scan.mount == robot.lidar.mount
    assert scan.angles[-1] == pytest.approx(robot.lidar.angle_max)


def test_unknown_preset_lists_the_known_ones():
    with pytest.raises(UnknownName, match="unknown robot preset 'turtlebot'; expected one of: m2wr, puzzlebot, rosbot"):
        preset("turtlebot")


def test_velocity_bounds_intersect_limits_with_what_acceleration_allows():
    robot = preset("rosbot")
    lower, upper = robot.velocity_bounds((0.9, 0.0), dt=0.1)
    assert lower == pytest.approx([0.75, -0.6]) and upper == pytest.approx([1.0, 0.6])
    lower, upper = robot.velocity_bounds()
    assert lower.tolist() == [-1.0, -3.0] and upper.tolist() == [1.0, 3.0]


def test_velocity_bounds_from_outside_the_limits_stay_inside_them():
    robot = preset("rosbot")
    lower, upper = robot.velocity_bounds((2.0, 0.0), dt=0.1)
    assert lower[0] == upper[0] == 1.0
    lower, upper = robot.velocity_bounds((-1.1, 0.0), dt=0.1)
    assert lower[0] == -1.0 and upper[0] == pytest.approx(-0.95)


def test_brake_decelerates_at_the_acceleration_limit():
    robot = preset("m2wr")
    assert robot.brake((0.8, -1.0), dt=0.1) == pytest.approx([0.7, -0.7])
    assert robot.brake((0.05, 0.1), dt=0.1).tolist() == [0.0, 0.0]
    assert robot.brake().tolist() == [0.0, 0.0]


def test_clip_respects_limits():
    robot = preset("puzzlebot")
    assert robot.clip((5.0, -9.0)).tolist() == [0.4, -2.0]


BAD_CONFIGS = [
    (dict(radius=0.0), "RobotSpec.radius must be a finite number > 0"),
    (dict(radius=math.nan), "RobotSpec.radius must be a finite number > 0"),
    (dict(v_max=-1.0), "RobotSpec.v_max must be a finite number > 0"),
    (dict(v_min=0.5), "RobotSpec.v_min must be a finite number <= 0"),
    (dict(omega_max="fast"), "RobotSpec.omega_max must be a finite number > 0"),
    (dict(a_max=0), "RobotSpec.a_max must be a finite number > 0"),
    (dict(footprint=((1.0, 1.0), (-1.0, 1.0), (0.0, -1.0))), "footprint reaches 1.4142 m"),
    (dict(footprint=((0.0, 0.0),)), "footprint must be >= 3"),
    (dict(lidar="hokuyo"), "RobotSpec.lidar must be a LidarSpec"),
]


@pytest.mark.parametrize(("changes", "fragment"), BAD_CONFIGS)
def test_bad_robot_configs_raise(changes, fragment):
    with pytest.raises(InvalidConfig, match=fragment.replace("(", r"\(").replace(")", r"\)")):
        preset("rosbot").replace(**changes)


def test_bad_lidar_config_names_the_field():
    with pytest.raises(InvalidConfig, match="n_beams must be an integer >= 1"):
        LidarSpec(n_beams=0, angle_min=0.0, angle_max=1.0, range_min=0.1, range_max=2.0)
    with pytest.raises(ValueError, match="range_max must be > range_min"):
        LidarSpec(n_beams=10, angle_min=0.0, angle_max=1.0, range_min=3.0, range_max=2.0)


@pytest.mark.parametrize(
    ("value", "exception", "fragment"),
    [
        (None, InvalidCommandType, "u must be a pair"),
        ("fast", InvalidCommandType, "u must be a pair"),
        ((1.0, "left"), InvalidCommandType, "u must be a pair"),
        ((1.0,), InvalidCommand, "shape (2,)"),
        ((1.0, 2.0, 3.0), InvalidCommand, "shape (2,)"),
        ([[1.0, 2.0]], InvalidCommand, "shape (2,)"),
    ],
)
def test_as_command_rejects_structural_garbage(value, exception, fragment):
    with pytest.raises(exception) as info:
        as_command(value)
    assert type(info.value) is exception and fragment in str(info.value)


def test_as_command_keeps_non_finite_values_for_the_filter_to_handle():
    assert np.isnan(as_command((math.nan, 0.0))[0])


def test_velocity_limits_are_read_only_so_callers_cannot_change_the_robot():
    robot = preset("rosbot")
    with pytest.raises(ValueError):
        robot.lower[0] = 0.0
    assert robot.lower.tolist() == [-1.0, -3.0] and robot.upper.tolist() == [1.0, 3.0]

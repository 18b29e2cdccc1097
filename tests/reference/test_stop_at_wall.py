"""StopAtWall (tutorial 1): the front found by angle on every lidar convention, the published bug."""

import math

import numpy as np
import pytest

from safenav import Command, InvalidScan, LidarSpec, Pose2D, preset, wrap_angle
from safenav.reference import Proximity, StopAtWall
from safenav.synthetic import Scene, synthetic_scan, wall
from tests.reference.closed_loop import tutorial_episode
from tests.scans import DEG, INF, LIDARS, NAN, scan_of

# ------------------------------------------------------------------ StopAtWall (tutorial 1)


@pytest.mark.parametrize("background", [0.3, INF])
@pytest.mark.parametrize(
    ("front", "expected", "state"),
    [
        (2.0, (0.5, 0.0), "go"),
        (math.nextafter(1.0, INF), (0.5, 0.0), "go"),   # just above the threshold: the tutorial's `>` holds
        (1.0, (0.0, 0.0), "stop"),                       # exactly at the threshold: `1.0 > 1.0` is false
        (0.99, (0.0, 0.0), "stop"),
        (0.3, (0.0, 0.0), "stop"),
    ],
)
def test_stop_at_wall_reads_the_front_by_angle(lidar, background, front, expected, state):
    # Everything except the front reads `background`: obstacles elsewhere must not matter.
    policy = StopAtWall()
    command = policy(scan_of(lidar, [((-2, 2), front)], background=background))
    assert isinstance(command, Command)
    assert command == expected
    assert policy.state == state


@pytest.mark.parametrize(
    ("front", "expected", "why"),
    [
        (INF, (0.5, 0.0), "no return within range_max (>= 1 m): free"),
        (-INF, (0.0, 0.0), "object closer than range_min"),
        (NAN, (0.0, 0.0), "invalid: unknown, do not drive into it"),
        (100.0, (0.0, 0.0), "above range_max: discarded, so unknown"),
        (0.01, (0.0, 0.0), "below range_min: discarded, so unknown"),
    ],
)
def test_stop_at_wall_special_front_readings(lidar, front, expected, why):
    policy = StopAtWall()
    assert policy(scan_of(lidar, [((-2, 2), front)], background=5.0)) == expected, why


def test_stop_at_wall_stops_when_the_front_is_not_in_the_field_of_view():
    backwards = LidarSpec(n_beams=720, angle_min=-0.5 * math.pi, angle_max=0.5 * math.pi, range_min=0.1,
                          range_max=30.0, mount=Pose2D(0.0, 0.0, math.pi))
    policy = StopAtWall()
    assert policy(backwards.scan()) == (0.0, 0.0)
    assert policy.front.proximity is Proximity.UNKNOWN and math.isnan(policy.front.distance)


def test_stop_at_wall_does_not_trust_free_space_beyond_a_short_range_max():
    scan = LIDARS["hokuyo_240"].scan()  # all +inf; range_max 5.6 m
    assert StopAtWall(threshold=5.0)(scan) == (0.5, 0.0)
    assert StopAtWall(threshold=6.0)(scan) == (0.0, 0.0)


def test_stop_at_wall_on_synthetic_walls_of_each_robot(robot):
    policy = StopAtWall()
    offset = robot.lidar.mount.x  # ranges are measured from the laser, as in the tutorial
    assert policy(synthetic_scan(robot, Scene.of(wall(offset + 0.8)))) == (0.0, 0.0)
    assert policy.front.distance == pytest.approx(0.8, abs=1e-4)  # the m2wr has no beam exactly ahead
    assert policy(synthetic_scan(robot, Scene.of(wall(offset + 1.2)))) == (0.5, 0.0)
    # A wall right behind (where the lidar sees) and one to the side do not stop it.
    assert policy(synthetic_scan(robot, Scene.of(wall(0.4, 0.5 * math.pi), wall(0.4, -0.5 * math.pi)))) == (0.5, 0.0)


def test_the_tutorials_beam_360_looks_backward_on_the_rosbot():
    scan = preset("rosbot").scan()
    assert abs(wrap_angle(scan.base_angles[360] - math.pi)) < scan.angle_increment
    assert scan.beam_index(0.0) == 0


@pytest.mark.parametrize(
    ("scene", "fixed", "buggy"),
    [
        # Wall 0.5 m ahead, nothing behind: the tutorial reads beam 360 (behind), sees nothing, drives into it.
        (Scene.of(wall(0.5, 0.0)), (0.0, 0.0), (0.5, 0.0)),
        # Wall 0.5 m behind, nothing ahead: the tutorial stops for no reason.
        (Scene.of(wall(0.5, math.pi)), (0.5, 0.0), (0.0, 0.0)),
    ],
)
def test_the_buggy_stop_at_wall_reads_beam_360_like_the_tutorial(scene, fixed, buggy):
    rosbot = preset("rosbot")
    scan = synthetic_scan(rosbot, scene)
    assert StopAtWall()(scan) == fixed
    assert StopAtWall.tutorial_bug()(scan) == buggy
    assert StopAtWall(front_index=360)(scan) == buggy


def test_the_buggy_stop_at_wall_reads_exactly_raw_beam_360():
    template = preset("rosbot").scan()
    ranges = np.full(template.n_beams, 0.2)  # everything near ...
    ranges[360] = 3.0                         # ... except beam 360
    policy = StopAtWall.tutorial_bug()
    assert policy.buggy and policy.front_index == 360
    assert policy(template.with_ranges(ranges)) == (0.5, 0.0)
    ranges[:] = 5.0
    ranges[360] = 0.9                         # only beam 360 is near
    assert policy(template.with_ranges(ranges)) == (0.0, 0.0)


@pytest.mark.parametrize(
    ("raw", "expected"),
    [
        (1.0, (0.0, 0.0)),     # `1.0 > 1.0` is false
        (NAN, (0.0, 0.0)),     # `nan > 1.0` is false
        (INF, (0.5, 0.0)),     # `inf > 1.0`
        (-INF, (0.0, 0.0)),
        (100.0, (0.5, 0.0)),   # above range_max: the tutorial takes it at face value (the fixed policy stops)
    ],
)
def test_the_buggy_stop_at_wall_compares_the_raw_value(raw, expected):
    template = preset("rosbot").scan()
    ranges = np.full(template.n_beams, 5.0)
    ranges[360] = raw
    assert StopAtWall.tutorial_bug()(template.with_ranges(ranges)) == expected


def test_the_buggy_stop_at_wall_needs_beam_360():
    with pytest.raises(InvalidScan, match=r"front_index=360 but the scan has 360 beams \(indices 0..359\)"):
        StopAtWall.tutorial_bug()(preset("puzzlebot").scan())


def test_stop_at_wall_with_a_front_cone_sees_what_the_single_beam_misses():
    scan = scan_of(LIDARS["rosbot"], [((7, 9), 0.6)])  # a post 8 degrees left of straight ahead
    assert StopAtWall()(scan) == (0.5, 0.0)
    assert StopAtWall(front_half_width=10 * DEG)(scan) == (0.0, 0.0)


def test_stop_at_wall_clips_to_the_robot_it_is_given():
    scan = LIDARS["rosbot"].scan()
    assert StopAtWall(robot=preset("rosbot"))(scan) == (0.5, 0.0)      # the tutorial's own robot: unchanged
    assert StopAtWall(robot=preset("puzzlebot"))(scan) == (0.4, 0.0)   # v_max 0.4 m/s


def test_stop_at_wall_reset_forgets_the_front():
    policy = StopAtWall()
    assert policy.state == "stop" and policy.front is None
    policy(LIDARS["rosbot"].scan())
    assert policy.state == "go" and policy.front.proximity is Proximity.CLEAR
    policy.reset()
    assert policy.state == "stop" and policy.front is None

@pytest.mark.sim
def test_stop_at_wall_ends_stopped_between_half_a_metre_and_a_metre_from_the_wall():
    _, _, result = tutorial_episode("stop_at_wall", StopAtWall(robot=preset("rosbot")), 12.0)
    metrics, trajectory = result.metrics, result.trajectory
    assert not metrics.collided
    x, _, yaw = trajectory.pose[-1]
    ahead = (3.0 - x) / math.cos(yaw)          # the wall's near face is the line x = 3 m
    assert 0.5 <= ahead <= 1.0
    assert np.all(np.abs(trajectory.velocity[-20:]) < 1e-9)      # stopped, and stays stopped
    assert trajectory.policy_state[-1] == "stop"


@pytest.mark.sim
def test_the_published_stop_at_wall_drives_into_the_wall():
    _, _, result = tutorial_episode("stop_at_wall", StopAtWall.tutorial_bug(), 12.0)
    assert result.metrics.collided
    assert set(result.trajectory.policy_state) == {"go"}      # beam 360 looks backwards: never sees the wall

import math

import numpy as np
import pytest

from safenav import InvalidConfig, Pose2D, preset
from safenav.synthetic import Circle, Scene, box, cast, synthetic_scan, wall


def test_cast_hits_segments_and_circles_at_the_exact_distance():
    scene = Scene.of(wall(2.0), Circle((0.0, 3.0), 0.5))
    ranges = cast((0.0, 0.0), np.array([0.0, math.pi / 2, math.pi, math.atan2(1.0, 2.0)]), scene)
    assert ranges[0] == pytest.approx(2.0)
    assert ranges[1] == pytest.approx(2.5)
    assert ranges[2] == math.inf
    assert ranges[3] == pytest.approx(math.hypot(2.0, 1.0))


def test_scan_uses_the_lidar_mount_and_rep117_limits():
    robot = preset("m2wr")
    scan = synthetic_scan(robot, Scene.of(wall(1.0)), Pose2D(0.0, 0.0, 0.0))
    assert scan.ranges[scan.beam_index(0.0)] == pytest.approx(0.85, abs=1e-5)
    too_close = synthetic_scan(robot, Scene.of(wall(0.2)))
    assert too_close.ranges[too_close.beam_index(0.0)] == -math.inf
    empty = synthetic_scan(robot, Scene())
    assert np.all(empty.ranges == math.inf)


def test_scan_from_a_moved_robot_sees_the_world_in_its_own_frame():
    robot = preset("puzzlebot")
    scene = Scene.of(box((3.0, 1.0), (0.4, 0.4)))
    pose = Pose2D(3.0, 0.0, math.pi / 2)   # box now 1 m straight ahead, minus half its size
    scan = synthetic_scan(robot, scene, pose)
    assert scan.ranges[scan.beam_index(0.0)] == pytest.approx(0.8)


def test_clearance_of_a_disk():
    scene = Scene.of(wall(1.0), Circle((-2.0, 0.0), 0.5))
    assert scene.clearance((0.0, 0.0), 0.2) == pytest.approx(0.8)
    assert scene.clearance((-1.0, 0.0), 0.2) == pytest.approx(0.3)
    assert scene.clearance((0.95, 0.0), 0.2) == pytest.approx(-0.15)


def test_noise_needs_a_generator_and_is_reproducible():
    robot = preset("rosbot")
    scene = Scene.of(wall(1.0))
    with pytest.raises(InvalidConfig, match="needs rng"):
        synthetic_scan(robot, scene, noise_std=0.01)
    a = synthetic_scan(robot, scene, noise_std=0.01, rng=np.random.default_rng(3))
    b = synthetic_scan(robot, scene, noise_std=0.01, rng=np.random.default_rng(3))
    assert np.array_equal(a.ranges, b.ranges)

"""ObstacleAvoidance (tutorial 2): both branches, strict threshold, unknown cones."""

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from safenav import LidarSpec, preset
from safenav.reference import ObstacleAvoidance, Proximity
from safenav.synthetic import Scene, synthetic_scan, wall
from tests.reference.closed_loop import tutorial_episode
from tests.scans import DEG, INF, LIDARS, NAN, scan_of

# ------------------------------------------------------------------ ObstacleAvoidance (tutorial 2)

TURN, CRUISE = (0.0, 0.5), (0.2, 0.3)


@pytest.mark.parametrize(
    ("patch", "expected", "state"),
    [
        (None, CRUISE, "drive"),
        ((-0.5, 0.5), TURN, "turn in place"),
        ((13.5, 14.5), TURN, "turn in place"),     # inside +-15 degrees, left
        ((-14.5, -13.5), TURN, "turn in place"),   # inside, right (the wrap-around on a 0..2pi scan)
        ((16.5, 20.0), CRUISE, "drive"),           # just outside, left
        ((-20.0, -16.5), CRUISE, "drive"),         # just outside, right
        ((60.0, 120.0), CRUISE, "drive"),
    ],
)
def test_obstacle_avoidance_both_branches(lidar, patch, expected, state):
    policy = ObstacleAvoidance()
    scan = scan_of(lidar, [] if patch is None else [(patch, 0.4)], background=3.0)
    assert policy(scan) == expected
    assert policy.state == state


@pytest.mark.parametrize(
    ("nearest", "expected"),
    [
        (0.5, CRUISE),                          # exactly at the threshold: `0.5 < 0.5` is false
        (math.nextafter(0.5, 0.0), TURN),
        (0.51, CRUISE),
    ],
)
def test_obstacle_avoidance_threshold_is_strict(lidar, nearest, expected):
    assert ObstacleAvoidance()(scan_of(lidar, [((4, 6), nearest)], background=INF)) == expected


@pytest.mark.parametrize(
    ("cone", "expected", "why"),
    [
        ([((-15, 15), NAN)], TURN, "no valid beam in the cone: unknown is not clear"),
        ([((-15, 15), 100.0)], TURN, "only readings above range_max: unknown"),
        ([((-15, 15), NAN), ((-1, 1), INF)], CRUISE, "the valid readings say free; invalid ones are ignored"),
        ([((-15, 15), NAN), ((-1, 1), 2.0)], CRUISE, "the valid readings are far"),
        ([((5, 6), -INF)], TURN, "an object closer than range_min"),
        ([((5, 6), 0.01)], CRUISE, "below range_min: discarded (the tutorial would turn)"),
    ],
)
def test_obstacle_avoidance_invalid_readings(lidar, cone, expected, why):
    assert ObstacleAvoidance()(scan_of(lidar, cone, background=INF)) == expected, why


@pytest.mark.parametrize(("beam", "expected"), [(0, TURN), (14, TURN), (345, TURN), (355, TURN), (359, TURN),
                                                (15, CRUISE), (344, CRUISE), (180, CRUISE)])
def test_obstacle_avoidance_wraps_around_the_puzzlebots_scan(beam, expected):
    template = preset("puzzlebot").scan()
    ranges = np.full(template.n_beams, INF)
    ranges[beam] = 0.3
    assert ObstacleAvoidance()(template.with_ranges(ranges)) == expected


def test_obstacle_avoidance_turns_when_the_cone_is_only_partly_seen():
    left_only = LidarSpec(n_beams=200, angle_min=5 * DEG, angle_max=180 * DEG, range_min=0.1, range_max=10.0)
    policy = ObstacleAvoidance()
    assert policy(left_only.scan()) == TURN
    assert policy.cone.proximity is Proximity.UNKNOWN


def test_obstacle_avoidance_on_synthetic_walls_of_each_robot(robot):
    policy = ObstacleAvoidance()
    offset = robot.lidar.mount.x
    assert policy(synthetic_scan(robot, Scene.of(wall(offset + 0.4)))) == TURN
    assert policy(synthetic_scan(robot, Scene.of(wall(offset + 0.6)))) == CRUISE
    assert policy(synthetic_scan(robot, Scene.of(wall(0.4, 0.5 * math.pi)))) == CRUISE  # to the side


@given(st.lists(st.sampled_from([0.2, 0.49, 0.5, 0.8, 3.0, INF, -INF, NAN, 0.05, 99.0]), min_size=360, max_size=360))
def test_obstacle_avoidance_matches_the_tutorial_index_rule_on_the_puzzlebot(values):
    # Oracle: the puzzlebot's +-15 degree cone by index, the tutorial's `< 0.5` on valid readings,
    # and the documented conservative rule for a cone with no valid reading.
    scan = preset("puzzlebot").scan(values)
    cone = np.r_[np.arange(0, 15), np.arange(345, 360)]
    r = np.asarray(values)[cone]
    hit = (r >= 0.15) & (r <= 12.0)
    informative = hit | np.isinf(r)
    turn = bool(np.any(hit & (r < 0.5)) or np.any(r == -INF) or not np.any(informative))
    assert ObstacleAvoidance()(scan) == (TURN if turn else CRUISE)


def test_obstacle_avoidance_clips_to_the_robot_it_is_given():
    slow = preset("puzzlebot").replace(v_max=0.1, omega_max=0.25)
    scan = LIDARS["puzzlebot"].scan()
    assert ObstacleAvoidance(robot=preset("puzzlebot"))(scan) == CRUISE
    assert ObstacleAvoidance(robot=slow)(scan) == (0.1, 0.25)

@pytest.mark.sim
def test_obstacle_avoidance_turns_away_when_something_enters_its_cone():
    _, _, result = tutorial_episode("obstacle_avoidance", ObstacleAvoidance(robot=preset("puzzlebot")), 40.0)
    trajectory = result.trajectory
    states = trajectory.policy_state
    turning = [index for index, state in enumerate(states) if state == "turn in place"]
    assert turning, "the tutorial world must put something in the cone"
    assert np.allclose(trajectory.u_nom[turning], [0.0, 0.5])
    assert np.allclose(trajectory.u_nom[[i for i, s in enumerate(states) if s == "drive"]], [0.2, 0.3])
    cone = math.radians(15.0)
    ends = [index for index in turning[:-1] if states[index + 1] == "drive"]
    assert ends
    for index in ends:                         # each turn ends with the cone clear again
        after = trajectory.scans[index + 1].sector(-cone, cone)
        assert after.min_range >= 0.5
    assert not result.metrics.collided

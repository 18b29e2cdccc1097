"""GoToGoal: straight at the goal, turns in place, stops, blind to obstacles."""

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from safenav import PRESET_NAMES, InvalidConfig, InvalidScanType, Pose2D, preset, unicycle_step
from safenav.reference import GoToGoal
from safenav.synthetic import Scene, synthetic_scan, wall
from tests.scans import NAN
from tests.strategies import poses, presets

# ------------------------------------------------------------------ GoToGoal


@pytest.mark.parametrize("name", PRESET_NAMES)
def test_go_to_goal_drives_straight_at_a_goal_ahead(name):
    robot = preset(name)
    policy = GoToGoal(robot, goal=(5.0, 0.0))
    assert policy(robot.scan(), Pose2D(0.0, 0.0, 0.0)) == (robot.v_max, 0.0)
    assert policy.state == "drive" and not policy.reached and policy.distance == 5.0
    # 0.5 m from the goal the distance gain (1/s) slows it to 0.5 m/s unless v_max is lower.
    assert policy(robot.scan(), Pose2D(4.5, 0.0, 0.0)) == (pytest.approx(min(robot.v_max, 0.5)), 0.0)


@pytest.mark.parametrize(("goal", "sign"), [((-1.0, 0.5), 1.0), ((-1.0, -0.5), -1.0), ((0.0, 2.0), 1.0)])
def test_go_to_goal_turns_in_place_toward_a_goal_behind(goal, sign):
    robot = preset("rosbot")
    policy = GoToGoal(robot, goal=goal)
    v, omega = policy(robot.scan(), Pose2D())
    assert v == 0.0 and policy.state == "turn"
    assert math.copysign(1.0, omega) == sign
    assert abs(omega) == pytest.approx(min(2.0 * abs(policy.heading_error), robot.omega_max))


def test_go_to_goal_stops_within_the_stop_radius():
    robot = preset("m2wr")
    policy = GoToGoal(robot, goal=(1.0, 1.0), stop_radius=0.2)
    assert policy(robot.scan(), Pose2D(1.1, 0.9, 2.0)) == (0.0, 0.0)
    assert policy.reached and policy.state == "reached"
    assert policy(robot.scan(), Pose2D(1.3, 1.0, 0.0)) != (0.0, 0.0)
    assert not policy.reached


def test_go_to_goal_ignores_obstacles():
    robot = preset("rosbot")
    policy = GoToGoal(robot, goal=(3.0, 0.0))
    blocked = synthetic_scan(robot, Scene.of(wall(0.3)))
    assert policy(blocked, Pose2D()) == policy(robot.scan(), Pose2D()) == (robot.v_max, 0.0)


@pytest.mark.parametrize("name", PRESET_NAMES)
@pytest.mark.parametrize("start", [Pose2D(0.0, 0.0, 0.0), Pose2D(2.0, -1.0, 2.5), Pose2D(-1.5, 2.0, -1.0)])
def test_go_to_goal_reaches_the_goal_in_open_space(name, start):
    robot = preset(name)
    policy = GoToGoal(robot, goal=(1.0, 1.0))
    pose, scan = start, robot.scan()
    for _ in range(2000):
        v, omega = policy(scan, pose)
        if policy.reached:
            break
        pose = unicycle_step(pose, v, omega, 0.05)
    assert policy.reached
    assert math.hypot(pose.x - 1.0, pose.y - 1.0) <= policy.stop_radius


@given(
    presets,
    st.tuples(*[st.floats(-20, 20)] * 2),
    poses,
)
def test_go_to_goal_commands_are_within_limits_and_never_reverse(name, goal, pose):
    robot = preset(name)
    policy = GoToGoal(robot, goal=goal)
    v, omega = policy(robot.scan(), pose)
    assert 0.0 <= v <= robot.v_max
    assert abs(omega) <= robot.omega_max
    if policy.state == "drive":
        assert abs(policy.heading_error) <= math.pi / 4 and v > 0.0
    if policy.state == "turn":
        assert v == 0.0 and omega != 0.0


def test_go_to_goal_needs_a_pose_and_a_scan():
    robot = preset("rosbot")
    policy = GoToGoal(robot, goal=(1.0, 0.0))
    with pytest.raises(InvalidConfig, match="needs the robot's pose"):
        policy(robot.scan())
    with pytest.raises(InvalidConfig, match=r"GoToGoal.pose\[2\] must be a finite number, got nan"):
        policy(robot.scan(), (0.0, 0.0, NAN))
    with pytest.raises(InvalidScanType, match="GoToGoal needs a safenav LaserScan, got list"):
        policy([1.0, 2.0], Pose2D())


def test_go_to_goal_new_goal_resets_the_state():
    robot = preset("rosbot")
    policy = GoToGoal(robot, goal=(0.0, 0.0))
    policy(robot.scan(), Pose2D())
    assert policy.reached
    policy.goal = (2.0, 0.0)
    assert policy.goal == (2.0, 0.0) and policy.state == "idle" and math.isnan(policy.distance)
    with pytest.raises(InvalidConfig, match=r"GoToGoal\.goal must be a sequence of 2 finite numbers"):
        policy.goal = (1.0, 2.0, 3.0)

@pytest.mark.sim
def test_go_to_goal_reaches_a_goal_in_free_space_and_hits_an_obstacle_on_the_way():
    from safenav.episode import EpisodeConfig, run_episode
    from safenav.worlds import Cylinder, Wall, World

    robot = preset("puzzlebot")
    walls = (Wall((-1.0, -2.0), (4.0, -2.0)), Wall((-1.0, 2.0), (4.0, 2.0)))
    free = World("open", walls, start=Pose2D(0.0, 0.0, 0.5), goal=(3.0, 0.5))
    reached = run_episode(free, robot, GoToGoal(robot, free.goal), config=EpisodeConfig(duration=20.0)).metrics
    assert reached.goal_reached and not reached.collided
    blocked = free.replace(obstacles=(*walls, Cylinder((1.5, 0.25), 0.2)))
    crashed = run_episode(blocked, robot, GoToGoal(robot, blocked.goal), config=EpisodeConfig(duration=20.0)).metrics
    assert crashed.collided and not crashed.goal_reached

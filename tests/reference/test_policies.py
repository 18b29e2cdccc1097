"""The policy table (make_policy), the contract every policy keeps, and the errors of their settings."""

import math

import pytest

from safenav import Command, InvalidConfig, InvalidScanType, Pose2D, UnknownName, preset
from safenav.reference import (
    POLICY_NAMES,
    GoToGoal,
    ObstacleAvoidance,
    Policy,
    RandomWalk,
    StopAtWall,
    WallFollower,
    make_policy,
)
from tests.scans import INF, NAN

# ------------------------------------------------------------------ make_policy and the common contract

POLICY_KWARGS = {"go_to_goal": {"goal": (1.0, 0.0)}, "random_walk": {"seed": 0}}


@pytest.mark.parametrize("name", POLICY_NAMES)
def test_make_policy_builds_every_policy_for_every_robot(robot, name):
    policy = make_policy(name, robot, **POLICY_KWARGS.get(name, {}))
    expected = {"stop_at_wall": StopAtWall, "stop_at_wall_buggy": StopAtWall, "obstacle_avoidance": ObstacleAvoidance,
                "wall_follower": WallFollower, "go_to_goal": GoToGoal, "random_walk": RandomWalk}[name]
    assert type(policy) is expected and isinstance(policy, Policy)
    assert policy.robot is robot
    if name.startswith("stop_at_wall"):
        assert policy.buggy is (name == "stop_at_wall_buggy")
    if name == "stop_at_wall_buggy" and robot.lidar.n_beams <= 360:
        return  # the tutorial's bug needs beam 360 (tested above)
    command = policy(robot.scan(), Pose2D())
    assert isinstance(command, Command) and all(isinstance(x, float) and math.isfinite(x) for x in command)
    assert robot.lower[0] <= command.v <= robot.upper[0] and abs(command.omega) <= robot.omega_max
    assert isinstance(policy.state, str) and policy.state
    policy.reset(seed=1)


def test_make_policy_passes_arguments_through():
    policy = make_policy("wall_follower", preset("m2wr"), threshold=1.0, clamp=5.0)
    assert (policy.threshold, policy.clamp) == (1.0, 5.0)
    assert make_policy("random_walk", preset("rosbot"), hold_steps=4).hold_steps == 4


def test_make_policy_unknown_name_lists_the_names():
    message = ("unknown policy 'bug2'; expected one of: go_to_goal, obstacle_avoidance, random_walk, stop_at_wall, "
               "stop_at_wall_buggy, wall_follower")
    with pytest.raises(UnknownName, match=message):
        make_policy("bug2", preset("rosbot"))


def test_make_policy_needs_a_robot_spec():
    with pytest.raises(InvalidConfig, match="make_policy: robot must be a RobotSpec"):
        make_policy("stop_at_wall", "rosbot")


@pytest.mark.parametrize("policy", [StopAtWall(), ObstacleAvoidance(), WallFollower(),
                                    RandomWalk(preset("rosbot"), seed=0)],
                         ids=lambda policy: type(policy).__name__)
@pytest.mark.parametrize("scan", [None, [1.0] * 720, "scan"])
def test_policies_reject_what_is_not_a_scan(policy, scan):
    with pytest.raises(InvalidScanType, match=f"{type(policy).__name__} needs a safenav LaserScan"):
        policy(scan)


ROSBOT = preset("rosbot")
BAD_CONFIGS = [
    (lambda: StopAtWall(speed=0.0), "StopAtWall.speed must be a finite number > 0, got 0.0"),
    (lambda: StopAtWall(threshold=NAN), "StopAtWall.threshold must be a finite number > 0, got nan"),
    (lambda: StopAtWall(threshold=True), "StopAtWall.threshold must be a finite number > 0, got True"),
    (lambda: StopAtWall(front_half_width=-0.1), r"StopAtWall.front_half_width must be an angle in \[0, 1.5708\]"),
    (lambda: StopAtWall(front_index=-1), "StopAtWall.front_index must be an integer >= 0 or None, got -1"),
    (lambda: StopAtWall(front_index=360.0), "StopAtWall.front_index must be an integer >= 0 or None, got 360.0"),
    (lambda: StopAtWall(front_index=360, front_half_width=0.1), "front_half_width must be 0, got 0.1"),
    (lambda: StopAtWall(robot="rosbot"), "StopAtWall.robot must be a RobotSpec"),
    (lambda: ObstacleAvoidance(threshold=-0.5), "ObstacleAvoidance.threshold must be a finite number > 0"),
    (lambda: ObstacleAvoidance(half_angle=0.0), r"ObstacleAvoidance.half_angle must be an angle in \(0, 3.14159\]"),
    (lambda: ObstacleAvoidance(half_angle=4.0), "ObstacleAvoidance.half_angle must be an angle in .* got 4.0"),
    (lambda: ObstacleAvoidance(cruise=(0.2,)), r"ObstacleAvoidance.cruise must be a pair \(v \[m/s\]"),
    (lambda: ObstacleAvoidance(turn=(0.0, INF)), r"ObstacleAvoidance.turn\[1\] must be a finite number, got inf"),
    (lambda: ObstacleAvoidance(turn="fast"), "ObstacleAvoidance.turn must be a pair"),
    (lambda: WallFollower(clamp=1.5), "WallFollower.clamp must be > threshold=1.5"),
    (lambda: WallFollower(threshold=0), "WallFollower.threshold must be a finite number > 0, got 0"),
    (lambda: WallFollower(span=7.0), r"WallFollower.span must be an angle in \(0, 6.28319\] rad, got 7.0"),
    (lambda: WallFollower(follow_wall=(NAN, 0.0)), r"WallFollower.follow_wall\[0\] must be a finite number"),
    (lambda: GoToGoal("rosbot", (1.0, 0.0)), "GoToGoal.robot must be a RobotSpec"),
    (lambda: GoToGoal(ROSBOT, (1.0,)), "GoToGoal.goal must be a sequence of 2 finite numbers"),
    (lambda: GoToGoal(ROSBOT, (1.0, INF)), r"GoToGoal.goal\[1\] must be a finite number, got inf"),
    (lambda: GoToGoal(ROSBOT, (1.0, 0.0), speed=2.0), "GoToGoal.speed must be at most robot.v_max=1.0 m/s, got 2.0"),
    (lambda: GoToGoal(ROSBOT, (1.0, 0.0), stop_radius=0.0), "GoToGoal.stop_radius must be a finite number > 0"),
    (lambda: GoToGoal(ROSBOT, (1.0, 0.0), heading_gain=-1.0), "GoToGoal.heading_gain must be a finite number > 0"),
    (lambda: GoToGoal(ROSBOT, (1.0, 0.0), turn_in_place_angle=2.0), "GoToGoal.turn_in_place_angle must be an angle"),
    (lambda: RandomWalk(ROSBOT, hold_steps=0), "RandomWalk.hold_steps must be an integer >= 1, got 0"),
    (lambda: RandomWalk(ROSBOT, hold_steps=2.5), "RandomWalk.hold_steps must be an integer >= 1, got 2.5"),
    (lambda: RandomWalk(ROSBOT, forward_only=1), "RandomWalk.forward_only must be True or False, got 1"),
    (lambda: RandomWalk(ROSBOT, seed=-3), "RandomWalk seed must be None or a non-negative integer, got -3"),
    (lambda: RandomWalk(None), "RandomWalk.robot must be a RobotSpec"),
]


@pytest.mark.parametrize(("build", "message"), BAD_CONFIGS)
def test_bad_configs_name_the_value(build, message):
    with pytest.raises(InvalidConfig, match=message) as info:
        build()
    assert isinstance(info.value, ValueError)

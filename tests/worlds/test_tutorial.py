"""The three tutorial worlds: each one's robot, start and geometry, and its seeded start jitter."""

import math

import pytest

from safenav import UnknownName, preset
from safenav.synthetic import synthetic_scan
from safenav.worlds import TUTORIAL_WORLDS, TUTORIALS, WALL_THICKNESS, reachable, tutorial_world


@pytest.mark.parametrize("name", TUTORIAL_WORLDS)
def test_tutorial_worlds_start_collision_free_for_their_robot(name):
    world = tutorial_world(name)
    robot = preset(TUTORIALS[name].robot)
    assert world.name == name
    assert world.clearance(world.start, robot.radius) > 0.3


def test_stop_at_wall_has_the_wall_three_metres_ahead_and_nothing_else():
    robot = preset("rosbot")
    scan = synthetic_scan(robot, tutorial_world("stop_at_wall").scene(), tutorial_world("stop_at_wall").start)
    assert scan.ranges[scan.beam_index(0.0)] == pytest.approx(3.0)
    assert scan.ranges[scan.beam_index(math.pi / 2)] == math.inf
    assert scan.ranges[scan.beam_index(math.pi)] == math.inf


def test_obstacle_avoidance_start_faces_the_middle_post():
    world = tutorial_world("obstacle_avoidance")
    scan = synthetic_scan(preset("puzzlebot"), world.scene(), world.start)
    assert scan.ranges[scan.beam_index(0.0)] == pytest.approx(math.hypot(2.2, 2.2) - 0.35)
    assert {type(o).__name__ for o in world.obstacles} == {"Wall", "Box", "Cylinder"}


def test_wall_follower_starts_with_the_wall_on_the_right_and_has_corners_both_ways():
    world = tutorial_world("wall_follower")
    robot = preset("m2wr")
    scan = synthetic_scan(robot, world.scene(), world.start)
    assert scan.ranges[scan.beam_index(-math.pi / 2)] == pytest.approx(0.8 - 0.5 * WALL_THICKNESS, abs=1e-6)
    # The L-shaped room: the room wraps three quadrants round the outside corner (5, 5) and one
    # round the inside corners such as (10, 0); the cut-away quarter is outside the room.
    def inside_quadrants(x: float, y: float) -> int:
        return sum(reachable(world, 0.05, world.start, (x + dx, y + dy))
                   for dx, dy in ((0.3, 0.3), (-0.3, 0.3), (-0.3, -0.3), (0.3, -0.3)))

    assert inside_quadrants(5.0, 5.0) == 3
    assert inside_quadrants(10.0, 0.0) == inside_quadrants(0.0, 10.0) == inside_quadrants(10.0, 5.0) == 1
    assert not reachable(world, robot.radius, world.start, (7.5, 7.5))
    assert reachable(world, robot.radius, world.start, (1.0, 9.0))


def test_unknown_tutorial_world_lists_the_names():
    with pytest.raises(UnknownName, match="obstacle_avoidance, stop_at_wall, wall_follower"):
        tutorial_world("maze")


@pytest.mark.parametrize("name", TUTORIAL_WORLDS)
def test_a_seed_jitters_the_start_within_the_tutorials_bounds(name):
    tutorial = TUTORIALS[name]
    built = tutorial.world().start
    position, heading = tutorial.start_jitter
    starts = [tutorial.world(seed).start for seed in range(20)]
    assert len(set(starts)) == 20 and tutorial.world(3) == tutorial.world(3)
    for start in starts:
        assert abs(start.x - built.x) <= position and abs(start.y - built.y) <= position
        assert abs(start.yaw - built.yaw) <= heading
    assert tutorial.world(3).obstacles == tutorial.world().obstacles   # only the start moves


def test_the_tutorial_table_is_read_only_and_names_robots_and_policies_that_exist():
    from safenav.reference import POLICY_NAMES
    from safenav.robot import PRESET_NAMES

    assert TUTORIAL_WORLDS == tuple(TUTORIALS) == ("stop_at_wall", "obstacle_avoidance", "wall_follower")
    assert [t.robot for t in TUTORIALS.values()] == list(PRESET_NAMES)
    assert all({t.policy, t.published_policy} <= set(POLICY_NAMES) for t in TUTORIALS.values())
    assert TUTORIALS["stop_at_wall"].published_policy == "stop_at_wall_buggy"
    with pytest.raises(TypeError):
        TUTORIALS["maze"] = TUTORIALS["stop_at_wall"]

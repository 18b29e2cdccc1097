"""Seeded random arenas: same seed same world, gaps kept, reachable goals through narrow doors."""

import math

import numpy as np
import pytest

from safenav import InvalidConfig, preset
from safenav.synthetic import Scene, cast
from safenav.worlds import START_CLEARANCE, Box, Cylinder, Wall, World, gap, random_world, reachable, tutorial_world


def test_same_seed_same_world_and_different_seeds_differ():
    robot = preset("rosbot")
    assert random_world(11, robot, corridors=1, goal=True) == random_world(11, robot, corridors=1, goal=True)
    worlds = [random_world(seed, robot) for seed in range(4)]
    assert len({w.obstacles for w in worlds}) == 4
    assert len({w.start for w in worlds}) == 4


@pytest.mark.parametrize("robot_name", ["rosbot", "puzzlebot", "m2wr"])
def test_random_worlds_start_collision_free_and_keep_the_gap(robot_name):
    robot = preset(robot_name)
    for seed in range(6):
        world = random_world(seed, robot)
        assert world.clearance(world.start, robot.radius) >= START_CLEARANCE - 1e-9
        walls = [o for o in world.obstacles if isinstance(o, Wall)]
        free = [o for o in world.obstacles if not isinstance(o, Wall)]
        assert len(walls) == 4 and len(free) == 30
        assert {type(o) for o in free} == {Box, Cylinder}
        min_gap = 2 * robot.radius + 0.1
        for i, a in enumerate(free):
            for b in free[i + 1:] + walls:
                assert gap(a, b) >= min_gap - 1e-9


def test_random_world_arena_interior_has_the_requested_size():
    world = random_world(0, preset("puzzlebot"), n_obstacles=0, size=(6.0, 4.0))
    inside = np.array([[-2.99, -1.99], [2.99, 1.99], [0.0, 0.0]])
    outside = np.array([[-3.01, 0.0], [0.0, 2.01]])
    assert np.all(world.signed_distance(inside) > 0)
    assert np.all(world.signed_distance(outside) < 0)


def test_goal_is_clear_far_and_reachable_through_narrow_passages():
    robot = preset("rosbot")
    for seed in range(3):
        world = random_world(seed, robot, corridors=1, narrow_passages=2, goal=True)
        assert world.goal is not None
        assert world.clearance(world.goal, robot.radius) >= START_CLEARANCE - 1e-9
        assert math.dist(world.start[:2], world.goal) >= 5.0
        assert reachable(world, robot.radius, world.start, world.goal)
        walls = [o for o in world.obstacles if isinstance(o, Wall)]
        assert len(walls) == 4 + 2 * 2 + 2   # arena, two dividers in two pieces each, one corridor
        # Dividers: start and goal on either side; each door a little wider than the robot.
        for low, high in (walls[4:6], walls[6:8]):
            divider_x = low.start[0]
            assert (world.start.x - divider_x) * (world.goal[0] - divider_x) < 0
            assert 2 * robot.radius + 0.12 - 1e-9 <= gap(low, high) <= 2 * robot.radius + 0.3 + 1e-9
        # The corridor: two parallel walls a little more than the robot apart.
        first, second = walls[8:10]
        assert 2 * robot.radius + 0.25 - 1e-9 <= gap(first, second) <= 2 * robot.radius + 0.5 + 1e-9
        # Closing every door makes the goal unreachable: the check is not vacuous.
        closed = world.replace(obstacles=world.obstacles + tuple(
            Wall((low.start[0], -5.0), (low.start[0], 5.0)) for low in walls[4:8:2]))
        assert not reachable(closed, robot.radius, world.start, world.goal)


def test_an_enclosed_goal_is_not_reachable():
    room = World("room", (Wall((2, -1), (2, 1)), Wall((2, 1), (4, 1)), Wall((4, 1), (4, -1)), Wall((4, -1), (2, -1))),
                 bounds=(-1.0, -2.0, 5.0, 2.0))
    assert not reachable(room, 0.2, (0.0, 0.0), (3.0, 0.0))
    assert reachable(room, 0.2, (0.0, 0.0), (0.0, 1.5))


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"seed": -1}, "seed"),
        ({"seed": 1.5}, "seed"),
        ({"n_obstacles": -1}, "n_obstacles"),
        ({"size": (0.5, 10.0)}, "size"),
        ({"min_gap": -0.1}, "min_gap"),
        ({"obstacle_size": (0.5, 0.2)}, "obstacle_size"),
        ({"narrow_passages": 9}, "narrow passages"),
        ({"n_obstacles": 200}, "could not place obstacle"),
        ({"robot": "rosbot"}, "RobotSpec"),
    ],
)
def test_random_world_rejects_bad_arguments(kwargs, message):
    arguments = {"seed": 0, "robot": preset("rosbot")} | kwargs
    seed, robot = arguments.pop("seed"), arguments.pop("robot")
    with pytest.raises(InvalidConfig, match=message):
        random_world(seed, robot, max_tries=200, **arguments)


def test_scene_cast_agrees_with_world_geometry_along_a_ray():
    world = tutorial_world("obstacle_avoidance")
    ranges = cast((world.start.x, world.start.y), np.array([world.start.yaw]), world.scene())
    hit = np.array([[world.start.x, world.start.y]]) + ranges[0] * np.array([[math.cos(world.start.yaw),
                                                                              math.sin(world.start.yaw)]])
    assert world.signed_distance(hit)[0] == pytest.approx(0.0, abs=1e-9)
    assert isinstance(world.scene(), Scene)

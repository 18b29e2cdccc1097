"""Seeded random arenas: same seed same world, gaps kept, reachable goals through narrow doors."""

import math

import numpy as np
import pytest

from safenav import InvalidConfig, preset
from safenav.seeding import generator
from safenav.synthetic import Scene, cast
from safenav.worlds import (
    START_CLEARANCE,
    WALL_THICKNESS,
    Box,
    Cylinder,
    Wall,
    World,
    gap,
    random_world,
    reachable,
    tutorial_world,
)
from safenav.worlds.generator import dead_end_world, door_world


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


# ------------------------------------------------------------------------------------- door and dead end


@pytest.mark.parametrize("robot_name", ["rosbot", "puzzlebot", "m2wr"])
def test_door_world_has_one_door_of_the_exact_width_start_in_front_goal_behind(robot_name):
    robot = preset(robot_name)
    door_width = 2 * robot.radius + 0.13
    for seed in range(8):
        world = door_world(seed, robot, door_width)
        walls = [o for o in world.obstacles if isinstance(o, Wall)]
        assert len(walls) == 6    # the room, and the divider in two pieces
        low, high = walls[4:]
        assert gap(low, high) == pytest.approx(door_width, abs=1e-12)
        # The door is the only way through: on the divider's line, free only between the jambs.
        line = np.column_stack((np.zeros(5001), np.linspace(-2.5, 2.5, 5001)))
        free = line[world.signed_distance(line) > 0.0]
        assert free[:, 1].min() == pytest.approx(-door_width / 2, abs=0.0015)
        assert free[:, 1].max() == pytest.approx(door_width / 2, abs=0.0015)
        assert world.start.x < -robot.radius - 0.05 < 0.05 + robot.radius < world.goal[0]
        assert world.clearance(world.start, robot.radius) >= START_CLEARANCE
        assert world.clearance(world.goal, robot.radius) >= START_CLEARANCE
        assert reachable(world, robot.radius, world.start, world.goal)


@pytest.mark.parametrize("robot_name", ["rosbot", "puzzlebot", "m2wr"])
def test_dead_end_traps_the_straight_line_from_start_to_goal(robot_name):
    robot = preset(robot_name)
    for seed in range(8):
        world = dead_end_world(seed, robot, depth=1.2)
        walls = [o for o in world.obstacles if isinstance(o, Wall)]
        top, back, bottom = walls[4:]
        mouth_width = 4 * robot.radius + 0.4
        assert gap(top, bottom) == pytest.approx(mouth_width, abs=1e-12)
        # The pocket is free and open towards the start; its closed end faces the goal.
        pocket = np.array([[x, y] for x in np.linspace(-0.59, 0.59, 13)
                           for y in np.linspace(-mouth_width / 2 + 0.01, mouth_width / 2 - 0.01, 7)])
        assert np.all(world.signed_distance(pocket) > 0.0)
        assert world.signed_distance(np.array([[0.61, 0.0]]))[0] < 0.0
        # The straight line from the start to the goal enters the mouth and hits the closed end.
        line = np.linspace(world.start[:2], world.goal, 2001)
        blocked = line[world.signed_distance(line) < 0.0]
        assert blocked.size and np.all(np.abs(blocked[:, 0] - back.start[0]) <= 0.5 * WALL_THICKNESS + 1e-9)
        assert world.start.x < -0.6 - robot.radius and world.goal[0] > 0.7 + robot.radius
        assert world.clearance(world.start, robot.radius) >= START_CLEARANCE
        assert world.clearance(world.goal, robot.radius) >= START_CLEARANCE
        assert reachable(world, robot.radius, world.start, world.goal)


@pytest.mark.parametrize("build", [lambda seed, robot: door_world(seed, robot, 0.5), dead_end_world])
def test_door_and_dead_end_draw_start_and_goal_from_the_seed(build):
    robot = preset("rosbot")
    assert build(5, robot) == build(5, robot)
    worlds = [build(seed, robot) for seed in range(5)]
    assert len({w.start for w in worlds}) == 5 and len({w.goal for w in worlds}) == 5
    assert len({w.obstacles for w in worlds}) == 1      # the seed moves the start and the goal only
    rng = generator(5, "world")                          # drawn from the seed's world stream, start first
    assert build(5, robot).start.x == pytest.approx(rng.uniform(*((-2.3, -1.0) if worlds[0].name.startswith("door")
                                                                  else (-3.2, -2.0))))


@pytest.mark.parametrize(("call", "message"), [
    (lambda robot: door_world(0, robot, 0.3), r"door_world: door_width must be .*> 0.31.*got 0.3"),
    (lambda robot: door_world(0, robot, 4.5), r"door_world: door_width must be .*<= 4.*got 4.5"),
    (lambda robot: door_world(0, robot, 0.5, size=(3.0, 5.0)), r"door_world: size must be at least \(4, 2\) m"),
    (lambda robot: door_world(-1, robot, 0.5), r"door_world: seed must be an integer >= 0, got -1"),
    (lambda robot: door_world(0, "rosbot", 0.5), r"door_world: robot must be a RobotSpec, got 'rosbot'"),
    (lambda robot: dead_end_world(0, robot, mouth_width=0.2), r"dead_end_world: mouth_width must be .*got 0.2"),
    (lambda robot: dead_end_world(0, robot, depth=0.0), r"dead_end_world: depth must be .*got 0.0"),
    (lambda robot: dead_end_world(0, robot, size=(8.0, 3.0)), r"dead_end_world: size must be at least \(6, 4\) m"),
])
def test_door_and_dead_end_reject_bad_arguments(call, message):
    with pytest.raises(InvalidConfig, match=message):
        call(preset("rosbot"))

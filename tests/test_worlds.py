import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from safenav import InvalidConfig, Pose2D, UnknownName, preset
from safenav.synthetic import Scene, cast, synthetic_scan
from safenav.worlds import (
    START_CLEARANCE,
    TUTORIAL_PRESETS,
    TUTORIAL_WORLDS,
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

# ---------------------------------------------------------------------------------------------- shapes


def test_box_signed_distance_outside_inside_and_at_a_corner():
    box = Box((1.0, 2.0), (2.0, 1.0), yaw=math.pi / 2)   # 1 m along x, 2 m along y once turned
    points = np.array([[1.0, 2.0], [2.5, 2.0], [1.0, 4.0], [2.5, 4.0], [1.2, 2.0]])
    expected = [-0.5, 1.0, 1.0, math.hypot(1.0, 1.0), -0.3]
    assert box.signed_distance(points) == pytest.approx(expected)


def test_cylinder_polygon_contains_the_circle_within_the_tolerance():
    cylinder = Cylinder((0.5, -0.2), 0.4)
    for tolerance in (0.0005, 0.001, 0.005):
        polygon = cylinder.polygon(tolerance)
        radii = np.hypot(*(polygon - cylinder.center).T)
        midpoints = 0.5 * (polygon + np.roll(polygon, -1, axis=0))
        assert np.all(radii <= cylinder.radius + tolerance + 1e-12)
        # Edge midpoints touch the circle: the polygon contains the disk.
        assert np.hypot(*(midpoints - cylinder.center).T) == pytest.approx(cylinder.radius)
    assert len(cylinder.polygon(0.0005)) > len(cylinder.polygon(0.005)) >= 12


def test_walls_are_squared_off_so_corners_close():
    a, b = Wall((0.0, 0.0), (2.0, 0.0)), Wall((0.0, 0.0), (0.0, 2.0))
    assert a.box.size == pytest.approx((2.0 + WALL_THICKNESS, WALL_THICKNESS))
    corner = np.array([[-0.045, -0.045]])   # outside both centre lines, inside both caps
    assert a.signed_distance(corner)[0] < 0 and b.signed_distance(corner)[0] < 0
    assert gap(a, b) < 0


@pytest.mark.parametrize(
    ("a", "b", "expected"),
    [
        (Box((0, 0), (1, 1)), Box((2, 0), (1, 1)), 1.0),
        (Box((0, 0), (1, 1)), Box((2.5, 2.5), (1, 1)), math.hypot(1.5, 1.5)),
        (Box((0, 0), (1, 1)), Box((0, 1.5 + math.sqrt(0.5)), (1, 1), yaw=math.pi / 4), 1.0),   # corner to face
        (Cylinder((0, 0), 0.5), Cylinder((3, 4), 1.0), 3.5),
        (Cylinder((0, 3), 0.5), Box((0, 0), (2, 2)), 1.5),
        (Wall((0, 0), (4, 0), 0.2), Cylinder((2, 1.1), 0.5), 0.5),
        (Box((0, 0), (2, 2)), Box((1.5, 0), (2, 2)), -0.5),
        (Box((0, 0), (4, 0.2)), Box((0, 0), (0.2, 4)), -0.2),   # a cross: no corner inside the other
        (Cylinder((0, 0), 1.0), Cylinder((1.5, 0), 1.0), -0.5),
    ],
)
def test_gap_between_shapes(a, b, expected):
    assert gap(a, b) == pytest.approx(expected)
    assert gap(b, a) == pytest.approx(expected)


def _outline(obstacle, n=600):
    """Points on the outline of an obstacle, dense enough for a brute-force distance."""
    polygon = obstacle.polygon(1e-5) if isinstance(obstacle, Cylinder) else obstacle.polygon()
    edges = np.roll(polygon, -1, axis=0) - polygon
    t = np.linspace(0.0, 1.0, n // len(polygon), endpoint=False)
    return (polygon[:, None, :] + t[None, :, None] * edges[:, None, :]).reshape(-1, 2)


shapes = st.one_of(
    st.builds(Box, st.tuples(st.floats(-3, 3), st.floats(-3, 3)), st.tuples(st.floats(0.1, 2), st.floats(0.1, 2)),
              st.floats(0, math.pi)),
    st.builds(Cylinder, st.tuples(st.floats(-3, 3), st.floats(-3, 3)), st.floats(0.05, 1.0)),
)


@given(shapes, shapes)
def test_gap_matches_a_brute_force_distance_between_outlines(a, b):
    result = gap(a, b)
    outline_a, outline_b = _outline(a), _outline(b)
    if result > 0:
        brute = np.min(np.hypot(*(outline_a[:, None, :] - outline_b[None, :, :]).T))
        assert result == pytest.approx(brute, abs=0.02)
        assert np.all(b.signed_distance(outline_a) > -1e-9) and np.all(a.signed_distance(outline_b) > -1e-9)
    elif result < -1e-3:
        low = np.maximum(outline_a.min(axis=0), outline_b.min(axis=0))
        high = np.minimum(outline_a.max(axis=0), outline_b.max(axis=0))
        grid = np.stack(np.meshgrid(*(np.linspace(low[k], high[k], 101) for k in range(2))), axis=-1).reshape(-1, 2)
        assert np.min(np.maximum(a.signed_distance(grid), b.signed_distance(grid))) < 0   # a common point


@pytest.mark.parametrize(
    ("call", "message"),
    [
        (lambda: Box((0, 0), (0, 1)), "Box.size"),
        (lambda: Box((0, math.nan), (1, 1)), "Box.center"),
        (lambda: Box("ab", (1, 1)), "Box.center"),
        (lambda: Cylinder((0, 0), -1.0), "Cylinder.radius"),
        (lambda: Wall((1, 1), (1, 1)), "must differ"),
        (lambda: Wall((0, 0), (1, 0), thickness=0), "Wall.thickness"),
        (lambda: World("w", ("wall",)), "World.obstacles"),
        (lambda: World("w", (), start=(0, 0)), "World.start"),
        (lambda: World("w", (), bounds=(0, 0, -1, 1)), "World.bounds"),
        (lambda: World("w", (), obstacle_height=0.0), "World.obstacle_height"),
        (lambda: Cylinder((0, 0), 1.0).polygon(0.0), "tolerance"),
    ],
)
def test_bad_geometry_is_rejected_with_a_message(call, message):
    with pytest.raises(InvalidConfig, match=message):
        call()


# ---------------------------------------------------------------------------------------------- world


def test_world_clearance_is_signed_and_exact():
    world = World("w", (Box((0.0, 0.0), (2.0, 2.0)), Cylinder((5.0, 0.0), 1.0)))
    assert world.clearance(Pose2D(3.0, 0.0, 1.0), 0.2) == pytest.approx(0.8)   # 1 m to either, minus the radius
    assert world.clearance((0.0, 0.0), 0.1) == pytest.approx(-1.1)           # deep inside the box
    assert world.clearance((5.0, 1.3), 0.1) == pytest.approx(0.2)
    assert World("empty", ()).clearance((0.0, 0.0), 0.3) == math.inf


def test_world_scene_is_the_same_geometry():
    world = random_world(4, preset("rosbot"), corridors=1)
    scene = world.scene()
    points = np.random.default_rng(0).uniform(-5.0, 5.0, size=(300, 2))
    signed = world.signed_distance(points)
    assert np.any(signed < 0) and np.any(signed > 0)
    # The scene's distance is unsigned to segments (box sides) and signed to circles.
    from_scene = np.array([scene.clearance(p, 0.0) for p in points])
    assert np.abs(from_scene) == pytest.approx(np.abs(signed), abs=1e-9)


def test_world_default_bounds_hold_everything():
    world = World("w", (Wall((0, 0), (4, 0)), Cylinder((2, 3), 0.5)), start=Pose2D(1, 1, 0), goal=(6.0, 1.0))
    xmin, ymin, xmax, ymax = world.bounds
    assert xmin <= -0.05 and ymin <= -0.05 and xmax >= 6.0 and ymax >= 3.5
    assert world.replace(goal=None).goal is None


# ---------------------------------------------------------------------------------------------- tutorials


@pytest.mark.parametrize("name", TUTORIAL_WORLDS)
def test_tutorial_worlds_start_collision_free_for_their_robot(name):
    world = tutorial_world(name)
    robot = preset(TUTORIAL_PRESETS[name])
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


# ---------------------------------------------------------------------------------------------- random


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

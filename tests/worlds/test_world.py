"""World: exact signed clearance, the analytic scene, bounds, the simulator's mesh."""

import math

import numpy as np
import pytest

from safenav import Pose2D, preset
from safenav.worlds import Box, Cylinder, Wall, World, obstacle_mesh, random_world


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

def test_obstacle_mesh_is_closed_prisms_of_the_world():
    world = World("w", (Box((0, 0), (1, 2)), Cylinder((3, 0), 0.5), Wall((0, 3), (2, 3))), obstacle_height=0.4)
    vertices, triangles = obstacle_mesh(world, tolerance=0.002, caps=True)
    sides, _ = obstacle_mesh(world, tolerance=0.002)
    n_cylinder = len(Cylinder((3, 0), 0.5).polygon(0.002))
    assert len(vertices) == len(sides) == 2 * (4 + n_cylinder + 4)
    assert len(triangles) == 2 * (4 + n_cylinder + 4) + 2 * (2 + (n_cylinder - 2) + 2)
    assert set(np.unique(vertices[:, 2])) == {0.0, 0.4}
    assert triangles.min() == 0 and triangles.max() == len(vertices) - 1
    edges = np.sort(np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]]), axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    assert np.all(counts == 2)   # watertight: every edge is shared by two triangles


# ------------------------------------------------------------------ the footprint's clearance

M2WR_BOX = np.array([(0.25, 0.15), (-0.25, 0.15), (-0.25, -0.15), (0.25, -0.15)])


@pytest.mark.parametrize("yaw, expected", [(0.0, 0.75), (0.5 * np.pi, 0.85), (np.pi, 0.75),
                                           (0.25 * np.pi, 1.0 - 0.4 * np.cos(0.25 * np.pi))])
def test_a_footprint_facing_a_wall_keeps_the_distance_of_its_farthest_corner_along_the_normal(yaw, expected):
    world = World("wall", (Box((1.5, 0.0), (1.0, 4.0)),))                # the near face at x = 1
    assert world.footprint_clearance(np.array([[0.0, 0.0, yaw]]), M2WR_BOX)[0] == pytest.approx(expected, abs=1e-12)
    assert world.footprint_clearance(np.array([[0.0, 0.0, yaw]]), M2WR_BOX[::-1])[0] == pytest.approx(expected)


@pytest.mark.parametrize("obstacle, pose, expected", [
    (Cylinder((1.0, 0.0), 0.1), (0.0, 0.0, 0.0), 0.65),                  # ahead of the front side
    (Cylinder((1.0, 0.0), 0.1), (0.0, 0.0, 0.5 * np.pi), 0.75),          # beside the long side
    (Cylinder((0.45, 0.35), 0.1), (0.0, 0.0, 0.0), np.hypot(0.2, 0.2) - 0.1),   # off the corner
    (Cylinder((0.1, 0.0), 0.05), (0.0, 0.0, 0.0), -0.2),                 # the centre 0.15 m inside: depth + radius
    (Box((0.7, 0.0), (1.0, 4.0)), (0.0, 0.0, 0.0), -0.05),               # the front 5 cm into a wall
    # a post inside the body turned by 0.3 rad: out across the short side, its half-width and the post's reach
    (Box((0.0, 0.0), (0.1, 0.1)), (0.0, 0.0, 0.3), -0.15 - 0.05 * (np.cos(0.3) + np.sin(0.3))),
])
def test_footprint_clearance_is_exact_apart_and_minus_the_penetration_depth_in_overlap(obstacle, pose, expected):
    world = World("one", (obstacle,))
    assert world.footprint_clearance(np.array([pose]), M2WR_BOX)[0] == pytest.approx(expected, abs=1e-12)


def _footprint_worlds(n_seeds: int):
    """``(robot, footprint, world)`` for the presets with a footprint and ``n_seeds`` random worlds each."""
    for name in ("m2wr", "rosbot"):
        robot = preset(name)
        for seed in range(n_seeds):
            yield robot, np.asarray(robot.footprint), random_world(seed=seed, robot=robot)


def test_footprint_clearance_of_a_period_is_the_minimum_over_every_obstacle_alone():
    """The simulator asks for a period's five poses at once, and only the obstacles that can be the nearest are
    evaluated (circumscribed circles): the values are those of every obstacle evaluated alone, bit for bit,
    apart and overlapping."""
    from safenav.worlds.shapes import box_sides, placed_polygons, polygon_gaps

    rng = np.random.default_rng(5)
    for _robot, footprint, world in _footprint_worlds(2):
        boxes, circles = world._boxes, world._circles
        overlapping = 0
        for _ in range(150):
            start = np.array([*rng.uniform(-5.0, 5.0, 2), rng.uniform(-np.pi, np.pi)])
            poses = start + np.cumsum(rng.uniform(-0.02, 0.02, (5, 3)), axis=0)
            polygons = placed_polygons(poses, footprint)
            alone = [polygon_gaps(polygons, box_sides(boxes[k:k + 1]), np.empty((0, 3))) for k in range(len(boxes))]
            alone += [polygon_gaps(polygons, box_sides(np.empty((0, 6))), circles[k:k + 1])
                      for k in range(len(circles))]
            expected = np.min(alone, axis=0)
            np.testing.assert_array_equal(world.footprint_clearance(poses, footprint), expected)
            overlapping += int(np.any(expected < 0.0))
        assert overlapping > 5


@pytest.mark.parametrize("parametrised", [False, True])
def test_the_compiled_footprint_clearance_is_the_numpy_one(parametrised):
    """``COMPILED_GAPS`` (numba, loops over every obstacle, no pruning) against the numpy reference on random
    five-pose periods in random worlds of both presets with a footprint, overlaps included, and on worlds of
    boxes only, of cylinders only and without obstacles: the same values to 1e-12 (bit for bit, as measured)."""
    pytest.importorskip("numba", reason="the compiled kernels need numba (pip install 'safenav[fast]')")
    from safenav.worlds.shapes import COMPILED_GAPS

    compiled = COMPILED_GAPS.load()
    rng = np.random.default_rng(7 if parametrised else 8)
    overlapping = 0
    for _robot, footprint, world in _footprint_worlds(3):
        worlds = [world]
        if parametrised:
            worlds += [World("boxes", tuple(o for o in world.obstacles if not isinstance(o, Cylinder))),
                       World("cylinders", tuple(o for o in world.obstacles if isinstance(o, Cylinder))),
                       World("empty", ())]
        for each in worlds:
            for _ in range(100):
                start = np.array([*rng.uniform(-5.0, 5.0, 2), rng.uniform(-np.pi, np.pi)])
                poses = start + np.cumsum(rng.uniform(-0.05, 0.05, (5, 3)), axis=0)
                reference = each.footprint_clearance(poses, footprint)
                fast = each.footprint_clearance(poses, footprint, compiled)
                np.testing.assert_allclose(fast, reference, rtol=0.0, atol=1e-12)
                overlapping += int(np.any(reference < 0.0))
    assert overlapping > 10


def test_the_compiled_signed_distance_is_the_numpy_one():
    """The disk truth's compiled distance (``COMPILED_GAPS.signed_distance``) gives ``World.signed_distance``'s
    values bit for bit: random points in and around random worlds (inside boxes and cylinders, on their
    outlines, far away), worlds of boxes only, of cylinders only and without obstacles; and
    ``World.clearance`` likewise."""
    pytest.importorskip("numba", reason="the compiled kernels need numba (pip install 'safenav[fast]')")
    from safenav.worlds.shapes import COMPILED_GAPS

    compiled = COMPILED_GAPS.load()
    rng = np.random.default_rng(9)
    inside = 0
    for _robot, _footprint, world in _footprint_worlds(3):
        for each in (world, World("boxes", tuple(o for o in world.obstacles if not isinstance(o, Cylinder))),
                     World("cylinders", tuple(o for o in world.obstacles if isinstance(o, Cylinder))),
                     World("empty", ())):
            points = np.vstack((rng.uniform(-6.0, 6.0, (2000, 2)), rng.uniform(-40.0, 40.0, (50, 2)),
                                np.round(rng.uniform(-6.0, 6.0, (200, 2)), 1)))
            reference = each.signed_distance(points)
            np.testing.assert_array_equal(each.signed_distance(points, compiled), reference)
            for point in points[:50]:
                assert each.clearance(point, 0.2, compiled) == each.clearance(point, 0.2)
            inside += int(np.count_nonzero(reference < 0.0))
    assert inside > 500


def test_footprint_clearance_agrees_with_the_falsifiers_and_is_never_below_the_disks():
    """An independent implementation (the falsifier's, on the world's outlines as segments and circles) gives
    the same distance wherever both see the footprint apart; the footprint, inside its disk, is never nearer."""
    from benchmarks.falsify import _footprint_clearances

    rng = np.random.default_rng(11)
    for robot, footprint, world in _footprint_worlds(3):
        poses = np.column_stack((rng.uniform(-5.0, 5.0, (1500, 2)), rng.uniform(-np.pi, np.pi, 1500)))
        ours = world.footprint_clearance(poses, footprint)
        theirs = _footprint_clearances(world.scene(), poses, footprint)
        apart = (ours > 0.0) & (theirs > 0.0)
        assert apart.sum() > 900
        np.testing.assert_allclose(ours[apart], theirs[apart], atol=1e-12)
        assert not np.any((ours > 0.0) & (theirs <= 0.0))
        assert np.all(ours >= world.signed_distance(poses[:, :2]) - robot.radius - 1e-12)


@pytest.mark.parametrize("name", ["rosbot", "puzzlebot", "m2wr"])
def test_ray_reach_is_where_each_ray_first_meets_an_obstacle(name):
    """``World.ray_reach`` (the compiled kernel that shortens the simulator's rays) against the analytic ray caster
    of :mod:`safenav.synthetic` on the same exact boxes and circles: in random worlds, from random poses (a full
    turn, the ROSbot's backward mount, the m2wr's half turn), every beam that meets something reaches exactly 1 cm
    past it, every other beam its full length; from inside an obstacle every beam its full length."""
    pytest.importorskip("numba", reason="the compiled kernels need numba (pip install 'safenav[fast]')")
    from safenav.synthetic import cast
    from safenav.worlds.shapes import COMPILED_GAPS, RayFan

    robot = preset(name)
    lidar = robot.lidar
    angles = lidar.scan().angles + lidar.mount.yaw
    lengths = np.full(lidar.n_beams, lidar.range_max)
    rays = RayFan(np.array([[lidar.mount.x, lidar.mount.y, angles[0]]]), np.array([lidar.angle_increment]),
                  np.array([lidar.n_beams], dtype=np.intp), np.column_stack((np.cos(angles), np.sin(angles))), lengths)
    compiled = COMPILED_GAPS.load()
    rng = np.random.default_rng(7)
    hits = inside = 0
    for seed in range(4):
        world = random_world(seed, robot, n_obstacles=30)
        xmin, ymin, xmax, ymax = world.bounds
        for _ in range(100):
            pose = Pose2D(rng.uniform(xmin, xmax), rng.uniform(ymin, ymax), rng.uniform(-math.pi, math.pi))
            reach = world.ray_reach(pose, rays, compiled, slack=0.01)
            sensor = pose.compose(lidar.mount)
            if world.signed_distance(np.array([[sensor.x, sensor.y]]))[0] <= 0.0:
                np.testing.assert_array_equal(reach, lengths)
                inside += 1
                continue
            exact = cast((sensor.x, sensor.y), lidar.scan().angles + sensor.yaw, world.scene())
            meets = exact + 0.01 < lengths
            np.testing.assert_allclose(reach[meets], exact[meets] + 0.01, rtol=0.0, atol=1e-9)
            np.testing.assert_array_equal(reach[~meets], lengths[~meets])
            hits += int(meets.sum())
    assert hits > 10000 and inside > 5

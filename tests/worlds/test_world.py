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

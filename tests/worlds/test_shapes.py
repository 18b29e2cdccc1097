"""Boxes, cylinders and walls: exact signed distances, outlines, gaps between shapes, bad values."""

import math

import numpy as np
import pytest
from hypothesis import given

from safenav import InvalidConfig
from safenav.worlds import WALL_THICKNESS, Box, Cylinder, Wall, World, gap
from tests.strategies import shapes


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

"""Body models: the disk, the exact footprint polygon and the disk cover; their clearances and outlines."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from benchmarks.falsify import Episode, _thick, run
from safenav import InvalidConfig, LidarSpec, RobotSpec, preset
from safenav.filters import CBFSafetyFilter, make_filter
from safenav.filters.body import BodyModel, inside_polygon, polygon_distance
from safenav.filters.perception import _exit_ranges, obstacle_beams
from safenav.synthetic import Scene, synthetic_scan, wall


def test_a_box_robot_beside_a_wall_has_the_polygon_s_clearance():
    m2wr = preset("m2wr")                                   # 0.50 x 0.30 m, circumscribed radius 0.29 m
    scene = Scene.of(wall(0.25, math.pi / 2))               # a wall 0.25 m to the left of the base origin
    scan = synthetic_scan(m2wr, scene)
    points = scan.points()
    assert BodyModel.polygon(m2wr).clearance(points) == pytest.approx(0.25 - 0.15, abs=1e-6)
    # The nearest wall point the forward 180-degree lidar sees is beside its own plane, (0.15, 0.25):
    assert BodyModel.disk(m2wr).clearance(points) == pytest.approx(math.hypot(0.15, 0.25) - m2wr.radius, abs=1e-4)
    result = CBFSafetyFilter(m2wr, 0.05, body="polygon").filter((0.5, 0.0), scan)
    assert result.clearance == pytest.approx(0.10, abs=1e-6) and result.status.value == "ok"


def test_the_disk_and_polygon_models_agree_for_a_round_robot():
    round_robot = preset("puzzlebot")                       # no footprint: every model is its disk
    assert BodyModel.polygon(round_robot).name == "disk" and BodyModel.cover(round_robot, 3).name == "disk"
    # A regular 64-gon inscribed in a disk has the disk's clearance to within the sagitta.
    angles = np.linspace(0.0, 2 * math.pi, 64, endpoint=False)
    polygon = 0.2 * np.column_stack((np.cos(angles), np.sin(angles)))
    robot = round_robot.replace(radius=0.2, footprint=tuple(map(tuple, polygon)))
    points = np.random.default_rng(0).uniform(-2.0, 2.0, (200, 2))
    points = points[np.hypot(points[:, 0], points[:, 1]) > 0.25]
    sagitta = 0.2 * (1.0 - math.cos(math.pi / 64))
    for point in points:
        by_polygon = BodyModel.polygon(robot).clearance(point[None])
        by_disk = BodyModel.disk(robot).clearance(point[None])
        assert by_disk <= by_polygon <= by_disk + sagitta + 1e-12


@settings(max_examples=200)
@given(st.sampled_from(["rosbot", "m2wr"]), st.integers(1, 6), st.floats(-1, 1), st.floats(-1, 1))
def test_a_cover_contains_the_footprint(name, n_disks, x, y):
    robot = preset(name)
    cover = BodyModel.cover(robot, n_disks)
    point = np.array([[x, y]]) * np.abs(np.asarray(robot.footprint)).max(axis=0)   # inside the bounding box
    if inside_polygon(np.asarray(robot.footprint), point)[0]:
        assert cover.clearance(point) <= 1e-12                # covered by some disk


def test_signed_distance_and_inside_test_of_a_rectangle():
    square = np.array([[1.0, 1.0], [-1.0, 1.0], [-1.0, -1.0], [1.0, -1.0]])
    points = np.array([[0.0, 0.0], [0.5, 0.0], [2.0, 0.0], [2.0, 2.0], [1.0, 0.0]])
    np.testing.assert_allclose(polygon_distance(square, points), [-1.0, -0.5, 1.0, math.sqrt(2), 0.0], atol=1e-12)
    assert inside_polygon(square, points[:3]).tolist() == [True, True, False]


def test_readings_closer_than_range_min_are_put_on_the_outline():
    # The ROSbot's lidar cannot measure closer than 0.15 m, beyond its front edge (0.10 m) plus the margin:
    # a too-close reading straight ahead must count as touching the polygon, not 5 cm away.
    rosbot = preset("rosbot")
    ranges = np.full(720, math.inf)
    ranges[rosbot.scan().beam_index(0.0)] = -math.inf
    scan = rosbot.scan(ranges)
    _, placed = obstacle_beams(scan, BodyModel.polygon(rosbot))
    assert placed[0] == pytest.approx(0.10, abs=1e-9)
    _, on_disk = obstacle_beams(scan, BodyModel.disk(rosbot))
    assert on_disk[0] == pytest.approx(min(rosbot.lidar.range_min, rosbot.radius), abs=1e-9)
    result = CBFSafetyFilter(rosbot, 0.05, body="polygon").filter((0.5, 0.0), scan)
    assert result.status.value == "recovering" and result.u[0] <= 0.0
    square = np.array([[1.0, 1.0], [-1.0, 1.0], [-1.0, -1.0], [1.0, -1.0]])
    np.testing.assert_allclose(_exit_ranges(np.array([0.5, 0.0]), np.array([[1.0, 0.0], [-1.0, 0.0]]), square),
                               [0.5, 1.5])


def test_a_concave_footprint_is_refused_by_the_polygon_model():
    lidar = LidarSpec(n_beams=360, angle_min=0.0, angle_max=2 * math.pi * 359 / 360, range_min=0.1, range_max=8.0)
    l_shape = ((0.2, 0.0), (0.2, 0.2), (-0.2, 0.2), (-0.2, -0.2), (0.0, -0.2), (0.0, 0.0))
    robot = RobotSpec(name="l", radius=0.3, v_max=1.0, v_min=-1.0, omega_max=2.0, a_max=1.0, alpha_max=2.0,
                      lidar=lidar, footprint=l_shape)
    with pytest.raises(InvalidConfig, match="convex footprint"):
        BodyModel.polygon(robot)
    assert BodyModel.cover(robot, 3).n_disks == 3


def door(width: float, distance: float = 1.5) -> tuple:
    return tuple(_thick((distance, width / 2), (distance, 3.0), 0.0) + _thick((distance, -width / 2), (distance,
                                                                                                       -3.0), 0.0))


@pytest.mark.parametrize("name", ["rosbot", "m2wr"])
def test_the_polygon_cbf_passes_a_door_of_body_width_plus_margins_plus_5_cm(name):
    robot = preset(name)
    margin = make_filter("cbf", robot, 0.05, body="polygon").margin
    widths = [y for _, y in robot.footprint]
    width = max(widths) - min(widths) + 2 * margin + 0.05           # m2wr 0.44 m, ROSbot 0.34 m
    outcome, _ = run(Episode(robot=name, filter="cbf", base="ramp_limit", dt=0.05, segments=door(width),
                             nominal="goal", params=(3.0, 0.0), duration=12.0, settings={"body": "polygon"}))
    assert not outcome.contact and outcome.min_clearance >= outcome.margin - 0.01
    assert outcome.goal_distance < 0.3, "through the door to the goal"
    disk, _ = run(Episode(robot=name, filter="cbf", base="ramp_limit", dt=0.05, segments=door(width),
                          nominal="goal", params=(3.0, 0.0), duration=12.0))
    assert disk.goal_distance > 1.0        # the circumscribed disk does not fit: the reason for the polygon


@pytest.mark.parametrize("body, half_width", [("disk", 0.292), ("cover", math.hypot(0.25 / 3, 0.15)),
                                              ("polygon", 0.15)])
def test_the_corridor_a_body_drives_along_is_its_own_width_and_the_escape_looks_for_that(body, half_width):
    """``corridor_half_width`` (what the escape's gap search and clear ways use) is the body model's lateral
    extent plus the margin: the disk's radius, a cover's disks, the polygon's half-width, not always the disk's."""
    from safenav.filters.escape import Escape

    robot = preset("m2wr")
    for name in ("cbf", "mpc") if body != "polygon" else ("cbf",):
        safety = make_filter(name, robot, 0.05, body=body)
        assert safety.body.half_width == pytest.approx(half_width, abs=1e-3)
        assert safety.corridor_half_width == pytest.approx(half_width + safety.margin, abs=1e-3)
        assert Escape(safety).clear_half_width == safety.corridor_half_width


def test_inside_polygon_is_the_even_odd_rule_of_every_edge_with_or_without_the_bounding_box():
    """The bounding-box shortcut changes no answer: random points (many outside the box, some on its edges and
    on vertices) against a convex footprint, an inflated disk and a concave polygon."""
    from safenav.filters import body

    rng = np.random.default_rng(11)
    concave = np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 2.0], [1.0, 0.5], [0.0, 2.0]])
    for polygon in (np.asarray(preset("rosbot").footprint, dtype=float), concave,
                    np.column_stack((np.cos(np.linspace(0, 6.2, 40)), np.sin(np.linspace(0, 6.2, 40))))):
        points = np.vstack((rng.uniform(-3.0, 3.0, (2000, 2)), polygon, polygon * 0.999, polygon * 1.001,
                            [[polygon[:, 0].min(), 0.3], [polygon[:, 0].max(), 0.1]]))
        full = body._even_odd(polygon, points)
        assert full.any() and not full.all()
        np.testing.assert_array_equal(inside_polygon(polygon, points), full)

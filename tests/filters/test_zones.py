"""The collision-monitor baseline on synthetic scans."""

import math

import numpy as np
import pytest

from safenav import InvalidConfig, preset
from safenav.filters import FilterStatus, ZonesFilter, make_filter
from safenav.filters.zones import inflate_footprint
from safenav.synthetic import Circle, Scene, synthetic_scan, wall

DT = 0.05


def front_of(robot) -> float:
    """Distance from the base origin to the front of the body disk the zones grow [m]."""
    return robot.radius


def test_point_inside_the_stop_polygon_stops(robot):
    filt = ZonesFilter(robot, DT)
    scan = synthetic_scan(robot, Scene.of(Circle((front_of(robot) + 0.03 + 0.05, 0.0), 0.05)))
    result = filt.filter((0.3, 0.5), scan)
    assert result.u.tolist() == [0.0, 0.0]
    assert result.reason.family == "zone" and result.reason.detail.startswith("stop zone")
    assert result.reason.point is not None
    assert result.status is FilterStatus.OK


def test_point_inside_the_slowdown_polygon_scales_the_command(robot):
    filt = ZonesFilter(robot, DT)
    scan = synthetic_scan(robot, Scene.of(wall(front_of(robot) + 0.3)))
    result = filt.filter((0.3, 0.5), scan)
    assert result.u == pytest.approx([0.3 * 0.3, 0.3 * 0.5])
    assert result.reason.family == "zone" and result.reason.detail.startswith("slowdown zone")


def test_nothing_near_passes_the_command_unchanged(robot):
    filt = ZonesFilter(robot, DT)
    scan = synthetic_scan(robot, Scene.of(wall(2.0)))
    result = filt.filter((0.3, -0.5), scan)
    assert result.u.tolist() == [0.3, -0.5] and not result.modified and result.message == ""
    assert result.reason is None


def test_stop_zone_ignores_the_direction_of_motion():
    """The known weakness: an obstacle behind stops a robot driving away from it."""
    robot = preset("rosbot")
    scan = synthetic_scan(robot, Scene.of(wall(robot.radius + 0.03, math.pi)))   # 3 cm behind the body
    assert ZonesFilter(robot, DT).filter((0.5, 0.0), scan).u.tolist() == [0.0, 0.0]


def test_fewer_than_min_points_do_not_act():
    robot = preset("rosbot")
    ranges = np.full(720, math.inf)
    ranges[robot.scan().beam_index(0.5)] = 0.18   # one spurious return inside the stop polygon
    assert ZonesFilter(robot, DT, min_points=3).filter((0.5, 0.0), robot.scan(ranges)).u[0] == 0.5
    assert ZonesFilter(robot, DT, min_points=1).filter((0.5, 0.0), robot.scan(ranges)).u[0] == 0.0


def test_footprint_zones_hug_a_rectangle_closer_than_the_disk():
    robot = preset("m2wr")
    footprint_zones = ZonesFilter(robot, DT, use_footprint=True)
    assert footprint_zones.stop_polygon[:, 1].max() < ZonesFilter(robot, DT).stop_polygon[:, 1].max()


def test_inflated_footprint_contains_the_exact_offset_shape(robot):
    polygon = inflate_footprint(robot, 0.1)
    from matplotlib.path import Path

    angles = np.linspace(0, 2 * math.pi, 200)
    if robot.footprint is None:
        inside = (robot.radius + 0.1 - 1e-6) * np.column_stack((np.cos(angles), np.sin(angles)))
    else:
        corners = np.asarray(robot.footprint)
        inside = np.array([corner + (0.1 - 1e-6) * np.array([math.cos(a), math.sin(a)])
                           for corner in corners for a in angles])
    assert Path(polygon).contains_points(inside).all()


def test_bad_zone_config_names_the_value():
    with pytest.raises(InvalidConfig, match=r"slowdown_distance=0\.01 must be >= stop_distance=0\.05"):
        ZonesFilter(preset("rosbot"), DT, slowdown_distance=0.01)
    with pytest.raises(InvalidConfig, match="min_points must be an integer >= 1"):
        ZonesFilter(preset("rosbot"), DT, min_points=0)


def test_make_filter_knows_every_name_and_lists_them():
    robot = preset("puzzlebot")
    assert make_filter("none", robot) is None
    assert isinstance(make_filter("zones", robot), ZonesFilter)
    from safenav import UnknownName

    with pytest.raises(UnknownName, match="unknown filter 'rrt'; expected one of: cbf, mpc, none, zones"):
        make_filter("rrt", robot)

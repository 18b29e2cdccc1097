"""The lidar encoding: REP-117 readings into bounded sectors, found by angle through the mount."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from safenav import preset
from safenav.errors import InvalidConfig
from safenav.geometry import Pose2D
from safenav.synthetic import Scene, synthetic_scan, wall
from tests.gym.conftest import SKIP_REASON

gymnasium = pytest.importorskip("gymnasium", reason=SKIP_REASON)

from safenav.gym.observation import ObservationConfig, encode_goal, encode_lidar  # noqa: E402 - after the importorskip

CONFIG = ObservationConfig(sectors=8, lidar_range=4.0)


def _sector(scan, direction: float) -> tuple[float, int]:
    lidar, known = encode_lidar(scan, CONFIG)
    index = round(direction / (2 * math.pi / CONFIG.sectors)) % CONFIG.sectors
    return float(lidar[index]), int(known[index])


@pytest.mark.parametrize(("reading", "expected", "known"), [
    (2.0, 0.5, 1),               # a hit: range / lidar_range
    (8.0, 1.0, 1),               # beyond the horizon: 1
    (math.inf, 1.0, 1),          # +inf: free up to range_max (12 m > 4 m)
    (-math.inf, 0.0, 1),         # -inf: an object at the sensor
    (math.nan, 0.0, 0),          # NaN: no information, so unknown
    (0.05, 0.0, 0),              # below range_min: discarded, unknown
    (40.0, 0.0, 0),              # above range_max: discarded, unknown
])
def test_every_rep117_reading_maps_as_documented(reading: float, expected: float, known: int) -> None:
    robot = preset("puzzlebot")
    scan = robot.scan(np.full(robot.lidar.n_beams, reading))
    lidar, flags = encode_lidar(scan, CONFIG)
    assert lidar.dtype == np.float32 and flags.dtype == np.int8
    np.testing.assert_array_equal(lidar, np.float32(expected))
    np.testing.assert_array_equal(flags, known)


def test_a_sector_keeps_its_nearest_informative_reading_and_ignores_invalid_ones() -> None:
    robot = preset("puzzlebot")                      # 360 beams, beam i at i degrees, mount yaw 0
    ranges = np.full(360, math.inf)
    ranges[0], ranges[5], ranges[10] = 3.0, math.nan, 1.0   # all three in the sector ahead (+-22.5 deg)
    lidar, known = encode_lidar(robot.scan(ranges), CONFIG)
    assert lidar[0] == pytest.approx(0.25) and known[0] == 1
    assert np.all(lidar[1:] == 1.0)


def test_range_max_below_the_horizon_bounds_a_no_return() -> None:
    robot = preset("puzzlebot")
    short = robot.replace(lidar=dataclasses.replace(robot.lidar, range_max=2.0))
    lidar, _ = encode_lidar(short.scan(), CONFIG)
    np.testing.assert_allclose(lidar, 0.5)          # free only up to 2 m of a 4 m horizon


@pytest.mark.parametrize("name", ["rosbot", "puzzlebot", "m2wr"])
def test_sectors_are_found_by_angle_through_the_mount(name: str) -> None:
    # A wall 1 m ahead of the base must land in sector 0 whatever the lidar's convention
    # (the ROSbot's lidar is mounted backwards, the m2wr's sits 0.15 m ahead of the base).
    robot = preset(name)
    scan = synthetic_scan(robot, Scene.of(wall(distance=1.0, direction=0.0, length=0.4)))
    ahead, known = _sector(scan, 0.0)
    assert known == 1
    assert ahead == pytest.approx((1.0 - robot.lidar.mount.x) / CONFIG.lidar_range, abs=0.01)
    behind, _ = _sector(scan, math.pi)
    assert behind == (0.0 if name == "m2wr" else 1.0)


def test_the_m2wr_rear_is_unknown_never_free() -> None:
    robot = preset("m2wr")                           # 180-degree lidar facing forward
    lidar, known = encode_lidar(robot.scan(), ObservationConfig(sectors=36))
    rear = [k for k in range(36) if abs(math.remainder(k * 10.0, 360.0)) > 95.0]
    front = [k for k in range(36) if abs(math.remainder(k * 10.0, 360.0)) < 85.0]
    assert not known[rear].any() and np.all(lidar[rear] == 0.0)
    assert known[front].all() and np.all(lidar[front] == 1.0)


def test_goal_in_polar_coordinates_of_the_base_frame() -> None:
    # REP-103: a goal 2 m to the left of a robot facing +x has bearing +pi/2.
    distance, bearing = encode_goal(Pose2D(1.0, 1.0, 0.0), (1.0, 3.0), ObservationConfig())
    assert distance == pytest.approx(2.0) and bearing == pytest.approx(math.pi / 2)
    distance, bearing = encode_goal(Pose2D(0.0, 0.0, math.pi / 2), (0.0, 50.0), ObservationConfig())
    assert distance == pytest.approx(20.0) and bearing == pytest.approx(0.0, abs=1e-6)  # clipped to 20 m


@pytest.mark.parametrize(("kwargs", "message"), [
    ({"sectors": 3}, "ObservationConfig.sectors must be an integer >= 4, got 3"),
    ({"sectors": 8.0}, "ObservationConfig.sectors must be an integer >= 4, got 8.0"),
    ({"lidar_range": 0.0}, "ObservationConfig.lidar_range must be a finite number > 0, got 0.0"),
    ({"max_goal_distance": math.inf}, "ObservationConfig.max_goal_distance must be a finite number > 0, got inf"),
])
def test_observation_config_errors_name_the_value(kwargs: dict, message: str) -> None:
    with pytest.raises(InvalidConfig, match=message.replace("(", r"\(")) as error:
        ObservationConfig(**kwargs)
    assert isinstance(error.value, ValueError)

"""The rule every reference policy uses to compare a direction of a scan with a threshold (REP-117)."""

import math

import pytest

from safenav import LidarSpec
from safenav.reference import ObstacleAvoidance, Proximity, RangeCheck, check_beam, check_sector
from tests.scans import DEG, INF, LIDARS, NAN, scan_of


def test_the_conventions_really_differ():
    front = {name: lidar.scan().beam_index(0.0) for name, lidar in LIDARS.items()}
    assert front["rosbot"] == 0 and front["puzzlebot"] == 0 and front["m2wr"] == 360
    assert len(set(front.values()) - {0}) >= 3  # the others put the front at different indices

# ------------------------------------------------------------------ shared comparison rule


@pytest.mark.parametrize(
    ("value", "proximity", "distance"),
    [
        (0.7, Proximity.NEAR, 0.7),
        (1.0, Proximity.AT_THRESHOLD, 1.0),
        (1.3, Proximity.CLEAR, 1.3),
        (INF, Proximity.CLEAR, INF),          # nothing within range_max = 12 m >= 1 m
        (-INF, Proximity.NEAR, 0.15),         # closer than range_min: at most range_min away
        (NAN, Proximity.UNKNOWN, NAN),
        (0.05, Proximity.UNKNOWN, NAN),       # below range_min: discarded
        (40.0, Proximity.UNKNOWN, NAN),       # above range_max: discarded
    ],
)
def test_check_beam_and_check_sector_follow_rep_117(value, proximity, distance):
    scan = scan_of(LIDARS["rosbot"], [((-5, 5), value)], background=0.3)
    for check in (check_beam(scan, 0.0, 1.0), check_sector(scan, -3 * DEG, 3 * DEG, 1.0)):
        assert check.proximity is proximity
        assert check.distance == pytest.approx(distance, nan_ok=True)


def test_a_reading_closer_than_range_min_is_near_even_below_a_smaller_threshold():
    # range_min 0.6 m: an object closer than that may well be closer than 0.5 m.
    short_sighted = LidarSpec(n_beams=360, angle_min=0.0, angle_max=2 * math.pi, range_min=0.6, range_max=12.0)
    scan = scan_of(short_sighted, [((-3, 3), -INF)])
    assert check_beam(scan, 0.0, 0.5) == RangeCheck(0.6, Proximity.NEAR)
    assert check_sector(scan, -0.1, 0.1, 0.5).proximity is Proximity.NEAR
    assert ObstacleAvoidance()(scan) == (0.0, 0.5)


def test_free_beyond_a_short_range_max_is_not_clear():
    scan = LIDARS["hokuyo_240"].scan()  # all +inf, range_max 5.6 m
    assert check_beam(scan, 0.0, 5.6).proximity is Proximity.CLEAR
    assert check_beam(scan, 0.0, 6.0).proximity is Proximity.UNKNOWN
    assert check_sector(scan, -0.1, 0.1, 6.0).proximity is Proximity.UNKNOWN


def test_a_partly_seen_sector_is_clear_only_if_fully_seen():
    scan = LIDARS["m2wr"].scan()  # 180 degrees: nothing behind is seen
    assert check_sector(scan, 60 * DEG, 120 * DEG, 1.0).proximity is Proximity.UNKNOWN
    assert check_sector(scan, 150 * DEG, -150 * DEG, 1.0).proximity is Proximity.UNKNOWN
    near = scan_of(LIDARS["m2wr"], [((70, 80), 0.5)])
    assert check_sector(near, 60 * DEG, 120 * DEG, 1.0).proximity is Proximity.NEAR
    assert check_beam(scan, math.pi, 1.0).proximity is Proximity.UNKNOWN


def test_invalid_beams_among_informative_ones_are_ignored():
    scan = scan_of(LIDARS["puzzlebot"], [((-10, 10), 3.0), ((-2, 2), NAN)])
    check = check_sector(scan, -10 * DEG, 10 * DEG, 1.0)
    assert check.proximity is Proximity.CLEAR and check.distance == 3.0

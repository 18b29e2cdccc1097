"""Reference nominal policies on exact synthetic scans, over every lidar convention."""

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from safenav import (
    PRESET_NAMES,
    Command,
    InvalidConfig,
    InvalidScan,
    InvalidScanType,
    LidarSpec,
    Pose2D,
    UnknownName,
    preset,
    unicycle_step,
    wrap_angle,
)
from safenav.reference import (
    POLICY_NAMES,
    GoToGoal,
    ObstacleAvoidance,
    Policy,
    Proximity,
    RandomWalk,
    RangeCheck,
    StopAtWall,
    WallFollower,
    check_beam,
    check_sector,
    make_policy,
)
from safenav.synthetic import Scene, box, synthetic_scan, wall

DEG = math.pi / 180.0
INF, NAN = math.inf, math.nan

# ------------------------------------------------------------------ lidar conventions

LIDARS = {
    # The three tutorial robots: mounted backwards over -pi..pi; 0..2pi; 180 degrees with beam 0 on the right.
    **{name: preset(name).lidar for name in PRESET_NAMES},
    # A Hokuyo URG-04LX-like 240-degree scan, 0.02-5.6 m.
    "hokuyo_240": LidarSpec(n_beams=683, angle_min=-120 * DEG, angle_max=120 * DEG, range_min=0.02, range_max=5.6),
    # A 360-degree lidar mounted sideways and off-centre: its beam 0 looks left.
    "rotated_mount": LidarSpec(n_beams=400, angle_min=0.0, angle_max=2 * math.pi * 399 / 400, range_min=0.1,
                               range_max=8.0, mount=Pose2D(0.05, 0.02, 0.5 * math.pi)),
    # A 270-degree SICK-like scan whose mount is yawed 0.3 rad: no beam is special.
    "yawed_270": LidarSpec(n_beams=541, angle_min=-135 * DEG, angle_max=135 * DEG, range_min=0.05, range_max=20.0,
                           mount=Pose2D(0.1, 0.0, 0.3)),
}


@pytest.fixture(params=sorted(LIDARS))
def lidar(request: pytest.FixtureRequest) -> LidarSpec:
    """Each lidar convention in turn."""
    return LIDARS[request.param]


def scan_of(lidar, patches=(), background=INF):
    """A scan of ``lidar`` reading ``background`` everywhere, then each ``((lo_deg, hi_deg), value)`` in turn.

    Sectors are base-frame angles [deg], counter-clockwise from lo to hi; later patches overwrite earlier ones.
    """
    template = lidar.scan()
    ranges = np.full(template.n_beams, background, dtype=float)
    for (lo, hi), value in patches:
        mask = template.sector_mask(lo * DEG, hi * DEG)
        assert mask.any(), f"patch {lo}..{hi} deg holds no beam of this lidar"
        ranges[mask] = value
    return template.with_ranges(ranges)


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


# ------------------------------------------------------------------ StopAtWall (tutorial 1)


@pytest.mark.parametrize("background", [0.3, INF])
@pytest.mark.parametrize(
    ("front", "expected", "state"),
    [
        (2.0, (0.5, 0.0), "go"),
        (math.nextafter(1.0, INF), (0.5, 0.0), "go"),   # just above the threshold: the tutorial's `>` holds
        (1.0, (0.0, 0.0), "stop"),                       # exactly at the threshold: `1.0 > 1.0` is false
        (0.99, (0.0, 0.0), "stop"),
        (0.3, (0.0, 0.0), "stop"),
    ],
)
def test_stop_at_wall_reads_the_front_by_angle(lidar, background, front, expected, state):
    # Everything except the front reads `background`: obstacles elsewhere must not matter.
    policy = StopAtWall()
    command = policy(scan_of(lidar, [((-2, 2), front)], background=background))
    assert isinstance(command, Command)
    assert command == expected
    assert policy.state == state


@pytest.mark.parametrize(
    ("front", "expected", "why"),
    [
        (INF, (0.5, 0.0), "no return within range_max (>= 1 m): free"),
        (-INF, (0.0, 0.0), "object closer than range_min"),
        (NAN, (0.0, 0.0), "invalid: unknown, do not drive into it"),
        (100.0, (0.0, 0.0), "above range_max: discarded, so unknown"),
        (0.01, (0.0, 0.0), "below range_min: discarded, so unknown"),
    ],
)
def test_stop_at_wall_special_front_readings(lidar, front, expected, why):
    policy = StopAtWall()
    assert policy(scan_of(lidar, [((-2, 2), front)], background=5.0)) == expected, why


def test_stop_at_wall_stops_when_the_front_is_not_in_the_field_of_view():
    backwards = LidarSpec(n_beams=720, angle_min=-0.5 * math.pi, angle_max=0.5 * math.pi, range_min=0.1,
                          range_max=30.0, mount=Pose2D(0.0, 0.0, math.pi))
    policy = StopAtWall()
    assert policy(backwards.scan()) == (0.0, 0.0)
    assert policy.front.proximity is Proximity.UNKNOWN and math.isnan(policy.front.distance)


def test_stop_at_wall_does_not_trust_free_space_beyond_a_short_range_max():
    scan = LIDARS["hokuyo_240"].scan()  # all +inf; range_max 5.6 m
    assert StopAtWall(threshold=5.0)(scan) == (0.5, 0.0)
    assert StopAtWall(threshold=6.0)(scan) == (0.0, 0.0)


def test_stop_at_wall_on_synthetic_walls_of_each_robot(robot):
    policy = StopAtWall()
    offset = robot.lidar.mount.x  # ranges are measured from the laser, as in the tutorial
    assert policy(synthetic_scan(robot, Scene.of(wall(offset + 0.8)))) == (0.0, 0.0)
    assert policy.front.distance == pytest.approx(0.8, abs=1e-4)  # the m2wr has no beam exactly ahead
    assert policy(synthetic_scan(robot, Scene.of(wall(offset + 1.2)))) == (0.5, 0.0)
    # A wall right behind (where the lidar sees) and one to the side do not stop it.
    assert policy(synthetic_scan(robot, Scene.of(wall(0.4, 0.5 * math.pi), wall(0.4, -0.5 * math.pi)))) == (0.5, 0.0)


def test_the_tutorials_beam_360_looks_backward_on_the_rosbot():
    scan = preset("rosbot").scan()
    assert abs(wrap_angle(scan.base_angles[360] - math.pi)) < scan.angle_increment
    assert scan.beam_index(0.0) == 0


@pytest.mark.parametrize(
    ("scene", "fixed", "buggy"),
    [
        # Wall 0.5 m ahead, nothing behind: the tutorial reads beam 360 (behind), sees nothing, drives into it.
        (Scene.of(wall(0.5, 0.0)), (0.0, 0.0), (0.5, 0.0)),
        # Wall 0.5 m behind, nothing ahead: the tutorial stops for no reason.
        (Scene.of(wall(0.5, math.pi)), (0.5, 0.0), (0.0, 0.0)),
    ],
)
def test_the_buggy_stop_at_wall_reads_beam_360_like_the_tutorial(scene, fixed, buggy):
    rosbot = preset("rosbot")
    scan = synthetic_scan(rosbot, scene)
    assert StopAtWall()(scan) == fixed
    assert StopAtWall.tutorial_bug()(scan) == buggy
    assert StopAtWall(front_index=360)(scan) == buggy


def test_the_buggy_stop_at_wall_reads_exactly_raw_beam_360():
    template = preset("rosbot").scan()
    ranges = np.full(template.n_beams, 0.2)  # everything near ...
    ranges[360] = 3.0                         # ... except beam 360
    policy = StopAtWall.tutorial_bug()
    assert policy.buggy and policy.front_index == 360
    assert policy(template.with_ranges(ranges)) == (0.5, 0.0)
    ranges[:] = 5.0
    ranges[360] = 0.9                         # only beam 360 is near
    assert policy(template.with_ranges(ranges)) == (0.0, 0.0)


@pytest.mark.parametrize(
    ("raw", "expected"),
    [
        (1.0, (0.0, 0.0)),     # `1.0 > 1.0` is false
        (NAN, (0.0, 0.0)),     # `nan > 1.0` is false
        (INF, (0.5, 0.0)),     # `inf > 1.0`
        (-INF, (0.0, 0.0)),
        (100.0, (0.5, 0.0)),   # above range_max: the tutorial takes it at face value (the fixed policy stops)
    ],
)
def test_the_buggy_stop_at_wall_compares_the_raw_value(raw, expected):
    template = preset("rosbot").scan()
    ranges = np.full(template.n_beams, 5.0)
    ranges[360] = raw
    assert StopAtWall.tutorial_bug()(template.with_ranges(ranges)) == expected


def test_the_buggy_stop_at_wall_needs_beam_360():
    with pytest.raises(InvalidScan, match=r"front_index=360 but the scan has 360 beams \(indices 0..359\)"):
        StopAtWall.tutorial_bug()(preset("puzzlebot").scan())


def test_stop_at_wall_with_a_front_cone_sees_what_the_single_beam_misses():
    scan = scan_of(LIDARS["rosbot"], [((7, 9), 0.6)])  # a post 8 degrees left of straight ahead
    assert StopAtWall()(scan) == (0.5, 0.0)
    assert StopAtWall(front_half_width=10 * DEG)(scan) == (0.0, 0.0)


def test_stop_at_wall_clips_to_the_robot_it_is_given():
    scan = LIDARS["rosbot"].scan()
    assert StopAtWall(robot=preset("rosbot"))(scan) == (0.5, 0.0)      # the tutorial's own robot: unchanged
    assert StopAtWall(robot=preset("puzzlebot"))(scan) == (0.4, 0.0)   # v_max 0.4 m/s


def test_stop_at_wall_reset_forgets_the_front():
    policy = StopAtWall()
    assert policy.state == "stop" and policy.front is None
    policy(LIDARS["rosbot"].scan())
    assert policy.state == "go" and policy.front.proximity is Proximity.CLEAR
    policy.reset()
    assert policy.state == "stop" and policy.front is None


# ------------------------------------------------------------------ ObstacleAvoidance (tutorial 2)

TURN, CRUISE = (0.0, 0.5), (0.2, 0.3)


@pytest.mark.parametrize(
    ("patch", "expected", "state"),
    [
        (None, CRUISE, "drive"),
        ((-0.5, 0.5), TURN, "turn in place"),
        ((13.5, 14.5), TURN, "turn in place"),     # inside +-15 degrees, left
        ((-14.5, -13.5), TURN, "turn in place"),   # inside, right (the wrap-around on a 0..2pi scan)
        ((16.5, 20.0), CRUISE, "drive"),           # just outside, left
        ((-20.0, -16.5), CRUISE, "drive"),         # just outside, right
        ((60.0, 120.0), CRUISE, "drive"),
    ],
)
def test_obstacle_avoidance_both_branches(lidar, patch, expected, state):
    policy = ObstacleAvoidance()
    scan = scan_of(lidar, [] if patch is None else [(patch, 0.4)], background=3.0)
    assert policy(scan) == expected
    assert policy.state == state


@pytest.mark.parametrize(
    ("nearest", "expected"),
    [
        (0.5, CRUISE),                          # exactly at the threshold: `0.5 < 0.5` is false
        (math.nextafter(0.5, 0.0), TURN),
        (0.51, CRUISE),
    ],
)
def test_obstacle_avoidance_threshold_is_strict(lidar, nearest, expected):
    assert ObstacleAvoidance()(scan_of(lidar, [((4, 6), nearest)], background=INF)) == expected


@pytest.mark.parametrize(
    ("cone", "expected", "why"),
    [
        ([((-15, 15), NAN)], TURN, "no valid beam in the cone: unknown is not clear"),
        ([((-15, 15), 100.0)], TURN, "only readings above range_max: unknown"),
        ([((-15, 15), NAN), ((-1, 1), INF)], CRUISE, "the valid readings say free; invalid ones are ignored"),
        ([((-15, 15), NAN), ((-1, 1), 2.0)], CRUISE, "the valid readings are far"),
        ([((5, 6), -INF)], TURN, "an object closer than range_min"),
        ([((5, 6), 0.01)], CRUISE, "below range_min: discarded (the tutorial would turn)"),
    ],
)
def test_obstacle_avoidance_invalid_readings(lidar, cone, expected, why):
    assert ObstacleAvoidance()(scan_of(lidar, cone, background=INF)) == expected, why


@pytest.mark.parametrize(("beam", "expected"), [(0, TURN), (14, TURN), (345, TURN), (355, TURN), (359, TURN),
                                                (15, CRUISE), (344, CRUISE), (180, CRUISE)])
def test_obstacle_avoidance_wraps_around_the_puzzlebots_scan(beam, expected):
    template = preset("puzzlebot").scan()
    ranges = np.full(template.n_beams, INF)
    ranges[beam] = 0.3
    assert ObstacleAvoidance()(template.with_ranges(ranges)) == expected


def test_obstacle_avoidance_turns_when_the_cone_is_only_partly_seen():
    left_only = LidarSpec(n_beams=200, angle_min=5 * DEG, angle_max=180 * DEG, range_min=0.1, range_max=10.0)
    policy = ObstacleAvoidance()
    assert policy(left_only.scan()) == TURN
    assert policy.cone.proximity is Proximity.UNKNOWN


def test_obstacle_avoidance_on_synthetic_walls_of_each_robot(robot):
    policy = ObstacleAvoidance()
    offset = robot.lidar.mount.x
    assert policy(synthetic_scan(robot, Scene.of(wall(offset + 0.4)))) == TURN
    assert policy(synthetic_scan(robot, Scene.of(wall(offset + 0.6)))) == CRUISE
    assert policy(synthetic_scan(robot, Scene.of(wall(0.4, 0.5 * math.pi)))) == CRUISE  # to the side


@given(st.lists(st.sampled_from([0.2, 0.49, 0.5, 0.8, 3.0, INF, -INF, NAN, 0.05, 99.0]), min_size=360, max_size=360))
def test_obstacle_avoidance_matches_the_tutorial_index_rule_on_the_puzzlebot(values):
    # Oracle: the puzzlebot's +-15 degree cone by index, the tutorial's `< 0.5` on valid readings,
    # and the documented conservative rule for a cone with no valid reading.
    scan = preset("puzzlebot").scan(values)
    cone = np.r_[np.arange(0, 15), np.arange(345, 360)]
    r = np.asarray(values)[cone]
    hit = (r >= 0.15) & (r <= 12.0)
    informative = hit | np.isinf(r)
    turn = bool(np.any(hit & (r < 0.5)) or np.any(r == -INF) or not np.any(informative))
    assert ObstacleAvoidance()(scan) == (TURN if turn else CRUISE)


def test_obstacle_avoidance_clips_to_the_robot_it_is_given():
    slow = preset("puzzlebot").replace(v_max=0.1, omega_max=0.25)
    scan = LIDARS["puzzlebot"].scan()
    assert ObstacleAvoidance(robot=preset("puzzlebot"))(scan) == CRUISE
    assert ObstacleAvoidance(robot=slow)(scan) == (0.1, 0.25)


# ------------------------------------------------------------------ WallFollower (tutorial 3)

FIND_WALL, TURN_LEFT, FOLLOW_WALL = (0.2, -0.3), (0.0, 0.3), (0.5, 0.0)
SECTORS_DEG = {"right": (-90, -54), "fright": (-54, -18), "front": (-18, 18), "fleft": (18, 54), "left": (54, 90)}

WALL_FOLLOWER_CASES = [
    # front, fleft, fright near?  case  state              command
    ((False, False, False), 1, "find the wall", FIND_WALL),
    ((True, False, False), 2, "turn left", TURN_LEFT),
    ((False, False, True), 3, "follow the wall", FOLLOW_WALL),
    ((False, True, False), 4, "find the wall", FIND_WALL),
    ((True, False, True), 5, "turn left", TURN_LEFT),
    ((True, True, False), 6, "turn left", TURN_LEFT),
    ((True, True, True), 7, "turn left", TURN_LEFT),
    ((False, True, True), 8, "find the wall", FIND_WALL),
]


def regions_scan(lidar, front, fleft, fright, sides=INF, far=3.0, near=1.0):
    """Right and left read ``sides``; front, fleft and fright read ``far``, with ``near`` in the middle of near ones.

    Every other direction reads 0.2 m, which no region may see.
    """
    patches = [(SECTORS_DEG["right"], sides), (SECTORS_DEG["left"], sides)]
    patches += [(SECTORS_DEG[name], far) for name in ("fright", "front", "fleft")]
    for name, is_near in (("front", front), ("fleft", fleft), ("fright", fright)):
        if is_near:
            lo, hi = SECTORS_DEG[name]
            patches.append(((0.5 * (lo + hi) - 12, 0.5 * (lo + hi) + 12), near))
    return scan_of(lidar, patches, background=0.2)


@pytest.mark.parametrize("sides", [INF, 0.5])  # right and left are computed but unused, as in the tutorial
@pytest.mark.parametrize("far", [3.0, INF])
@pytest.mark.parametrize(("near", "case", "state", "command"), WALL_FOLLOWER_CASES)
def test_wall_follower_eight_cases(lidar, near, case, state, command, sides, far):
    policy = WallFollower()
    assert policy(regions_scan(lidar, *near, sides=sides, far=far)) == command
    assert (policy.case, policy.state) == (case, state)
    assert policy.case_description.startswith(f"case {case} - ")
    assert policy.state_id == ("find the wall", "turn left", "follow the wall").index(state)


@pytest.mark.parametrize(("near", "case", "state", "command"), WALL_FOLLOWER_CASES)
def test_wall_follower_cases_with_exact_regions(near, case, state, command):
    policy = WallFollower()
    assert policy(regions_scan(LIDARS["m2wr"], *near, far=INF, near=1.2)) == command
    assert (policy.case, policy.state) == (case, state)
    names = ("front", "fleft", "fright")
    expected = {name: 1.2 if is_near else 10.0 for name, is_near in zip(names, near, strict=True)}
    assert {name: policy.regions[name] for name in expected} == expected
    assert policy.regions["right"] == policy.regions["left"] == 10.0  # +inf clamped to 10 m


@pytest.mark.parametrize("previous", WALL_FOLLOWER_CASES[:3], ids=["from find", "from turn", "from follow"])
@pytest.mark.parametrize("region", ["front", "fleft", "fright"])
def test_wall_follower_keeps_its_state_when_a_region_is_exactly_at_the_threshold(lidar, previous, region):
    near, _, state, command = previous
    policy = WallFollower()
    policy(regions_scan(lidar, *near))
    assert policy.state == state
    lo, hi = SECTORS_DEG[region]
    inside = (lo + 5, hi - 5)  # clear of the neighbouring regions
    exact = scan_of(lidar, [((-90, 90), 3.0), (inside, 1.5)])
    assert policy(exact) == command          # the tutorial's "unknown case": no state change
    assert policy.state == state and policy.case == 0 and policy.case_description == "unknown case"
    assert policy.regions[region] == 1.5
    below = scan_of(lidar, [((-90, 90), 3.0), (inside, math.nextafter(1.5, 0.0))])
    policy(below)
    assert policy.case == {"front": 2, "fleft": 4, "fright": 3}[region]


@pytest.mark.parametrize(
    ("region", "value", "case", "why"),
    [
        ("front", NAN, 2, "an unknown front counts as near: turn left, never drive into it"),
        ("front", 100.0, 2, "only readings above range_max: unknown, near"),
        ("front", 0.01, 2, "only readings below range_min: unknown, near"),
        ("fright", NAN, 3, "an unknown fright counts as near"),
        ("fleft", NAN, 4, "an unknown fleft counts as near"),
    ],
)
def test_wall_follower_treats_an_unknown_region_as_near(lidar, region, value, case, why):
    policy = WallFollower()
    policy(scan_of(lidar, [((-90, 90), INF), (SECTORS_DEG[region], value)]))  # every beam of the region
    assert policy.case == case, why
    assert math.isnan(policy.regions[region])
    assert policy.checks[region].proximity is Proximity.UNKNOWN


@pytest.mark.parametrize(("region", "case"), [("front", 2), ("fright", 3), ("fleft", 4)])
def test_wall_follower_reading_closer_than_range_min_is_near(lidar, region, case):
    lo, _ = SECTORS_DEG[region]
    policy = WallFollower()
    policy(scan_of(lidar, [((-90, 90), INF), ((lo + 10, lo + 12), -INF)]))
    assert policy.case == case
    assert policy.regions[region] == lidar.range_min


def test_wall_follower_partly_invalid_region_uses_its_valid_beams():
    policy = WallFollower()
    policy(scan_of(LIDARS["m2wr"], [((-90, 90), INF), ((-18, 18), NAN), ((-2, 2), 2.0)]))
    assert policy.case == 1 and policy.regions["front"] == 2.0


def test_wall_follower_clamps_regions_to_ten_metres():
    policy = WallFollower()
    policy(scan_of(LIDARS["m2wr"], [((-90, 90), 25.0), ((-60, -58), 12.0), ((-1, 1), 9.0)]))
    assert dict(policy.regions) == {"right": 10.0, "fright": 10.0, "front": 9.0, "fleft": 10.0, "left": 10.0}


def test_wall_follower_sectors_are_the_tutorials_36_degree_slices():
    sectors = WallFollower().sectors
    assert list(sectors) == ["right", "fright", "front", "fleft", "left"]
    for name, (lo, hi) in sectors.items():
        assert (lo / DEG, hi / DEG) == pytest.approx(SECTORS_DEG[name])
    wide = WallFollower(span=2 * math.pi).sectors
    assert wide["front"] == pytest.approx((-36 * DEG, 36 * DEG))


@pytest.mark.parametrize(("name", "first", "stop"), [("right", 0, 143), ("fright", 144, 287), ("front", 288, 431),
                                                     ("fleft", 432, 575), ("left", 576, 713)])
def test_wall_follower_angle_sectors_cover_the_tutorials_index_slices_on_the_m2wr(name, first, stop):
    scan = preset("m2wr").scan()
    lo, hi = WallFollower().sectors[name]
    indices = set(np.flatnonzero(scan.sector_mask(lo, hi)).tolist())
    tutorial = set(range(first, stop))  # the tutorial's msg.ranges[first:stop]
    assert tutorial <= indices
    assert len(indices - tutorial) <= 1 or name == "left"  # the boundary beam the slice skipped
    assert len(indices) in (144, 145)


@pytest.mark.parametrize(
    ("scene", "state"),
    [
        (Scene.of(), "find the wall"),                                             # open space
        (Scene.of(wall(1.0, -0.5 * math.pi)), "follow the wall"),                  # a wall on the right
        (Scene.of(wall(1.0, 0.0)), "turn left"),                                   # a wall ahead
        (Scene.of(wall(1.0, 0.0), wall(1.0, -0.5 * math.pi)), "turn left"),        # a corner
        (Scene.of(wall(1.0, 0.5 * math.pi)), "find the wall"),                     # a wall on the left only
        (Scene.of(box((2.5, -0.8), (0.4, 0.4))), "find the wall"),                 # a post ahead-right, far
    ],
)
def test_wall_follower_on_synthetic_scenes_of_each_robot(robot, scene, state):
    policy = WallFollower()
    policy(synthetic_scan(robot, scene))
    assert policy.state == state


def test_wall_follower_with_a_narrow_lidar_treats_unseen_regions_as_near():
    narrow = LidarSpec(n_beams=181, angle_min=-45 * DEG, angle_max=45 * DEG, range_min=0.1, range_max=10.0)
    policy = WallFollower()
    assert policy(narrow.scan()) == FIND_WALL
    assert policy.case == 8  # fleft and fright partly unseen: near
    assert policy.checks["right"].proximity is Proximity.UNKNOWN and math.isnan(policy.regions["right"])


def test_wall_follower_reset_returns_to_find_the_wall():
    policy = WallFollower()
    assert (policy.state, policy.case, policy.case_description, dict(policy.regions)) == ("find the wall", None, "", {})
    policy(regions_scan(LIDARS["m2wr"], True, False, False))
    assert policy.state == "turn left"
    policy.reset()
    assert policy.state == "find the wall" and policy.case is None


def test_wall_follower_clips_to_the_robot_it_is_given():
    scan = regions_scan(LIDARS["m2wr"], False, False, True)
    assert WallFollower(robot=preset("m2wr"))(scan) == FOLLOW_WALL
    assert WallFollower(robot=preset("puzzlebot").replace(v_max=0.3))(scan) == (0.3, 0.0)


# ------------------------------------------------------------------ GoToGoal


@pytest.mark.parametrize("name", PRESET_NAMES)
def test_go_to_goal_drives_straight_at_a_goal_ahead(name):
    robot = preset(name)
    policy = GoToGoal(robot, goal=(5.0, 0.0))
    assert policy(robot.scan(), Pose2D(0.0, 0.0, 0.0)) == (robot.v_max, 0.0)
    assert policy.state == "drive" and not policy.reached and policy.distance == 5.0
    # 0.5 m from the goal the distance gain (1/s) slows it to 0.5 m/s unless v_max is lower.
    assert policy(robot.scan(), Pose2D(4.5, 0.0, 0.0)) == (pytest.approx(min(robot.v_max, 0.5)), 0.0)


@pytest.mark.parametrize(("goal", "sign"), [((-1.0, 0.5), 1.0), ((-1.0, -0.5), -1.0), ((0.0, 2.0), 1.0)])
def test_go_to_goal_turns_in_place_toward_a_goal_behind(goal, sign):
    robot = preset("rosbot")
    policy = GoToGoal(robot, goal=goal)
    v, omega = policy(robot.scan(), Pose2D())
    assert v == 0.0 and policy.state == "turn"
    assert math.copysign(1.0, omega) == sign
    assert abs(omega) == pytest.approx(min(2.0 * abs(policy.heading_error), robot.omega_max))


def test_go_to_goal_stops_within_the_stop_radius():
    robot = preset("m2wr")
    policy = GoToGoal(robot, goal=(1.0, 1.0), stop_radius=0.2)
    assert policy(robot.scan(), Pose2D(1.1, 0.9, 2.0)) == (0.0, 0.0)
    assert policy.reached and policy.state == "reached"
    assert policy(robot.scan(), Pose2D(1.3, 1.0, 0.0)) != (0.0, 0.0)
    assert not policy.reached


def test_go_to_goal_ignores_obstacles():
    robot = preset("rosbot")
    policy = GoToGoal(robot, goal=(3.0, 0.0))
    blocked = synthetic_scan(robot, Scene.of(wall(0.3)))
    assert policy(blocked, Pose2D()) == policy(robot.scan(), Pose2D()) == (robot.v_max, 0.0)


@pytest.mark.parametrize("name", PRESET_NAMES)
@pytest.mark.parametrize("start", [Pose2D(0.0, 0.0, 0.0), Pose2D(2.0, -1.0, 2.5), Pose2D(-1.5, 2.0, -1.0)])
def test_go_to_goal_reaches_the_goal_in_open_space(name, start):
    robot = preset(name)
    policy = GoToGoal(robot, goal=(1.0, 1.0))
    pose, scan = start, robot.scan()
    for _ in range(2000):
        v, omega = policy(scan, pose)
        if policy.reached:
            break
        pose = unicycle_step(pose, v, omega, 0.05)
    assert policy.reached
    assert math.hypot(pose.x - 1.0, pose.y - 1.0) <= policy.stop_radius


@given(
    st.sampled_from(PRESET_NAMES),
    st.tuples(*[st.floats(-20, 20)] * 2),
    st.tuples(st.floats(-20, 20), st.floats(-20, 20), st.floats(-10, 10)),
)
def test_go_to_goal_commands_are_within_limits_and_never_reverse(name, goal, pose):
    robot = preset(name)
    policy = GoToGoal(robot, goal=goal)
    v, omega = policy(robot.scan(), pose)
    assert 0.0 <= v <= robot.v_max
    assert abs(omega) <= robot.omega_max
    if policy.state == "drive":
        assert abs(policy.heading_error) <= math.pi / 4 and v > 0.0
    if policy.state == "turn":
        assert v == 0.0 and omega != 0.0


def test_go_to_goal_needs_a_pose_and_a_scan():
    robot = preset("rosbot")
    policy = GoToGoal(robot, goal=(1.0, 0.0))
    with pytest.raises(InvalidConfig, match="needs the robot's pose"):
        policy(robot.scan())
    with pytest.raises(InvalidConfig, match=r"GoToGoal.pose\[2\] must be a finite number, got nan"):
        policy(robot.scan(), (0.0, 0.0, NAN))
    with pytest.raises(InvalidScanType, match="GoToGoal needs a safenav LaserScan, got list"):
        policy([1.0, 2.0], Pose2D())


def test_go_to_goal_new_goal_resets_the_state():
    robot = preset("rosbot")
    policy = GoToGoal(robot, goal=(0.0, 0.0))
    policy(robot.scan(), Pose2D())
    assert policy.reached
    policy.goal = (2.0, 0.0)
    assert policy.goal == (2.0, 0.0) and policy.state == "idle" and math.isnan(policy.distance)
    with pytest.raises(InvalidConfig, match=r"GoToGoal\.goal must be a sequence of 2 finite numbers"):
        policy.goal = (1.0, 2.0, 3.0)


# ------------------------------------------------------------------ RandomWalk


@given(
    st.sampled_from(PRESET_NAMES),
    st.integers(1, 7),
    st.integers(0, 2**32 - 1),
    st.booleans(),
    st.integers(1, 60),
)
def test_random_walk_stays_within_limits_and_holds_each_command(name, hold_steps, seed, forward_only, n):
    robot = preset(name)
    policy = RandomWalk(robot, hold_steps=hold_steps, seed=seed, forward_only=forward_only)
    commands = [policy(robot.scan()) for _ in range(n)]
    array = np.array(commands)
    assert np.all(array >= robot.lower) and np.all(array <= robot.upper)
    if forward_only:
        assert np.all(array[:, 0] >= 0.0)
    for i in range(1, n):
        assert (commands[i] == commands[i - 1]) is (i % hold_steps != 0)
    assert policy.command == commands[-1] and policy.calls == n


@given(st.integers(0, 2**32 - 1), st.integers(1, 5))
def test_random_walk_same_seed_same_sequence(seed, hold_steps):
    robot = preset("puzzlebot")
    scan = robot.scan()
    first = RandomWalk(robot, hold_steps=hold_steps, seed=seed)
    second = RandomWalk(robot, hold_steps=hold_steps, seed=seed)
    other = RandomWalk(robot, hold_steps=hold_steps, seed=seed + 1)
    sequence = [first(scan) for _ in range(20)]
    assert [second(scan) for _ in range(20)] == sequence
    assert [other(scan) for _ in range(20)] != sequence
    first.reset(seed)
    assert [first(scan) for _ in range(20)] == sequence


def test_random_walk_reset_without_a_seed_continues_the_stream():
    robot = preset("rosbot")
    policy = RandomWalk(robot, hold_steps=3, seed=7)
    first = policy(robot.scan())
    policy.reset()
    assert policy.state == "idle" and policy.command is None
    assert policy(robot.scan()) != first
    assert policy.state == "new command"
    policy(robot.scan())
    assert policy.state == "hold"


def test_random_walk_draws_uniformly_over_the_limits():
    robot = preset("m2wr")
    policy = RandomWalk(robot, hold_steps=1, seed=3)
    draws = np.array([policy(robot.scan()) for _ in range(4000)])
    for column, low, high in ((0, robot.v_min, robot.v_max), (1, -robot.omega_max, robot.omega_max)):
        values = (draws[:, column] - low) / (high - low)  # uniform on [0, 1)
        assert values.min() < 0.01 and values.max() > 0.99
        assert values.mean() == pytest.approx(0.5, abs=0.02)
        assert np.histogram(values, bins=4, range=(0, 1))[0] == pytest.approx([1000] * 4, rel=0.1)


# ------------------------------------------------------------------ make_policy and the common contract

POLICY_KWARGS = {"go_to_goal": {"goal": (1.0, 0.0)}, "random_walk": {"seed": 0}}


@pytest.mark.parametrize("name", POLICY_NAMES)
def test_make_policy_builds_every_policy_for_every_robot(robot, name):
    policy = make_policy(name, robot, **POLICY_KWARGS.get(name, {}))
    expected = {"stop_at_wall": StopAtWall, "stop_at_wall_buggy": StopAtWall, "obstacle_avoidance": ObstacleAvoidance,
                "wall_follower": WallFollower, "go_to_goal": GoToGoal, "random_walk": RandomWalk}[name]
    assert type(policy) is expected and isinstance(policy, Policy)
    assert policy.robot is robot
    if name.startswith("stop_at_wall"):
        assert policy.buggy is (name == "stop_at_wall_buggy")
    if name == "stop_at_wall_buggy" and robot.lidar.n_beams <= 360:
        return  # the tutorial's bug needs beam 360 (tested above)
    command = policy(robot.scan(), Pose2D())
    assert isinstance(command, Command) and all(isinstance(x, float) and math.isfinite(x) for x in command)
    assert robot.lower[0] <= command.v <= robot.upper[0] and abs(command.omega) <= robot.omega_max
    assert isinstance(policy.state, str) and policy.state
    policy.reset(seed=1)


def test_make_policy_passes_arguments_through():
    policy = make_policy("wall_follower", preset("m2wr"), threshold=1.0, clamp=5.0)
    assert (policy.threshold, policy.clamp) == (1.0, 5.0)
    assert make_policy("random_walk", preset("rosbot"), hold_steps=4).hold_steps == 4


def test_make_policy_unknown_name_lists_the_names():
    message = ("unknown policy 'bug2'; expected one of: go_to_goal, obstacle_avoidance, random_walk, stop_at_wall, "
               "stop_at_wall_buggy, wall_follower")
    with pytest.raises(UnknownName, match=message):
        make_policy("bug2", preset("rosbot"))


def test_make_policy_needs_a_robot_spec():
    with pytest.raises(InvalidConfig, match="make_policy: robot must be a RobotSpec"):
        make_policy("stop_at_wall", "rosbot")


@pytest.mark.parametrize("policy", [StopAtWall(), ObstacleAvoidance(), WallFollower(),
                                    RandomWalk(preset("rosbot"), seed=0)],
                         ids=lambda policy: type(policy).__name__)
@pytest.mark.parametrize("scan", [None, [1.0] * 720, "scan"])
def test_policies_reject_what_is_not_a_scan(policy, scan):
    with pytest.raises(InvalidScanType, match=f"{type(policy).__name__} needs a safenav LaserScan"):
        policy(scan)


ROSBOT = preset("rosbot")
BAD_CONFIGS = [
    (lambda: StopAtWall(speed=0.0), "StopAtWall.speed must be a finite number > 0, got 0.0"),
    (lambda: StopAtWall(threshold=NAN), "StopAtWall.threshold must be a finite number > 0, got nan"),
    (lambda: StopAtWall(threshold=True), "StopAtWall.threshold must be a finite number > 0, got True"),
    (lambda: StopAtWall(front_half_width=-0.1), r"StopAtWall.front_half_width must be an angle in \[0, 1.5708\]"),
    (lambda: StopAtWall(front_index=-1), "StopAtWall.front_index must be an integer >= 0 or None, got -1"),
    (lambda: StopAtWall(front_index=360.0), "StopAtWall.front_index must be an integer >= 0 or None, got 360.0"),
    (lambda: StopAtWall(front_index=360, front_half_width=0.1), "front_half_width must be 0, got 0.1"),
    (lambda: StopAtWall(robot="rosbot"), "StopAtWall.robot must be a RobotSpec"),
    (lambda: ObstacleAvoidance(threshold=-0.5), "ObstacleAvoidance.threshold must be a finite number > 0"),
    (lambda: ObstacleAvoidance(half_angle=0.0), r"ObstacleAvoidance.half_angle must be an angle in \(0, 3.14159\]"),
    (lambda: ObstacleAvoidance(half_angle=4.0), "ObstacleAvoidance.half_angle must be an angle in .* got 4.0"),
    (lambda: ObstacleAvoidance(cruise=(0.2,)), r"ObstacleAvoidance.cruise must be a pair \(v \[m/s\]"),
    (lambda: ObstacleAvoidance(turn=(0.0, INF)), r"ObstacleAvoidance.turn\[1\] must be a finite number, got inf"),
    (lambda: ObstacleAvoidance(turn="fast"), "ObstacleAvoidance.turn must be a pair"),
    (lambda: WallFollower(clamp=1.5), "WallFollower.clamp must be > threshold=1.5"),
    (lambda: WallFollower(threshold=0), "WallFollower.threshold must be a finite number > 0, got 0"),
    (lambda: WallFollower(span=7.0), r"WallFollower.span must be an angle in \(0, 6.28319\] rad, got 7.0"),
    (lambda: WallFollower(follow_wall=(NAN, 0.0)), r"WallFollower.follow_wall\[0\] must be a finite number"),
    (lambda: GoToGoal("rosbot", (1.0, 0.0)), "GoToGoal.robot must be a RobotSpec"),
    (lambda: GoToGoal(ROSBOT, (1.0,)), "GoToGoal.goal must be a sequence of 2 finite numbers"),
    (lambda: GoToGoal(ROSBOT, (1.0, INF)), r"GoToGoal.goal\[1\] must be a finite number, got inf"),
    (lambda: GoToGoal(ROSBOT, (1.0, 0.0), speed=2.0), "GoToGoal.speed must be at most robot.v_max=1.0 m/s, got 2.0"),
    (lambda: GoToGoal(ROSBOT, (1.0, 0.0), stop_radius=0.0), "GoToGoal.stop_radius must be a finite number > 0"),
    (lambda: GoToGoal(ROSBOT, (1.0, 0.0), heading_gain=-1.0), "GoToGoal.heading_gain must be a finite number > 0"),
    (lambda: GoToGoal(ROSBOT, (1.0, 0.0), turn_in_place_angle=2.0), "GoToGoal.turn_in_place_angle must be an angle"),
    (lambda: RandomWalk(ROSBOT, hold_steps=0), "RandomWalk.hold_steps must be an integer >= 1, got 0"),
    (lambda: RandomWalk(ROSBOT, hold_steps=2.5), "RandomWalk.hold_steps must be an integer >= 1, got 2.5"),
    (lambda: RandomWalk(ROSBOT, forward_only=1), "RandomWalk.forward_only must be True or False, got 1"),
    (lambda: RandomWalk(ROSBOT, seed=-3), "RandomWalk seed must be None or a non-negative integer, got -3"),
    (lambda: RandomWalk(None), "RandomWalk.robot must be a RobotSpec"),
]


@pytest.mark.parametrize(("build", "message"), BAD_CONFIGS)
def test_bad_configs_name_the_value(build, message):
    with pytest.raises(InvalidConfig, match=message) as info:
        build()
    assert isinstance(info.value, ValueError)


# ------------------------------------------------------------------ closed loop, in each tutorial's world

def tutorial_episode(world_name: str, policy, duration: float, *, world=None):
    from safenav.episode import EpisodeConfig, run_episode
    from safenav.worlds import TUTORIAL_PRESETS, tutorial_world

    robot = preset(TUTORIAL_PRESETS[world_name])
    world = world or tutorial_world(world_name)
    return robot, world, run_episode(world, robot, policy, config=EpisodeConfig(duration=duration), seed=0,
                                     record=True, record_scans=True)


@pytest.mark.sim
def test_stop_at_wall_ends_stopped_between_half_a_metre_and_a_metre_from_the_wall():
    _, _, result = tutorial_episode("stop_at_wall", StopAtWall(robot=preset("rosbot")), 12.0)
    metrics, trajectory = result.metrics, result.trajectory
    assert not metrics.collided
    x, _, yaw = trajectory.pose[-1]
    ahead = (3.0 - x) / math.cos(yaw)          # the wall's near face is the line x = 3 m
    assert 0.5 <= ahead <= 1.0
    assert np.all(np.abs(trajectory.velocity[-20:]) < 1e-9)      # stopped, and stays stopped
    assert trajectory.policy_state[-1] == "stop"


@pytest.mark.sim
def test_the_published_stop_at_wall_drives_into_the_wall():
    _, _, result = tutorial_episode("stop_at_wall", StopAtWall.tutorial_bug(), 12.0)
    assert result.metrics.collided
    assert set(result.trajectory.policy_state) == {"go"}      # beam 360 looks backwards: never sees the wall


@pytest.mark.sim
def test_obstacle_avoidance_turns_away_when_something_enters_its_cone():
    _, _, result = tutorial_episode("obstacle_avoidance", ObstacleAvoidance(robot=preset("puzzlebot")), 40.0)
    trajectory = result.trajectory
    states = trajectory.policy_state
    turning = [index for index, state in enumerate(states) if state == "turn in place"]
    assert turning, "the tutorial world must put something in the cone"
    assert np.allclose(trajectory.u_nom[turning], [0.0, 0.5])
    assert np.allclose(trajectory.u_nom[[i for i, s in enumerate(states) if s == "drive"]], [0.2, 0.3])
    cone = math.radians(15.0)
    ends = [index for index in turning[:-1] if states[index + 1] == "drive"]
    assert ends
    for index in ends:                         # each turn ends with the cone clear again
        after = trajectory.scans[index + 1].sector(-cone, cone)
        assert after.min_range >= 0.5
    assert not result.metrics.collided


@pytest.mark.sim
def test_wall_follower_finds_a_wall_and_follows_it_on_its_right_for_ten_metres():
    from safenav.worlds import tutorial_world

    # Start in the open, 2.5 m from every wall, so that it has to find one first.
    world = tutorial_world("wall_follower").replace(start=Pose2D(2.5, 2.5, 0.0))
    _, _, result = tutorial_episode("wall_follower", WallFollower(robot=preset("m2wr")), 60.0, world=world)
    trajectory = result.trajectory
    states = list(trajectory.policy_state)
    assert states[0] == "find the wall" and "follow the wall" in states
    first_follow = states.index("follow the wall")
    steps = np.diff(trajectory.pose[:, :2], axis=0)
    travelled = float(np.sum(np.hypot(steps[first_follow:, 0], steps[first_follow:, 1])))
    assert travelled >= 10.0                   # before the episode ends or the robot touches anything
    right = (-math.radians(108), -math.radians(18))    # the tutorial's "right" and "front-right" sectors
    following = [index for index in range(first_follow, len(states)) if states[index] == "follow the wall"]
    wall_on_right = [trajectory.scans[index].sector(*right).min_range < 1.5 for index in following]
    assert np.mean(wall_on_right) > 0.95


@pytest.mark.sim
def test_go_to_goal_reaches_a_goal_in_free_space_and_hits_an_obstacle_on_the_way():
    from safenav.episode import EpisodeConfig, run_episode
    from safenav.worlds import Cylinder, Wall, World

    robot = preset("puzzlebot")
    walls = (Wall((-1.0, -2.0), (4.0, -2.0)), Wall((-1.0, 2.0), (4.0, 2.0)))
    free = World("open", walls, start=Pose2D(0.0, 0.0, 0.5), goal=(3.0, 0.5))
    reached = run_episode(free, robot, GoToGoal(robot, free.goal), config=EpisodeConfig(duration=20.0)).metrics
    assert reached.goal_reached and not reached.collided
    blocked = free.replace(obstacles=(*walls, Cylinder((1.5, 0.25), 0.2)))
    crashed = run_episode(blocked, robot, GoToGoal(robot, blocked.goal), config=EpisodeConfig(duration=20.0)).metrics
    assert crashed.collided and not crashed.goal_reached

"""WallFollower (tutorial 3): the eight cases over five sectors, unknown regions, the clamp."""

import math

import numpy as np
import pytest

from safenav import LidarSpec, Pose2D, preset
from safenav.reference import Proximity, WallFollower
from safenav.synthetic import Scene, box, synthetic_scan, wall
from tests.reference.closed_loop import tutorial_episode
from tests.scans import DEG, INF, LIDARS, NAN, scan_of

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

"""Dynamic worlds: movers' paths, exact truth at any time, the simulator's lidar and clearance, seeding, errors."""

import math

import numpy as np
import pytest

from safenav import InvalidConfig, Pose2D, UnknownName, preset
from safenav.episode import EpisodeConfig, run_episode
from safenav.reference import StopAtWall
from safenav.sim_bullet import BulletSim, SimConfig
from safenav.worlds import Box, Cylinder, Wall, World
from safenav.worlds.dynamic import (
    DynamicWorld,
    MovingObstacle,
    crossing,
    head_on,
    overtaking,
    pass_beside,
    patrols,
    random_movers,
    step_in,
)

START = Pose2D(0.0, 0.0, 0.0)
# The pose is then exactly v * t along x; the analytic clearances below are the circumscribed disk's.
EXACT = SimConfig(range_noise=0.0, base="instant", truth="disk")


# ---------------------------------------------------------------------------------------------- paths


def test_constant_velocity_path_position_velocity_and_presence():
    mover = MovingObstacle.constant_velocity(Cylinder((0.0, 0.0), 0.2), start=(1.0, 2.0), velocity=(0.5, -1.0),
                                             appear=2.0, disappear=6.0)
    assert mover.position(2.0) == (1.0, 2.0)
    assert mover.position(4.0) == pytest.approx((2.0, 0.0))
    assert mover.position(10.0) == pytest.approx((3.0, -2.0))   # stays at its last waypoint
    assert mover.velocity(3.0) == pytest.approx((0.5, -1.0))
    assert mover.max_speed == pytest.approx(math.hypot(0.5, 1.0))
    assert [mover.present(t) for t in (1.99, 2.0, 5.99, 6.0)] == [False, True, True, False]
    assert mover.shape_at(1.0) is None
    assert mover.shape_at(4.0) == Cylinder((2.0, 0.0), 0.2)


def test_step_in_walks_onto_the_line_stays_and_walks_back():
    mover = step_in(Pose2D(1.0, 0.0, math.pi / 2), distance=2.0, enter=3.0, stay=4.0, speed=0.5, side_distance=1.0)
    # heading +y: ahead is +y, left is -x
    assert mover.position(1.0) == pytest.approx((0.0, 2.0))        # appears 1 m to the left, 2 s before it enters
    assert mover.position(2.0) == pytest.approx((0.5, 2.0))
    assert mover.position(3.0) == pytest.approx((1.0, 2.0))        # on the line
    assert mover.position(6.5) == pytest.approx((1.0, 2.0))        # stays
    assert mover.position(8.0) == pytest.approx((0.5, 2.0))        # walks back
    assert (mover.appear, mover.disappear) == (1.0, 9.0)


def test_scripted_encounters_move_as_named():
    assert crossing(START, distance=3.0, speed=1.0, time=5.0).position(5.0) == pytest.approx((3.0, 0.0))
    walker = head_on(START, distance=6.0, speed=1.5, appear=1.0)
    assert walker.position(3.0) == pytest.approx((3.0, 0.0))
    chaser = overtaking(START, distance=2.0, speed=1.0, lateral=0.3)
    assert chaser.position(1.0) == pytest.approx((-1.0, 0.3))
    beside = pass_beside(START, distance=5.0, lateral=-1.0, speed=1.0, length=8.0)
    assert beside.position(2.0) == pytest.approx((3.0, -1.0)) and beside.disappear == 8.0


def test_dynamic_world_truth_includes_the_movers_where_they_are():
    mover = MovingObstacle.constant_velocity(Box((0.0, 0.0), (0.4, 0.2)), start=(2.0, 0.0), velocity=(0.0, 1.0))
    world = DynamicWorld("box", obstacles=(Wall((5.0, -1.0), (5.0, 1.0)),), movers=(mover,))
    assert world.clearance_at((0.0, 0.0), 0.1, 0.0) == pytest.approx(2.0 - 0.2 - 0.1)
    assert world.clearance_at((0.0, 0.0), 0.1, 10.0) == pytest.approx(5.0 - 0.05 - 0.1)   # the box has left
    snapshot = world.snapshot(1.0)
    assert isinstance(snapshot, World) and snapshot.obstacles[-1] == Box((2.0, 1.0), (0.4, 0.2))


# ---------------------------------------------------------------------------------------------- simulator truth


@pytest.mark.sim
def test_crossing_obstacle_clearance_and_lidar_match_the_analytic_values():
    robot = preset("rosbot")
    speed, distance, radius, walker_speed, cross_time = 0.3, 2.0, 0.25, 1.2, 3.0
    walker = crossing(START, distance=distance, speed=walker_speed, radius=radius, time=cross_time, offset=3.0)
    world = DynamicWorld("crossing", obstacles=(), movers=(walker,), start=START)
    mount = robot.lidar.mount
    checked_scans = 0
    with BulletSim(world, robot, EXACT, seed=0) as sim:
        state = sim.reset()
        assert state.clearance == math.inf   # not there yet: it appears at 0.5 s
        assert np.all(np.isposinf(state.scan.ranges))
        for _ in range(100):
            previous = state.time
            state = sim.step((speed, 0.0))
            t = state.time
            x_robot = speed * t
            y_walker = walker_speed * (cross_time - t)
            present = cross_time - 2.5 <= t < cross_time + 2.5
            expected = math.hypot(distance - x_robot, y_walker) - radius - robot.radius if present else math.inf
            assert state.clearance == pytest.approx(expected, abs=1e-9)
            # the smallest clearance over the period's physics steps, computed the same way
            steps = previous + np.arange(1, 6) * 0.01
            inside = (steps >= cross_time - 2.5) & (steps < cross_time + 2.5)
            gaps = np.hypot(distance - speed * steps, walker_speed * (cross_time - steps)) - radius - robot.radius
            assert state.min_clearance == pytest.approx(gaps[inside].min() if inside.any() else math.inf, abs=1e-9)
            if present:
                sensor = (x_robot + mount.x, 0.0)
                bearing = math.atan2(y_walker, distance - sensor[0])
                if abs(bearing) < 0.5:
                    expected_range = math.hypot(distance - sensor[0], y_walker) - radius
                    beam = state.scan.beam_index(bearing)
                    # the nearest beam points within half an increment of the centre: its range is the
                    # distance to the circle up to that angle and the polygon's 1 mm
                    assert state.scan.ranges[beam] == pytest.approx(expected_range, abs=0.01)
                    checked_scans += 1
            else:
                assert np.all(np.isposinf(state.scan.ranges))
    assert checked_scans > 5


@pytest.mark.sim
def test_a_collision_with_a_mover_is_recorded_when_it_happens():
    robot = preset("puzzlebot")
    walker = head_on(START, distance=3.0, speed=1.0, radius=0.2)
    with BulletSim(DynamicWorld("head-on", (), movers=(walker,)), robot, EXACT, seed=0) as sim:
        state = sim.reset()
        while state.first_collision_time is None and state.time < 5.0:
            state = sim.step((0.0, 0.0))
    # the walker's front reaches the body when 3 - t = 0.2 + radius
    assert state.first_collision_time == pytest.approx(3.0 - 0.2 - robot.radius, abs=0.01 + 1e-9)


@pytest.mark.sim
def test_with_the_footprint_truth_a_head_on_walker_meets_the_m2wr_s_box_not_its_disk():
    """A walker coming head-on at 1 m/s meets the m2wr's front side (0.25 m ahead of the base) with
    ``truth="footprint"``, (R - 0.25) later than its disk; the clearance with movers is the snapshot's."""
    robot = preset("m2wr")
    walker = head_on(START, distance=3.0, speed=1.0, radius=0.2)
    world = DynamicWorld("head-on", (), movers=(walker,))
    with BulletSim(world, robot, SimConfig(range_noise=0.0, truth="footprint"), seed=0) as sim:
        state = sim.reset()
        while state.first_collision_time is None and state.time < 5.0:
            state = sim.step((0.0, 0.0))
            assert state.clearance == pytest.approx(
                world.snapshot(state.time).footprint_clearance(np.array([tuple(state.pose)]), robot.footprint)[0])
    assert state.first_collision_time == pytest.approx(3.0 - 0.2 - 0.25, abs=0.01 + 1e-9)


# ---------------------------------------------------------------------------------------------- seeding


def test_random_movers_same_seed_same_movers_and_within_the_speed_range():
    first = random_movers(7, 6, start=START, speed=(0.3, 1.5))
    assert first == random_movers(7, 6, start=START, speed=(0.3, 1.5))
    assert first != random_movers(8, 6, start=START, speed=(0.3, 1.5))
    assert all(0.3 - 1e-9 <= mover.max_speed <= 1.5 + 1e-9 for mover in first)
    kinds = random_movers(3, 20, start=START, kinds=("head_on",))
    assert all(mover.waypoints[1][1] < mover.waypoints[0][1] for mover in kinds)   # walking towards -x


@pytest.mark.sim
def test_same_seed_same_episode_in_a_dynamic_world():
    robot = preset("rosbot")

    def episode(seed):
        movers = random_movers(seed, 4, start=START, speed=(0.5, 1.0))
        world = DynamicWorld(f"traffic-{seed}", (), movers=movers, start=START)
        config = EpisodeConfig(duration=4.0, sim=SimConfig(range_noise=0.01), stop_on_collision=False)
        return run_episode(world, robot, StopAtWall(), None, config=config, seed=seed, record=True).trajectory

    first, again, other = episode(5), episode(5), episode(6)
    np.testing.assert_array_equal(first.pose, again.pose)
    np.testing.assert_array_equal(first.clearance, again.clearance)
    assert not np.array_equal(first.clearance, other.clearance)


# ---------------------------------------------------------------------------------------------- errors


@pytest.mark.parametrize(("call", "error", "message"), [
    (lambda: MovingObstacle(Wall((0, 0), (1, 0)), ((0.0, 0.0, 0.0),)), InvalidConfig, "Cylinder or a Box"),
    (lambda: MovingObstacle(Cylinder((0, 0), 0.2), ()), InvalidConfig, "at least one"),
    (lambda: MovingObstacle(Cylinder((0, 0), 0.2), ((1.0, 0.0, 0.0), (1.0, 1.0, 0.0))), InvalidConfig,
     "increase strictly"),
    (lambda: MovingObstacle(Cylinder((0, 0), 0.2), ((0.0, 0.0),)), InvalidConfig, "waypoints[0]"),
    (lambda: MovingObstacle(Cylinder((0, 0), 0.2), ((0.0, 0.0, 0.0),), appear=2.0, disappear=1.0), InvalidConfig,
     "MovingObstacle.disappear"),
    (lambda: DynamicWorld("x", (), movers=(Cylinder((0, 0), 0.2),)), InvalidConfig, "DynamicWorld.movers"),
    (lambda: crossing(START, distance=2.0, speed=0.0), InvalidConfig, "crossing speed"),
    (lambda: random_movers(0, 2, start=START, speed=(1.0, 0.5)), InvalidConfig, "random_movers speed"),
    (lambda: random_movers(0, 2, start=START, kinds=("jogging",)), UnknownName, "jogging"),
])
def test_bad_input_is_a_clear_error(call, error, message):
    with pytest.raises(error, match=message.replace("[", r"\[").replace("]", r"\]")):
        call()


# ---------------------------------------------------------------------------------------------- patrols


def test_patrols_pace_between_two_points_at_the_speed_and_keep_the_start_clear():
    walkers = patrols(4, 5, bounds=(-3.0, -3.0, 3.0, 3.0), speed=0.8, duration=30.0, radius=0.2,
                      keep_clear=(0.0, 0.0, 1.0))
    assert walkers == patrols(4, 5, bounds=(-3.0, -3.0, 3.0, 3.0), speed=0.8, duration=30.0, radius=0.2,
                              keep_clear=(0.0, 0.0, 1.0))
    for walker in walkers:
        table = np.array(walker.waypoints)
        speeds = np.hypot(*np.diff(table[:, 1:], axis=0).T) / np.diff(table[:, 0])
        np.testing.assert_allclose(speeds, 0.8)
        assert table[-1, 0] >= 30.0
        assert np.all(np.abs(table[:, 1:]) <= 3.0 - 0.2 + 1e-9)
        # back and forth: every other turning point is the same
        np.testing.assert_allclose(table[1::2][:, 1:], np.repeat(table[1:2, 1:], len(table[1::2]), axis=0))
        assert math.hypot(*walker.position(0.0)) >= 1.0 + 0.2
    with pytest.raises(InvalidConfig, match="less than 1 m"):
        patrols(0, 1, bounds=(0.0, 0.0, 1.0, 1.0), speed=1.0, duration=5.0)

"""A robot with several lidars in the simulator and in closed loops: every lidar cast, every scan filtered.

The robot is ``tests/test_robot.py``'s CORNERS: an m2wr-sized body with two 270-degree lidars at
opposite corners (``front_left_laser`` on the main mount, ``rear_right_laser`` as the extra one).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from safenav import InvalidConfig, Pose2D, preset
from safenav.episode import EpisodeConfig, run_episode
from safenav.experiments.runner import reproducible_settings
from safenav.filters import make_filter
from safenav.reference import make_policy
from safenav.scenarios import RANDOM_WALK_HOLD, scenario
from safenav.sim_bullet import BulletSim, SimConfig
from safenav.synthetic import synthetic_scan
from safenav.worlds import WALL_THICKNESS, Wall, World
from tests.test_episode import Constant
from tests.test_robot import CORNERS

pytestmark = pytest.mark.sim

EXACT = SimConfig(range_noise=0.0)
HALF_LENGTH, HALF_WIDTH = 2.0, 1.5   # inner faces of the room [m]
DT = 0.05


def room(start: Pose2D) -> World:
    """A closed room whose inner faces are at x = +-HALF_LENGTH and y = +-HALF_WIDTH."""
    x, y = HALF_LENGTH + 0.5 * WALL_THICKNESS, HALF_WIDTH + 0.5 * WALL_THICKNESS
    corners = [(x, y), (-x, y), (-x, -y), (x, -y)]
    walls = tuple(Wall(corners[i], corners[(i + 1) % 4]) for i in range(4))
    return World("room", walls, start=start)


def world_points(scan, pose: Pose2D) -> np.ndarray:
    """The scan's points (base frame, through its mount) in the world frame [m]."""
    points = scan.points()
    c, s = math.cos(pose.yaw), math.sin(pose.yaw)
    return np.column_stack((pose.x + c * points[:, 0] - s * points[:, 1], pose.y + s * points[:, 0] + c * points[:, 1]))


# ---------------------------------------------------------------------------------------------- the simulator


def test_every_lidar_is_cast_on_its_own_mount_and_lands_on_the_room_walls():
    start = Pose2D(0.3, -0.2, 0.4)
    world = room(start)
    with BulletSim(world, CORNERS, EXACT) as sim:
        state = sim.reset()
        later = sim.step((0.0, 0.5))
    assert len(state.scans) == 2 and state.scans[0] is state.scan and later.scans[0] is later.scan
    assert [scan.frame_id for scan in state.scans] == ["front_left_laser", "rear_right_laser"]
    for scan, lidar in zip(state.scans, CORNERS.lidars, strict=True):
        assert scan.mount == lidar.mount and scan.stamp == 0.0 and scan.n_beams == lidar.n_beams
        assert np.all(np.isfinite(scan.ranges))          # a closed room: every beam of the 270 degrees returns
        points = world_points(scan, start)
        on_wall = np.minimum(np.abs(np.abs(points[:, 0]) - HALF_LENGTH), np.abs(np.abs(points[:, 1]) - HALF_WIDTH))
        assert np.max(on_wall) < 1e-4                    # Bullet's hit fraction is a float32
        exact = synthetic_scan(lidar, world.scene(), start).ranges
        assert np.max(np.abs(scan.ranges - exact)) < 1e-4
    # The two lidars face opposite ways: the front-left one sees the +x wall ahead-left, the other the -x wall.
    front, rear = (world_points(scan, start) for scan in state.scans)
    assert np.any(np.abs(front[:, 0] - HALF_LENGTH) < 1e-4) and np.any(np.abs(rear[:, 0] + HALF_LENGTH) < 1e-4)
    assert [scan.stamp for scan in later.scans] == [later.time, later.time]


def test_together_the_two_lidars_see_every_direction_around_the_body():
    start = Pose2D(0.0, 0.0, 0.0)
    with BulletSim(room(start), CORNERS, EXACT) as sim:
        scans = sim.reset().scans
    bearings = np.concatenate([np.arctan2(*world_points(scan, start)[:, ::-1].T) for scan in scans])
    histogram, _ = np.histogram(bearings, bins=72, range=(-math.pi, math.pi))
    assert np.all(histogram > 0)                         # every 5-degree sector of the room is seen
    alone, _ = np.histogram(bearings[:scans[0].n_beams], bins=72, range=(-math.pi, math.pi))
    assert np.any(alone == 0)                            # the main lidar alone leaves the rear-right unseen


def test_one_lidar_robots_report_their_one_scan_in_scans():
    with BulletSim(room(Pose2D()), preset("rosbot"), EXACT) as sim:
        state = sim.reset()
        assert state.scans == (state.scan,)
        assert sim.step((0.2, 0.0)).scans[0].frame_id == preset("rosbot").lidar.frame_id
        assert len(sim.scans()) == 1


def test_an_extra_lidar_has_its_own_noise_and_leaves_the_main_lidars_readings_unchanged():
    config = SimConfig(range_noise=0.01, dropout=0.1)
    world = room(Pose2D(0.3, -0.2, 0.4))
    main_only = CORNERS.replace(extra_lidars=())

    def run(robot, seed):
        with BulletSim(world, robot, config, seed=seed) as sim:
            states = [sim.reset()] + [sim.step((0.1, 0.3)) for _ in range(3)]
        return [state.scans for state in states]

    both, again, alone, other = run(CORNERS, 5), run(CORNERS, 5), run(main_only, 5), run(CORNERS, 6)
    for step in range(4):
        pairs = zip(both[step], again[step], strict=True)
        assert all(np.array_equal(a.ranges, b.ranges, equal_nan=True) for a, b in pairs)
        assert np.array_equal(both[step][0].ranges, alone[step][0].ranges, equal_nan=True)
        assert not np.array_equal(both[step][1].ranges, other[step][1].ranges, equal_nan=True)
    with BulletSim(world, CORNERS, EXACT) as sim:
        truths = sim.reset().scans
    noise = [scan.ranges - truth.ranges for scan, truth in zip(both[0], truths, strict=True)]
    dropped = [np.isnan(scan.ranges) for scan in both[0]]
    for residual, nan in zip(noise, dropped, strict=True):
        assert 0.05 < nan.mean() < 0.15 and 0.007 < np.std(residual[~nan]) < 0.013
    # Their own streams: the two lidars' noise and dropout patterns are not the same draws.
    assert not np.allclose(noise[0][:100], noise[1][:100], equal_nan=True)


def test_scan_latency_delays_every_lidar_alike():
    with BulletSim(room(Pose2D()), CORNERS, SimConfig(range_noise=0.0, scan_latency=2)) as sim:
        sim.reset()
        states = [sim.step((0.2, 0.0)) for _ in range(4)]
    for state in states[1:]:
        assert [scan.stamp for scan in state.scans] == pytest.approx([state.time - 2 * DT] * 2)
    assert states[0].scans[1].stamp == 0.0


def test_an_extra_lidar_above_the_obstacles_is_rejected_by_name():
    robot = CORNERS.replace(extra_lidars=(dataclasses.replace(CORNERS.extra_lidars[0], height=5.0),))
    with pytest.raises(InvalidConfig, match=r"lidar 'rear_right_laser' scans at 5\.0 m, above the obstacles"):
        BulletSim(room(Pose2D()), robot)


# ---------------------------------------------------------------------------------------------- closed loops


class Recording(Constant):
    """A constant nominal that remembers which lidar's scan it was given."""

    def __init__(self, v: float, omega: float = 0.0) -> None:
        super().__init__(v, omega)
        self.frame_ids: list[str] = []

    def __call__(self, scan, pose=None):
        self.frame_ids.append(scan.frame_id)
        return super().__call__(scan, pose)


@pytest.mark.parametrize("filter_name", ["cbf", "mpc"])
def test_the_filter_sees_the_rear_lidar_and_lets_the_robot_back_up_to_a_wall(filter_name):
    """Backing up sweeps the rear-right, which only the extra lidar sees: without its scan the filter holds still."""
    world = World("wall_behind", (Wall((-2.0 - 0.5 * WALL_THICKNESS, -3.0), (-2.0 - 0.5 * WALL_THICKNESS, 3.0)),),
                  start=Pose2D(0.0, 0.0, 0.0))
    safety_filter = make_filter(filter_name, CORNERS, DT, **reproducible_settings(filter_name))
    policy = Recording(-0.3)
    metrics = run_episode(world, CORNERS, policy, safety_filter, config=EpisodeConfig(duration=12.0), seed=0).metrics
    assert not metrics.collided and metrics.fallbacks == 0
    assert metrics.min_clearance >= safety_filter.margin - 0.01
    assert metrics.distance > 2.0 - CORNERS.radius - 0.15        # it backed up to the wall, and stopped there
    assert set(policy.frame_ids) == {"front_left_laser"}          # policies keep the main lidar's scan


def random_walk_cases() -> list:
    return [pytest.param(filter_name, seed, marks=[pytest.mark.slow] if seed >= 1 else [],
                         id=f"{filter_name}-{seed}")
            for filter_name in ("cbf", "mpc") for seed in range(20)]


@pytest.mark.parametrize(("filter_name", "seed"), random_walk_cases())
def test_a_two_lidar_robot_random_walks_in_clutter_without_collisions(filter_name, seed):
    """The random-walk matrix's ``clutter_m2wr`` cell with the corner-lidar robot (acceleration limits active)."""
    task = scenario("clutter_m2wr")
    world = task.world(seed)
    # The MPC without its compute budget, so the episode does not depend on the machine's load
    # (as in tests/test_scenarios.py).
    safety_filter = make_filter(filter_name, CORNERS, DT, **reproducible_settings(filter_name))
    policy = make_policy("random_walk", CORNERS, seed=seed, hold_steps=RANDOM_WALK_HOLD)
    metrics = run_episode(world, CORNERS, policy, safety_filter, config=EpisodeConfig(duration=task.duration),
                          seed=seed).metrics
    assert not metrics.collided, f"collision at t={metrics.collision_time}"
    assert metrics.min_clearance >= safety_filter.margin - 0.01
    assert metrics.fallbacks == 0
    assert metrics.distance > 1.0                                 # it did walk

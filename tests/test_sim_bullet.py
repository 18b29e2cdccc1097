"""The PyBullet simulator: lidar truth, exact clearance, the base models' kinematics, noise streams, errors."""

import itertools
import math
import subprocess
import sys

import numpy as np
import pytest

from safenav import PRESET_NAMES, InvalidCommand, InvalidCommandType, InvalidConfig, Pose2D, UnknownName, preset
from safenav.sim_bullet import BulletSim, SimConfig, SimulatorError, gui_problem
from safenav.synthetic import Circle, Scene, cast, synthetic_scan
from safenav.worlds import START_CLEARANCE, WALL_THICKNESS, Box, Cylinder, Wall, World, random_world, tutorial_world

pytestmark = pytest.mark.sim

# The m2wr preset has 1 cm of lidar noise; truth tests switch it off, and measure the circumscribed disk.
EXACT = SimConfig(range_noise=0.0, truth="disk")


def wall_ahead(pose: Pose2D, distance: float, length: float = 6.0) -> Wall:
    """A wall whose near face is ``distance`` ahead of ``pose``, perpendicular to its heading."""
    c, s = math.cos(pose.yaw), math.sin(pose.yaw)
    centre = distance + 0.5 * WALL_THICKNESS
    cx, cy = pose.x + centre * c, pose.y + centre * s
    return Wall((cx + 0.5 * length * s, cy - 0.5 * length * c), (cx - 0.5 * length * s, cy + 0.5 * length * c))


# ---------------------------------------------------------------------------------------------- lidar truth


@pytest.mark.parametrize("name", PRESET_NAMES)
def test_a_wall_ahead_reads_its_distance_on_the_front_beam(name):
    robot = preset(name)
    start = Pose2D(1.0, -2.0, 2.0)
    sensor = start.compose(robot.lidar.mount)
    world = World("wall", (wall_ahead(Pose2D(sensor.x, sensor.y, start.yaw), 2.0),), start=start)
    with BulletSim(world, robot, EXACT) as sim:
        scan = sim.reset().scan
    front = scan.beam_index(0.0)
    assert scan.ranges[front] == pytest.approx(2.0, abs=0.01)
    assert scan.ranges[front] == pytest.approx(2.0, abs=1e-4)   # walls are exact; Bullet's hit fraction is float32
    assert np.nanargmin(np.where(np.isfinite(scan.ranges), scan.ranges, np.inf)) in (front - 1, front, front + 1)
    assert scan.mount == robot.lidar.mount and scan.stamp == 0.0
    assert (scan.angle_min, scan.n_beams) == (robot.lidar.angle_min, robot.lidar.n_beams)


@pytest.mark.parametrize("name", PRESET_NAMES)
def test_a_box_to_the_left_appears_at_plus_ninety_degrees(name):
    robot = preset(name)
    start = Pose2D(-1.0, 0.5, -0.7)
    sensor = start.compose(robot.lidar.mount)
    left = Pose2D(sensor.x, sensor.y, start.yaw).compose(Pose2D(0.0, 1.5, 0.0))   # 1.5 m left of the lidar
    world = World("box", (Box((left.x, left.y), (0.4, 0.4), yaw=start.yaw),), start=start)
    with BulletSim(world, robot, EXACT) as sim:
        scan = sim.reset().scan
    assert scan.ranges[scan.beam_index(math.pi / 2)] == pytest.approx(1.3, abs=0.01)
    seen = np.flatnonzero(np.isfinite(scan.ranges))
    directions = scan.base_angles[seen]
    assert np.all(np.abs(directions - math.pi / 2) < math.atan2(0.2, 1.3) + scan.angle_increment)
    assert scan.ranges[scan.beam_index(-math.pi / 2)] == math.inf
    assert scan.ranges[scan.beam_index(0.0)] == math.inf


@pytest.mark.parametrize("name", PRESET_NAMES)
def test_nothing_in_range_reads_plus_infinity(name):
    robot = preset(name)
    far = World("far", (wall_ahead(Pose2D(), robot.lidar.range_max + 1.0),))
    for world in (World("empty", ()), far):
        with BulletSim(world, robot, EXACT) as sim:
            scan = sim.reset().scan
        assert np.all(scan.ranges == math.inf)


def test_objects_closer_than_range_min_read_minus_infinity():
    robot = preset("rosbot")   # range_min 0.15 m
    world = World("close", (wall_ahead(Pose2D(), 0.1),))
    with BulletSim(world, robot, EXACT) as sim:
        state = sim.reset()
    assert state.scan.ranges[state.scan.beam_index(0.0)] == -math.inf
    assert state.collided   # 0.1 m is inside the body disk


def test_a_sensor_inside_an_obstacle_reads_minus_infinity_everywhere():
    world = World("inside", (Box((0.0, 0.0), (2.0, 2.0)),))
    with BulletSim(world, preset("puzzlebot"), EXACT) as sim:
        assert np.all(sim.reset().scan.ranges == -math.inf)


@pytest.mark.parametrize(("x", "inside"), [(0.55, False), (0.26, False), (0.2, False), (0.1, True), (-0.2, True)])
def test_with_the_footprint_truth_the_lidar_reads_minus_infinity_only_from_inside_an_obstacle(x, inside, monkeypatch):
    """The m2wr's lidar sits 0.15 m ahead of the base, inside its 0.5 x 0.3 m box (front at 0.25 m). A block whose
    near face is ``x`` ahead: clear of the box, overlapping the box but not the lidar, overlapping the lidar. The
    lidar's own clearance is looked up only when the footprint overlaps something (a clear footprint holds its lidar
    clear)."""
    robot = preset("m2wr")
    world = World("block", (Box((x + 0.2, 0.0), (0.4, 2.0)),))
    with BulletSim(world, robot, SimConfig(range_noise=0.0, truth="footprint")) as sim:
        assert sim._cast_lidars[0].in_footprint
        looked_up = []
        real = sim._disk_truth
        monkeypatch.setattr(sim, "_disk_truth", lambda *args: looked_up.append(args) or real(*args))
        state = sim.reset()
    assert state.collided == (x < 0.25)
    assert bool(looked_up) == state.collided
    assert np.all(state.scan.ranges == -math.inf) == inside
    if not inside:
        assert np.isfinite(state.scan.ranges).any()


@pytest.mark.parametrize("name", PRESET_NAMES)
def test_bullet_scans_match_the_analytic_ray_caster_in_random_worlds(name):
    """Walls and boxes are exact; a cylinder is seen as its polygon, between the circle and the circle + tolerance.

    Bullet's triangle ray test accepts a hit up to 1e-4 of a face's width past the face's edge (the
    sim_bullet docstring), so a beam grazing a corner may read the face it just misses: the lower
    bound is the world with every box that much larger.
    """
    robot = preset(name)
    world = random_world(3, robot, corridors=1, n_obstacles=20)
    tolerance = EXACT.cylinder_tolerance
    grazed = world.replace(obstacles=tuple(
        Box(box.center, (box.size[0] * (1 + 2e-4), box.size[1] * (1 + 2e-4)), box.yaw)
        for box in (o.box if isinstance(o, Wall) else o for o in world.obstacles) if isinstance(box, Box)))
    fat = Scene(grazed.scene().segments, tuple(Circle(c.center, c.radius + tolerance) for c in world.scene().circles))
    rng = np.random.default_rng(0)
    checked = 0
    with BulletSim(world, robot, EXACT) as sim:
        sim.reset()
        while checked < 8:
            pose = Pose2D(*rng.uniform(-4.5, 4.5, 2), rng.uniform(-math.pi, math.pi))
            if world.clearance(pose, robot.radius) < 0.0:
                continue
            checked += 1
            scan = sim.scan(pose)
            exact = synthetic_scan(robot, world.scene(), pose).ranges
            sensor = pose.compose(robot.lidar.mount)
            inflated = cast((sensor.x, sensor.y), scan.angles + sensor.yaw, fat)
            inflated[inflated > robot.lidar.range_max] = math.inf
            finite = np.isfinite(exact)
            assert np.array_equal(np.isfinite(scan.ranges) | ~finite, np.ones_like(finite))
            # Bullet's hit fraction is a float32: 1e-5 m covers it over 30 m rays.
            assert np.all(scan.ranges[finite] <= exact[finite] + 1e-5)          # never long
            assert np.all(scan.ranges[finite] >= inflated[finite] - 1e-5)       # at most the polygon's excess
            assert np.median(np.abs(scan.ranges[finite] - exact[finite])) < 1e-5


def test_mount_yaw_error_turns_the_world_in_the_reported_scan():
    robot = preset("puzzlebot")
    world = World("wall", (wall_ahead(Pose2D(), 1.0),))
    with BulletSim(world, robot, SimConfig(range_noise=0.0, mount_yaw_error=0.1)) as sim:
        scan = sim.reset().scan
    nearest = int(np.argmin(np.where(np.isfinite(scan.ranges), scan.ranges, np.inf)))
    assert scan.base_angles[nearest] == pytest.approx(-0.1, abs=scan.angle_increment)
    assert scan.mount == robot.lidar.mount   # the scan reports the nominal mount


def test_range_noise_and_dropout_follow_the_config():
    robot = preset("rosbot")
    world = World("room", tuple(wall_ahead(Pose2D(0, 0, yaw), 2.0, 5.0) for yaw in np.arange(4) * math.pi / 2))
    config = SimConfig(range_noise=0.02, dropout=0.1)
    with BulletSim(world, robot, config, seed=1) as noisy, BulletSim(world, robot, EXACT) as exact:
        truth = exact.reset().scan.ranges
        scans = [noisy.reset().scan.ranges] + [noisy.step((0.0, 0.0)).scan.ranges for _ in range(4)]
    readings = np.concatenate(scans)
    dropped = np.isnan(readings)
    assert 0.07 < dropped.mean() < 0.13
    residual = (readings - np.tile(truth, 5))[~dropped]
    assert abs(np.mean(residual)) < 0.003
    assert np.std(residual) == pytest.approx(0.02, rel=0.1)
    assert not np.array_equal(scans[0], scans[1], equal_nan=True)


def test_preset_noise_is_the_default():
    robot = preset("m2wr")   # 1 cm Gaussian noise in its tutorial model
    world = World("wall", (wall_ahead(Pose2D(), 3.0, 20.0),))
    with BulletSim(world, robot, seed=0) as sim:
        scan = sim.reset().scan
    front = scan.ranges[scan.sector_mask(-0.3, 0.3)]
    truth = 2.85 / np.cos(scan.base_angles[scan.sector_mask(-0.3, 0.3)])
    assert np.std(front - truth) == pytest.approx(0.01, rel=0.3)


# ---------------------------------------------------------------------------------------------- clearance truth


@pytest.mark.parametrize("name", PRESET_NAMES)
def test_clearance_to_a_wall_at_a_known_distance(name):
    robot = preset(name)
    start = Pose2D(0.5, 0.3, 0.4)
    distance = 0.7
    world = World("wall", (wall_ahead(start, robot.radius + distance),), start=start)
    with BulletSim(world, robot, EXACT) as sim:
        state = sim.reset()
        assert state.clearance == pytest.approx(distance, abs=1e-9)
        assert sim.bullet_clearance() == pytest.approx(distance, abs=0.01)
        assert not state.collided and state.first_collision_time is None


def test_analytic_clearance_agrees_with_bullet_closest_points():
    robot = preset("rosbot")
    world = random_world(5, robot, corridors=1)
    rng = np.random.default_rng(1)
    tolerance = EXACT.cylinder_tolerance
    compared = 0
    with BulletSim(world, robot, EXACT) as sim:
        sim.reset()
        for _ in range(200):
            pose = Pose2D(*rng.uniform(-5.0, 5.0, 2), 0.0)
            truth = world.clearance(pose, robot.radius)
            if not -0.1 < truth < 1.0:
                continue
            compared += 1
            bullet = sim.bullet_clearance(pose)
            # The polygon of a cylinder is up to `tolerance` larger than the circle.
            assert truth - tolerance - 2e-3 <= bullet <= truth + 2e-3
    assert compared > 20


def test_driving_into_a_wall_raises_the_collision_flag_at_the_right_time():
    robot = preset("rosbot")
    world = tutorial_world("stop_at_wall")   # wall face 3 m ahead
    with BulletSim(world, robot, EXACT) as sim:
        state = sim.reset()
        states = [sim.step((0.5, 0.0)) for _ in range(140)]   # 7 s
    first = next(s for s in states if s.collided)
    # Accelerate to 0.5 m/s at 1.5 m/s^2, then cruise: contact after 3 - R m.
    ramp = 0.5 / robot.a_max
    expected = ramp + (3.0 - robot.radius - 0.5 * 0.5 * ramp) / 0.5
    assert first.first_collision_time == pytest.approx(expected, abs=0.02)
    assert first.min_clearance < 0.0 and state.clearance > 0.0
    # Contacts are recorded, not resolved: the robot passes through and the first time stays.
    assert not states[-1].collided and states[-1].pose.x > 3.2
    assert states[-1].first_collision_time == first.first_collision_time


@pytest.mark.parametrize("yaw", [0.0, 0.5 * math.pi])
def test_with_the_footprint_truth_the_m2wr_touches_a_wall_when_its_box_does_not_its_disk(yaw):
    """The m2wr (a 0.5 x 0.3 m box in a 0.292 m disk) driven head-on into a wall, along x or along y: with
    ``truth="footprint"`` the contact comes when the box's front reaches the wall, (R - 0.25) / v later than the
    disk's. The clearance turns with the heading: a quarter turn at the start puts the long side 0.15 m from
    the centre towards the wall."""
    robot = preset("m2wr")
    start = Pose2D(0.0, 0.0, yaw)
    world = World("wall", (wall_ahead(start, 1.0),), start=start)
    times = {}
    for truth in ("disk", "footprint"):
        with BulletSim(world, robot, SimConfig(range_noise=0.0, base="instant", truth=truth)) as sim:
            state = sim.reset()
            assert state.clearance == pytest.approx(1.0 - (robot.radius if truth == "disk" else 0.25), abs=1e-9)
            states = [sim.step((0.5, 0.0)) for _ in range(60)]
            times[truth] = next(s for s in states if s.collided).first_collision_time
            assert sim.clearance(Pose2D(0.0, 0.0, yaw + 0.5 * math.pi)) == pytest.approx(
                1.0 - (robot.radius if truth == "disk" else 0.15), abs=1e-9)
    assert times["footprint"] - times["disk"] == pytest.approx((robot.radius - 0.25) / 0.5, abs=0.011)


def test_the_footprint_truth_needs_a_convex_footprint_and_a_pose_with_its_yaw_and_a_round_robot_keeps_its_disk():
    world = World("empty", (Cylinder((5.0, 5.0), 0.1),))
    with BulletSim(world, preset("puzzlebot"), SimConfig(truth="footprint")) as sim:      # round: its disk
        assert sim.reset().clearance == pytest.approx(world.clearance(world.start, preset("puzzlebot").radius))
    concave = preset("m2wr").replace(footprint=((0.25, 0.15), (0.0, 0.0), (-0.25, 0.15), (-0.25, -0.15), (0.25, -0.15)))
    with pytest.raises(InvalidConfig, match="needs a convex footprint"):
        BulletSim(world, concave, SimConfig(truth="footprint"))
    with BulletSim(world, preset("m2wr"), SimConfig(truth="footprint")) as sim:
        sim.reset()
        with pytest.raises(InvalidConfig, match=r"the pose needs its yaw \(x \[m\], y \[m\], yaw \[rad\]\)"):
            sim.clearance((1.0, 1.0))
    with pytest.raises(UnknownName, match=r"SimConfig\.truth"):
        SimConfig(truth="hull")


def test_by_default_the_footprint_is_measured_and_the_disk_of_a_round_robot_or_a_concave_footprint():
    """What touches an obstacle is the footprint (and the filters keep it clear with their narrow body where the
    circumscribed disk would not fit): ``truth="auto"``, the default, measures it when it is convex."""
    start = Pose2D(0.0, 0.0, 0.0)
    world = World("wall", (wall_ahead(start, 1.0),), start=start)
    concave = preset("m2wr").replace(footprint=((0.25, 0.15), (0.0, 0.0), (-0.25, 0.15), (-0.25, -0.15), (0.25, -0.15)))
    assert SimConfig().truth == "auto"
    for robot, reach in ((preset("m2wr"), 0.25), (preset("puzzlebot"), preset("puzzlebot").radius),
                         (concave, concave.radius)):
        with BulletSim(world, robot, SimConfig(range_noise=0.0)) as sim:
            assert sim.reset().clearance == pytest.approx(1.0 - reach, abs=1e-9)


def test_a_robot_far_from_everything_never_collides():
    robot = preset("m2wr")
    world = World("far", (Wall((-10.0, 10.0), (10.0, 10.0)), Cylinder((8.0, -8.0), 1.0)))
    with BulletSim(world, robot, SimConfig(actuation_noise=0.1), seed=0) as sim:
        sim.reset()
        states = [sim.step((0.8, 1.0)) for _ in range(200)]
    assert not any(s.collided for s in states)
    assert all(s.first_collision_time is None for s in states)
    assert min(s.min_clearance for s in states) > 5.0


def test_random_worlds_start_collision_free_in_the_simulator():
    robot = preset("rosbot")
    for seed in range(3):
        with BulletSim(random_world(seed, robot, goal=True), robot, EXACT) as sim:
            state = sim.reset()
            assert not state.collided and state.clearance >= START_CLEARANCE - 1e-9
            assert sim.bullet_clearance() >= START_CLEARANCE - 1e-2


# ---------------------------------------------------------------------------------------------- kinematics


@pytest.mark.parametrize("name", PRESET_NAMES)
def test_commands_are_reached_no_faster_than_the_acceleration_limits(name):
    robot = preset(name)
    config = SimConfig(control_dt=0.05, physics_dt=0.01, range_noise=0.0)
    with BulletSim(World("empty", ()), robot, config) as sim:
        previous = sim.reset().velocity
        target = np.array([robot.v_max, robot.omega_max])
        history = []
        for _ in range(60):
            state = sim.step(10.0 * target)   # beyond the limits: clipped
            change = np.abs(state.velocity - previous)
            assert np.all(change <= np.array([robot.a_max, robot.alpha_max]) * config.control_dt + 1e-12)
            assert np.all(np.abs(state.velocity) <= target + 1e-12)
            np.testing.assert_allclose(state.command, target)
            history.append(state.velocity)
            previous = state.velocity
    history = np.array(history)
    for axis, limit in ((0, robot.a_max), (1, robot.alpha_max)):
        reached = np.flatnonzero(np.isclose(history[:, axis], target[axis]))[0]
        # Full speed within one physics step of the fastest possible time, not earlier.
        assert (reached + 1) * config.control_dt >= target[axis] / limit - 1e-9
        assert (reached + 1) * config.control_dt <= target[axis] / limit + config.control_dt + 1e-9


def test_a_straight_run_covers_v_times_t():
    robot = preset("rosbot")
    with BulletSim(World("empty", ()), robot, EXACT) as sim:
        sim.reset()
        for _ in range(20):   # 1 s: well past the 1/3 s ramp
            state = sim.step((0.5, 0.0))
        start = state.pose
        for _ in range(40):
            state = sim.step((0.5, 0.0))
    assert state.pose.x - start.x == pytest.approx(0.5 * 2.0, abs=1e-9)
    assert state.pose.y == pytest.approx(0.0, abs=1e-12) and state.pose.yaw == 0.0


@pytest.mark.parametrize("v", [0.0, 0.3])
def test_a_full_turn_returns_to_the_start_heading(v):
    robot = preset("puzzlebot")
    omega = 2.0 * math.pi / 5.0   # one turn in exactly 100 control periods of 0.05 s
    with BulletSim(World("empty", (), start=Pose2D(1.0, 2.0, 0.5)), robot, EXACT) as sim:
        sim.reset()
        for _ in range(40):
            state = sim.step((v, omega))
        start = state.pose
        halfway = None
        for k in range(100):
            state = sim.step((v, omega))
            if k == 49:
                halfway = state.pose
    assert math.remainder(state.pose.yaw - start.yaw, 2 * math.pi) == pytest.approx(0.0, abs=1e-9)
    assert (state.pose.x, state.pose.y) == pytest.approx((start.x, start.y), abs=1e-9)
    assert abs(math.remainder(halfway.yaw - start.yaw, 2 * math.pi)) == pytest.approx(math.pi, abs=1e-9)
    if v > 0:   # a circle of radius v / omega: half way round it is one diameter away
        assert math.dist(halfway[:2], start[:2]) == pytest.approx(2 * v / omega, abs=1e-9)


def test_time_and_steps_follow_the_control_period():
    with BulletSim(World("empty", ()), preset("rosbot"), SimConfig(control_dt=0.1, physics_dt=0.02)) as sim:
        sim.reset()
        for _ in range(7):
            state = sim.step((0.1, 0.0))
    assert state.time == pytest.approx(0.7, abs=1e-12) and state.steps == 7
    assert state.scan.stamp == state.time


# ---------------------------------------------------------------------------------------------- latency and noise


def test_command_latency_delays_execution_by_whole_periods():
    with BulletSim(World("empty", ()), preset("rosbot"), SimConfig(command_latency=2)) as sim:
        sim.reset()
        first = sim.step((0.5, 0.0))
        second = sim.step((0.2, 0.0))
        third = sim.step((0.0, 0.0))
    np.testing.assert_array_equal(first.command, [0.0, 0.0])
    np.testing.assert_array_equal(first.velocity, [0.0, 0.0])
    np.testing.assert_array_equal(second.command, [0.0, 0.0])
    np.testing.assert_array_equal(third.command, [0.5, 0.0])
    assert third.velocity[0] > 0.0 and second.pose == Pose2D(0.0, 0.0, 0.0)


def test_scan_latency_delivers_old_scans_with_their_acquisition_stamp():
    robot = preset("rosbot")
    world = tutorial_world("stop_at_wall")
    with BulletSim(world, robot, SimConfig(scan_latency=2, range_noise=0.0)) as sim, \
            BulletSim(world, robot, EXACT) as prompt:
        delayed = [sim.reset()] + [sim.step((0.5, 0.0)) for _ in range(5)]
        fresh = [prompt.reset()] + [prompt.step((0.5, 0.0)) for _ in range(5)]
    assert [s.scan.stamp for s in delayed] == pytest.approx([0.0, 0.0, 0.0, 0.05, 0.10, 0.15])
    for k in range(2, 6):
        np.testing.assert_array_equal(delayed[k].scan.ranges, fresh[k - 2].scan.ranges)
        assert delayed[k].pose == fresh[k].pose   # only the scan is late


def _counting_casts(monkeypatch) -> list[int]:
    """Count PyBullet's ray batches from now on (the simulator looks the function up at each cast)."""
    import pybullet

    calls = [0]
    real = pybullet.rayTestBatch

    def counted(*args, **kwargs):
        calls[0] += 1
        return real(*args, **kwargs)

    monkeypatch.setattr(pybullet, "rayTestBatch", counted)
    return calls


def _drive_then_rest(sim: BulletSim, forget: bool) -> list:
    """Drive 0.3 m/s towards the wall, command a stop and wait at rest; with ``forget`` the simulator
    keeps no last cast (every period casts afresh). A scan from elsewhere is taken half way through."""
    states = [sim.reset()]
    for k in range(40):
        if forget:
            sim._last_cast = (None, sim._last_cast[1])
        if k == 30:
            sim.scan(Pose2D(0.5, 0.2, 1.0))        # moves the body for its cast; the next period is back
        states.append(sim.step((0.3, 0.0) if k < 8 else (0.0, 0.0)))
    return states


def test_a_base_at_rest_reuses_its_last_rays_and_clearance_and_reads_as_a_fresh_cast(monkeypatch):
    robot = preset("rosbot")
    world = tutorial_world("stop_at_wall")
    config = SimConfig(range_noise=0.01, dropout=0.05)
    calls = _counting_casts(monkeypatch)
    with BulletSim(world, robot, config, seed=3) as sim:
        reusing = _drive_then_rest(sim, forget=False)
    reused_casts, calls[0] = calls[0], 0
    with BulletSim(world, robot, config, seed=3) as sim:
        fresh = _drive_then_rest(sim, forget=True)
    assert calls[0] == 42                              # reset, 40 periods, the scan from elsewhere
    moved = sum(after.pose != before.pose for before, after in itertools.pairwise(reusing))
    assert 8 <= moved < 20 and reusing[-1].velocity.tolist() == [0.0, 0.0]
    assert reused_casts == 1 + moved + 2               # the stray scan, and the period after it
    for a, b in zip(reusing, fresh, strict=True):       # the same scans, noise and dropout drawn alike
        assert a.pose == b.pose and a.clearance == b.clearance and a.min_clearance == b.min_clearance
        np.testing.assert_array_equal(a.scan.ranges, b.scan.ranges)


def test_among_moving_obstacles_a_base_at_rest_casts_every_period(monkeypatch):
    from safenav.worlds.dynamic import DynamicWorld, head_on

    walker = head_on(Pose2D(), distance=3.0, speed=1.0, radius=0.2)
    calls = _counting_casts(monkeypatch)
    with BulletSim(DynamicWorld("head-on", (), movers=(walker,)), preset("puzzlebot"), EXACT, seed=0) as sim:
        states = [sim.reset()] + [sim.step((0.0, 0.0)) for _ in range(20)]
    assert calls[0] == 21
    front = [float(np.nanmin(np.abs(state.scan.ranges))) for state in states]
    assert all(later < earlier for earlier, later in itertools.pairwise(front))   # the walker comes closer
    assert states[-1].clearance < states[0].clearance - 0.9


def test_the_compiled_footprint_truth_gives_the_same_episode(monkeypatch):
    """``SimConfig.kernels``: the m2wr driven through clutter into contact with the footprint truth computed by
    numba and by numpy: the same poses, clearances, period minima and first contact; ``SAFENAV_KERNELS`` decides
    ``"auto"``; a bad value is named."""
    pytest.importorskip("numba", reason="the compiled kernels need numba (pip install 'safenav[fast]')")
    robot = preset("m2wr")
    world = random_world(3, robot, n_obstacles=25)
    runs = {}
    for kernels in ("numba", "numpy"):
        with BulletSim(world, robot, SimConfig(kernels=kernels, truth="footprint"), seed=1) as sim:
            assert (sim._gap_kernels is not None) == (kernels == "numba")
            rng = np.random.default_rng(4)
            states = [sim.reset()] + [sim.step((rng.uniform(0.2, 0.6), rng.uniform(-1.5, 1.5))) for _ in range(300)]
        runs[kernels] = [(s.pose, s.clearance, s.min_clearance, s.first_collision_time) for s in states]
    assert runs["numba"] == runs["numpy"]
    assert runs["numpy"][-1][3] is not None and min(run[2] for run in runs["numpy"]) < 0.0   # contact, overlap
    monkeypatch.setenv("SAFENAV_KERNELS", "numpy")
    with BulletSim(world, robot, SimConfig(truth="footprint")) as sim:
        assert sim._gap_kernels is None
    with pytest.raises(UnknownName, match="cuda"):
        SimConfig(kernels="cuda")


@pytest.mark.parametrize(("name", "short_by"), [("rosbot", 0.0), ("m2wr", 0.0), ("rosbot", 0.05)])
def test_rays_cast_only_as_far_as_they_must_reach_read_as_full_rays(monkeypatch, name, short_by):
    """The compiled kernels shorten each ray to just past the exact obstacle it first meets (and cast it again at
    full length when it misses there): an episode through clutter with noise and dropout, scans compared period by
    period with a simulator that casts every ray at full length: the same hits and misses, the ranges to Bullet's
    rounding, the same poses and clearances. Most rays are shortened, and hardly any cast again; with the reach
    made ``short_by`` too short, the rays that miss are cast again and read the same."""
    pytest.importorskip("numba", reason="the compiled kernels need numba (pip install 'safenav[fast]')")
    reach = World.ray_reach
    monkeypatch.setattr(World, "ray_reach", lambda *args, **kwargs: reach(*args, **kwargs) - short_by)
    robot = preset(name)
    world = random_world(2, robot, n_obstacles=30)
    runs = {}
    for shorten in (True, False):
        with BulletSim(world, robot, SimConfig(kernels="numba", dropout=0.05), seed=3) as sim:
            if not shorten:
                sim._ray_kernels = None
            rng = np.random.default_rng(8)
            states = [sim.reset()] + [sim.step((rng.uniform(-0.2, 0.6), rng.uniform(-1.5, 1.5))) for _ in range(200)]
            runs[shorten] = states, dict(sim.ray_counts)
    (short, counts), (full, full_counts) = runs[True], runs[False]
    for a, b in zip(short, full, strict=True):
        assert (a.pose, a.clearance, a.min_clearance) == (b.pose, b.clearance, b.min_clearance)
        for scan_a, scan_b in zip(a.scans, b.scans, strict=True):
            np.testing.assert_array_equal(scan_a.readings, scan_b.readings)
            np.testing.assert_allclose(scan_a.ranges, scan_b.ranges, rtol=0.0, atol=1e-6)
    assert counts["cast"] == full_counts["cast"] > 0 and full_counts["shortened"] == 0
    assert counts["shortened"] > 0.7 * counts["cast"], counts
    if short_by:
        assert counts["recast"] > 0.5 * counts["shortened"], counts
    else:
        assert counts["recast"] < 0.02 * counts["shortened"], counts
    from safenav.worlds.shapes import COMPILED_GAPS

    compiled = COMPILED_GAPS.load()   # compiled once, when built, for the types the simulator passes
    assert len(compiled.ray_reach.signatures) == 1 and len(compiled.polygon_gaps.signatures) == 1


def test_actuation_noise_is_relative_and_seeded():
    robot = preset("rosbot")
    config = SimConfig(actuation_noise=0.1, range_noise=0.0)

    def run(seed):
        with BulletSim(World("empty", ()), robot, config, seed=seed) as sim:
            sim.reset()
            still = [sim.step((0.0, 0.0)) for _ in range(5)]
            moving = [sim.step((0.5, 0.5)) for _ in range(40)]
        return still, moving

    still, moving = run(3)
    assert all(s.pose == Pose2D() and not s.velocity.any() for s in still)   # no drift at rest
    ratios = np.array([s.velocity / s.command for s in moving[20:]])
    assert 0.03 < np.std(ratios[:, 0]) < 0.2 and 0.03 < np.std(ratios[:, 1]) < 0.2
    assert [s.pose for s in run(3)[1]] == [s.pose for s in moving]
    assert [s.pose for s in run(4)[1]] != [s.pose for s in moving]


# ---------------------------------------------------------------------------------------------- determinism


def _episode(world: World, seed: int) -> tuple[list[Pose2D], list[np.ndarray]]:
    robot = preset("m2wr")
    config = SimConfig(dropout=0.05, actuation_noise=0.05, command_latency=1, scan_latency=1)
    with BulletSim(world, robot, config, seed=seed) as sim:
        states = [sim.reset()] + [sim.step((0.4, 0.3 * math.sin(0.1 * k))) for k in range(30)]
    return [s.pose for s in states], [s.scan.ranges for s in states]


def test_same_seed_same_scans_and_poses_different_seed_different_noise():
    world = random_world(2, preset("m2wr"), n_obstacles=15)
    poses_a, scans_a = _episode(world, 7)
    poses_b, scans_b = _episode(world, 7)
    poses_c, scans_c = _episode(world, 8)
    assert poses_a == poses_b
    assert all(np.array_equal(a, b, equal_nan=True) for a, b in zip(scans_a, scans_b, strict=True))
    assert poses_a != poses_c
    assert not all(np.array_equal(a, c, equal_nan=True) for a, c in zip(scans_a, scans_c, strict=True))


def test_reset_with_a_seed_replays_the_episode():
    robot = preset("rosbot")
    with BulletSim(tutorial_world("stop_at_wall"), robot, SimConfig(range_noise=0.01, dropout=0.1)) as sim:
        first = [sim.reset(seed=5).scan.ranges] + [sim.step((0.3, 0.1)).scan.ranges for _ in range(3)]
        other = [sim.reset().scan.ranges] + [sim.step((0.3, 0.1)).scan.ranges for _ in range(3)]
        again = [sim.reset(seed=5).scan.ranges] + [sim.step((0.3, 0.1)).scan.ranges for _ in range(3)]
    assert all(np.array_equal(a, b, equal_nan=True) for a, b in zip(first, again, strict=True))
    assert not np.array_equal(first[0], other[0], equal_nan=True)


def test_reset_at_another_start():
    robot = preset("puzzlebot")
    world = tutorial_world("obstacle_avoidance")
    with BulletSim(world, robot, EXACT) as sim:
        sim.reset()
        sim.step((0.3, 0.0))
        state = sim.reset(start=(0.0, -0.6, math.pi / 2))   # facing the middle post, 0.25 m from it
    assert state.time == 0.0 and state.steps == 0 and not state.velocity.any()
    assert state.clearance == pytest.approx(0.25 - robot.radius)
    assert state.scan.ranges[state.scan.beam_index(0.0)] == pytest.approx(0.25, abs=1e-3)


# ---------------------------------------------------------------------------------------------- mesh, config, errors


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"control_dt": 0.05, "physics_dt": 0.02}, "whole multiple"),
        ({"control_dt": 0.01, "physics_dt": 0.02}, "whole multiple"),
        ({"physics_dt": 0.0}, "physics_dt"),
        ({"range_noise": -0.01}, "range_noise"),
        ({"dropout": 1.0}, "dropout"),
        ({"actuation_noise": math.nan}, "actuation_noise"),
        ({"command_latency": -1}, "command_latency"),
        ({"scan_latency": 1.5}, "scan_latency"),
        ({"mount_yaw_error": 4.0}, "mount_yaw_error"),
        ({"gui": "yes"}, "gui"),
        ({"num_threads": -1}, "num_threads"),
        ({"cylinder_tolerance": 0.0}, "cylinder_tolerance"),
        ({"base_time_constant": 0.0}, r"SimConfig\.base_time_constant must be a finite number > 0, got 0\.0"),
        ({"base_time_constant": "slow"}, "SimConfig.base_time_constant"),
    ],
)
def test_bad_sim_config_is_rejected(kwargs, message):
    with pytest.raises(InvalidConfig, match=message):
        SimConfig(**kwargs)


def test_sim_config_substeps():
    assert SimConfig().substeps == 5
    assert SimConfig(control_dt=0.1, physics_dt=0.1 / 3).substeps == 3


def test_sim_config_base_names_are_checked_and_the_lag_defaults_to_the_control_period():
    with pytest.raises(UnknownName, match=r"unknown base model \(SimConfig.base\) 'hover'; expected one of: instant, "
                                          r"lag, ramp, ramp_limit"):
        SimConfig(base="hover")
    assert SimConfig().base == "ramp_limit"
    assert SimConfig(control_dt=0.1, physics_dt=0.02).time_constant == 0.1
    assert SimConfig(base="lag", base_time_constant=0.3).time_constant == 0.3


def test_simulator_usage_errors():
    robot = preset("rosbot")
    with pytest.raises(InvalidConfig, match="above the obstacles"):
        BulletSim(World("low", (), obstacle_height=0.1), robot)
    with pytest.raises(InvalidConfig, match="World"):
        BulletSim("stop_at_wall", robot)
    sim = BulletSim(World("empty", ()), robot)
    with pytest.raises(SimulatorError, match="reset"):
        sim.step((0.0, 0.0))
    with pytest.raises(SimulatorError, match="reset"):
        _ = sim.state
    sim.reset()
    with pytest.raises(InvalidCommand, match="finite"):
        sim.step((math.nan, 0.0))
    with pytest.raises(InvalidCommandType):
        sim.step("forward")
    with pytest.raises(InvalidCommand):
        sim.step((1.0, 2.0, 3.0))
    assert "t=0.000" in repr(sim)
    sim.close()
    sim.close()
    assert sim.closed and "closed" in repr(sim)
    with pytest.raises(SimulatorError, match="closed"):
        sim.step((0.0, 0.0))


# ---------------------------------------------------------------------------------------------- base models


def _straight_run(base: str, periods: int, command: tuple[float, float], **config) -> list:
    robot = preset("rosbot")
    with BulletSim(World("empty", ()), robot, SimConfig(range_noise=0.0, base=base, **config)) as sim:
        return [sim.reset()] + [sim.step(command) for _ in range(periods)]


@pytest.mark.parametrize("v", [0.3, -0.6])
def test_each_base_model_follows_its_closed_form_on_a_straight_run(v):
    """From rest, a constant command ``v``: the pose and the odometry at the end of every period."""
    period, h, tau, a = 0.05, 0.01, 0.12, preset("rosbot").a_max
    t = period * np.arange(31)
    sign, speed = math.copysign(1.0, v), abs(v)
    steps = np.round(t / h)                     # physics steps so far; |v| / (a h) is a whole number of them
    ramping = steps <= speed / (a * h)
    closed = {
        "instant": (np.where(t > 0, v, 0.0), v * t),
        "ramp": (np.minimum(t / period, 1.0) * v, np.where(t < period, v * t**2 / (2 * period), v * (t - period / 2))),
        "lag": (v * (1.0 - np.exp(-t / tau)), v * t - v * tau * (1.0 - np.exp(-t / tau))),
        # a h per physics step, held over the step: a h^2 K (K + 1) / 2 after K steps, then half a step ahead
        # of the continuous ramp, v t - v |v| / (2 a) + v h / 2.
        "ramp_limit": (sign * np.minimum(speed, a * t),
                       np.where(ramping, sign * a * h**2 * steps * (steps + 1) / 2,
                                v * t - v * speed / (2 * a) + v * h / 2)),
    }
    for base, (velocity, distance) in closed.items():
        states = _straight_run(base, 30, (v, 0.0), base_time_constant=tau)
        np.testing.assert_allclose([s.velocity[0] for s in states], velocity, rtol=0, atol=1e-12, err_msg=base)
        np.testing.assert_allclose([s.pose.x for s in states], distance, rtol=0, atol=1e-12, err_msg=base)
        assert all(s.pose.y == 0.0 and s.pose.yaw == 0.0 and s.velocity[1] == 0.0 for s in states)


def test_the_ramp_base_goes_from_the_velocity_it_has_to_the_new_command_in_one_period():
    states = _straight_run("ramp", 2, (0.4, 0.0))
    with BulletSim(World("empty", ()), preset("rosbot"), SimConfig(range_noise=0.0, base="ramp")) as sim:
        sim.reset()
        for _ in range(2):
            sim.step((0.4, 0.0))
        slower = sim.step((-0.2, 1.0))
    assert tuple(slower.velocity) == pytest.approx((-0.2, 1.0), abs=1e-15)   # whatever the acceleration limits
    assert slower.pose.yaw == pytest.approx(0.05 * 1.0 / 2, abs=1e-12)         # the mean yaw rate over the ramp
    assert states[-1].velocity[0] == pytest.approx(0.4)


def test_the_lag_base_turns_by_the_integral_of_its_yaw_rate():
    tau, omega = 0.2, 2.0
    states = _straight_run("lag", 20, (0.0, omega), base_time_constant=tau)
    t = 0.05 * np.arange(21)
    np.testing.assert_allclose([s.pose.yaw for s in states], omega * t - omega * tau * (1 - np.exp(-t / tau)),
                               rtol=0, atol=1e-12)
    assert all(s.pose.x == 0.0 for s in states)


# ---------------------------------------------------------------------------------------------- streams


def test_sensor_noise_does_not_move_the_robot_and_actuation_noise_does_not_change_the_readings():
    """Sensor and actuation noise draw from their own streams of the seed."""
    robot = preset("rosbot")
    world = random_world(2, robot, n_obstacles=10)

    def run(range_noise, actuation_noise):
        config = SimConfig(range_noise=range_noise, dropout=0.1 if range_noise else 0.0,
                           actuation_noise=actuation_noise)
        with BulletSim(world, robot, config, seed=5) as sim:
            states = [sim.reset()] + [sim.step((0.3, 0.4)) for _ in range(10)]
        return [s.pose for s in states], [s.scan.ranges for s in states]

    quiet_poses, _ = run(0.0, 0.1)
    noisy_poses, _ = run(0.02, 0.1)
    assert noisy_poses == quiet_poses   # more sensor draws, the same actuation draws
    _, still_scans = run(0.02, 0.0)
    _, noisy_scans = run(0.02, 0.1)
    assert np.array_equal(still_scans[0], noisy_scans[0], equal_nan=True)   # the same first scan, same noise


def test_building_a_simulator_prints_nothing():
    """PyBullet prints a "build time" line when it is imported: the simulator swallows it."""
    code = ("from safenav import preset; from safenav.sim_bullet import BulletSim; from safenav.worlds import World; "
            "BulletSim(World('empty', ()), preset('rosbot')).close()")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=False)
    assert result.returncode == 0
    assert (result.stdout, result.stderr) == ("", "")


def test_gui_problem_names_the_missing_display(monkeypatch):
    monkeypatch.setattr(sys, "platform", "linux")
    monkeypatch.delenv("DISPLAY", raising=False)
    assert "DISPLAY is not set" in gui_problem()
    with pytest.raises(SimulatorError, match="the PyBullet GUI needs a display"):
        BulletSim(World("empty", ()), preset("rosbot"), SimConfig(gui=True))
    monkeypatch.setenv("DISPLAY", ":0")
    assert gui_problem() is None



def test_without_the_sim_extra_only_simulating_and_drawing_need_it():
    """Specs, configs and experiments load without PyBullet, matplotlib and tqdm; building a simulator or
    drawing says which extra to install."""
    code = """
import sys
for name in ("pybullet", "matplotlib", "tqdm"):
    sys.modules[name] = None
from safenav import MissingDependency, preset
from safenav.experiments import EpisodeSpec, cell_records
from safenav.plots import plot_world
from safenav.sim_bullet import BulletSim, SimConfig
from safenav.worlds import World
EpisodeSpec("stop_at_wall", "stop_at_wall", "cbf", 0, sim_options={"base": "lag"})
for call in (lambda: BulletSim(World("empty", ()), preset("rosbot"), SimConfig()), lambda: plot_world(World("e", ()))):
    try:
        call()
    except MissingDependency as error:
        print(error)
"""
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=False)
    assert result.returncode == 0, result.stderr
    assert result.stdout.splitlines() == [
        "the PyBullet simulator needs the optional package 'pybullet': pip install \"safenav[sim]\"",
        "drawing worlds and episodes (safenav.plots) needs the optional package 'matplotlib': "
        "pip install \"safenav[sim]\"",
    ]

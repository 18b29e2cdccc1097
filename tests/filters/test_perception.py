"""The memory's dead reckoning (A5): a remembered point stays within its stated uncertainty.

The attack: the four base models of the simulator (A4's family) and a base that follows each
command only after a delay (outside A4, as real bases do), commands chosen to make the dead
reckoning err the most (jumps between the velocity limits, a yaw rate flipping every period,
changes all of one sign), remembered points near the body, and the filter's own sequence per
call (recall the points with their uncertainty, carry them by the motion between two velocity
measurements, store them again).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from safenav.base_models import BASE_MODELS, period_velocities
from safenav.filters import perception
from safenav.filters.perception import (
    SHADOW_SPACING,
    PointMemory,
    SeenFree,
    blind_cells,
    dead_reckoning,
    shadow_points,
)
from safenav.geometry import Pose2D, unicycle_step
from safenav.robot import LidarSpec, preset
from safenav.scan import Reading
from safenav.synthetic import Circle, Scene, Segment, synthetic_scan

SUBSTEPS = 20
TIME_CONSTANT = 0.04
LATE = "late"   # holds the old velocity for 95 % of the period, then the command: a delayed base


def _commands(robot, rng: np.random.Generator, kind: str, periods: int) -> np.ndarray:
    """Command sequences that make the dead reckoning err the most."""
    lower, upper = np.asarray(robot.lower), np.asarray(robot.upper)
    if kind == "extremes":      # jumps between the limits, far beyond one period's acceleration
        return np.where(rng.random((periods, 2)) < 0.5, lower, upper)
    if kind == "flip":          # the yaw rate flips every period (a robot held in front of a wall), slow forward
        omega = 0.1 * robot.omega_max * (-1.0) ** np.arange(periods)
        return np.column_stack((np.full(periods, 0.1 * robot.v_max), omega))
    if kind == "turn_at_speed":   # full speed, the yaw rate flipping between its limits: the heading errs most
        omega = robot.omega_max * (-1.0) ** np.arange(periods)   # while the base covers the most ground
        return np.column_stack((np.full(periods, robot.v_max), omega))
    if kind == "ramp_up":       # every change in the same direction: errors of one sign add up
        fraction = np.linspace(0.0, 1.0, periods)[:, None]
        return lower * 0.0 + fraction * upper
    return rng.uniform(lower, upper, size=(periods, 2))


def _drive(model: str, robot, commands: np.ndarray, dt: float, start: np.ndarray
           ) -> tuple[list[Pose2D], list[np.ndarray]]:
    """True poses and measured velocities at every call, the base following ``commands``."""
    pose, velocity = Pose2D(), np.asarray(start, dtype=float)
    poses, velocities = [pose], [velocity]
    for command in commands:
        if model == LATE:
            ends = np.where(np.arange(SUBSTEPS)[:, None] < 0.95 * SUBSTEPS, velocity, command)
            means = ends
        else:
            ends, means = period_velocities(model, robot, velocity, command, period=dt, substeps=SUBSTEPS,
                                            time_constant=TIME_CONSTANT)
        for mean in means:
            pose = unicycle_step(pose, float(mean[0]), float(mean[1]), dt / SUBSTEPS)
        velocity = ends[-1]
        poses.append(pose)
        velocities.append(velocity)
    return poses, velocities


def _worst_excess(model: str, kind: str, seed: int, estimator=dead_reckoning) -> float:
    """The largest distance [m] by which a remembered point's true position left its stated uncertainty."""
    robot = preset("rosbot")
    dt = 0.05
    rng = np.random.default_rng(seed)
    commands = _commands(robot, rng, kind, 60)
    poses, velocities = _drive(model, robot, commands, dt, start=np.zeros(2))
    angles = rng.uniform(-np.pi, np.pi, 40)
    ranges = rng.uniform(robot.radius, 1.0, 40)
    world = np.column_stack((ranges * np.cos(angles), ranges * np.sin(angles)))   # stored in the start frame
    memory = PointMemory(max_range=100.0, capacity=1000)
    memory.store(world.copy(), np.empty((0, 2)), np.empty(0))
    worst = -np.inf
    for k in range(1, len(poses)):
        # The filter's sequence per call: recall (points with their uncertainty), carry, store again.
        motion, error = estimator(velocities[k - 1], velocities[k], dt)
        memory.carry(motion, error)
        points, uncertainty = memory.points, memory.uncertainty
        memory.store(np.empty((0, 2)), points, uncertainty)
        truth = poses[k].to_local(world)
        worst = max(worst, float(np.max(np.hypot(*(points - truth).T) - uncertainty)))
    return worst


@pytest.mark.parametrize("kind", ["extremes", "flip", "turn_at_speed", "ramp_up", "random"])
@pytest.mark.parametrize("model", [*BASE_MODELS, LATE])
def test_a_remembered_point_stays_within_its_uncertainty(model, kind):
    for seed in range(3):
        assert _worst_excess(model, kind, seed) <= 1e-9


def _shrunk(start, end, elapsed):
    motion, (translation, rotation) = dead_reckoning(start, end, elapsed)
    return motion, (0.8 * translation, 0.8 * rotation)


@pytest.mark.parametrize("model", ["instant", LATE])
def test_the_bound_is_exact_a_fifth_less_is_not_a_bound(model):
    # The instant base covers the newer velocity for the whole period, the late one the older:
    # each is half the change times the period off the trapezoid, on the bound.
    assert max(_worst_excess(model, "extremes", seed, _shrunk) for seed in range(3)) > 1e-3


def test_a_remembered_point_whose_uncertainty_reaches_out_of_the_field_of_view_is_not_dropped_by_one_free_beam():
    # A pole beside the m2wr's body, just behind the lidar's 90-degree edge; the odometry says the base turned
    # left by 0.06 rad when it did not (within its stated bound), so the pole is remembered just inside the field
    # of view, where the beam nearest it reads free. It may truly be anywhere within its uncertainty, and there
    # the lidar does not look: the memory must keep it.
    robot = preset("m2wr")
    pole = np.array([0.13, 0.45])          # 92 degrees from the lidar at (0.15, 0): out of view
    scene = Scene.of(Circle(tuple(pole), 0.01))
    memory = PointMemory(max_range=2.0, capacity=100)
    memory.store(pole[None].copy(), np.empty((0, 2)), np.empty(0))
    memory.carry(Pose2D(0.0, 0.0, 0.06), (0.0, 0.06))
    remembered = memory.points[0]
    assert math.degrees(math.atan2(remembered[1], remembered[0] - 0.15)) < 90.0    # it is thought to be in view
    assert np.hypot(*(remembered - pole)) <= memory.uncertainty[0] + 1e-12        # and the bound holds
    points, uncertainty = memory.recall((synthetic_scan(robot, scene, Pose2D()),), tolerance=0.03)
    assert points.shape[0] == 1 and np.hypot(*(points[0] - pole)) <= uncertainty[0] + 1e-12


def test_a_remembered_point_is_dropped_only_when_every_beam_towards_where_it_may_be_says_something():
    # The same memory in a room the lidar sees all of: free beyond the point everywhere it may be, it is dropped;
    # one beam within its uncertainty (not the nearest) invalid, the point may be there unseen, so it is kept.
    # (A beam there reading nearer hides it as it hides any obstacle: the filters keep the edges of what
    # obstacles hide for every scan, shadow_points.)
    robot = preset("rosbot")
    memory = PointMemory(max_range=3.0, capacity=100)
    point = np.array([1.0, 0.0])
    memory.store(point[None].copy(), np.empty((0, 2)), np.empty(0))
    memory.carry(Pose2D(), (0.0, 0.05))                    # 5 cm of uncertainty, about 2.9 degrees
    scan = synthetic_scan(robot, Scene.of(Segment((3.0, -3.0), (3.0, 3.0))), Pose2D())
    assert memory.recall((scan,), tolerance=0.03)[0].shape[0] == 0
    bearing = scan.mount.inverse().compose(Pose2D(*point, 0.0))        # the point from the lidar
    nearest = round((math.atan2(bearing.y, bearing.x) - scan.angle_min) / scan.angle_increment) % scan.n_beams
    ranges = scan.ranges.copy()
    ranges[(nearest + 4) % scan.n_beams] = math.nan                  # 2 degrees off the nearest beam
    assert memory.recall((scan.with_ranges(ranges),), tolerance=0.03)[0].shape[0] == 1


@pytest.mark.parametrize("n", [5, 181, 720])
def test_range_minima_are_the_smallest_value_of_each_range_round_the_turn(n):
    rng = np.random.default_rng(n)
    values = np.where(rng.random(n) < 0.05, -np.inf, rng.uniform(0.0, 5.0, n))
    minima = perception._window_minima(values, True)
    low = rng.integers(-n, n, 400)
    high = low + rng.integers(0, n, 400)
    got = perception._range_minima(values, minima, low, high)
    for k in range(400):
        assert got[k] == values.take(np.arange(low[k], high[k] + 1) % n).min()


def _lidar(view_deg: float, yaw: float) -> LidarSpec:
    half = math.radians(view_deg) / 2.0
    return LidarSpec(n_beams=int(view_deg * 2), angle_min=-half, angle_max=half, range_min=0.05, range_max=10.0,
                     mount=Pose2D(0.1, -0.05, yaw))


@pytest.mark.parametrize("view_deg, yaw", [(180.0, 0.0), (270.0, 0.6), (120.0, math.pi)])
def test_what_the_memory_keeps_of_a_point_it_cannot_see_still_holds_where_it_truly_is(view_deg, yaw):
    # Remembered points off their true place by up to their uncertainty, the true ones thin posts; a post the
    # lidar cannot see (out of its field of view) must stay remembered, within the uncertainty of what is kept
    # of it (a point seen but for the part of its disk beyond one edge of the field of view is narrowed to that
    # part). Posts in view are the scan's.
    lidar = _lidar(view_deg, yaw)
    rng = np.random.default_rng(int(view_deg))
    narrowed = 0
    for _ in range(300):
        spread = rng.choice([0.5, 1.5])          # near the lidar, disks that hold it
        truth = rng.uniform(-spread, spread, size=(6, 2))
        uncertainty = rng.uniform(0.0, 0.8, 6) * rng.choice([0.05, 0.3, 1.0], 6)
        direction = rng.uniform(-np.pi, np.pi, 6)
        remembered = truth + (rng.uniform(0.0, 1.0, 6) * uncertainty)[:, None] * np.column_stack(
            (np.cos(direction), np.sin(direction)))
        memory = PointMemory(max_range=10.0, capacity=100)
        memory.store(np.empty((0, 2)), remembered, uncertainty.copy())     # as recalled after odometry errors up to it
        scene = Scene.of(*(Circle(tuple(post), 0.004) for post in truth))
        scan = synthetic_scan(lidar, scene, Pose2D())
        kept, kept_uncertainty = memory.recall((scan,), tolerance=0.02)
        sensor = lidar.mount.inverse()
        for post in truth:
            local = sensor.compose(Pose2D(*post, 0.0))
            bearing = math.atan2(local.y, local.x)
            if abs(bearing) < lidar.angle_max + 0.5 * scan.angle_increment:
                continue                                    # in view: the scan's
            holds = np.hypot(*(kept - post).T) <= kept_uncertainty + 1e-9
            assert holds.any(), (post, remembered, uncertainty, kept, kept_uncertainty)
        narrowed += int(np.sum(kept_uncertainty < np.min(uncertainty) - 1e-9) > 0)
    assert narrowed > 0            # the narrowing happened, not only keeping the whole disks


@pytest.mark.parametrize("model", [*BASE_MODELS, LATE])
@pytest.mark.parametrize("start", [(1.0, -1.0), (1.0, 0.0), (0.5, -1.0), (0.0, -1.0), (-1.0, 1.0)])
def test_one_period_at_speed_with_the_yaw_rate_jumping_stays_within_the_bound(model, start):
    # One carry, the speed held (no translation error of its own) or changing, the yaw rate jumping across its
    # range: the base covers ground while its heading errs, which drags its path sideways by up to the ground
    # covered times half the turn error; points ahead and behind see that drag and the turn add up.
    robot = preset("rosbot")
    dt = 0.05
    start = np.array(start) * robot.upper
    command = np.array([start[0] if start[0] != 0.0 else robot.v_max, -start[1] if start[1] else robot.omega_max])
    poses, velocities = _drive(model, robot, command[None], dt, start=start)
    angles = np.linspace(-np.pi, np.pi, 720, endpoint=False)
    world = np.concatenate([d * np.column_stack((np.cos(angles), np.sin(angles))) for d in (0.2, 0.5, 1.0)])
    memory = PointMemory(max_range=100.0, capacity=10_000)
    memory.store(world.copy(), np.empty((0, 2)), np.empty(0))
    memory.carry(*dead_reckoning(velocities[0], velocities[1], dt))
    excess = np.hypot(*(memory.points - poses[1].to_local(world)).T) - memory.uncertainty
    assert excess.max() <= 1e-12, excess.max()


@pytest.mark.parametrize("turn", [0.05, -0.05])
def test_points_carried_over_several_periods_count_a_turn_error_with_the_path_driven_since(turn):
    # The memory carried period after period without being stored again (what the filter does across calls that
    # brake before they look at the scan: stale, no data): the odometry errs by a turn in place in the first
    # period (within its stated bound), then the robot drives 1.5 m on exactly, past the point. The turn happened
    # 1.5 m from the point, so the point is off by 1.5 m times the turn, not by its distance from the base now
    # times it.
    memory = PointMemory(max_range=5.0, capacity=10)
    world = np.array([[1.5, 0.3], [1.5, -0.3], [2.0, 0.0], [0.5, 0.4]])
    memory.store(world.copy(), np.empty((0, 2)), np.empty(0))
    memory.carry(Pose2D(0.0, 0.0, 0.0), (0.0, abs(turn)))      # the base really turned by `turn`
    pose = Pose2D(0.0, 0.0, turn)
    step = Pose2D(0.05, 0.0, 0.0)
    for _ in range(30):
        memory.carry(step)
        pose = pose.compose(step)
        excess = np.hypot(*(memory.points - pose.to_local(world)).T) - memory.uncertainty
        assert np.all(excess <= 1e-12), excess
    assert memory.uncertainty[0] >= 1.5 * abs(turn)


def test_the_estimate_is_the_trapezoid_and_the_bound_half_the_change():
    motion, (translation, rotation) = dead_reckoning(np.zeros(2), np.array([1.0, 0.0]), 0.05)
    assert motion.x == pytest.approx(0.025) and motion.y == 0.0 and motion.yaw == 0.0
    assert translation == pytest.approx(0.025)
    assert rotation == 0.0


# ------------------------------------------------------------------ the edges of what obstacles hide


def _shadow_edges_by_hand(scan, reach: float, jump: float) -> set[int]:
    """The beams whose neighbour (the previous or the next; round the turn only for a full-turn scan) reads
    farther by more than ``jump`` (no return: infinitely far; invalid or too close: never), hit within reach."""
    n, lever = scan.n_beams, math.hypot(scan.mount.x, scan.mount.y)
    wraps = n * scan.angle_increment >= 2.0 * math.pi - 1e-9

    def far(i: int) -> float:
        reading = scan.readings[i]
        return math.inf if reading == Reading.NO_RETURN else scan.ranges[i] if reading == Reading.HIT else -math.inf

    edges = set()
    for i in range(n):
        if scan.readings[i] != Reading.HIT or not scan.ranges[i] < reach + lever - SHADOW_SPACING:
            continue
        neighbours = [j % n for j in (i - 1, i + 1) if wraps or 0 <= j < n]
        if any(far(j) > scan.ranges[i] + jump for j in neighbours):
            edges.add(i)
    return edges


@pytest.mark.parametrize("name", ["rosbot", "puzzlebot", "m2wr"])
def test_shadow_edges_are_the_beams_a_neighbour_sees_past_round_the_turn_only_for_a_full_turn(name):
    """The points of :func:`shadow_points` start one spacing beyond exactly the hand-computed edge beams, on
    random readings (hits, no returns, invalid, too close), a full-turn lidar's first and last beams being
    neighbours and a 180-degree lidar's not."""
    robot = preset(name)
    rng = np.random.default_rng(7)
    reach, jump = 1.5, 0.3
    for _ in range(50):
        ranges = rng.uniform(0.2, 3.0, robot.lidar.n_beams)
        kind = rng.uniform(size=ranges.size)
        ranges[kind < 0.1] = math.inf
        ranges[(kind >= 0.1) & (kind < 0.15)] = math.nan
        ranges[(kind >= 0.15) & (kind < 0.17)] = -math.inf
        ranges[0], ranges[-1] = 0.5, 2.5 if rng.uniform() < 0.5 else 0.5      # the wrap, either way
        scan = robot.lidar.scan(ranges)
        points = shadow_points((scan,), reach, jump)
        lever = math.hypot(scan.mount.x, scan.mount.y)
        expected = [scan.beam_points(np.array([i]), np.array([scan.ranges[i] + k * SHADOW_SPACING]))[0]
                    for i in sorted(_shadow_edges_by_hand(scan, reach, jump))
                    for k in range(1, math.floor((reach + lever - scan.ranges[i]) / SHADOW_SPACING) + 1)]
        np.testing.assert_allclose(points, np.array(expected).reshape(-1, 2), atol=1e-9)


# ---------------------------------------------------------------------------------------------- seen free


def _window_minima_by_hand(seen: np.ndarray, half: int, wraps: bool) -> np.ndarray:
    n = seen.size
    out = np.empty(n)
    for beam in range(n):
        window = np.arange(beam - half, beam + half + 1)
        if wraps:
            out[beam] = seen[window % n].min()
        else:
            inside = (window >= 0) & (window < n)
            out[beam] = seen[window[inside]].min() if inside.all() else -np.inf
    return out


@pytest.mark.parametrize("wraps", [False, True])
@pytest.mark.parametrize("n", [5, 90, 720])
def test_window_minima_are_the_smallest_reading_of_each_window(n, wraps):
    rng = np.random.default_rng(n)
    seen = rng.uniform(0.1, 5.0, n)
    seen[rng.random(n) < 0.1] = -np.inf
    minima = perception._window_minima(seen, wraps)
    for level, half in enumerate(perception._WINDOWS):
        np.testing.assert_array_equal(minima[level], _window_minima_by_hand(seen, int(half), wraps))


def _fov_covers(lidar, mount: Pose2D, points: np.ndarray) -> np.ndarray:
    """Whether each point's bearing from the lidar lies within the half-increments its beams cover."""
    bearing = np.arctan2(points[:, 1] - mount.y, points[:, 0] - mount.x) - mount.yaw
    offset = np.mod(bearing - lidar.angle_min + 0.5 * lidar.angle_increment, 2.0 * math.pi)
    return offset <= lidar.n_beams * lidar.angle_increment


@pytest.mark.parametrize("name", ["rosbot", "m2wr"])
def test_every_cell_left_out_of_the_blind_cells_is_wholly_in_the_field_of_view(name):
    robot = preset(name)
    scan = synthetic_scan(robot, Scene())
    spacing, extent, inside = 0.025, 0.9, perception_inside(robot)
    cells, distance = blind_cells((perception._layout_key(scan),), inside, extent, spacing)
    radius = spacing / math.sqrt(2.0)
    axis = spacing * np.arange(-40, 41)
    grid = np.array([(x, y) for x in axis for y in axis])
    near = (np.hypot(grid[:, 0], grid[:, 1]) - radius < extent) & (np.hypot(grid[:, 0], grid[:, 1]) + radius > inside)
    kept = {tuple(np.round(cell / spacing).astype(int)) for cell in cells}
    angles = np.linspace(0.0, 2.0 * math.pi, 33)
    ring = radius * np.column_stack((np.cos(angles), np.sin(angles)))
    for centre in grid[near]:
        if tuple(np.round(centre / spacing).astype(int)) in kept:
            continue
        assert np.all(_fov_covers(robot.lidar, scan.mount, centre + ring)), centre
    np.testing.assert_array_equal(np.sort(distance), distance)
    if name == "rosbot":
        assert cells.shape[0] == 0        # a full turn sees every cell but those round the lidar itself
    else:
        behind = cells[cells[:, 0] < 0.0]
        assert behind.shape[0] > 0 and np.all(np.hypot(behind[:, 0], behind[:, 1]) + radius > inside)


def perception_inside(robot) -> float:
    from safenav.filters.body import inscribed_radius
    return inscribed_radius(robot)


def _random_scene(rng: np.random.Generator) -> Scene:
    items = []
    for _ in range(rng.integers(2, 6)):
        start = rng.uniform(-3.0, 3.0, 2)
        end = start + rng.uniform(-2.0, 2.0, 2)
        items.append(Segment(tuple(start), tuple(end)))
    for _ in range(rng.integers(0, 6)):
        items.append(Circle(tuple(rng.uniform(-3.0, 3.0, 2)), float(rng.uniform(0.05, 0.3))))
    return Scene.of(*items)


def _seen_free_walk(seed: int) -> tuple[int, int]:
    """A random walk through a random scene of walls and poles, the scans kept by SeenFree and carried by a
    motion that errs by its whole bound each period (a translation and a turn about the base, in random
    directions), and disks queried round the robot; asserts that whatever is certified is free in the world.
    Returns how many disks were certified and queried."""
    rng = np.random.default_rng(seed)
    robot = preset("m2wr")
    scene = _random_scene(rng)
    memory = SeenFree(max_range=3.0, capacity=12, step=(0.05, math.radians(10.0)))
    pose = Pose2D(float(rng.uniform(-0.5, 0.5)), float(rng.uniform(-0.5, 0.5)), float(rng.uniform(-3, 3)))
    noise = 0.01
    certified_total = queried_total = 0
    for _ in range(60):
        if scene.clearance((pose.x, pose.y), robot.radius) > 0.0:
            scan = synthetic_scan(robot, scene, pose)
            ranges = scan.ranges.copy()
            hit = np.isfinite(ranges)
            ranges[hit] += rng.uniform(-2.0 * noise, 2.0 * noise, int(hit.sum()))
            memory.store((scan.replace(ranges=ranges),), noise)
        motion = unicycle_step(Pose2D(), float(rng.uniform(-0.5, 1.0)), float(rng.uniform(-2.0, 2.0)), 0.05)
        error_t, error_r = float(rng.uniform(0.0, 0.01)), float(rng.uniform(0.0, 0.02))
        direction = rng.uniform(0.0, 2.0 * math.pi)
        slip = Pose2D(error_t * math.cos(direction), error_t * math.sin(direction), error_r * rng.choice([-1.0, 1.0]))
        memory.carry(motion.compose(slip), (error_t, error_r))   # what odometry says; the base really did `motion`
        pose = pose.compose(motion)
        centres = rng.uniform(-1.2, 1.2, (200, 2))
        radius = float(rng.uniform(0.005, 0.03))
        distance = np.hypot(centres[:, 0], centres[:, 1])
        free = memory.certified(centres, distance, radius)
        certified_total += int(free.sum())
        queried_total += free.size
        world = pose.to_parent(centres[free]) if free.any() else np.empty((0, 2))
        for centre in world:
            assert scene.clearance(tuple(centre), radius) >= -1e-9, (centre, radius)
    return certified_total, queried_total


@pytest.mark.parametrize("seed", range(12))
def test_what_seen_free_certifies_is_free_with_odometry_erring_at_its_bound(seed):
    _seen_free_walk(seed)


def test_seen_free_certifies_space_on_those_walks():
    counts = np.array([_seen_free_walk(seed) for seed in range(12)])
    assert counts[:, 0].sum() > 0.05 * counts[:, 1].sum()


def test_seen_free_travel_is_zero_until_the_space_behind_was_seen_and_grows_as_the_robot_drives_on():
    robot = preset("m2wr")
    scene = Scene.of(Segment((-0.45, -5.0), (-0.45, 5.0)))   # a wall just behind the start, never seen
    memory = SeenFree(max_range=3.0)
    inside, keep, extent = perception_inside(robot), robot.radius + 0.05, robot.radius + 0.05 + 0.5
    travel = []
    pose = Pose2D()
    for _ in range(40):
        scan = synthetic_scan(robot, scene, pose)
        travel.append(memory.travel((scan,), inside, keep, extent))
        memory.store((scan,), 0.0)
        motion = Pose2D(0.025, 0.0, 0.0)
        memory.carry(motion)
        pose = pose.compose(motion)
    assert travel[0] == 0.0 and travel[10] == 0.0
    assert travel[-1] >= 0.3       # most of the 0.5 m the grid reaches, once the robot has driven on
    assert np.all(np.diff(travel) >= 0.0)
    # Backing up by the travel the memory allowed never brings the body and margin past the robot's start line
    # of sight (the lidar's plane at the start, x = 0.15 m): nothing behind it was ever seen.
    for step, allowed in enumerate(travel):
        assert 0.025 * step - allowed - keep >= 0.15 - robot.radius - 1e-9 or allowed == 0.0


@pytest.mark.parametrize("seed", range(6))
def test_seen_free_moves_its_scans_when_they_are_used_as_if_at_every_carry(seed):
    # Carrying sums the motions and error bounds; the kept scans move when another is stored or one is asked
    # whether space was seen free. Asked after every carry (one motion at a time, as every carry once moved
    # them), the same poses and error bounds to rounding, and the same answers.
    rng = np.random.default_rng(seed)
    robot = preset("m2wr")
    scene = _random_scene(rng)
    lazy, eager = (SeenFree(max_range=3.0, capacity=6, step=(0.05, math.radians(10.0))) for _ in range(2))
    pose, compared = Pose2D(), 0
    for call in range(80):
        if call % 3 == 0:
            scan = synthetic_scan(robot, scene, pose)
            lazy.store((scan,), 0.01)
            eager.store((scan,), 0.01)
        motion = unicycle_step(Pose2D(), float(rng.uniform(-0.5, 1.0)), float(rng.uniform(-2.0, 2.0)), 0.05)
        rates = (float(rng.uniform(0.0, 0.01)), float(rng.uniform(0.0, 0.02)))
        lazy.carry(motion, rates)
        eager.carry(motion, rates)
        pose = pose.compose(motion)
        kept = eager.kept()
        if call % 7 == 6:
            centres = rng.uniform(-1.2, 1.2, (100, 2))
            distance = np.hypot(centres[:, 0], centres[:, 1])
            assert np.array_equal(lazy.certified(centres, distance, 0.02), eager.certified(centres, distance, 0.02))
            for (poses, error), (eager_poses, eager_error) in zip(lazy.kept(), kept, strict=True):
                compared += len(poses)
                np.testing.assert_allclose(poses[:, :2], eager_poses[:, :2], rtol=0.0, atol=1e-12)
                np.testing.assert_allclose(np.cos(poses[:, 2] - eager_poses[:, 2]), 1.0, rtol=0.0, atol=1e-12)
                np.testing.assert_allclose(error, eager_error, rtol=1e-12, atol=1e-15)
    assert len(lazy) == len(eager)
    assert compared >= 20, compared


def test_seen_free_keeps_the_newest_scans_within_range_up_to_its_capacity():
    robot = preset("m2wr")
    scene = Scene.of(Segment((2.0, -3.0), (2.0, 3.0)))
    memory = SeenFree(max_range=1.0, capacity=3, step=(0.01, 1.0))
    scan = synthetic_scan(robot, scene, Pose2D())
    for _ in range(6):
        memory.store((scan,), 0.0)
        memory.carry(Pose2D(0.2, 0.0, 0.0))
    (poses, error), = memory.kept()
    # The three newest, oldest first: 0.6, 0.4 and 0.2 m behind their mount now (the 0.8 m one is out of range too).
    np.testing.assert_allclose(poses[:, 0], [scan.mount.x - 0.6, scan.mount.x - 0.4, scan.mount.x - 0.2], atol=1e-12)
    assert len(memory) == 3 and not error.any()
    assert abs(scan.mount.x) < 0.2
    memory.carry(Pose2D(0.8, 0.0, 0.0))
    memory.store((scan,), 0.0)              # the two farthest now out of range: the new one and the nearest stay
    assert len(memory) == 2
    # Two scans of one layout in one call beyond a capacity of one: both kept (they are equally new).
    single = SeenFree(max_range=3.0, capacity=1, step=(0.0, 0.0))
    single.store((scan,), 0.0)
    single.store((scan, scan.replace(mount=Pose2D(0.1, 0.0, math.pi))), 0.0)
    (poses, _), = single.kept()
    np.testing.assert_allclose(poses[:, 0], [scan.mount.x, 0.1])
    certified = single.certified(np.array([[1.0, 0.0], [-1.0, 0.0]]), np.array([1.0, 1.0]), 0.01)
    assert certified.tolist() == [True, True]   # seen ahead by the first, behind by the second


@pytest.mark.parametrize("turn", [0.05, -0.05])
def test_a_turn_error_long_ago_counts_with_the_path_driven_since(turn):
    # One scan kept, a wall beside the path; the odometry errs by a turn about the base in the first period only
    # (within its stated bound), then the robot drives 1.5 m on exactly. About where the base is now the kept scan
    # is off by 1.5 m times the turn, not by the distance from the base now times it: disks the scan did not see
    # free (inside the wall) must not be certified.
    robot = preset("m2wr")
    scene = Scene.of(Segment((-1.0, 0.5), (4.0, 0.5)), Segment((-1.0, -0.5), (4.0, -0.5)))
    memory = SeenFree(max_range=5.0, capacity=1, step=(100.0, 100.0))
    memory.store((synthetic_scan(robot, scene, Pose2D()),), 0.0)
    step = Pose2D(0.05, 0.0, 0.0)
    memory.carry(step.compose(Pose2D(0.0, 0.0, turn)), (0.0, abs(turn)))     # the base really did `step`
    pose = step
    for _ in range(29):
        memory.carry(step)
        pose = pose.compose(step)
    xs, ys = np.meshgrid(np.linspace(-0.6, 0.6, 25), np.linspace(-0.6, 0.6, 49))
    centres = np.column_stack((xs.ravel(), ys.ravel()))
    radius = 0.01
    free = memory.certified(centres, np.hypot(centres[:, 0], centres[:, 1]), radius)
    assert free.any()
    for centre in pose.to_parent(centres[free]):
        assert scene.clearance(tuple(centre), radius) >= -1e-9, centre

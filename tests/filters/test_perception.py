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
from safenav.filters.perception import SHADOW_SPACING, PointMemory, dead_reckoning, shadow_points
from safenav.geometry import Pose2D, unicycle_step
from safenav.robot import preset
from safenav.scan import Reading

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


@pytest.mark.parametrize("kind", ["extremes", "flip", "ramp_up", "random"])
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

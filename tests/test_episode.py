"""Closed-loop episodes in the simulator: determinism and metrics that can be checked by hand."""

from __future__ import annotations

import math

import numpy as np
import pytest

from safenav import InvalidConfig, Pose2D, preset
from safenav.episode import EpisodeConfig, run_episode
from safenav.filters import CBFSafetyFilter, ZonesFilter
from safenav.reference import Policy, RandomWalk
from safenav.robot import Command
from safenav.worlds import Wall, World, random_world, tutorial_world

pytestmark = pytest.mark.sim


class Constant(Policy):
    """A scripted nominal: the same command at every step."""

    def __init__(self, v: float, omega: float = 0.0) -> None:
        self.command = Command(v, omega)

    def __call__(self, scan, pose=None) -> Command:
        return self.command


def test_same_seed_gives_identical_metrics():
    robot = preset("puzzlebot")
    world = random_world(4, robot)
    runs = [run_episode(world, robot, RandomWalk(robot), CBFSafetyFilter(robot, 0.05),
                        config=EpisodeConfig(duration=8.0), seed=11, record=True) for _ in range(2)]
    a, b = (run.metrics for run in runs)
    assert (a.steps, a.collided, a.min_clearance, a.distance, a.mean_intervention, a.statuses) == \
           (b.steps, b.collided, b.min_clearance, b.distance, b.mean_intervention, b.statuses)
    assert np.array_equal(runs[0].trajectory.pose, runs[1].trajectory.pose)
    other = run_episode(world, robot, RandomWalk(robot), CBFSafetyFilter(robot, 0.05),
                        config=EpisodeConfig(duration=8.0), seed=12).metrics
    assert other.distance != a.distance


def test_driving_straight_into_a_wall_is_measured_right():
    robot = preset("rosbot")
    world = tutorial_world("stop_at_wall")          # wall face 3 m ahead of the start
    speed = 0.5
    result = run_episode(world, robot, Constant(speed), config=EpisodeConfig(duration=12.0), seed=0, record=True)
    metrics = result.metrics
    ramp_time = speed / robot.a_max                  # accelerating at the limit from rest
    ramp_distance = 0.5 * speed * ramp_time
    expected_time = ramp_time + (3.0 - robot.radius - ramp_distance) / speed
    assert metrics.collided
    assert metrics.collision_time == pytest.approx(expected_time, abs=0.011)   # one physics step
    # The period in which it touched runs to its end: at most 0.05 s x 0.5 m/s further.
    assert 3.0 - robot.radius - 0.005 <= metrics.distance <= 3.0 - robot.radius + 0.026
    assert metrics.min_clearance < 0.0
    assert metrics.steps == len(result.trajectory.u) == math.ceil(metrics.collision_time / 0.05 - 1e-9)
    assert metrics.mean_intervention == 0.0 and metrics.statuses == {"none": metrics.steps}
    assert metrics.goal_reached is None and metrics.filter_times.size == 0


def test_the_same_drive_with_the_cbf_filter_stops_short_and_counts_the_blocked_time():
    robot = preset("rosbot")
    filt = CBFSafetyFilter(robot, 0.05)
    result = run_episode(tutorial_world("stop_at_wall"), robot, Constant(0.5), filt,
                         config=EpisodeConfig(duration=12.0), seed=0)
    metrics = result.metrics
    assert not metrics.collided
    assert metrics.min_clearance >= filt.margin - 0.01
    assert metrics.stuck_time > 3.0          # it wanted to go on, the filter held it
    assert metrics.mean_intervention > 0.0
    assert metrics.filter_times.size == metrics.steps
    assert metrics.filter_p99_us >= metrics.filter_p50_us > 0


def test_goal_reached_ends_the_episode_with_its_time():
    robot = preset("puzzlebot")
    world = World("open", (Wall((5.0, -3.0), (5.0, 3.0)),), start=Pose2D(0.0, 0.0, 0.0), goal=(2.0, 0.0))
    from safenav.reference import GoToGoal

    result = run_episode(world, robot, GoToGoal(robot, world.goal), config=EpisodeConfig(duration=20.0), seed=0)
    metrics = result.metrics
    tolerance = EpisodeConfig().goal_tolerance
    assert metrics.goal_reached
    assert (2.0 - tolerance) / robot.v_max < metrics.time_to_goal < 2.0 / robot.v_max + 3.0
    assert metrics.goal_progress == pytest.approx(2.0, abs=0.31)
    assert metrics.time == metrics.time_to_goal


def test_zones_baseline_gets_stuck_with_an_obstacle_in_its_stop_zone():
    robot = preset("rosbot")
    behind = -(robot.radius + 0.03 + 0.01)    # 3 cm behind the body, inside the 5 cm stop zone
    world = World("cornered", (Wall((behind, -1.0), (behind, 1.0), thickness=0.02),), start=Pose2D(0.0, 0.0, 0.0))
    result = run_episode(world, robot, Constant(0.4), ZonesFilter(robot, 0.05), config=EpisodeConfig(duration=3.0))
    assert result.metrics.distance < 1e-9            # stopped although it drives away from the wall
    assert result.metrics.stuck_time == pytest.approx(3.0)


def test_filter_period_must_match_the_control_period():
    robot = preset("rosbot")
    with pytest.raises(InvalidConfig, match="differs from the control period"):
        run_episode(tutorial_world("stop_at_wall"), robot, Constant(0.1), CBFSafetyFilter(robot, 0.1))


def test_bad_episode_config_names_the_field():
    with pytest.raises(InvalidConfig, match=r"EpisodeConfig\.duration must be a finite number > 0"):
        EpisodeConfig(duration=0.0)

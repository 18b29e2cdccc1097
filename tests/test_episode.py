"""Closed-loop episodes in the simulator, and the liveness metrics on hand-computed command sequences."""

from __future__ import annotations

import math

import numpy as np
import pytest

from safenav import InvalidConfig, Pose2D, preset
from safenav.episode import RESUME_TIME, EpisodeConfig, liveness, run_episode, stalled, stationary
from safenav.filters import CBFSafetyFilter, ZonesFilter, make_filter
from safenav.geometry import wrap_angle
from safenav.reference import GoToGoal, Policy, RandomWalk
from safenav.robot import Command
from safenav.worlds import Wall, World, random_world, tutorial_world


class Constant(Policy):
    """A scripted nominal: the same command at every step."""

    def __init__(self, v: float, omega: float = 0.0) -> None:
        self.command = Command(v, omega)

    def __call__(self, scan, pose=None) -> Command:
        return self.command


@pytest.mark.sim
def test_same_seed_gives_identical_metrics():
    robot = preset("puzzlebot")
    world = random_world(4, robot)
    # Without a compute budget: with one, a process pause in either run would brake a call (reproducible_settings).
    runs = [run_episode(world, robot, RandomWalk(robot), CBFSafetyFilter(robot, 0.05, budget=math.inf),
                        config=EpisodeConfig(duration=8.0), seed=11, record=True) for _ in range(2)]
    a, b = (run.metrics for run in runs)
    assert (a.steps, a.collided, a.min_clearance, a.distance, a.mean_intervention, a.statuses) == \
           (b.steps, b.collided, b.min_clearance, b.distance, b.mean_intervention, b.statuses)
    assert np.array_equal(runs[0].trajectory.pose, runs[1].trajectory.pose)
    other = run_episode(world, robot, RandomWalk(robot), CBFSafetyFilter(robot, 0.05),
                        config=EpisodeConfig(duration=8.0), seed=12).metrics
    assert other.distance != a.distance


@pytest.mark.sim
def test_driving_straight_into_a_wall_is_measured_right():
    robot = preset("rosbot")
    world = tutorial_world("stop_at_wall")          # wall face 3 m ahead of the start
    front = max(x for x, _ in robot.footprint)      # what touches it: the footprint (the default truth)
    speed = 0.5
    result = run_episode(world, robot, Constant(speed), config=EpisodeConfig(duration=12.0), seed=0, record=True)
    metrics = result.metrics
    ramp_time = speed / robot.a_max                  # accelerating at the limit from rest
    ramp_distance = 0.5 * speed * ramp_time
    expected_time = ramp_time + (3.0 - front - ramp_distance) / speed
    assert metrics.collided
    assert metrics.collision_time == pytest.approx(expected_time, abs=0.011)   # one physics step
    # The period in which it touched runs to its end: at most 0.05 s x 0.5 m/s further.
    assert 3.0 - front - 0.005 <= metrics.distance <= 3.0 - front + 0.026
    assert metrics.min_clearance < 0.0
    assert metrics.steps == len(result.trajectory.u) == math.ceil(metrics.collision_time / 0.05 - 1e-9)
    assert metrics.mean_intervention == 0.0 and metrics.statuses == {"none": metrics.steps}
    assert metrics.goal_reached is None and metrics.filter_times.size == 0


@pytest.mark.sim
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


@pytest.mark.sim
@pytest.mark.parametrize("give_pose", [False, True])
def test_with_the_odometry_pose_remembered_points_are_carried_exactly(give_pose):
    # The m2wr's 180-degree lidar leaves points behind it in the memory; dead reckoning from the
    # velocity adds half of each period's velocity change to their uncertainty, the pose adds none.
    robot = preset("m2wr")
    filt = CBFSafetyFilter(robot, 0.05)
    seen = []

    def watch(step, state, result):
        seen.append((len(filt.memory), float(filt.memory.uncertainty.max(initial=0.0))))

    run_episode(tutorial_world("wall_follower"), robot, Constant(0.3, 1.5), filt,
                config=EpisodeConfig(duration=2.0, give_pose=give_pose), seed=0, callback=watch)
    remembered = [uncertainty for count, uncertainty in seen if count]
    assert remembered
    if give_pose:
        assert max(remembered) == 0.0
    else:
        assert max(remembered) > 1e-3


@pytest.mark.sim
def test_goal_reached_ends_the_episode_with_its_time():
    robot = preset("puzzlebot")
    world = World("open", (Wall((5.0, -3.0), (5.0, 3.0)),), start=Pose2D(0.0, 0.0, 0.0), goal=(2.0, 0.0))
    result = run_episode(world, robot, GoToGoal(robot, world.goal), config=EpisodeConfig(duration=20.0), seed=0)
    metrics = result.metrics
    tolerance = EpisodeConfig().goal_tolerance
    assert metrics.goal_reached
    assert (2.0 - tolerance) / robot.v_max < metrics.time_to_goal < 2.0 / robot.v_max + 3.0
    assert metrics.goal_progress == pytest.approx(2.0, abs=0.31)
    assert metrics.time == metrics.time_to_goal


@pytest.mark.sim
def test_zones_baseline_gets_stuck_with_an_obstacle_in_its_stop_zone():
    robot = preset("rosbot")
    behind = -(robot.radius + 0.03 + 0.01)    # 3 cm behind the body, inside the 5 cm stop zone
    world = World("cornered", (Wall((behind, -1.0), (behind, 1.0), thickness=0.02),), start=Pose2D(0.0, 0.0, 0.0))
    result = run_episode(world, robot, Constant(0.4), ZonesFilter(robot, 0.05), config=EpisodeConfig(duration=3.0))
    assert result.metrics.distance < 1e-9            # stopped although it drives away from the wall
    assert result.metrics.stuck_time == pytest.approx(3.0)


@pytest.mark.sim
def test_filter_period_must_match_the_control_period():
    robot = preset("rosbot")
    with pytest.raises(InvalidConfig, match="differs from the control period"):
        run_episode(tutorial_world("stop_at_wall"), robot, Constant(0.1), CBFSafetyFilter(robot, 0.1))


def test_bad_episode_config_names_the_field():
    with pytest.raises(InvalidConfig, match=r"EpisodeConfig\.duration must be a finite number > 0"):
        EpisodeConfig(duration=0.0)
    with pytest.raises(InvalidConfig, match=r"EpisodeConfig\.stuck_window must be a finite number > 0"):
        EpisodeConfig(stuck_window=-1.0)


STEPS = np.arange(0.0, 5.0 + 1e-9, 0.05)      # 5 s of 50 ms periods [s]


def _poses(x=0.0, y=0.0, yaw=0.0):
    return np.column_stack(np.broadcast_arrays(x, y, yaw, STEPS)[:3])


@pytest.mark.parametrize(("poses", "stands"), [
    (_poses(), True),
    (_poses(x=0.03 * STEPS), False),                                     # 3 cm/s, steadily
    (_poses(x=0.015 * STEPS), True),                                     # 1.5 cm/s: under 2 cm/s
    (_poses(x=0.05 * np.abs(np.sin(2.0 * math.pi * STEPS))), True),      # back and forth at up to 0.3 m/s
    (_poses(yaw=3.1 + 0.1 * STEPS), False),                              # 0.1 rad/s, through +-pi
    (_poses(yaw=0.3 * np.sin(2.0 * math.pi * STEPS)), True),             # left and right at up to 1.9 rad/s
])
def test_a_robot_stands_when_it_got_nowhere_over_the_window_however_fast_it_shook(poses, stands):
    poses[:, 2] = wrap_angle(poses[:, 2])                                # yaw as a pose holds it
    stood = stationary(poses, STEPS, 0.02, 0.05, 1.0)
    assert stood[0]                                                      # the first pose has no past
    later = stood[STEPS >= 1.0]                                          # a full window behind it
    assert np.mean(later) >= 0.95 if stands else not later.any()



# ---------------------------------------------------------------------------------------------- liveness

ROSBOT_LIMITS = (1.0, 3.0)   # v_max [m/s], omega_max [rad/s]


@pytest.mark.parametrize(("nominal", "command", "expected"), [
    ((0.5, 0.0), (0.04, 0.0), True),      # keeps 0.04 * 0.5 / 0.25 = 8 % of the progress
    ((0.5, 0.0), (0.06, 0.0), False),     # 12 %
    ((0.5, 0.0), (0.0, 2.0), True),       # turning is no progress along a straight nominal
    ((0.0, 1.5), (-0.05, 0.3), False),    # 0.1 / 0.5 of a turn in place: 20 %
    ((0.0, 1.5), (0.0, -0.3), True),      # the other way
    ((2.0, 0.0), (0.09, 0.0), True),      # the nominal clipped to v_max first: 9 %
    ((2.0, 0.0), (0.1, 0.0), False),      # 10 % is enough
    ((0.04, 0.1), (0.0, 0.0), False),     # under 5 % of both limits: does not ask to move
    ((math.nan, 0.5), (0.0, 0.0), False),  # a non-finite nominal does not ask either
])
def test_a_period_stalls_when_the_command_keeps_under_a_tenth_of_the_nominals_progress(nominal, command, expected):
    assert stalled(np.array([nominal]), np.array([command]), ROSBOT_LIMITS).tolist() == [expected]


def _sequence(*parts: tuple[int, tuple[float, float], tuple[float, float], bool]):
    """Concatenate ``(periods, nominal, command, escaping)`` parts into per-period arrays."""
    nominal = np.vstack([np.tile(n, (k, 1)) for k, n, _, _ in parts])
    command = np.vstack([np.tile(u, (k, 1)) for k, _, u, _ in parts])
    escaping = np.concatenate([np.full(k, e) for k, _, _, e in parts])
    return nominal, command, escaping


GO, BLOCKED, TURN = (0.5, 0.0), (0.0, 0.0), (0.0, 1.0)


def test_deadlocks_are_runs_of_stalled_periods_and_a_blip_of_progress_does_not_end_one():
    dt = 0.1
    blip = round(RESUME_TIME / dt) - 1   # shorter than RESUME_TIME: bridged
    nominal, command, escaping = _sequence(
        (10, GO, GO, False),
        (30, GO, BLOCKED, False), (blip, GO, GO, False), (20, GO, BLOCKED, False),   # one deadlock: 5.1 s
        (10, GO, GO, False),
        (5, GO, BLOCKED, False),                                                    # 0.5 s: under 1.5 s
        (10, GO, GO, False),
        (16, GO, BLOCKED, False), (3, GO, GO, False), (16, GO, BLOCKED, False),     # 0.3 s of progress: two
    )
    result = liveness(nominal, command, escaping, dt, ROSBOT_LIMITS, min_deadlock=1.5)
    first = (30 + blip + 20) * dt
    assert result.longest_deadlock == pytest.approx(first)
    assert result.deadlock_time == pytest.approx(first + 1.6 + 1.6)
    assert (result.escapes_started, result.escapes_succeeded, result.escape_time) == (0, 0, 0.0)


def test_an_escape_succeeds_when_the_nominal_makes_progress_right_after_it_and_else_counts_as_deadlock():
    dt = 0.05
    nominal, command, escaping = _sequence(
        (30, GO, BLOCKED, False), (40, GO, TURN, True), (20, GO, GO, False),        # 1.5 s stall, 2 s escape: ok
        (30, GO, BLOCKED, False), (100, GO, TURN, True), (10, GO, BLOCKED, False),  # 5 s escape, blocked after
        (20, GO, GO, False),
    )
    result = liveness(nominal, command, escaping, dt, ROSBOT_LIMITS)
    assert (result.escapes_started, result.escapes_succeeded) == (2, 1)
    assert result.escape_time == pytest.approx(7.0)
    assert result.longest_deadlock == pytest.approx((30 + 100 + 10) * dt)       # the failed escape joins its stall
    assert result.deadlock_time == pytest.approx(1.5 + 7.0)


def test_an_escape_succeeds_when_progress_resumes_as_fast_as_the_base_can_turn_after_it():
    """The escape hands back heading away from where the nominal now points (a turn in place the other way):
    the base needs a period or two at its acceleration limits before the command keeps a tenth of the
    nominal's progress. That is progress resuming, not a failed escape (before, the escape's 6.7 s counted as
    deadlocked: goal_puzzlebot, CBF + escape, seed 9, which then reached its goal); a stall that outlasts
    ``RESUME_TIME`` after the escape is a failure as before."""
    dt, back = 0.05, (0.0, -ROSBOT_LIMITS[1])
    ramp = round(RESUME_TIME / dt)                     # stalled periods right after the escape, at most
    for ramping, succeeds in ((1, True), (ramp, True), (ramp + 1, False)):
        nominal, command, escaping = _sequence(
            (30, GO, BLOCKED, False), (130, GO, TURN, True),
            (ramping, back, (0.0, -0.05 * ROSBOT_LIMITS[1]), False), (20, back, back, False))
        result = liveness(nominal, command, escaping, dt, ROSBOT_LIMITS)
        assert result.escapes_succeeded == int(succeeds), ramping
        assert result.longest_deadlock == pytest.approx(1.5 if succeeds else (30 + 130 + ramping) * dt), ramping


def test_an_escape_cut_off_by_the_goal_succeeds_and_one_cut_off_by_the_time_limit_fails():
    nominal, command, escaping = _sequence((30, GO, BLOCKED, False), (50, GO, TURN, True))
    reached = liveness(nominal, command, escaping, 0.05, ROSBOT_LIMITS, goal_reached=True)
    timed_out = liveness(nominal, command, escaping, 0.05, ROSBOT_LIMITS, goal_reached=False)
    assert (reached.escapes_succeeded, reached.longest_deadlock) == (1, pytest.approx(1.5))
    assert (timed_out.escapes_succeeded, timed_out.longest_deadlock) == (0, pytest.approx(4.0))


def test_chatter_is_the_mean_yaw_rate_change_and_the_speed_reversals_per_second():
    commands = np.array([(0.2, 0.0), (0.0005, 0.5), (-0.1, -0.5), (0.0, -0.5), (0.3, -0.5)])
    result = liveness(np.tile(GO, (5, 1)), commands, np.zeros(5, dtype=bool), 0.1, ROSBOT_LIMITS)
    assert result.omega_chatter == pytest.approx((0.5 + 1.0 + 0.0 + 0.0) / 4 / 0.1)
    assert result.v_reversals == pytest.approx(2 / 0.5)   # +, (within the deadband), -, (0), +
    still = liveness(np.tile(GO, (1, 1)), np.array([(0.3, 1.0)]), np.zeros(1, dtype=bool), 0.1, ROSBOT_LIMITS)
    assert (still.omega_chatter, still.v_reversals) == (0.0, 0.0)
    assert math.isnan(result.escape_omega_chatter) and math.isnan(still.escape_omega_chatter)   # no escape drove


def test_the_nominals_chatter_and_the_chatter_while_escaping_are_told_apart():
    # The nominal flips its yaw rate (one period without a nominal); the escape drives periods 3-5 smoothly.
    nominal = np.array([(0.3, 1.0), (0.3, -1.0), (math.nan, math.nan), (0.3, 1.0), (0.3, -1.0), (0.3, 1.0)])
    commands = np.array([(0.2, 0.4), (0.2, -0.4), (0.0, 0.0), (0.2, 0.5), (0.2, 0.6), (0.2, 0.6)])
    escaping = np.array([False, False, False, True, True, True])
    result = liveness(nominal, commands, escaping, 0.1, ROSBOT_LIMITS)
    assert result.omega_chatter == pytest.approx((0.8 + 0.4 + 0.5 + 0.1 + 0.0) / 5 / 0.1)
    assert result.nominal_omega_chatter == pytest.approx((2.0 + 2.0 + 2.0) / 3 / 0.1)   # finite pairs only
    assert result.escape_omega_chatter == pytest.approx((0.1 + 0.0) / 2 / 0.1)          # pairs inside the escape


def _wall_ahead_with_goal_behind(robot):
    """A wall 3 m wide, its face 1 m ahead, the goal 3 m ahead straight behind it: a symmetric deadlock."""
    return World("wall", (Wall((1.05, -1.5), (1.05, 1.5)),), start=Pose2D(0.0, 0.0, 0.0), goal=(3.0, 0.0))


@pytest.mark.sim
def test_episode_deadlock_matches_what_the_filter_reports_and_the_escape_is_counted():
    robot = preset("rosbot")
    world = _wall_ahead_with_goal_behind(robot)
    config = EpisodeConfig(duration=40.0)
    reported: list[float] = []
    run = run_episode(world, robot, GoToGoal(robot, world.goal), make_filter("cbf", robot, 0.05), config=config,
                      callback=lambda step, state, result: reported.append(result.deadlock.time if result.deadlock
                                                                           else 0.0))
    metrics = run.metrics
    assert max(reported) >= 5.0                              # the filter itself reports a long deadlock
    assert metrics.longest_deadlock == pytest.approx(max(reported), abs=1e-9)
    assert metrics.deadlock_time == pytest.approx(max(reported), abs=1e-9)
    assert metrics.escapes_started == 0 and not metrics.goal_reached

    escaping: list[bool] = []
    escaped = run_episode(world, robot, GoToGoal(robot, world.goal), make_filter("cbf+escape", robot, 0.05),
                          config=config, callback=lambda step, state, result: escaping.append(bool(result.escape)))
    metrics = escaped.metrics
    assert metrics.escapes_started >= 1 and metrics.escape_time == pytest.approx(0.05 * sum(escaping))
    assert metrics.goal_reached and not metrics.collided
    assert metrics.escapes_succeeded == metrics.escapes_started and metrics.longest_deadlock < 5.0

"""The CBF filter's compute budget (half the period by default), with an injected clock and an injected slow QP solver.

With a budget, a QP that could not end within the call's budget (lasting as long as the longest QP of the
recent calls or of this call) is not begun: the filter brakes at the acceleration limits
(status ``FALLBACK``, reason family ``"deadline"``). The fast path solves nothing and is never
cut short.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from safenav import Pose2D, preset
from safenav.errors import InvalidConfig
from safenav.filters import CBFSafetyFilter, FilterStatus
from safenav.synthetic import Scene, synthetic_scan, wall
from tests.filters.test_mpc_deadline import SimulatedClock, SlowQP, ramp, slowed

DT = 0.05


def slow_cbf(robot, seconds: float, **settings) -> tuple[CBFSafetyFilter, SimulatedClock, SlowQP]:
    clock = SimulatedClock()
    safety = CBFSafetyFilter(robot, DT, clock=clock, **settings)
    slow = SlowQP(clock, seconds)
    safety.backend = slow
    return safety, clock, slow


def test_the_default_budget_is_half_the_period_and_one_can_be_given_or_none():
    assert CBFSafetyFilter(preset("rosbot"), 0.05).budget == pytest.approx(0.025)
    assert CBFSafetyFilter(preset("m2wr"), 0.02).config.budget == pytest.approx(0.01)
    assert CBFSafetyFilter(preset("rosbot"), 0.02, budget=0.004).budget == 0.004
    assert CBFSafetyFilter(preset("rosbot"), 0.02, budget=math.inf).budget == math.inf
    assert "default ``BUDGET_FRACTION = 0.5``" in CBFSafetyFilter.__doc__
    for bad in (0.0, -1.0, math.nan):
        with pytest.raises(InvalidConfig, match=r"CBFConfig.budget must be a number > 0, got"):
            CBFSafetyFilter(preset("rosbot"), 0.05, budget=bad)


def test_a_qp_that_cannot_end_within_the_budget_is_not_begun_and_the_filter_brakes():
    robot = preset("rosbot")
    budget = 0.01
    scan = synthetic_scan(robot, Scene.of(wall(0.6)))
    # Without a budget this call needs two QPs (it cannot brake in time: no command in the box keeps the wall's
    # row, which needs no QP to know, so the rows get slack, over two tiers).
    unlimited, _, counted = slow_cbf(robot, 0.6 * budget, budget=math.inf)
    answered = unlimited.filter((1.0, 0.0), scan, velocity=(0.5, 0.0))
    assert answered.status is FilterStatus.SLACK and counted.calls == 2
    # Each QP takes 0.6 of the budget: the first is begun, the second could not end in time.
    safety, clock, slow = slow_cbf(robot, 0.6 * budget, budget=budget)
    started = clock.now
    result = safety.filter((1.0, 0.0), scan, velocity=(0.5, 0.0))
    assert result.status is FilterStatus.FALLBACK and result.braked and result.reason.family == "deadline"
    assert result.timed_out and not answered.timed_out
    assert "no answer within the compute budget of 10 ms" in result.message
    assert "braking at the acceleration limits" in result.message
    assert result.u == pytest.approx(robot.brake((0.5, 0.0), DT))
    assert slow.calls == 1 and clock.now - started <= budget


def test_a_call_whose_perception_took_its_budget_brakes_before_its_first_qp_and_the_fast_path_still_answers():
    robot = preset("rosbot")
    budget = 0.01
    safety, clock, slow = slow_cbf(robot, 0.2 * budget, budget=budget)
    scan = synthetic_scan(robot, Scene.of(wall(0.6)))
    first = safety.filter((1.0, 0.0), scan, velocity=(0.5, 0.0))
    assert first.status is FilterStatus.SLACK and slow.calls == 2      # QPs of 0.2 budget, timed
    safety._observe = slowed(safety._observe, clock, 0.85 * budget)     # 0.15 of the budget left
    slow.calls = 0
    started = clock.now
    late = safety.filter((1.0, 0.0), scan, velocity=(0.5, 0.0))
    assert late.status is FilterStatus.FALLBACK and late.reason.family == "deadline"
    assert slow.calls == 0 and clock.now - started <= budget
    # A nominal that keeps every row needs no QP: answered as it is, whatever the time.
    safety._observe = slowed(safety._observe, clock, 0.2 * budget)      # now past the budget before any QP
    kept = safety.filter((0.0, 0.0), scan, velocity=(0.0, 0.0))
    assert kept.status is FilterStatus.OK and np.array_equal(kept.u, (0.0, 0.0)) and slow.calls == 0


def test_a_new_filters_first_qp_is_taken_to_last_a_share_of_the_budget():
    """Nothing timed yet: a first call whose perception took 0.7 of the budget does not begin a QP
    (taken to last RESERVE_SHARE, with as much kept for the answer) that would take it past the budget."""
    robot = preset("rosbot")
    budget = 0.01
    safety, clock, slow = slow_cbf(robot, 0.4 * budget, budget=budget)
    safety._observe = slowed(safety._observe, clock, 0.7 * budget)
    result = safety.filter((1.0, 0.0), synthetic_scan(robot, Scene.of(wall(0.6))), velocity=(0.5, 0.0))
    assert result.status is FilterStatus.FALLBACK and result.reason.family == "deadline"
    assert slow.calls == 0 and clock.now <= budget


@pytest.mark.parametrize("name", ["rosbot", "m2wr"])
def test_closed_loop_with_qps_too_slow_for_every_slack_tier_keeps_the_margin(name):
    """Full speed at a wall with every QP taking 0.4 of the budget: a call that needs a third QP
    (the slack tiers) brakes instead; the robot comes to rest before the wall and keeps its margin."""
    robot = preset(name)
    budget = 0.01
    safety, clock, slow = slow_cbf(robot, 0.4 * budget, budget=budget)
    scene = Scene.of(wall(1.3))
    pose, velocity, worst = Pose2D(), np.array([robot.v_max, 0.0]), math.inf
    deadlines = solved_since = 0
    for _ in range(80):
        started = clock.now
        result = safety.filter((robot.v_max, 0.0), synthetic_scan(robot, scene, pose), velocity=velocity)
        assert clock.now - started <= budget + slow.seconds + 1e-12
        deadline = result.reason is not None and result.reason.family == "deadline"
        solved_since += deadlines > 0 and bool(result.solver) and not deadline   # each call timed afresh
        deadlines += deadline
        pose, velocity, clearance = ramp(robot, pose, velocity, result.u, scene)
        worst = min(worst, clearance)
    assert deadlines >= 1 and solved_since >= 1
    assert worst >= safety.margin - 1e-4
    assert abs(velocity[0]) < 0.02                          # come to (nearly) rest in front of the wall

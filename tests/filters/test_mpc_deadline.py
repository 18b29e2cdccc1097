"""The MPC filter's compute budget, with an injected clock and an injected slow QP solver (deterministic).

When the optimisation cannot finish within the budget the filter abandons it and follows the
next command of its last verified plan, which ends stopped (status ``FALLBACK``, reason family
``"deadline"``); the next call starts afresh, so it is on time too.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from safenav import Pose2D, preset, unicycle_step
from safenav.filters import FilterStatus, MPCSafetyFilter
from safenav.filters.qp import DirectDAQP, QPData, QPOutcome
from safenav.synthetic import Scene, synthetic_scan, wall

DT = 0.05


class SimulatedClock:
    """A clock that only moves when told to [s]."""

    def __init__(self) -> None:
        self.now = 0.0

    def __call__(self) -> float:
        return self.now


class SlowQP:
    """DAQP, but each QP takes ``seconds`` of the simulated clock (a slow or overloaded computer)."""

    name = "slow-daqp"
    direct_rows = 512

    def __init__(self, clock: SimulatedClock, seconds: float) -> None:
        self.clock, self.seconds = clock, seconds
        self.solver = DirectDAQP()
        self.calls = 0

    def solve(self, qp: QPData) -> QPOutcome:
        self.calls += 1
        self.clock.now += self.seconds
        return self.solver.solve(qp)


def slow_filter(robot, seconds: float, **settings) -> tuple[MPCSafetyFilter, SimulatedClock, SlowQP]:
    clock = SimulatedClock()
    safety = MPCSafetyFilter(robot, DT, clock=clock, **settings)
    slow = SlowQP(clock, seconds)
    safety.backend.qp = slow
    return safety, clock, slow


def ramp(robot, pose, velocity, command, scene, substeps=5):
    """One period of a base ramping at its limits; the new pose, velocity and the smallest clearance."""
    worst = math.inf
    for _ in range(substeps):
        velocity = robot.clip(command, velocity, DT / substeps)
        pose = unicycle_step(pose, float(velocity[0]), float(velocity[1]), DT / substeps)
        worst = min(worst, scene.clearance((pose.x, pose.y), robot.radius))
    return pose, velocity, worst


def test_the_default_budget_is_half_the_period_and_documented():
    assert MPCSafetyFilter(preset("rosbot"), 0.05).budget == pytest.approx(0.025)
    assert MPCSafetyFilter(preset("rosbot"), 0.02).budget == pytest.approx(0.01)
    assert MPCSafetyFilter(preset("rosbot"), 0.05, budget=0.004).budget == 0.004
    assert "BUDGET_FRACTION = 0.5" in MPCSafetyFilter.__doc__


def test_a_solve_past_the_budget_follows_the_stored_plan_and_the_call_ends_on_time():
    robot = preset("rosbot")
    budget = 0.01
    safety, clock, slow = slow_filter(robot, seconds=0.0, budget=budget)
    scan = synthetic_scan(robot, Scene.of(wall(0.45)))
    first = safety.filter((1.0, 0.0), scan, velocity=(0.8, 0.0))
    assert first.status is FilterStatus.OK and first.solver and slow.calls > 0   # a verified plan is stored
    slow.seconds = 0.6 * budget     # from now on each QP takes 60 % of the budget
    slow.calls = 0
    started = clock.now
    late = safety.filter((1.0, 2.5), scan, velocity=tuple(first.u))   # a new nominal: several SQP iterations
    assert late.status is FilterStatus.FALLBACK and late.braked
    assert late.reason.family == "deadline" and "following the last verified plan" in late.message
    # the stored plan's next command (to rounding: it is clipped to this call's reachable box, on whose edge it lies)
    np.testing.assert_allclose(late.u, first.plan[2, 3:], rtol=0.0, atol=1e-12)
    assert np.all(late.plan[-1, 3:] == 0.0)                        # which ends stopped
    # Abandoned at the first check past the budget: at most one QP of overrun.
    assert clock.now - started <= budget + slow.seconds + 1e-12
    assert slow.calls >= 2


def test_a_stored_plan_that_crosses_a_wall_seen_since_gives_way_to_braking():
    # The plan of the first call was verified in free space; the next scan shows a wall across it and the
    # solve misses the budget. Following the plan would drive into the wall (it was verified against
    # the points seen then): the filter brakes at its limits, which keeps more clearance, and says why.
    robot = preset("rosbot")
    budget = 0.01
    safety, _, slow = slow_filter(robot, seconds=0.0, budget=budget)
    first = safety.filter((1.0, 0.0), synthetic_scan(robot, Scene.of(wall(0.45))), velocity=(0.8, 0.0))
    assert first.status is FilterStatus.OK and first.solver       # a solved plan: on, then braking late
    slow.seconds = 2.0 * budget
    late = safety.filter((1.0, 0.0), synthetic_scan(robot, Scene.of(wall(0.36))), velocity=tuple(first.u))
    assert late.status is FilterStatus.FALLBACK and late.reason.family == "deadline"
    assert "too near a point seen since: braking at the acceleration limits" in late.message
    assert late.u == pytest.approx(robot.brake(first.u, DT))
    # A stored plan that still keeps clear is followed as before (the test above).


def test_without_a_stored_plan_the_deadline_brakes_at_the_acceleration_limits():
    robot = preset("rosbot")
    safety, _, _ = slow_filter(robot, seconds=0.02, budget=0.01)
    result = safety.filter((1.0, 0.0), synthetic_scan(robot, Scene.of(wall(0.35))), velocity=(0.8, 0.2))
    assert result.status is FilterStatus.FALLBACK and result.reason.family == "deadline"
    assert "no verified plan" in result.message
    assert result.u == pytest.approx(robot.brake((0.8, 0.2), DT))


@pytest.mark.parametrize("name", ["rosbot", "m2wr"])
def test_closed_loop_with_a_solver_that_misses_every_deadline_keeps_the_margin(name):
    """Full speed at a wall; after the first solve every QP takes a whole period: each call falls back
    to the last verified plan (shifted once more each time), and the robot stops before the wall."""
    robot = preset(name)
    safety, clock, slow = slow_filter(robot, seconds=0.0)
    scene = Scene.of(wall(1.3))
    pose, velocity, worst = Pose2D(), np.array([robot.v_max, 0.0]), math.inf
    statuses = []
    for _ in range(60):
        clock.now += DT
        started = clock.now
        result = safety.filter((robot.v_max, 0.0), synthetic_scan(robot, scene, pose), velocity=velocity)
        statuses.append(result.status)
        assert clock.now - started <= safety.budget + slow.seconds + 1e-12      # every call on time
        if result.status is FilterStatus.OK and result.solver:
            slow.seconds = DT
        pose, velocity, clearance = ramp(robot, pose, velocity, result.u, scene)
        worst = min(worst, clearance)
    fallbacks = [s for s in statuses if s is FilterStatus.FALLBACK]
    assert len(fallbacks) > 10
    assert worst >= safety.margin - 1e-4                     # no contact, the margin kept
    assert np.allclose(velocity, 0.0)                        # the stored plan ended stopped


def test_an_unlimited_budget_never_falls_back_on_time():
    robot = preset("rosbot")
    safety, _, _ = slow_filter(robot, seconds=1.0, budget=math.inf)
    result = safety.filter((1.0, 0.0), synthetic_scan(robot, Scene.of(wall(0.45))), velocity=(0.8, 0.0))
    assert result.status is FilterStatus.OK and result.solver

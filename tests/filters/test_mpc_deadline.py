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
from safenav.filters.deadline import TAIL_WINDOW
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
    # Abandoned at the first check where another QP (as long as the first) would end past the budget.
    assert clock.now - started <= budget
    assert slow.calls == 1


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


def slowed(method, clock: SimulatedClock, seconds: float):
    """``method``, taking ``seconds`` of the simulated clock at each call."""
    def slow(*args, **kwargs):
        clock.now += seconds
        return method(*args, **kwargs)
    return slow


@pytest.mark.parametrize(("name", "perception", "check", "qps"), [
    ("rosbot", 0.15, 0.1, (0.1, 0.2, 0.25)), ("m2wr", 0.15, 0.1, (0.1, 0.2, 0.25)),
    ("rosbot", 0.1, 0.1, (0.1, 0.2, 0.25)), ("rosbot", 0.1, 0.1, (0.2,)), ("m2wr", 0.3, 0.05, (0.12, 0.17, 0.22))])
def test_the_whole_call_ends_within_the_budget_perception_steps_and_verification_included(name, perception, check,
                                                                                         qps):
    """The budget is the call's, from its start: the perception before the solve and the
    verification and answer after it take time of it too. Here each takes a share of the budget
    (``perception`` per call, ``check`` per verification of a plan) and each QP one of ``qps``
    (by turns, one per call; at most RESERVE_SHARE of the budget, the most a step from earlier
    calls is taken to last): the solver begins a step only when that step and the call's tail
    (verifying and answering, as long as the recent calls' tails) fit before the call's end.
    Every call, the filter's first solving one included (nothing timed yet: a step and the tail are
    taken to last RESERVE_SHARE of the budget), ends within its budget, solved or following its
    stored plan, unless its tail is longer than every tail measured before it (a verification more
    than before); the robot keeps its margin."""
    robot = preset(name)
    budget = 0.01
    safety, clock, slow = slow_filter(robot, seconds=0.0, budget=budget)
    safety._observe = slowed(safety._observe, clock, perception * budget)
    safety.check_plan = slowed(safety.check_plan, clock, check * budget)
    scene = Scene.of(wall(1.3))
    pose, velocity, worst = Pose2D(), np.array([0.5 * robot.v_max, 0.0]), math.inf
    late, solved, fallbacks, new_tails = [], 0, 0, 0
    tails = safety._budget._tails
    for k in range(60):
        slow.seconds = qps[k % len(qps)] * budget
        started, reserve, measured = clock.now, safety._budget.reserve, len(tails)
        result = safety.filter((robot.v_max, 0.0), synthetic_scan(robot, scene, pose), velocity=velocity)
        longer_tail = len(tails) > measured and tails[-1] > reserve + 1e-12
        new_tails += longer_tail
        if clock.now - started > budget + 1e-12 and not longer_tail:
            late.append((k, clock.now - started))
        deadline = result.reason is not None and result.reason.family == "deadline"
        fallbacks += deadline
        solved += bool(result.solver) and result.status is FilterStatus.OK and not deadline
        pose, velocity, clearance = ramp(robot, pose, velocity, result.u, scene)
        worst = min(worst, clearance)
    assert solved >= 3 and fallbacks >= 3
    assert late == []
    assert new_tails <= 2       # a longer tail is measured, then kept for the next calls
    assert worst >= safety.margin - 1e-4


def test_a_call_begins_no_step_longer_than_the_recent_calls_steps_could_take():
    """The first step of a call is taken to last as long as the longest step of the recent calls:
    a call whose perception has used up all but less than that gives up before its first QP
    and still ends within its budget."""
    robot = preset("rosbot")
    budget = 0.01
    safety, clock, slow = slow_filter(robot, seconds=0.2 * budget, budget=budget)
    scan = synthetic_scan(robot, Scene.of(wall(0.45)))
    first = safety.filter((1.0, 0.0), scan, velocity=(0.8, 0.0))
    # Steps of 0.2 budget measured (three begun: a fourth, taken to last a quarter, would end in the reserve).
    assert first.solver and slow.calls == 3
    first = safety.filter((1.0, 0.0), scan, velocity=(0.8, 0.0))    # now with the measured estimates
    assert first.status is FilterStatus.OK and first.solver
    observe = safety._observe
    safety._observe = slowed(observe, clock, 0.85 * budget)     # a slow perception: 0.15 of the budget left
    slow.calls = 0
    started = clock.now
    late = safety.filter((1.0, 2.5), scan, velocity=tuple(first.u))
    assert late.status is FilterStatus.FALLBACK and late.reason.family == "deadline"
    assert slow.calls == 0 and clock.now - started <= budget
    safety._observe = slowed(observe, clock, 0.7 * budget)      # 0.3 left: a step of 0.2 fits, a second not
    started = clock.now
    again = safety.filter((1.0, 2.5), scan, velocity=tuple(first.u))
    assert slow.calls == 1 and clock.now - started <= budget and again.reason.family == "deadline"


def test_a_new_filters_first_solving_call_ends_within_its_budget():
    """Nothing timed yet: the first step is taken to last RESERVE_SHARE of the budget, and as much is
    kept for the verification, so a first call whose perception took 0.6 of the budget does not
    begin a QP of 0.3 (it would end at 0.9 and the verification after it)."""
    robot = preset("rosbot")
    budget = 0.01
    safety, clock, slow = slow_filter(robot, seconds=0.3 * budget, budget=budget)
    safety._observe = slowed(safety._observe, clock, 0.6 * budget)
    safety.check_plan = slowed(safety.check_plan, clock, 0.05 * budget)
    result = safety.filter((1.0, 0.0), synthetic_scan(robot, Scene.of(wall(0.45))), velocity=(0.8, 0.0))
    assert result.status is FilterStatus.FALLBACK and result.reason.family == "deadline"
    assert slow.calls == 0 and clock.now <= budget
    # With the perception at 0.4 of the budget the first QP fits (0.4 + 0.25 <= 0.75), the second not.
    safety, clock, slow = slow_filter(robot, seconds=0.2 * budget, budget=budget)
    safety._observe = slowed(safety._observe, clock, 0.4 * budget)
    result = safety.filter((1.0, 0.0), synthetic_scan(robot, Scene.of(wall(0.45))), velocity=(0.8, 0.0))
    assert slow.calls >= 1 and clock.now <= budget


def test_the_cbf_reference_has_no_budget_of_its_own():
    """With ``reference="cbf"`` the reference's call is not cut short (only the MPC's solve is): a
    reference QP begun after a perception of 0.6 of the budget is solved, not braked for a deadline."""
    robot = preset("rosbot")
    budget = 0.01
    clock = SimulatedClock()
    safety = MPCSafetyFilter(robot, DT, clock=clock, budget=budget, reference="cbf")
    assert safety.budget == budget and safety.reference.budget == math.inf
    slow = SlowQP(clock, 0.3 * budget)
    safety.reference.backend = slow
    safety.reference._observe = slowed(safety.reference._observe, clock, 0.6 * budget)
    result = safety.filter((1.0, 0.0), synthetic_scan(robot, Scene.of(wall(0.6))), velocity=(0.5, 0.0))
    assert slow.calls >= 1
    assert "the cbf reference (fallback)" not in result.message


def test_one_preempted_step_does_not_make_the_next_calls_give_up():
    """A step from earlier calls is taken to last at most RESERVE_SHARE of the budget: one QP
    that took three budgets (the process was preempted) does not make every later call give up
    before its first QP."""
    robot = preset("rosbot")
    budget = 0.01
    safety, clock, slow = slow_filter(robot, seconds=3.0 * budget, budget=budget)
    scan = synthetic_scan(robot, Scene.of(wall(0.45)))
    preempted = safety.filter((1.0, 0.0), scan, velocity=(0.8, 0.0))
    assert slow.calls == 1 and clock.now >= 3.0 * budget
    slow.seconds = 0.05 * budget
    velocity = tuple(preempted.u)
    answers = []
    for turn in (2.5, -2.5, 1.5):
        result = safety.filter((1.0, turn), scan, velocity=velocity)
        answers.append(result)
        velocity = tuple(result.u)
    assert all(result.status is FilterStatus.OK for result in answers)
    assert any(result.solver for result in answers)
    # The preempted step leaves the estimate once TAIL_WINDOW solving calls have been timed since:
    # a call with 0.2 of its budget left after the perception then begins a step of 0.05.
    solving, turn = 0, 2.5
    while solving <= TAIL_WINDOW:
        result = safety.filter((1.0, turn), scan, velocity=velocity)
        solving += bool(result.solver)
        velocity, turn = tuple(result.u), -turn
    safety._observe = slowed(safety._observe, clock, 0.8 * budget)
    slow.calls = 0
    safety.filter((1.0, turn), scan, velocity=velocity)
    assert slow.calls >= 1

"""safenav/filters/deadline.py: a call's budget and a solver's steps against it, on a simulated clock."""

from __future__ import annotations

import math

import pytest

from safenav.filters.deadline import RESERVE_SHARE, TAIL_WINDOW, CallBudget, StepClock
from tests.filters.test_mpc_deadline import SimulatedClock


def test_outside_a_call_the_deadline_counts_from_now_and_begins_nothing():
    clock = SimulatedClock()
    budget = CallBudget(0.01, clock)
    clock.now = 5.0
    assert budget.solver_deadline() == pytest.approx(5.01 - RESERVE_SHARE * 0.01)   # nothing timed: a share kept
    assert budget.start is None          # a filter's next call still begins its own budget
    budget.begin()
    clock.now = 5.004
    assert budget.deadline == pytest.approx(5.01) and budget.spent() == pytest.approx(0.004)
    budget.end()
    assert budget.start is None
    assert CallBudget(math.inf, clock).solver_deadline() == math.inf


def test_the_estimates_are_the_longest_of_the_last_calls_within_a_share_of_the_budget():
    clock = SimulatedClock()
    budget = CallBudget(0.01, clock)
    for step, tail in [(0.001, 0.0005), (0.004, 0.003), *[(0.0002, 0.0001)] * (TAIL_WINDOW - 1)]:
        budget.begin()
        clock.now += step
        budget.returned(step)
        clock.now += tail
        budget.end()
    budget.begin()
    # The longest step (0.004) and tail (0.003) are within the last TAIL_WINDOW calls, capped at a quarter.
    assert budget.step == pytest.approx(RESERVE_SHARE * 0.01) and budget.reserve == pytest.approx(0.0025)
    budget.end()
    for _ in range(2):      # two more calls push the long ones out of the window
        budget.begin()
        clock.now += 0.0002
        budget.returned(0.0002)
        clock.now += 0.0001
        budget.end()
    budget.begin()
    assert budget.step == pytest.approx(0.0002) and budget.reserve == pytest.approx(0.0001)


def test_a_step_is_begun_only_when_it_can_end_before_the_deadline():
    clock = SimulatedClock()
    steps = StepClock(deadline=1.0, clock=clock, step=0.3)
    assert not steps.late()              # 0 + 0.3 <= 1
    clock.now = 0.6                      # the first step took 0.6
    assert steps.late()                  # 0.6 + 0.6 > 1
    assert steps.finished() == pytest.approx(0.6)     # measured, the estimate given left out
    fresh = StepClock(deadline=1.0, clock=clock, step=0.4)
    clock.now = 0.55
    assert not fresh.late() and fresh.finished() == 0.0


def test_before_any_step_is_timed_a_step_and_the_tail_are_taken_to_last_the_share_of_the_budget():
    """A new filter's first solving calls are held to the same estimates as later ones: until a step
    (a tail) has been measured, it is taken to last RESERVE_SHARE of the budget."""
    clock = SimulatedClock()
    budget = CallBudget(0.01, clock)
    share = RESERVE_SHARE * 0.01
    budget.begin()
    assert budget.step == pytest.approx(share) and budget.reserve == pytest.approx(share)
    assert budget.solver_deadline() == pytest.approx(0.01 - share)
    budget.returned(0.0)                 # the solver gave up before its first step: no step measured
    clock.now += 0.0001
    budget.end()
    budget.begin()
    assert budget.step == pytest.approx(share) and budget.reserve == pytest.approx(0.0001)
    budget.returned(0.001)
    clock.now += 0.0002
    budget.end()
    budget.begin()
    assert budget.step == pytest.approx(0.001) and budget.reserve == pytest.approx(0.0002)
    unlimited = CallBudget(math.inf, clock)
    unlimited.begin()
    assert unlimited.step == 0.0 and unlimited.reserve == 0.0 and unlimited.solver_deadline() == math.inf


def test_a_solver_that_gives_up_at_a_check_measures_no_step_after_it():
    clock = SimulatedClock()
    steps = StepClock(deadline=1.0, clock=clock, step=0.3)
    clock.now = 0.8
    assert steps.late()                  # 0.8 + 0.3 > 1: nothing begun
    clock.now = 0.9                      # what the solver does on its way out is no step
    assert steps.finished() == 0.0
    running = StepClock(deadline=1.0, clock=clock, step=0.05)
    assert not running.late()            # begun at 0.9
    clock.now = 0.95
    assert running.finished() == pytest.approx(0.05)
